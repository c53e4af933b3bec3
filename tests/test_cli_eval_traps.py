"""Traps a paper author met in evaluate, predict and plot (walkthrough 62): another ETH/UCY
fold's model, --protocol sgan off ETH/UCY, --samples below a generator's K, a seed that
changes nothing, --out's format and provenance, plot --scene by id, the protocol in the
header."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from helpers import _run
from synthetic import straight_rows, write_tracks

from trajpref import __version__
from trajpref.data import load_dataset
from trajpref.data.registry import ETH_UCY
from trajpref.models import checkpoint as ckpt

FOLDS = ("zara1", "zara2")


@pytest.fixture(scope="module")
def fold_root(tmp_path_factory):
    """A data root with two tiny ETH/UCY folds (eth_ucy/<fold>/<split>/*.txt): straight
    walkers in pairs, and one loner."""
    root = tmp_path_factory.mktemp("root")
    for fold in FOLDS:
        for split in ("train", "val", "test"):
            rows = straight_rows(24, agents=2) + [(10 * f, 9, 0.0, 0.5 * f) for f in range(30, 50)]
            write_tracks(root / "eth_ucy" / fold / split / f"{fold}_{split}.txt", rows)
    return root


@pytest.fixture(scope="module")
def zara2_model(tiny_run, tmp_path_factory):
    """The tiny generator (K = 4, two deterministic denoising steps), its header saying it was
    trained on the zara2 fold."""
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["data"]["dataset"] = "zara2"
    payload["meta"] = {k: v for k, v in payload["meta"].items() if k != "data_timing"}
    path = tmp_path_factory.mktemp("zara2") / "generator.safetensors"
    ckpt.save(path, payload)
    return path


def _base(command, fold_root, model, dataset="zara1"):
    return [command, "--dataset", dataset, "--data-root", fold_root, "--model", model,
            "--samples", "4", "--no-progress", "--device", "cpu"]  # fmt: skip


# finding 1: another fold's model has trained on this fold's windows


def test_evaluate_refuses_another_folds_model_naming_its_own_fold(
    capsys, fold_root, zara2_model, tmp_path
):
    out = tmp_path / "e.json"
    code, stdout, err = _run(capsys, *_base("evaluate", fold_root, zara2_model), "--out", out)
    assert code == 2 and stdout == "" and err.count("\n") == 1
    assert err.startswith(f"trajpref: error: {zara2_model} was trained on the zara2 fold "
                          "(leave-one-out: the other four scenes), zara1 among them")  # fmt: skip
    assert "uses data it trained on" in err and "its own fold is zara2" in err
    assert "e.g. --model zara1/generator on --dataset zara1" in err
    assert "--allow-overlap" in err and not out.exists()
    # any split of the other fold; a --scorer of another fold too
    code, _, err = _run(capsys, *_base("evaluate", fold_root, zara2_model), "--split", "train")
    assert code == 2 and "zara1 among them" in err
    code, _, err = _run(capsys, *_base("evaluate", fold_root, "cv"), "--scorer", zara2_model)
    assert code == 2 and f"{zara2_model} was trained on the zara2 fold" in err


def test_allow_overlap_evaluates_warns_and_records_it(capsys, fold_root, zara2_model):
    code, out, err = _run(capsys, *_base("evaluate", fold_root, zara2_model), "--json",
                          "--allow-overlap")  # fmt: skip
    assert code == 0 and err.count("trajpref: warning:") == 1 and "zara1 among them" in err
    assert json.loads(out)["overlap"] == "zara2 model on zara1"
    # its own fold: nothing to say or record
    code, out, err = _run(capsys, *_base("evaluate", fold_root, zara2_model, "zara2"), "--json")
    assert (code, err) == (0, "") and json.loads(out)["overlap"] is None


def test_predict_and_plot_warn_of_another_folds_model(capsys, fold_root, zara2_model, tmp_path):
    for command, out in (("predict", tmp_path / "p.npz"), ("plot", tmp_path / "p.png")):
        code, _, err = _run(capsys, *_base(command, fold_root, zara2_model), "--out", out)
        assert code == 0 and err.count("\n") == 1, command
        assert err.startswith(f"trajpref: warning: {zara2_model} was trained on the zara2 fold")
    meta = json.loads(np.load(tmp_path / "p.npz")["meta"].item())
    assert meta["overlap"] == "zara2 model on zara1"


def test_the_units_warning_says_a_fold_model_was_trained_on_the_other_scenes(
    capsys, walks, zara2_model
):
    code, _, err = _run(capsys, "evaluate", "--dataset", walks, "--units", "px", "--model",
                        zara2_model, "--samples", "4", "--no-progress")  # fmt: skip
    assert code == 0
    assert err == (f"trajpref: warning: {zara2_model} was trained on the zara2 fold "
                   "(leave-one-out: the other four scenes): this data is in px, the model's "
                   "in m\n")  # fmt: skip


# walkthrough 62 (a contributor), item 4: a folder of a fold's Social-GAN files is that fold;
# the advice names a published model only where there is one


SAID = ("--frame-interval", "0.4", "--units", "m")
"""A folder's pace and units, as the fold models read theirs (else a warning asks for them)."""


def _sgan_folder(root, test_files, splits=True):
    """A folder laid out like Social-GAN's: ``test/`` holds ``test_files`` (tiny straight
    walkers), ``train/`` and ``val/`` other scenes' ``*_train``/``*_val`` files; with
    ``splits`` False the test files lie in the folder itself."""
    rows = straight_rows(24, agents=2)
    for name in test_files:
        write_tracks(root / ("test" if splits else "") / name, rows)
    if splits:
        for split in ("train", "val"):
            write_tracks(root / split / f"biwi_hotel_{split}.txt", rows)
    return root


@pytest.mark.parametrize(("files", "splits"), [(["crowds_zara01.txt"], True),
                                               (["CROWDS_ZARA01.TXT"], False)])  # fmt: skip
def test_a_folder_of_a_folds_sgan_files_is_that_fold(capsys, zara2_model, tmp_path, files,
                                                     splits):  # fmt: skip
    folder = _sgan_folder(tmp_path / "mine", files, splits)
    code, stdout, err = _run(capsys, *_base("evaluate", tmp_path, zara2_model, folder))
    assert code == 2 and stdout == "" and err.count("\n") == 1
    assert err.startswith(f"trajpref: error: {zara2_model} was trained on the zara2 fold "
                          "(leave-one-out: the other four scenes), zara1 among them: "
                          f"--dataset {folder} holds zara1's Social-GAN test files "
                          "(crowds_zara01)")  # fmt: skip
    assert "its own fold is zara2" in err and "--model zara1/generator on that folder" in err
    # the files' pace and units said (else they are asked for): the overlap's warning alone
    code, out, err = _run(capsys, *_base("evaluate", tmp_path, zara2_model, folder), "--json",
                          "--allow-overlap", *SAID)  # fmt: skip
    assert code == 0 and err.count("trajpref: warning:") == 1
    assert json.loads(out)["overlap"] == f"zara2 model on zara1 ({folder})"


@pytest.mark.realdata
def test_the_real_zara1_folder_given_as_a_path_is_the_zara1_fold(capsys, zara2_model, data_root):
    from trajpref.data.registry import SGAN_TEST_FILES, sgan_folds

    root = data_root / "eth_ucy"
    assert (root / "zara1" / "test").is_dir(), f"the data root {data_root} has no ETH/UCY folds"
    for fold, names in SGAN_TEST_FILES.items():  # the release's test file names
        assert sorted(p.stem for p in (root / fold / "test").glob("*.txt")) == list(names)
        assert sgan_folds(root / fold) == (fold,)
    code, _, err = _run(capsys, "evaluate", "--dataset", root / "zara1", "--model", zara2_model,
                        "--samples", "4", "--no-progress")  # fmt: skip
    assert code == 2 and "zara1 among them" in err


def test_a_folder_of_its_own_folds_files_or_others_is_not_refused(capsys, zara2_model, tmp_path):
    own = _sgan_folder(tmp_path / "own", ["crowds_zara02.txt"])
    code, out, err = _run(capsys, *_base("evaluate", tmp_path, zara2_model, own), "--json",
                          *SAID)  # fmt: skip
    assert (code, err) == (0, "") and json.loads(out)["overlap"] is None
    # uni_examples and crowds_zara03 are in every fold's training split, no fold's test
    other = _sgan_folder(tmp_path / "other", ["uni_examples.txt", "crowds_zara03.txt"])
    code, out, err = _run(capsys, *_base("evaluate", tmp_path, zara2_model, other), "--json",
                          *SAID)  # fmt: skip
    assert (code, err) == (0, "") and json.loads(out)["overlap"] is None


def test_a_folder_of_several_folds_files_overlaps_every_folds_model(capsys, zara2_model, tmp_path):
    folder = _sgan_folder(tmp_path / "both", ["crowds_zara02.txt", "students003.txt"])
    code, _, err = _run(capsys, *_base("evaluate", tmp_path, zara2_model, folder))
    assert code == 2 and "zara2 fold (leave-one-out: the other four scenes), univ among them" in err
    assert "holds univ and zara2's Social-GAN test files (students001, students003, " in err
    assert "evaluate each fold's scenes apart" in err


def test_the_advice_names_a_published_model_only_where_there_is_one(
    capsys, fold_root, zara2_model, tmp_path, monkeypatch
):
    from trajpref.models import zoo

    shelf = tmp_path / "zoo"
    (shelf / "zara1").mkdir(parents=True)
    (shelf / "zara1" / "denoiser.safetensors").write_bytes(b"")  # a denoiser, no generator
    monkeypatch.setattr(zoo, "ZOO_DIR", shelf)
    code, _, err = _run(capsys, *_base("evaluate", fold_root, zara2_model))
    assert code == 2 and "--model zara1/generator" not in err
    assert "its own fold is zara2; evaluate each fold with its own fold's models: on --dataset " \
        "zara1, a model of your own trained on the zara1 fold);" in err  # fmt: skip
    scorer = tmp_path / "scorer.safetensors"  # another file trained on the zara2 fold
    scorer.write_bytes(zara2_model.read_bytes())
    code, _, err = _run(capsys, *_base("evaluate", fold_root, zara2_model), "--scorer", scorer)
    assert code == 2 and "on --dataset zara1, a model of your own trained on the zara1 fold " \
        "and --scorer zara1/denoiser);" in err  # fmt: skip


def test_the_dataset_help_lists_the_registrys_names(monkeypatch):
    from trajpref import cli

    monkeypatch.setattr(cli, "NAMES", (*cli.NAMES, "zara1b"))
    text = cli.build_parser()._subparsers._group_actions[0].choices["evaluate"].format_help()
    assert "zara1b" in " ".join(text.split())


# finding 2: sgan is ETH/UCY's counting


@pytest.mark.parametrize("command", ["data stats", "evaluate", "predict", "plot"])
def test_protocol_sgan_is_refused_on_sdd(capsys, command, tmp_path):
    argv = [*command.split(), "--dataset", "sdd", "--protocol", "sgan"]
    if command in ("predict", "plot"):
        argv += ["--out", tmp_path / ("p.npz" if command == "predict" else "p.png")]
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "--protocol sgan is Social-GAN's ETH/UCY counting" in err
    assert "the SDD and NBA peers count every agent" in err and "--protocol all" in err


@pytest.mark.parametrize("dataset", ["nba", "robo", "robo-mix", "robo-sim"])
def test_protocol_sgan_is_refused_on_other_built_in_datasets(capsys, dataset):
    code, _, err = _run(capsys, "data", "stats", "--dataset", dataset, "--protocol", "sgan")
    assert code == 2 and f"ETH/UCY folds ({', '.join(ETH_UCY)}) only" in err


def test_protocol_sgan_stays_for_eth_ucy_folds_and_own_folders(capsys, fold_root, walks):
    code, out, _ = _run(capsys, "data", "stats", "--dataset", "zara1", "--data-root", fold_root,
                        "--protocol", "sgan", "--json")  # fmt: skip
    assert code == 0 and json.loads(out)["protocol"] == "sgan"
    code, out, _ = _run(capsys, "data", "stats", "--dataset", walks, "--protocol", "sgan", "--json")
    assert code == 0 and json.loads(out)["protocol"] == "sgan"


# findings 4 and 6: --samples below a fixed K; a seed that changes nothing


def test_samples_below_the_generators_k_warn_once_pointing_at_keep(capsys, walks, tiny_run):
    gen = tiny_run / "generator.safetensors"
    base = ["--dataset", walks, "--model", gen, "--no-progress", "--device", "cpu"]
    code, _, err = _run(capsys, "evaluate", *base, "--samples", "2")
    assert code == 0 and err.count("\n") == 1
    assert err.startswith(f"trajpref: warning: {gen} emits a set of K = 4 samples")
    assert "--samples 2 takes its first 2" in err and "--samples 4 --keep 2" in err
    assert "docs/selection.md" in err
    code, _, err = _run(capsys, "predict", *base, "--samples", "3", "--out", walks.parent / "p.npz")
    assert code == 0 and "--samples 3 takes its first 3" in err
    code, _, err = _run(capsys, "plot", *base, "--samples", "3", "--out", walks.parent / "p.png")
    assert code == 0 and err.count("\n") == 1 and "--samples 3 takes its first 3" in err
    for samples in ("4", "3 --keep 2"):  # all of its K: silent; --keep of fewer: said too
        code, _, err = _run(capsys, "evaluate", *base, "--samples", *samples.split())
        assert code == 0 and ("takes its first" in err) == (samples != "4")
    code, _, err = _run(capsys, "evaluate", *base, "--model", "cv", "--samples", "1")
    assert (code, err) == (0, "")  # cv draws each sample on its own


def test_a_seed_given_to_a_model_that_draws_no_noise_is_said_to_change_nothing(
    capsys, walks, tiny_run
):
    gen = tiny_run / "generator.safetensors"
    base = ["evaluate", "--dataset", walks, "--model", gen, "--samples", "4", "--no-progress",
            "--device", "cpu", "--json"]  # fmt: skip
    code, out, err = _run(capsys, *base, "--seed", "1")
    assert code == 0 and json.loads(out)["seed"] == 1
    assert err == (f"trajpref: warning: {gen} draws no noise (its denoising steps are the "
                   "posterior mean): every seed gives the same samples, and --seed 1 changes "
                   "nothing (it is still recorded)\n")  # fmt: skip
    for flags in ([], ["--seed", "1", "--stochastic"], ["--seed", "1", "--keep", "2",
                                                       "--select", "random"]):  # fmt: skip
        code, _, err = _run(capsys, *base, *flags)
        assert (code, err) == (0, ""), flags
    code, _, err = _run(capsys, *base[:4], "cv", *base[5:], "--seed", "1")
    assert (code, err) == (0, "")  # cv draws with the seed
    code, _, err = _run(capsys, "plot", *base[1:-1], "--seed", "1", "--out", walks.parent / "s.png")
    assert code == 0 and err.endswith("--seed 1 changes nothing\n")  # a figure records no seed


# finding 5: --out's format, and what made a result


def test_evaluate_out_writes_json_or_csv_by_suffix_and_refuses_others(capsys, walks, tmp_path):
    base = ["evaluate", "--dataset", walks, "--samples", "3", "--no-progress", "--json",
            "--bins", "2"]  # fmt: skip
    code, out, _ = _run(capsys, *base, "--out", tmp_path / "r.json")
    assert code == 0 and json.loads((tmp_path / "r.json").read_text()) == json.loads(out)
    code, out, _ = _run(capsys, *base, "--out", tmp_path / "r.CSV")
    assert code == 0
    with open(tmp_path / "r.CSV", newline="") as fh:
        rows = list(csv.reader(fh))
    assert len(rows) == 2 and len(rows[0]) == len(rows[1])
    row = dict(zip(*rows, strict=True))
    res = json.loads(out)
    assert float(row["min_ade"]) == res["min_ade"] and row["dataset"] == str(walks)
    assert row["model"] == "cv" and row["sampler"] == "" and row["overlap"] == ""
    assert row["bins.<=2.agents"] == str(res["bins"]["<=2"]["agents"])  # nested: dotted
    assert row["trajpref_version"] == __version__ and row["command"].startswith("trajpref ")
    for name in ("r.txt", "r"):
        code, _, err = _run(capsys, *base, "--out", tmp_path / name)
        assert code == 2 and "the output must be a .json or .csv file" in err
        assert not (tmp_path / name).exists()


def test_evaluate_json_records_what_made_it(capsys, walks, tiny_run):
    gen = tiny_run / "generator.safetensors"
    argv = ["evaluate", "--dataset", walks, "--model", gen, "--samples", "4", "--no-progress",
            "--device", "cpu", "--json", "--max-speed", "0.5", "--spread-scale", "0.9",
            "--max-agents", "7"]  # fmt: skip
    code, out, _ = _run(capsys, *argv)
    res = json.loads(out)
    assert code == 0
    assert (res["sampler"], res["stochastic_steps"]) == ("leapfrog", False)
    assert (res["max_speed"], res["spread_scale"]) == (0.5, 0.9)
    assert "max_log_sigma" in res  # the file's own: none given
    assert (res["max_agents"], res["device"], res["trajpref_version"]) == (7, "cpu", __version__)
    assert res["torch_version"] and res["threads"] >= 1 and "CPU cores" in res["machine"]
    assert res["date"].endswith("Z") and res["date"][4] == "-"
    assert res["command"] == "trajpref " + " ".join(str(a) for a in argv)
    code, out, _ = _run(capsys, "evaluate", "--dataset", walks, "--model", gen, "--no-progress",
                        "--json", "--sampler", "full", "--samples", "2")  # fmt: skip
    full = json.loads(out)
    assert code == 0 and (full["sampler"], full["max_speed"]) == ("full", None)  # no generator


def test_predict_npz_carries_its_provenance(capsys, walks, tiny_run, tmp_path):
    gen = tiny_run / "generator.safetensors"
    out = tmp_path / "p.npz"
    code, _, _ = _run(capsys, "predict", "--dataset", walks, "--model", gen, "--samples", "4",
                      "--seed", "3", "--protocol", "sgan", "--no-progress", "--device", "cpu",
                      "--out", out)  # fmt: skip
    assert code == 0
    with np.load(out) as z:  # no pickle needed
        meta = json.loads(z["meta"].item())
        assert z["meta"].shape == () and z["pred"].shape[0] == 4
    assert (meta["dataset"], meta["split"], meta["protocol"]) == (str(walks), "test", "sgan")
    assert (meta["model"], meta["samples"], meta["seed"]) == (str(gen), 4, 3)
    assert meta["model_hash"] and meta["weights_hash"] and meta["sampler"] == "leapfrog"
    assert meta["trajpref_version"] == __version__
    assert meta["command"].startswith("trajpref predict ")


# finding 9: plot --scene by id


def test_plot_takes_a_scene_id_and_names_how_to_find_one(capsys, walks, tmp_path):
    ids = [s.scene_id for s in load_dataset(str(walks), "test").scenes]
    base = ["plot", "--dataset", walks, "--samples", "2", "--no-progress", "--out",
            tmp_path / "f.png"]  # fmt: skip
    code, out, _ = _run(capsys, *base, "--scene", ids[3])
    assert code == 0 and f"scene 3 ({ids[3]}): minADE_2" in out
    code, by_index, _ = _run(capsys, *base, "--scene", "3")
    assert code == 0 and by_index == out
    file, _, frame = ids[3].partition("@frame=")
    code, _, err = _run(capsys, *base, "--scene", f"{file}@frame={int(frame) + 1}")
    assert code == 2 and err.count("\n") == 1 and "has this id" in err
    assert f"the nearest of {file}: {ids[3]}" in err and "saves every scene's as scene_id" in err
    code, _, err = _run(capsys, *base, "--scene", "nope.txt@frame=1")
    assert code == 2 and "its files: walk0.txt" in err
    code, _, err = _run(capsys, *base, "--scene", "-1")
    assert code == 2 and "scene indices start at 0" in err


# finding 11: the header names the protocol


def test_the_evaluate_header_always_names_the_protocol(capsys, walks):
    for protocol in ("all", "sgan"):
        code, out, _ = _run(capsys, "evaluate", "--dataset", walks, "--samples", "1",
                            "--no-progress", "--protocol", protocol)  # fmt: skip
        assert code == 0 and out.startswith(f"{walks}/test (protocol {protocol})  model=cv")


def test_a_missing_scene_id_with_frames_written_as_times_names_the_nearest():
    """Frame labels written as times (0.4, 0.8, ...) are numbers too: the nearest ids are
    named (an int() of them raised a traceback)."""
    from types import SimpleNamespace

    from trajpref.cli import _scene_index
    from trajpref.errors import TrajprefError

    scenes = [SimpleNamespace(scene_id=f"w.txt@frame={t}") for t in ("0.4", "0.8", "1.2")]
    info = SimpleNamespace(name="mine", split="test", protocol="all")
    ds = SimpleNamespace(info=info, scenes=scenes)
    with pytest.raises(TrajprefError, match=r"the nearest of w\.txt: w\.txt@frame=0\.8, "):
        _scene_index(SimpleNamespace(scene="w.txt@frame=0.9"), ds)
