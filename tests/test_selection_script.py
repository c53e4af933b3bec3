"""benchmarks/selection.py: options that select a validation split refuse a test split."""

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
