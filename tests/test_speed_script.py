"""benchmarks/speed.py: the README's latency file is never overwritten by a subset's timings."""

import pytest
from bench import load_benchmark
from synthetic import tiny_generator_file


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


# Which weights a published number measured (the reproducibility audit of walk 67): a card's
# test row must name its file's digest, rows without one whose file is gone are counted, and
# the README's latencies are checked against the files they timed.


def test_speed_records_the_hash_of_each_file_it_times(tmp_path, monkeypatch):
    speed = load_benchmark("speed")
    path = tmp_path / "d" / "generator.safetensors"
    digest = tiny_generator_file(path, seed=1)

    class Split:
        num_agents = 3

        def __len__(self):
            return 3

    written = {}
    monkeypatch.setattr(speed.zoo, "generators", lambda datasets: {"d/generator": path})
    monkeypatch.setattr(speed, "load_dataset", lambda *a: Split())
    monkeypatch.setattr(speed.ckpt, "load_predictor", lambda *a, **k: None)
    monkeypatch.setattr(speed, "time_predictors",
                        lambda *a: {"scenes": 3, "leapfrog": 1.0, "full": 40.0})  # fmt: skip
    monkeypatch.setattr(speed, "write_meta", lambda out, **fields: written.update(fields))
    monkeypatch.setattr("sys.argv", ["speed.py", "--out", str(tmp_path / "speed.json")])
    speed.main()
    assert written["models"]["d/generator"]["model_hash"] == digest
