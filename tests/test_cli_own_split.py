"""``evaluate`` on a split its model trained on (or chose its epoch on) says so and records it:
by name (``--split train``) or as the split's folder given as a path. The test split is
silent. With ``data.val_dataset`` the model chose its epoch on another folder: its val
split by name is then not flagged, as by path."""

from __future__ import annotations

import json
import warnings
from types import SimpleNamespace

import pytest

from trajpref.cli import _own_split, main


def _evaluate(capsys, *argv):
    """(the result's ``overlap``, the warning lines about these windows)"""
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code = main([str(a) for a in ["evaluate", *argv, "--json", "--no-progress",
                                      "--device", "cpu", "--samples", "2"]])  # fmt: skip
    out, err = capsys.readouterr()
    assert code == 0
    notes = [line for line in err.splitlines() if "these windows" in line]
    return json.loads(out)["overlap"], notes


@pytest.mark.parametrize("split, role", [("train", "trained on"), ("val", "chose its epoch on")])
def test_a_split_the_model_trained_on_is_named_by_split_and_by_path(tiny_run, walks, capsys,
                                                                    split, role):  # fmt: skip
    gen = tiny_run / "generator.safetensors"
    overlap, notes = _evaluate(capsys, "--dataset", walks, "--split", split, "--model", gen)
    assert overlap == f"model {role} these windows ({split} split of {walks})"
    assert len(notes) == 1 and f"is the {split} split of {walks}" in notes[0]
    overlap, notes = _evaluate(capsys, "--dataset", walks / split, "--model", gen)  # its folder
    assert overlap == f"model {role} these windows ({split} split of {walks})"


def test_the_test_split_is_not_flagged(tiny_run, walks, capsys):
    overlap, notes = _evaluate(capsys, "--dataset", walks, "--split", "test", "--model",
                               tiny_run / "generator.safetensors")  # fmt: skip
    assert overlap is None and notes == []


def _info(name: str, split: str, source: str) -> SimpleNamespace:
    return SimpleNamespace(name=name, split=split, source=source)


def test_val_by_name_is_not_own_when_the_model_validated_elsewhere(tmp_path):
    root = tmp_path / "data"
    val = root / "eth_ucy" / "zara1" / "val"
    val.mkdir(parents=True)
    (root / "eth_ucy" / "zara1" / "train").mkdir()
    elsewhere = {"dataset": "zara1", "val_dataset": str(tmp_path / "elsewhere")}
    by_name = _info("zara1", "val", str(val))
    by_path = _info(str(val), "test", str(val))
    assert _own_split(elsewhere, by_name, str(root)) is None
    assert _own_split(elsewhere, by_path, str(root)) is None  # the path agrees
    # its own val split, and the training split either way, are still named
    assert _own_split({"dataset": "zara1"}, by_name, str(root)) == "val"
    assert _own_split(elsewhere, _info("zara1", "train", str(val.parent / "train")),
                      str(root)) == "train"  # fmt: skip


@pytest.mark.parametrize(("model", "dataset", "split", "said"), [
    ("robo/generator", "robo", "val", "chose its epoch on these windows: this is robo's val"),
    ("robo-mix/generator", "robo", "val", "trained on these windows: this is robo's val"),
    ("robo/generator", "robo-mix", "train", "robo-mix's train split holds robo-sim's train"),
    ("robo-mix/generator", "robo", "test", None),
    ("robo/generator", "robo-sim", "val", None),  # it chose its epoch on Robo's val, not this
])  # fmt: skip
def test_a_built_in_split_that_holds_what_the_model_saw_is_flagged(
    data_root, capsys, model, dataset, split, said
):
    """robo/generator chose its epoch on the official Robo val split (its val_dataset), and
    robo-mix is made of robo-sim and that split: evaluating them there was silent (a Robo
    walkthrough of 2026-12-06 got 0.2958 and 0.2697 with "overlap": null)."""
    overlap, notes = _evaluate(capsys, "--dataset", dataset, "--split", split, "--model", model,
                               "--max-scenes", "4", "--data-root", data_root)  # fmt: skip
    if said is None:
        assert overlap is None
    else:
        assert overlap is not None and any(said in n for n in notes), notes


def test_a_held_out_scene_is_named_trained_on_unless_the_model_held_it_out(data_root, capsys):
    """--holdout-scene reads that scene's files of both splits: a model trained on the fold
    without holding it out trained on most of them (it was said to have "chose its epoch on"
    them); one that held the same scene out chose its epoch on them."""
    from trajpref.cli import _held_out_split

    overlap, notes = _evaluate(capsys, "--dataset", "zara1", "--split", "val", "--holdout-scene",
                               "biwi_hotel", "--model", "zara1/generator", "--max-scenes", "4",
                               "--data-root", data_root)  # fmt: skip
    assert overlap == "model trained on these windows (held-out scene biwi_hotel* of zara1)"
    assert len(notes) == 1 and "held-out scene biwi_hotel* of zara1 is the windows" in notes[0]
    info = _info("zara1", "val", "")
    assert _held_out_split({"dataset": "zara1", "holdout_scene": "biwi_hotel"}, info,
                           "biwi_hotel") == "val"  # fmt: skip
    assert _held_out_split({"dataset": "zara1"}, info, "biwi_hotel") == "train"
    assert _held_out_split({"dataset": "eth"}, info, "biwi_hotel") is None
