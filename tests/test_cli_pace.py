"""The pace and units of a user's own data: a model trained on a folder records its frame
interval, time step and units, and evaluate/predict/plot warn in one line when data step
otherwise; the advice given is one the data can take."""

from __future__ import annotations

import json
from decimal import Decimal
from pathlib import Path

import pytest
from helpers import ZARA1
from synthetic import TINY_OVERRIDES

from trajpref import cli
from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.io import read_checkpoint_header

PACE = "this data steps 0.1 s, the model's 0.4 s (--time-step 4 reads it at the model's step)"


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _logged(root: Path, frames: int = 120) -> Path:
    """A robot's logs at 10 Hz, ``timestamp,id,x,y`` in seconds, split into train/val/test:
    three walkers each, 1.2 m/s along x."""
    for split, start in (("train", "12.3"), ("val", "40.0"), ("test", "60.5")):
        rows = []
        for k in range(frames):
            t = Decimal(start) + k * Decimal("0.1")
            rows += [f"{t},{a},{0.12 * k + a:.3f},{0.5 * a:.3f}" for a in (1, 2, 3)]
        folder = root / split
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"log_{split}.csv").write_text("timestamp,id,x,y\n" + "\n".join(rows) + "\n")
    return root


@pytest.fixture(scope="module")
def logged(tmp_path_factory) -> Path:
    return _logged(tmp_path_factory.mktemp("logged"))


@pytest.fixture(scope="module")
def paced_run(tmp_path_factory, logged) -> Path:
    """Both stages trained on ``logged`` read every 4 steps (0.4 s), through the CLI."""
    out = tmp_path_factory.mktemp("paced")
    sets = [a for o in TINY_OVERRIDES for a in ("--set", o)]
    for stage in ("diffusion", "generator"):
        code = main(["train", stage, "--dataset", str(logged), "--time-step", "4", "--units",
                     "m", "--out", str(out), "--device", "cpu", "--no-progress",
                     *sets])  # fmt: skip
        assert code == 0
    return out


def test_a_model_trained_on_a_folder_records_its_pace_and_units(paced_run, logged):
    header = read_checkpoint_header(paced_run / "generator.safetensors")
    data = header["config"]["data"]
    assert (data["time_step"], data["units"], data["frame_interval"]) == (4.0, "m", None)
    # the interval comes from the timestamps (0.1 s), times the time step
    assert header["meta"]["data_timing"] == {"frame_interval": pytest.approx(0.4),
                                             "interval_from": "timestamps", "time_step": 4.0,
                                             "units": "m", "agent_types": [0]}  # fmt: skip


def test_data_at_another_step_than_the_models_is_named_in_one_line(capsys, paced_run, logged,
                                                                    tmp_path):  # fmt: skip
    model = paced_run / "generator.safetensors"
    base = ["--dataset", logged, "--model", model, "--samples", "4", "--no-progress",
            "--device", "cpu"]  # fmt: skip
    warning = f"trajpref: warning: {model} was trained on {logged}: {PACE}\n"
    # forgetting --time-step: 0.1 s histories for a 0.4 s model, now said in every command
    for command in (["evaluate"], ["predict", "--rank", "--out", tmp_path / "p.npz"],
                    ["plot", "--out", tmp_path / "p.png"]):  # fmt: skip
        code, _, err = _run(capsys, *command, *base)
        assert (code, err) == (0, warning), command
    # read as the model was (its units too, else they are asked for): silent
    code, _, err = _run(capsys, "evaluate", *base, "--time-step", "4", "--units", "m")
    assert (code, err) == (0, "")
    # in other units too
    code, _, err = _run(capsys, "evaluate", *base, "--time-step", "4", "--units", "ft")
    assert code == 0 and err == (f"trajpref: warning: {model} was trained on {logged}: this data "
                                 "is in ft, the model's in m (units are named, not converted: "
                                 "multiply x and y by 0.3048 to give m before reading "
                                 "them, and the futures, in m, by 3.281 for ft)\n")  # fmt: skip


def test_a_published_model_on_timestamped_files_gets_their_interval(capsys, logged, tmp_path):
    # 10 Hz seconds into a 0.4 s model: said, with advice that works; read at --time-step 4:
    # silent (the advice was --time-step 1, which brought the mistake back)
    base = ["evaluate", "--dataset", logged, "--model", "zara1/generator", "--samples", "20",
            "--no-progress", "--units", "m"]  # fmt: skip
    code, _, err = _run(capsys, *base)
    assert (code, err) == (0, f"trajpref: warning: {ZARA1}: {PACE}\n")
    code, _, err = _run(capsys, *base, "--time-step", "4")
    assert (code, err) == (0, "")
    # data stats: the step, its source and the speed use the files' 0.1 s, times the step
    code, out, _ = _run(capsys, "data", "stats", "--dataset", logged, "--time-step", "4", "--json")
    stats = json.loads(out)
    assert stats["frame_interval"] == pytest.approx(0.4) and stats["interval_from"] == "timestamps"
    assert stats["mean_speed"] == pytest.approx(1.2, rel=1e-3)  # metres per second
    code, out, _ = _run(capsys, "data", "stats", "--dataset", logged, "--time-step", "4")
    assert "frame_interval: 0.4 s (0.1 s between frames: the step of the files' time column; " \
           "read every 4)" in out  # fmt: skip
    # TrajNet++ files written from them declare 2.5 fps, and read back without a warning
    pred, truth = tmp_path / "pred.ndjson", tmp_path / "gt.ndjson"
    code, _, err = _run(capsys, "predict", "--dataset", logged, "--time-step", "4", "--model",
                        "cv", "--format", "trajnet", "--truth", truth, "--out", pred,
                        "--no-progress")  # fmt: skip
    assert code == 0 and err == ""
    assert json.loads(truth.read_text().splitlines()[0])["scene"]["fps"] == 2.5
    code, _, err = _run(capsys, "evaluate", "--dataset", truth, "--model", "zara1/generator",
                        "--samples", "20", "--no-progress")  # fmt: skip
    assert (code, err) == (0, "")


def _pretend(monkeypatch, header: dict) -> None:
    monkeypatch.setattr(cli.ckpt, "header_of", lambda spec: header)
    monkeypatch.setattr(cli.ckpt, "resolve_path", lambda spec: spec)


def _warned(ds) -> list[str]:
    import warnings

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        cli._warn_if_trained_otherwise("m.safetensors", ds)
    return [str(w.message) for w in seen]


def test_trajnet_scenes_get_no_advice_they_cannot_take(monkeypatch, tmp_path):
    # a 0.8 s model (zara1 read every 2) on TrajNet++ scenes: --time-step is refused for them,
    # and --frame-interval is ignored where the scenes declare their fps
    _pretend(monkeypatch, {"config": {"data": {"dataset": "zara1", "time_step": 2.0}}})
    lines = [json.dumps({"scene": {"id": 0, "p": 1, "s": 0, "e": 19, "fps": 2.5}})]
    lines += [json.dumps({"track": {"f": f, "p": 1, "x": f / 10, "y": 0}}) for f in range(20)]
    (tmp_path / "declared.ndjson").write_text("\n".join(lines) + "\n")
    plain = [json.dumps({"scene": {"id": 0, "p": 1, "s": 0, "e": 19}}), *lines[1:]]
    (tmp_path / "plain.ndjson").write_text("\n".join(plain) + "\n")
    (message,) = _warned(load_dataset(str(tmp_path / "declared.ndjson"), "test"))
    assert message.endswith("this data steps 0.4 s, the model's 0.8 s (its TrajNet++ scenes "
                            "declare 2.5 fps; --time-step does not resample TrajNet++ "
                            "scenes)")  # fmt: skip
    assert "--frame-interval" not in message and "--time-step 2" not in message
    # scenes that declare nothing: their interval is assumed, and --frame-interval is read
    (message,) = _warned(load_dataset(str(tmp_path / "plain.ndjson"), "test"))
    assert message.endswith("(0.4 s between frames is assumed: give the files' own with "
                            "--frame-interval; --time-step does not resample TrajNet++ "
                            "scenes)")  # fmt: skip


def test_a_folder_model_from_before_the_record_is_checked_on_its_own_folder(monkeypatch, logged,
                                                                           tmp_path):  # fmt: skip
    # a checkpoint that recorded only data.time_step: the same folder read at another step is
    # named (exactly: same files); any other data is left alone, as before
    _pretend(monkeypatch, {"config": {"data": {"dataset": str(logged), "time_step": 4.0}},
                           "meta": {}})  # fmt: skip
    (message,) = _warned(load_dataset(str(logged), "test"))
    assert message == (f"m.safetensors was trained on {logged}: this data is read every 1 frame "
                       "step of its files, the model's (the same folder) every 4 (--time-step 4 "
                       "reads it at the model's step)")  # fmt: skip
    from trajpref.data import ReadOptions

    assert _warned(load_dataset(str(logged), "test", options=ReadOptions(time_step=4))) == []
    other = _logged(tmp_path / "other")
    assert _warned(load_dataset(str(other), "test")) == []


def test_a_folder_model_at_the_assumed_interval_hedges_its_advice(monkeypatch, tmp_path):
    # trained on frame-numbered files (0.4 s assumed), read every 2: the ratio of the time
    # steps is advised, if the files step alike; data with known seconds get a number
    from synthetic import write_dataset

    timing = {"frame_interval": 0.8, "interval_from": "default", "time_step": 2.0,
              "units": "unknown"}  # fmt: skip
    _pretend(monkeypatch, {"config": {"data": {"dataset": "/elsewhere", "time_step": 2.0}},
                           "meta": {"data_timing": timing}})  # fmt: skip
    frames = write_dataset(tmp_path / "frames", frames=44)
    (message,) = _warned(load_dataset(str(frames), "test"))
    assert message.endswith("this data steps 0.4 s, the model's 0.8 s (--time-step 2 reads it "
                            "at the model's step if these files step as the model's training "
                            "files did (both assume 0.4 s between frames: --frame-interval "
                            "gives this data's))")  # fmt: skip
    (message,) = _warned(load_dataset(str(frames), "test", frame_interval=0.1))
    assert message.endswith("this data steps 0.1 s, the model's 0.8 s (--time-step 8 reads it "
                            "at the model's step, if the model's training files were 0.4 s "
                            "apart as assumed when it was trained)")  # fmt: skip


def test_train_takes_the_folders_interval_units_and_time_step(capsys, logged, tmp_path):
    # shortcuts for --set data.*, refused for a built-in dataset, which knows its own
    code, _, err = _run(capsys, "train", "diffusion", "--dataset", "zara1", "--frame-interval",
                        "0.1", "--out", tmp_path / "z")  # fmt: skip
    assert code == 2 and err.startswith("trajpref: error: data.frame_interval describes a "
                                        "folder dataset; zara1 is a built-in one and "
                                        "knows its own units and frame interval")  # fmt: skip
    assert not (tmp_path / "z").exists()
    code, out, _ = _run(capsys, "config", "show", "--set", f"data.dataset={logged}", "--set",
                        "data.frame_interval=0.1", "--set", "data.units=m")  # fmt: skip
    assert code == 0 and "data.frame_interval = 0.1" in out and "data.units = m" in out
