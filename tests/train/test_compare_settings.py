"""``trajpref compare`` warns of runs validated on other data or settings (walkthrough 66: a
run validated on a tiny folder, or on feet against metres, printed +74.8 % / +269.6 % without
a word); the tables still print."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

from trajpref.cli import main
from trajpref.config import ExperimentConfig, save_config
from trajpref.models import checkpoint as ckpt
from trajpref.train import compare


def _run(path: Path, **data) -> Path:
    """A generator run folder validated at epochs 1 and 2, its config's data (and
    ``samples``) as given."""
    path.mkdir(parents=True)
    rows = [{"epoch": e, "val_min_ade": 0.3 / e, "val_min_fde": 0.6 / e, "val_score": 0.9 / e}
            for e in (1, 2)]  # fmt: skip
    (path / "generator_metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    cfg = ExperimentConfig()
    cfg.generator.epochs = 2
    cfg.model.samples = data.pop("samples", cfg.model.samples)
    cfg.model.t_fut = data.pop("t_fut", cfg.model.t_fut)
    for key, value in data.items():
        setattr(cfg.data, key, value)
    save_config(cfg, path / "generator_config.yaml")
    return path


def _compare(capsys, *groups):
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code = main(["compare", *map(str, groups)])
    return code, *capsys.readouterr()


def test_runs_validated_on_other_data_are_named_with_their_fields(tmp_path, capsys):
    a = _run(tmp_path / "a", dataset="/data/m", units="m", time_step=4.0)
    b = _run(tmp_path / "b", dataset="/data/tiny", units="m", time_step=4.0,
             val_dataset="/data/tinyval")  # fmt: skip
    c = _run(tmp_path / "c", dataset="/data/m", units="ft", time_step=1.0, samples=4)
    code, out, err = _compare(capsys, f"control={a}", f"tiny={b}", f"feet={c}")
    assert code == 0 and "| control |" in out and "change against the first" in out
    lines = [line for line in err.splitlines() if "validated otherwise" in line]
    assert len(lines) == 2
    assert lines[0].startswith(f"trajpref: warning: {b} was validated otherwise than {a} ("
                               "data.dataset /data/m -> /data/tiny; validated on its own val "
                               "split -> /data/tinyval's val split)")  # fmt: skip
    assert "units m -> ft; data.time_step 4.0 -> 1.0; model.samples 20 -> 4" in lines[1]


def test_runs_alike_say_nothing(tmp_path, capsys):
    a = _run(tmp_path / "a", dataset="/data/m", units="m")
    b = _run(tmp_path / "b", dataset="/data/m", units="metres")
    code, _, err = _compare(capsys, f"control={a}", f"candidate={b}")
    assert code == 0 and "validated otherwise" not in err


def test_the_checkpoints_step_and_units_are_compared(tmp_path, tiny_run):
    a = _run(tmp_path / "a", dataset="/data/m")
    b = _run(tmp_path / "b", dataset="/data/m")
    for run, step in ((a, 0.4), (b, 0.1)):
        payload = ckpt.load(tiny_run / "generator.safetensors")
        payload["meta"]["data_timing"] = {"frame_interval": step, "interval_from": "given",
                                          "time_step": 1.0, "units": "m"}  # fmt: skip
        ckpt.save(run / "generator.safetensors", payload)
    metrics = ("val_min_ade",)
    groups = {"a": [compare.read_curve(a, "generator", metrics)],
              "b": [compare.read_curve(b, "generator", metrics)]}  # fmt: skip
    assert compare.setting_differences(groups) == [
        f"{b} was validated otherwise than {a} (seconds per step 0.4 -> 0.1): its numbers and "
        "their change are not measured alike"
    ]


def test_units_one_run_cannot_tell_are_not_a_difference(tmp_path, capsys):
    """A built-in dataset's config leaves its units to the dataset (None) and a run without its
    checkpoint cannot say them: an identical run was reported as 'units m -> unknown'."""

    def curve(run: str, units: str | None) -> compare.RunCurve:
        setting = {"data.dataset": "zara1", "validated on": "its own val split", "units": units}
        return compare.RunCurve(run, 2, {1: {"val_score": 1.0}}, 1, setting=setting)

    with_file, without = curve("a", "m"), curve("b", None)  # b: its checkpoint deleted
    assert compare.setting_differences({"a": [with_file], "b": [without]}) == []
    other = curve("c", "ft")
    assert "units m -> ft" in compare.setting_differences({"a": [with_file], "c": [other]})[0]


def test_runs_of_other_window_lengths_are_named(tmp_path, capsys):
    """A minFDE over 16 future frames is not one over 12: the horizons differ in words."""
    a = _run(tmp_path / "a", dataset="/data/m")
    b = _run(tmp_path / "b", dataset="/data/m", t_fut=16)
    code, _, err = _compare(capsys, f"control={a}", f"longer={b}")
    assert code == 0
    assert "(windows 8 + 12 frames -> 8 + 16 frames)" in err
