"""A checkpoint records every run whose data went into it (``meta.trained_on``: a generator's
denoiser, a fine-tune's start), and the fold-overlap and own-windows checks read all of them
(walkthrough 66): a zara1 generator fine-tuned on another fold (``--set data.dataset=...``, the
documented way) was evaluated there without a word, as was a generator trained through another
fold's denoiser. A fine-tune records its preset (``evaluate --json``'s ``finetune_preset``),
and a loaded model's record says where it chose its epoch (``val_dataset``, ``holdout_scene``),
so that Python's ``evaluate`` names a validation split as the CLI does."""

from __future__ import annotations

import dataclasses
import json
import warnings

import pytest
from synthetic import straight_rows, write_dataset, write_tracks

from trajpref.cli import main
from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.evaluation import evaluate
from trajpref.io import read_checkpoint_header
from trajpref.models import checkpoint as ckpt
from trajpref.models.checkpoint import load_predictor
from trajpref.models.timing import model_timing, training_lineage
from trajpref.train.stages import finetune_preset

FINETUNE_TINY = ["--set", "finetune.epochs=1", "--set", "finetune.steps_per_epoch=1", "--set",
                 "finetune.eval_max_scenes=2", "--set", "finetune.warmup_steps=1", "--device",
                 "cpu", "--no-progress"]  # fmt: skip
START = "the generator it was fine-tuned from"
START_VIA = f"(through {START})"


def _run(capsys, *argv):
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _entry(stage, dataset, val=None, holdout=None):
    return {"stage": stage, "dataset": dataset, "val_dataset": val, "holdout_scene": holdout}


@pytest.fixture(scope="module")
def fold_root(tmp_path_factory):
    """A data root with tiny ETH/UCY folds (eth_ucy/<fold>/<split>/*.txt)."""
    root = tmp_path_factory.mktemp("root")
    for i, fold in enumerate(("eth", "zara1", "zara2")):
        for j, split in enumerate(("train", "val", "test")):
            shift = 0.1 * (3 * i + j)  # every file's windows its own (content digests differ)
            rows = straight_rows(24, agents=2) + [(10 * f, 9, shift, 0.5 * f)
                                                  for f in range(30, 50)]  # fmt: skip
            write_tracks(root / "eth_ucy" / fold / split / f"{fold}_{split}.txt", rows)
    return root


def _relabel(src, dst, dataset, denoiser=None):
    """A copy of checkpoint ``src`` whose config (and embedded denoiser's) names ``dataset``
    (``denoiser``), written as before the lineage record (no ``trained_on``, no
    ``data_timing``): what a published model's header looks like."""
    payload = ckpt.load(src)
    for part, name in ((payload, dataset), (payload.get("denoiser"), denoiser or dataset)):
        if part is not None:
            part["config"]["data"]["dataset"] = name
            part["meta"] = {k: v for k, v in part["meta"].items()
                            if k not in ("trained_on", "data_timing")}  # fmt: skip
    ckpt.save(dst, payload)
    return dst


@pytest.fixture(scope="module")
def zara1_generator(tiny_run, tmp_path_factory):
    """The tiny generator, its header (and its denoiser's) saying it trained on the zara1
    fold, as a file written before the record."""
    out = tmp_path_factory.mktemp("zara1") / "generator.safetensors"
    return _relabel(tiny_run / "generator.safetensors", out, "zara1")


def _finetune(capsys, start, out, *extra):
    code, stdout, err = _run(capsys, "finetune", "--method", "rlhf", "--from", start, "--out",
                             out, *extra, *FINETUNE_TINY)  # fmt: skip
    assert code == 0, err
    return out / "finetune.safetensors", stdout, err


@pytest.fixture(scope="module")
def on_zara2(zara1_generator, fold_root, tmp_path_factory):
    """zara1_generator fine-tuned on the zara2 fold (``--set data.dataset=zara2``)."""
    out = tmp_path_factory.mktemp("ft")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # test_finetune_warns_... checks them
        code = main([str(a) for a in ["finetune", "--method", "rlhf", "--from", zara1_generator,
                                      "--out", out, "--set", "data.dataset=zara2",
                                      "--data-root", fold_root, *FINETUNE_TINY]])  # fmt: skip
    assert code == 0
    return out / "finetune.safetensors"


# --------------------------------------------------------------------------- the record


def _without_files(lineage: list[dict]) -> list[dict]:
    """The lineage entries without their files' digests (tests/test_content_overlap.py)."""
    return [{k: v for k, v in entry.items() if k != "files"} for entry in lineage]


def test_each_stage_records_its_lineage(tiny_run, walks):
    den = read_checkpoint_header(tiny_run / "denoiser.safetensors")["meta"]["trained_on"]
    gen = read_checkpoint_header(tiny_run / "generator.safetensors")["meta"]["trained_on"]
    assert _without_files(den) == [_entry("denoiser", str(walks))]
    assert _without_files(gen) == [_entry("denoiser", str(walks)), _entry("generator", str(walks))]
    assert all("files" in entry for entry in gen)  # each run's files' digests


def test_a_finetune_records_its_starts_data_and_its_own(on_zara2):
    meta = read_checkpoint_header(on_zara2)["meta"]
    # the start, written before the record: its config's data and its denoiser's
    assert _without_files(meta["trained_on"]) == [_entry("denoiser", "zara1"),
                                                  _entry("generator", "zara1"),
                                                  _entry("finetune", "zara2")]  # fmt: skip
    assert meta["preset"] is None  # the default config


def test_a_header_before_the_record_reads_its_config_and_its_denoisers(zara1_generator):
    header = ckpt.load(zara1_generator)
    assert training_lineage(header) == [_entry("denoiser", "zara1"), _entry("generator", "zara1")]
    # a published generator's header names its denoiser by reference: its own data alone
    published = read_checkpoint_header(ckpt.resolve_path("zara1/generator"))
    assert training_lineage(published) == [_entry("generator", "zara1")]
    # the record's last entry is the checkpoint's own run: its config says its data
    header["meta"]["trained_on"] = [_entry("denoiser", "eth"), _entry("generator", "eth")]
    assert training_lineage(header) == [_entry("denoiser", "eth"), _entry("generator", "zara1")]


# ------------------------------------------------------------------ the folds, through the chain


def test_a_finetune_of_another_folds_generator_is_refused_on_its_fold(on_zara2, fold_root,
                                                                      capsys):  # fmt: skip
    path = on_zara2
    base = ["evaluate", "--dataset", "zara2", "--data-root", fold_root, "--model", path,
            "--samples", "4", "--no-progress", "--device", "cpu", "--json"]  # fmt: skip
    code, out, err = _run(capsys, *base)
    assert code == 2 and out == ""
    assert f"{path} {START_VIA} was trained on the zara1 fold" in err
    assert "zara2 among them" in err
    code, out, err = _run(capsys, *base, "--allow-overlap")
    assert code == 0
    assert json.loads(out)["overlap"] == f"zara1 model on zara2 {START_VIA}"
    # Python's evaluate refuses it too
    data = load_dataset("zara2", "test", fold_root)
    with pytest.raises(ConfigError, match=r"the model \(through the generator it was "
                       r"fine-tuned from\) was trained on the zara1 fold"):  # fmt: skip
        evaluate(load_predictor(path), data, 4, progress=False, collision_radius=None)


def test_finetune_warns_when_its_data_is_in_the_starts_training(zara1_generator, fold_root,
                                                                tmp_path, capsys):  # fmt: skip
    argv = ["finetune", "--method", "rlhf", "--from", zara1_generator, "--out", tmp_path / "ft",
            "--data-root", fold_root, *FINETUNE_TINY]  # fmt: skip
    code, _, err = _run(capsys, *argv, "--set", "data.dataset=zara2")
    assert code == 0
    assert (f"--from {zara1_generator}: the start was trained on the zara1 fold, whose "
            "leave-one-out training files (the other four scenes') hold most of zara2's "
            "windows") in err.replace("\n", " ")  # fmt: skip
    code, _, err = _run(capsys, *argv)  # its own fold: silent
    assert code == 0 and "the start was trained on" not in err


def test_a_finetune_written_before_the_record_is_checked_through_its_denoiser(
    on_zara2, fold_root, tmp_path, capsys
):
    """Its start's data is lost, but its embedded denoiser (its reward's) still names it."""
    payload = ckpt.load(on_zara2)
    payload["meta"] = {k: v for k, v in payload["meta"].items() if k != "trained_on"}
    old = tmp_path / "old.safetensors"
    ckpt.save(old, payload)
    code, _, err = _run(capsys, "evaluate", "--dataset", "zara2", "--data-root", fold_root,
                        "--model", old, "--samples", "4", "--no-progress", "--device",
                        "cpu")  # fmt: skip
    assert code == 2 and f"{old} (through its denoiser) was trained on the zara1 fold" in err


def test_a_generator_trained_through_another_folds_denoiser(tiny_run, fold_root, tmp_path,
                                                            capsys):  # fmt: skip
    eth = _relabel(tiny_run / "denoiser.safetensors", tmp_path / "eth.safetensors", "eth")
    out = tmp_path / "gen"
    code, _, err = _run(capsys, "train", "generator", "--config", tiny_run / "config.yaml",
                        "--dataset", "zara1", "--data-root", fold_root, "--denoiser", eth,
                        "--out", out, "--device", "cpu", "--no-progress", "--set",
                        "generator.epochs=1")  # fmt: skip
    assert code == 0
    assert f"--denoiser {eth}: the denoiser was trained on the eth fold" in err
    gen = out / "generator.safetensors"
    lineage = read_checkpoint_header(gen)["meta"]["trained_on"]
    assert _without_files(lineage) == [_entry("denoiser", "eth"), _entry("generator", "zara1")]
    code, _, err = _run(capsys, "evaluate", "--dataset", "zara1", "--data-root", fold_root,
                        "--model", gen, "--samples", "4", "--no-progress", "--device",
                        "cpu")  # fmt: skip
    assert code == 2 and f"{gen} (through its denoiser) was trained on the eth fold" in err
    # as its scorer alone would be
    code, _, err = _run(capsys, "evaluate", "--dataset", "zara1", "--data-root", fold_root,
                        "--model", "cv", "--scorer", eth, "--select", "score-first", "--keep",
                        "1", "--samples", "4", "--no-progress", "--device", "cpu")  # fmt: skip
    assert code == 2 and f"{eth} was trained on the eth fold" in err


# ------------------------------------------------------------- own windows, through the chain


def test_the_starts_training_split_is_named_through_the_finetune(tiny_run, walks, tmp_path,
                                                                 capsys):  # fmt: skip
    """Fine-tuned on another folder, the model has still trained on its start's windows."""
    other = write_dataset(tmp_path / "other", seed=3)
    path, _, _ = _finetune(capsys, tiny_run / "generator.safetensors", tmp_path / "ft", "--set",
                           f"data.dataset={other}")  # fmt: skip
    code, out, err = _run(capsys, "evaluate", "--dataset", walks, "--split", "train", "--model",
                          path, "--samples", "2", "--no-progress", "--device", "cpu",
                          "--json")  # fmt: skip
    assert code == 0
    assert json.loads(out)["overlap"] == (f"model trained on these windows (train split of "
                                          f"{walks}, through the generator it was fine-tuned "
                                          "from)")  # fmt: skip
    assert f"{path} {START_VIA} trained on these windows" in err
    # its own data's test split, and the start's, are silent
    for data in (other, walks):
        code, out, _ = _run(capsys, "evaluate", "--dataset", data, "--split", "test", "--model",
                            path, "--samples", "2", "--no-progress", "--device", "cpu",
                            "--json")  # fmt: skip
        assert code == 0 and json.loads(out)["overlap"] is None
    # Python's evaluate says the same
    with pytest.warns(UserWarning, match="through the generator it was fine-tuned from"):
        res = evaluate(load_predictor(path), load_dataset(str(walks), "train"), 2,
                       progress=False, collision_radius=None)  # fmt: skip
    said = f"model trained on these windows (train split of {walks}, through {START})"
    assert res["overlap"] == said


# ------------------------------------------------------------------------------ the preset


def test_the_paper_preset_is_recorded_and_shown(tiny_run, walks, tmp_path, capsys):
    start = tiny_run / "generator.safetensors"
    path, out, _ = _finetune(capsys, start, tmp_path / "paper", "--preset", "paper")
    assert out.strip().splitlines()[-1].startswith("fine-tuned (rlhf, paper preset) in ")
    assert read_checkpoint_header(path)["meta"]["preset"] == "paper"
    base = ["evaluate", "--dataset", walks, "--samples", "2", "--json", "--no-progress",
            "--device", "cpu"]  # fmt: skip
    code, out, _ = _run(capsys, *base, "--model", path)
    res = json.loads(out)
    assert code == 0 and (res["finetune_method"], res["finetune_preset"]) == ("rlhf", "paper")
    # a file written before meta.preset: its config's finetune section says it
    payload = ckpt.load(path)
    payload["meta"] = {k: v for k, v in payload["meta"].items() if k != "preset"}
    ckpt.save(tmp_path / "old.safetensors", payload)
    code, out, _ = _run(capsys, *base, "--model", tmp_path / "old.safetensors")
    assert json.loads(out)["finetune_preset"] == "paper"
    # the default run: no preset; a preset value changed: the line says which
    path, out, _ = _finetune(capsys, start, tmp_path / "plain")
    assert out.strip().splitlines()[-1].startswith("fine-tuned (rlhf) in ")
    code, out, _ = _run(capsys, *base, "--model", path)
    assert json.loads(out)["finetune_preset"] is None
    path, out, _ = _finetune(capsys, start, tmp_path / "changed", "--preset", "paper", "--set",
                             "finetune.clip=0.3")  # fmt: skip
    last = out.strip().splitlines()[-1]
    assert last.startswith("fine-tuned (rlhf, paper preset with finetune.clip changed) in ")
    assert read_checkpoint_header(path)["meta"]["preset"] is None


def test_finetune_preset_reads_a_config_or_its_dict():
    cfg = load_config(None, [])
    assert finetune_preset(cfg.finetune) is None
    paper = load_config(None, ["finetune.method=rlhf", "finetune.kl_form=paper",
                               "finetune.ratio_against=reference",
                               "finetune.likelihood=mean", "finetune.score_every=3",
                               "finetune.gae_lambda=0.0", "finetune.value_target=reward",
                               "finetune.adv_norm=none", "finetune.reward_clip=null",
                               "finetune.clip=0.2", "finetune.value_clip=0.2",
                               "finetune.policy_weight=1.0",
                               "finetune.value_weight=5.0"])  # fmt: skip
    assert finetune_preset(paper.finetune) == "paper"
    values = dataclasses.asdict(paper.finetune)
    assert finetune_preset(values) == "paper"
    assert finetune_preset({**values, "method": "control"}) is None
    assert finetune_preset({**values, "value_weight": 1.5}) is None
    assert finetune_preset(None) is None


# ------------------------------------------------------ the record names the validation data


def test_the_record_says_where_the_model_chose_its_epoch(tiny_run, walks, tmp_path):
    timing = load_predictor(tiny_run / "generator.safetensors").timing
    assert (timing["val_dataset"], timing["holdout_scene"]) == (None, None)
    header = read_checkpoint_header(ckpt.resolve_path("robo/generator"))
    assert (model_timing(header)["val_dataset"], model_timing(header)["holdout_scene"]) == \
        ("robo", None)  # fmt: skip
    # Python's evaluate names the validation split it chose its epoch on, as the CLI does
    with pytest.warns(UserWarning, match="the model chose its epoch on these windows"):
        res = evaluate(load_predictor(tiny_run / "generator.safetensors"),
                       load_dataset(str(walks), "val"), 2, progress=False,
                       collision_radius=None)  # fmt: skip
    assert res["overlap"] == f"model chose its epoch on these windows (val split of {walks})"
    # chosen on another folder (the generator and its denoiser): its own val split is not named
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["data"]["val_dataset"] = str(tmp_path / "elsewhere")
    for entry in payload["meta"]["trained_on"]:  # the record of another validation folder
        entry["val_dataset"] = str(tmp_path / "elsewhere")
        entry.pop("files", None)  # whose files' digests are not these
    ckpt.save(tmp_path / "g.safetensors", payload)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = evaluate(load_predictor(tmp_path / "g.safetensors"),
                       load_dataset(str(walks), "val"), 2, progress=False,
                       collision_radius=None)  # fmt: skip
    assert res["overlap"] is None


def test_robo_generator_on_robos_val_split_in_python(data_root):
    model = load_predictor("robo/generator")
    data = load_dataset("robo", "val", data_root).evenly_spaced(2)
    with pytest.warns(UserWarning, match="chose its epoch on these windows: this is robo's val"):
        res = evaluate(model, data, 2, progress=False)
    assert res["overlap"] == "model chose its epoch on these windows (robo's val split)"


def test_train_generator_through_a_denoiser_of_the_same_fold_is_silent(
    tiny_run, fold_root, tmp_path, capsys
):
    zara1 = _relabel(tiny_run / "denoiser.safetensors", tmp_path / "z.safetensors", "zara1")
    code, _, err = _run(capsys, "train", "generator", "--config", tiny_run / "config.yaml",
                        "--dataset", "zara1", "--data-root", fold_root, "--denoiser", zara1,
                        "--out", tmp_path / "g", "--device", "cpu", "--no-progress", "--set",
                        "generator.epochs=1")  # fmt: skip
    assert code == 0 and "the denoiser was trained on" not in err
