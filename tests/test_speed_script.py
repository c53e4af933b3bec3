"""benchmarks/speed.py: the README's latency file is never overwritten by a subset's timings."""

import pytest
from bench import load_benchmark


def test_a_subset_into_the_shared_file_is_refused_before_anything_is_timed(monkeypatch, capsys):
    speed = load_benchmark("speed")
    monkeypatch.setattr(speed.zoo, "generators", lambda *a: pytest.fail("timed a model"))
    monkeypatch.setattr("sys.argv", ["speed.py", "--datasets", "univ"])
    with pytest.raises(SystemExit):
        speed.main()
    assert "time a subset with --out somewhere else" in capsys.readouterr().err


def test_a_subset_may_be_timed_into_another_file(monkeypatch, tmp_path):
    speed = load_benchmark("speed")
    asked = []
    monkeypatch.setattr(speed.zoo, "generators", lambda datasets: asked.append(datasets) or {})
    out = tmp_path / "speed_univ.json"
    monkeypatch.setattr("sys.argv", ["speed.py", "--datasets", "univ", "--out", str(out)])
    with pytest.raises(SystemExit):  # no published generator matches: a clear parser error
        speed.main()
    assert asked == [["univ"]]
