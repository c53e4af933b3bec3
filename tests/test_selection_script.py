"""benchmarks/selection.py: options that select a validation split refuse a test split; the
rows a run writes."""

import json
import sys

import pytest
from bench import load_benchmark


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--split", "test", "--holdout-scene", "biwi_hotel"], "--holdout-scene"),
        (["--split", "val", "--holdout-scene", ""], "--holdout-scene"),
        (["--split", "test", "--stretch", "1.6"], "--stretch"),
    ],
)
def test_validation_only_options_refuse_before_reading_anything(argv, message, monkeypatch, capsys):
    sel = load_benchmark("selection")
    monkeypatch.setattr(sys, "argv", ["selection.py", "--dataset", "eth", *argv])
    with pytest.raises(SystemExit) as exc:
        sel.main()
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_speed_normalised_scoring_names_the_score_rows_only(tmp_path, monkeypatch, tiny_run, walks):
    sel = load_benchmark("selection")
    monkeypatch.setattr(sel, "ROOT", tmp_path)
    (tmp_path / "benchmarks" / "results").mkdir(parents=True)
    argv = ["selection.py", "--dataset", str(walks), "--model",
            str(tiny_run / "generator.safetensors"), "--split", "test", "--samples", "4",
            "--keep", "2", "--methods", "kmeans", "score-facility", "--drop", "0.3",
            "--temperature", "2", "--score-every", "40", "--speed-norm", "0.5"]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    sel.main()
    (rows_file,) = (tmp_path / "benchmarks" / "results").glob("select_*.json")
    methods = {r["method"]: r["uses_score"] for r in json.loads(rows_file.read_text())}
    assert methods == {"select-kmeans": False, "select-score-facility-d30-t2-sn50": True}
