"""Walkthroughs 63-A and 63-B, the command line: the pace and units check on data that leave
their interval or units unsaid, a folder without split sub-folders read as the model's own
training windows, ``n/a`` collision rates, the data's reading in ``evaluate --out``, what
``--frame-interval`` means, and a legacy ``.pt`` checkpoint in the pace check."""

from __future__ import annotations

import csv
import dataclasses
import json
import warnings
from pathlib import Path

import pytest
import torch
from synthetic import straight_rows, write_tracks

from trajpref import cli
from trajpref.cli import main
from trajpref.config import ExperimentConfig, to_dict
from trajpref.data import hold_out_scene, load_dataset
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo

ZARA1 = "zara1/generator was trained on the zara1 fold (leave-one-out: the other four scenes)"
ASSUMED = "this data's frame interval is only assumed (0.4 s between rows, none given)"
GIVE_INTERVAL = "--frame-interval (the seconds between an agent's consecutive rows)"


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _pretend(monkeypatch, header: dict) -> None:
    """Every checkpoint's header is ``header`` (the file itself is never read)."""
    monkeypatch.setattr(cli, "read_checkpoint_header", lambda path: header)
    monkeypatch.setattr(cli.ckpt, "resolve_path", lambda spec: spec)


def _warned(ds, spec: str = "m.safetensors") -> tuple[list[str], str | None]:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        note = cli._warn_if_trained_otherwise(spec, ds)
    return [str(w.message) for w in seen], note


def _timing(step: float, origin: str, every: float, units: str) -> dict:
    return {"frame_interval": step, "interval_from": origin, "time_step": every, "units": units}


# ---------------------------------------------------------------- 1: what the data leave unsaid


def test_a_published_model_on_data_of_assumed_interval_or_unknown_units_says_so(monkeypatch,
                                                                                walks):  # fmt: skip
    # walks' frames are numbered 10 apart: 0.4 s assumed, which equals zara1's step, so the
    # known values agree and nothing was said (10 Hz data read so looked healthy)
    _pretend(monkeypatch, {"config": {"data": {"dataset": "zara1", "time_step": 1.0}}})
    model = "the model's step is 0.4 s, its units m"
    (message,), _ = _warned(load_dataset(str(walks), "test"))
    assert message == (f"m.safetensors was trained on the zara1 fold (leave-one-out: the other "
                       f"four scenes): {ASSUMED} and its units are unknown, while {model}: "
                       f"give this data's with {GIVE_INTERVAL} and --units")  # fmt: skip
    (message,), _ = _warned(load_dataset(str(walks), "test", units="m"))
    assert message.endswith(f": {ASSUMED}, while {model}: give this data's with {GIVE_INTERVAL}")
    (message,), _ = _warned(load_dataset(str(walks), "test", frame_interval=0.4))
    assert message.endswith(": this data's units are unknown, while the model's step is 0.4 s, "
                            "its units m: give this data's with --units")  # fmt: skip
    # both said: silent, as before
    assert _warned(load_dataset(str(walks), "test", frame_interval=0.4, units="m")) == ([], None)


def test_a_folder_model_names_the_flags_that_read_data_as_it_did(monkeypatch, walks):
    # trained with --frame-interval 0.1 --time-step 4 --units m (0.4 s per step), evaluated
    # on frame-numbered files without the flags: the same 0.4 s, assumed
    data = {"dataset": "/elsewhere/lab_m", "time_step": 4.0}
    _pretend(monkeypatch, {"config": {"data": data},
                           "meta": {"data_timing": _timing(0.4, "given", 4.0, "m")}})  # fmt: skip
    (message,), _ = _warned(load_dataset(str(walks), "test"))
    assert message == ("m.safetensors was trained on /elsewhere/lab_m: "
                       f"{ASSUMED} and its units are unknown, while the model read its data "
                       "with --frame-interval 0.1 --time-step 4 --units m (0.4 s per step): "
                       f"give this data's with {GIVE_INTERVAL} and --units")  # fmt: skip
    # an interval read from a time column: no --frame-interval flag, the column's step said
    timing = _timing(0.4, "timestamps", 4.0, "m")
    _pretend(monkeypatch, {"config": {"data": data}, "meta": {"data_timing": timing}})
    (message,), _ = _warned(load_dataset(str(walks), "test", units="m"))
    assert message.endswith(f"{ASSUMED}, while the model read its data with --time-step 4 "
                            "--units m (0.4 s per step; its files' time column gave 0.1 s "
                            f"between rows): give this data's with {GIVE_INTERVAL}")  # fmt: skip
    # a model that recorded nothing known (its interval assumed too, its units unknown): silent
    _pretend(monkeypatch, {"config": {"data": {"dataset": "/elsewhere", "time_step": 1.0}},
                           "meta": {"data_timing": _timing(0.4, "default", 1.0,
                                                           "unknown")}})  # fmt: skip
    assert _warned(load_dataset(str(walks), "test")) == ([], None)


def test_pixels_by_any_name_are_the_same_units(monkeypatch, walks):
    timing = _timing(0.4, "default", 1.0, "px")
    _pretend(monkeypatch, {"config": {"data": {"dataset": "/elsewhere", "time_step": 1.0}},
                           "meta": {"data_timing": timing}})  # fmt: skip
    assert _warned(load_dataset(str(walks), "test", units="pixels")) == ([], None)
    (message,), _ = _warned(load_dataset(str(walks), "test", units="m"))
    assert message.endswith("this data is in m, the model's in px")


def test_evaluate_and_survey_build_say_it_for_a_published_model(capsys, walks, tmp_path):
    code, _, err = _run(capsys, "evaluate", "--dataset", walks, "--model", "zara1/generator",
                        "--samples", "20", "--no-progress", "--units", "m")  # fmt: skip
    assert (code, err) == (0, f"trajpref: warning: {ZARA1}: {ASSUMED}, while the model's step "
                              f"is 0.4 s, its units m: give this data's with "
                              f"{GIVE_INTERVAL}\n")  # fmt: skip
    # survey build reads its data through the same check (raters would see the wrong pace)
    code, _, err = _run(capsys, "survey", "build", "--dataset", walks, "--units", "m",
                        "--models", "cv", "gen=zara1/generator", "--scenes", "1", "--samples",
                        "2", "--min-gap", "0", "--device", "cpu", "--no-progress", "--out",
                        tmp_path / "study")  # fmt: skip
    assert code == 0
    assert f"trajpref: warning: {ZARA1}: {ASSUMED}, while the model's step" in err


# ------------------------------------------------------- 2: a model's own flat training folder


@pytest.fixture
def flat(tmp_path) -> Path:
    """A folder of two recordings without train/ val/ test/ sub-folders."""
    write_tracks(tmp_path / "flat" / "cam0.txt", straight_rows(30, agents=2))
    write_tracks(tmp_path / "flat" / "cam1.txt", straight_rows(30, agents=3))
    return tmp_path / "flat"


def test_a_folder_without_splits_is_named_as_the_models_training_windows(monkeypatch, flat,
                                                                         walks):  # fmt: skip
    _pretend(monkeypatch, {"config": {"data": {"dataset": str(flat), "time_step": 1.0}}})
    (message,), note = _warned(load_dataset(str(flat), "test"))
    assert message == (f"m.safetensors was trained on {flat}, which has no train/, val/ or "
                       "test/ sub-folders: whatever --split says, this data is the windows it "
                       "trained on, so numbers on it are training numbers, not a test (give the "
                       "folder train/ val/ test/ sub-folders and train on train/, or use files "
                       "it did not train on)")  # fmt: skip
    assert note == f"trained on these windows ({flat} has no split sub-folders)"
    # a model of another folder, or a folder with split sub-folders: nothing of the kind
    assert _warned(load_dataset(str(walks), "test")) == ([], None)
    _pretend(monkeypatch, {"config": {"data": {"dataset": str(walks), "time_step": 1.0}}})
    assert _warned(load_dataset(str(walks), "test")) == ([], None)
    # a model that held a scene out: the advice names it, and that scene read alone is fine
    data = {"dataset": str(flat), "time_step": 1.0, "holdout_scene": "cam1"}
    _pretend(monkeypatch, {"config": {"data": data}})
    (message,), _ = _warned(load_dataset(str(flat), "test"))
    assert "trained on (all but its held-out scene cam1*, which --split val --holdout-scene " \
           "cam1 reads alone), so numbers" in message  # fmt: skip
    held = hold_out_scene(load_dataset(str(flat), "train"), load_dataset(str(flat), "val"),
                          "cam1")[1]  # fmt: skip
    assert _warned(held) == ([], None)


def test_evaluate_records_training_windows_in_overlap(capsys, monkeypatch, flat):
    # the published file predicts; its header says it was trained on ``flat``
    real = zoo.header(zoo.resolve("zara1/generator"))
    data = {**real["config"]["data"], "dataset": str(flat)}
    header = {**real, "config": {**real["config"], "data": data}}
    monkeypatch.setattr(cli, "_checkpoint_header", lambda spec: header)
    code, out, err = _run(capsys, "evaluate", "--dataset", flat, "--model", "zara1/generator",
                          "--samples", "20", "--no-progress", "--json")  # fmt: skip
    assert code == 0 and err.count("\n") == 1
    assert err.startswith(f"trajpref: warning: zara1/generator was trained on {flat}, which "
                          "has no train/, val/ or test/ sub-folders")  # fmt: skip
    assert json.loads(out)["overlap"] == (f"model trained on these windows ({flat} has no split "
                                          "sub-folders)")  # fmt: skip


# ------------------------------------------------------------------ 3, 4: evaluate's outputs


def test_collision_rates_without_a_neighbour_print_as_n_a(capsys, tmp_path):
    write_tracks(tmp_path / "alone" / "a.txt", straight_rows(24, agents=1))
    code, out, _ = _run(capsys, "evaluate", "--dataset", tmp_path / "alone", "--model", "cv",
                        "--units", "m", "--no-progress")  # fmt: skip
    assert code == 0 and "nan" not in out
    assert "  Col-I n/a  Col-II n/a   ground truth n/a   (no agent has a neighbour; radius " \
           "0.1 m)" in out.splitlines()  # fmt: skip


def test_evaluate_out_records_the_datas_pace_and_notes_a_replaced_file(capsys, walks, tmp_path):
    base = ["evaluate", "--dataset", walks, "--model", "cv", "--samples", "2", "--no-progress",
            "--time-step", "0.5", "--units", "m"]  # fmt: skip
    result = tmp_path / "r.json"
    code, _, err = _run(capsys, *base, "--out", result)
    assert code == 0 and "note" not in err
    out = json.loads(result.read_text())
    read = (out["frame_interval"], out["time_step"], out["interval_from"])
    assert read == (0.2, 0.5, "default")
    code, _, err = _run(capsys, *base, "--out", result)
    assert code == 0 and err == (f"trajpref: note: --out {result} existed and is replaced by "
                                 "this result (one result per file: give each run its own --out "
                                 "to keep both)\n")  # fmt: skip
    table = tmp_path / "r.csv"
    code, _, _ = _run(capsys, *base, "--frame-interval", "0.1", "--out", table)
    (record,) = csv.DictReader(table.read_text().splitlines())
    assert (record["frame_interval"], record["time_step"], record["interval_from"]) == (
        "0.05", "0.5", "given")  # fmt: skip


# ------------------------------------------------------------------------- 5: --frame-interval


@pytest.mark.parametrize("command", [["evaluate"], ["predict"], ["train", "generator"],
                                     ["survey", "build"]])  # fmt: skip
def test_frame_interval_help_says_what_it_counts(capsys, command):
    code, out, _ = _run(capsys, *command, "--help")
    text = " ".join(out.split())
    assert code == 0
    assert "seconds between consecutive rows of an agent" in text
    assert "not per frame number nor per video frame" in text
    assert "--time-step then reads every n-th" in text


# ------------------------------------------------------------------- 7b: a legacy .pt header


def test_a_legacy_pt_checkpoint_is_checked_too(walks, tmp_path):
    cfg = ExperimentConfig()
    cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, dataset="zara1"))
    state = {"w": torch.zeros(2)}
    legacy = {"format": ckpt.LEGACY_FORMAT, "kind": "denoiser", "config": to_dict(cfg),
              "scale": 1.0, "state_dict": state, "hash": ckpt.state_hash(state),
              "meta": {}}  # fmt: skip
    torch.save(legacy, tmp_path / "old.pt")
    messages, _ = _warned(load_dataset(str(walks), "test", frame_interval=0.1, units="m"),
                          str(tmp_path / "old.pt"))  # fmt: skip
    assert messages == [f"{tmp_path / 'old.pt'} was trained on the zara1 fold (leave-one-out: "
                        "the other four scenes): this data steps 0.1 s, the model's 0.4 s "
                        "(--time-step 4 reads it at the model's step)"]  # fmt: skip
    # a file that cannot be read (a folder named like a checkpoint): no check, no crash
    (tmp_path / "dir.pt").mkdir()
    assert _warned(load_dataset(str(walks), "test"), str(tmp_path / "dir.pt")) == ([], None)


@pytest.mark.parametrize(("command", "name", "what"), [
    (["predict", "--model", "cv", "--samples", "2"], "p.npz", "prediction"),
    (["plot", "--model", "cv", "--samples", "2", "--scene", "0"], "f.png", "figure"),
])  # fmt: skip
def test_predict_and_plot_note_a_replaced_file_as_evaluate_does(capsys, walks, tmp_path,
                                                                  command, name, what):  # fmt: skip
    """evaluate said so when --out replaced a file; predict and plot replaced theirs silently
    (a CLI walkthrough of 2026-12-06)."""
    out = tmp_path / name
    argv = [*command, "--dataset", walks, "--no-progress", "--out", out]
    code, _, err = _run(capsys, *argv)
    assert code == 0 and "existed and is replaced" not in err
    code, _, err = _run(capsys, *argv)
    assert code == 0
    assert f"trajpref: note: --out {out} existed and is replaced by this {what}" in err
