"""Overlap by content, not by path (walkthrough 66): a copy of a training file in ``test/``, or
the training folder copied elsewhere, was evaluated without a word (``overlap`` null, the
training numbers). A checkpoint's lineage records short content digests of the files each run
trained and chose its epoch on (``timing.split_files``), and ``check_trained_on`` compares the
evaluated split's files with them; published checkpoints, without digests, are unchanged."""

from __future__ import annotations

import json
import shutil
import warnings

import pytest
from synthetic import write_dataset

from trajpref.cli import main
from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.evaluation import CLI_WORDS, check_trained_on, content_overlaps, evaluate
from trajpref.io import read_checkpoint_header
from trajpref.models import checkpoint as ckpt
from trajpref.models.checkpoint import load_predictor
from trajpref.models.timing import (
    DIGEST_CHARS,
    NAMED_FILES,
    files_record,
    model_timing,
    record_files,
    same_content_note,
    shared_files,
    split_files,
    training_lineage,
    window_digests,
)
from trajpref.train.stages import trained_on
from trajpref.types import TrajectoryDataset


def _folder(tmp_path, name="data"):
    """A dataset folder whose test/ holds a byte copy of a training file under another name."""
    root = write_dataset(tmp_path / name)
    shutil.copy(root / "train" / "walk0.txt", root / "test" / "copy.txt")
    return root


def _caught(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    return out, [str(w.message) for w in caught]


def test_a_copied_file_has_its_originals_digest_under_any_name(tmp_path):
    root = _folder(tmp_path)
    train = window_digests(load_dataset(str(root), "train"))
    test = window_digests(load_dataset(str(root), "test"))
    assert test["copy.txt"] == train["walk0.txt"]
    assert test["walk0.txt"] != train["walk0.txt"]  # another file of the same name
    assert shared_files(test, train) == [("copy.txt", "walk0.txt")]
    (root / "test" / "copy.txt").write_text(
        (root / "test" / "copy.txt").read_text().replace("\t0.", "\t1.", 1)
    )  # one changed value: another file
    changed = window_digests(load_dataset(str(root), "test"))
    assert shared_files(changed, train) == []


def test_the_record_is_small_and_unnamed_beyond_named_files():
    few = {f"f{i}.txt": f"{i:010x}{0:06x}" for i in range(3)}
    assert files_record(few) == {f: d[:DIGEST_CHARS] for f, d in few.items()}
    many = {f"game_{i}.txt": f"{i:010x}{0:06x}" for i in range(NAMED_FILES + 1)}
    record = files_record(many)
    assert isinstance(record, str) and len(record) == DIGEST_CHARS * len(many)
    assert shared_files({"x.txt": f"{5:010x}ffffff"}, record) == [("x.txt", None)]
    assert record_files(few) == {d: f for f, d in few.items()}
    assert record_files(None) == {} and record_files("abc") == {}


def test_same_content_note_names_train_and_val_copies(tmp_path):
    root = write_dataset(tmp_path / "d")
    shutil.copy(root / "train" / "walk1.txt", root / "val" / "again.txt")
    train, val = load_dataset(str(root), "train"), load_dataset(str(root), "val")
    note = same_content_note(train, val)
    assert note is not None and "val/again.txt = train/walk1.txt" in note
    assert same_content_note(train, load_dataset(str(root), "test")) is None


def test_stages_record_the_files_and_the_lineage_carries_them(tmp_path):
    root = _folder(tmp_path)
    cfg = load_config(None, [f"data.dataset={root}"])
    train, val = load_dataset(str(root), "train"), load_dataset(str(root), "val")
    entry = trained_on(cfg, "denoiser", train=train, val=val)[-1]
    assert entry["files"] == split_files(train, val)
    assert set(entry["files"]["train"]) == {"walk0.txt", "walk1.txt", "walk2.txt"}
    header = {"kind": "generator", "config": {"data": {"dataset": str(root)}},
              "meta": {"trained_on": [entry, {**entry, "stage": "generator"}]}}  # fmt: skip
    lineage = training_lineage(header)
    assert [e.get("files") for e in lineage] == [entry["files"]] * 2
    assert model_timing(header)["lineage"] == lineage
    assert "files" not in trained_on(cfg, "denoiser")[-1]  # nothing given, nothing recorded


def _record(root, train, val, stage="generator"):
    entry = {"stage": stage, "dataset": str(root), "val_dataset": None, "holdout_scene": None,
             "files": split_files(train, val)}  # fmt: skip
    header = {"kind": "generator", "config": {"data": {"dataset": str(root)}},
              "meta": {"trained_on": [entry]}}  # fmt: skip
    return model_timing(header)


def test_check_trained_on_warns_of_a_copy_in_test(tmp_path):
    root = _folder(tmp_path)
    train, val = load_dataset(str(root), "train"), load_dataset(str(root), "val")
    model = _record(root, train, val)
    test = load_dataset(str(root), "test")
    data = {"dataset": str(root)}
    note, texts = _caught(check_trained_on, "m", model, data, test.info, words=CLI_WORDS,
                          dataset=test)  # fmt: skip
    assert note == "trained on some of these windows (test/copy.txt = train/walk0.txt)"
    assert any("this data holds files the model trained on: 1 of this data's 2 files: "
               "test/copy.txt = train/walk0.txt" in t for t in texts)  # fmt: skip
    # without the data's windows (an older caller): the path checks alone, as before
    assert _caught(check_trained_on, "m", model, data, test.info)[0] is None


def test_a_copied_training_folder_is_the_training_data(tmp_path):
    root = _folder(tmp_path)
    train, val = load_dataset(str(root), "train"), load_dataset(str(root), "val")
    model = _record(root, train, val)
    elsewhere = shutil.copytree(root, tmp_path / "elsewhere")
    for split, role in (("train", "trained on"), ("val", "chose its epoch on")):
        ds = load_dataset(str(elsewhere), split)
        note, texts = _caught(check_trained_on, "m", model, {"dataset": str(root)}, ds.info,
                              dataset=ds)  # fmt: skip
        assert note is not None and note.startswith(f"{role} these windows ({split}/")
        assert any("numbers on it are" in t for t in texts)
    # the model's own folder: named by its path once, not again by content
    note, _ = _caught(check_trained_on, "m", model, {"dataset": str(root)}, train.info,
                      dataset=train)  # fmt: skip
    assert note == f"trained on these windows (train split of {root})"


def test_through_its_denoiser(tmp_path):
    root = _folder(tmp_path)
    train, val = load_dataset(str(root), "train"), load_dataset(str(root), "val")
    files = split_files(train, val)
    other = str(tmp_path / "other")
    header = {"kind": "generator", "config": {"data": {"dataset": other}},
              "meta": {"trained_on": [
                  {"stage": "denoiser", "dataset": str(root), "files": files},
                  {"stage": "generator", "dataset": other}]}}  # fmt: skip
    test = load_dataset(str(root), "test")
    note, _ = _caught(check_trained_on, "m", model_timing(header), {"dataset": other},
                      test.info, dataset=test)  # fmt: skip
    assert note == ("trained on some of these windows (test/copy.txt = train/walk0.txt, "
                    "through its denoiser)")  # fmt: skip


@pytest.fixture(scope="module")
def copy_run(tmp_path_factory):
    """A tiny run (both stages) trained on a folder whose test/ holds a copy of a training
    file."""
    from synthetic import TINY_OVERRIDES

    from trajpref.train.run import train_stage

    base = tmp_path_factory.mktemp("copyrun")
    root = _folder(base)
    cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={root}"])
    out = base / "run"
    train_stage("diffusion", cfg, out, device="cpu", progress=False)
    train_stage("generator", cfg, out, device="cpu", progress=False)
    return root, out


def test_python_evaluate_records_a_copy(copy_run):
    root, out = copy_run
    model = load_predictor(str(out / "generator.safetensors"), device="cpu")
    test = load_dataset(str(root), "test")
    res, texts = _caught(evaluate, model, test, num_samples=2, progress=False)
    assert "test/copy.txt = train/walk0.txt" in (res["overlap"] or "")
    assert any("test/copy.txt = train/walk0.txt" in t for t in texts)


def test_a_model_without_digests_is_checked_as_before(copy_run):
    root, out = copy_run
    payload = ckpt.load(out / "generator.safetensors")
    for part in (payload, payload["denoiser"]):
        for e in part["meta"]["trained_on"]:
            e.pop("files", None)
    ckpt.save(out.parent / "old.safetensors", payload)
    model = load_predictor(str(out.parent / "old.safetensors"), device="cpu")
    res, texts = _caught(evaluate, model, load_dataset(str(root), "test"), num_samples=2,
                         progress=False)  # fmt: skip
    assert res["overlap"] is None
    assert not any("this data holds files" in t for t in texts)


def test_the_header_stays_small(copy_run):
    _, out = copy_run
    head = read_checkpoint_header(out / "generator.safetensors")
    assert len(json.dumps(head["meta"]["trained_on"])) < 2000


def test_cli_evaluate_records_a_copy(copy_run, capsys):
    root, out = copy_run
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code = main(["evaluate", "--dataset", str(root), "--split", "test", "--model",
                     str(out / "generator.safetensors"), "--samples", "4", "--device", "cpu",
                     "--no-progress", "--json"])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0
    res = json.loads(captured.out)
    assert "test/copy.txt = train/walk0.txt" in (res["overlap"] or "")
    assert "this data holds files the model trained on" in captured.err


def test_empty_data_has_nothing_to_compare(tmp_path):
    root = _folder(tmp_path)
    train, val = load_dataset(str(root), "train"), load_dataset(str(root), "val")
    empty = TrajectoryDataset([], train.info)
    assert window_digests(empty) == {}
    assert content_overlaps(_record(root, train, val), window_digests(empty), train.info) == []
