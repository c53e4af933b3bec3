"""benchmarks/pretrain.py --keep-replaced: the replaced default's row is kept under its own
name, pointing at the commit that holds the weights it measured."""

import json
import shutil
import subprocess

import pytest
from bench import load_benchmark
from helpers import _files, _pretrain

from trajpref.results import FIELDS


def _git(root, *args):
    subprocess.run(["git", "-C", str(root), *args], check=True, capture_output=True)


def _repo(tmp_path):
    """A tiny repository laid out like ours: models -> src/trajpref/zoo, one published row."""
    root = tmp_path / "repo"
    zoo = root / "src" / "trajpref" / "zoo" / "zara1"
    zoo.mkdir(parents=True)
    (root / "models").symlink_to(root / "src" / "trajpref" / "zoo")
    (zoo / "generator.safetensors").write_bytes(b"old weights")
    results = root / "benchmarks" / "results"
    (results / "meta").mkdir(parents=True)
    row = {k: None for k in FIELDS} | {"dataset": "zara1", "method": "pretrained",
                                        "min_fde": 0.318, "checkpoint": "x"}  # fmt: skip
    other = row | {"method": "full-sampler", "min_fde": 0.5}
    (results / "pretrained_zara1.json").write_text(json.dumps([row, other]))
    (results / "meta" / "pretrained_zara1.json").write_text('{"val": 1}\n')
    _git(root, "init", "-q")
    _git(root, "-c", "user.name=t", "-c", "user.email=t@t", "add", ".")
    _git(root, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "old default")
    return root


def test_keep_replaced_writes_the_old_row_under_its_name_with_its_commit(tmp_path):
    mod = load_benchmark("pretrain")
    root = _repo(tmp_path)
    commit = subprocess.run(["git", "-C", str(root), "log", "-1", "--format=%h"],
                            capture_output=True, text=True).stdout.strip()  # fmt: skip
    out = mod.keep_replaced(root, "zara1", "tau5")
    rows = json.loads(out.read_text())
    assert out.name == "pretrained_zara1_tau5.json"
    assert [r["method"] for r in rows] == ["pretrained-tau5"]  # the full sampler's row stays
    assert rows[0]["min_fde"] == 0.318
    weights = "src/trajpref/zoo/zara1/generator.safetensors"
    assert rows[0]["checkpoint"] == f"git show {commit}:{weights}"
    meta = root / "benchmarks" / "results" / "meta" / "pretrained_zara1_tau5.json"
    assert meta.read_text() == '{"val": 1}\n'
    assert mod.keep_replaced(root, "zara1", "tau5") == out  # a rerun is a no-op


def test_keep_replaced_refuses_uncommitted_weights_and_a_taken_name(tmp_path):
    mod = load_benchmark("pretrain")
    root = _repo(tmp_path)
    weights = root / "models" / "zara1" / "generator.safetensors"
    weights.write_bytes(b"new weights, not committed")
    with pytest.raises(SystemExit, match="differs from its last commit"):
        mod.keep_replaced(root, "zara1", "tau5")
    assert not (root / "benchmarks" / "results" / "pretrained_zara1_tau5.json").exists()
    _git(root, "checkout", "--", "src/trajpref/zoo/zara1/generator.safetensors")
    taken = root / "benchmarks" / "results" / "pretrained_zara1_tau5.json"
    taken.write_text("[]")
    with pytest.raises(SystemExit, match="exists already with another row"):
        mod.keep_replaced(root, "zara1", "tau5")
    with pytest.raises(SystemExit, match="no 'pretrained' row"):
        mod.keep_replaced(root, "eth", "tau5")


def test_stage_records_say_how_long_each_stage_trained_and_how_much_of_its_budget_it_used():
    mod = load_benchmark("pretrain")
    logs = {
        "denoiser": [{"epoch": 1, "train_seconds": 10.0, "samples_per_second": 100.0},
                     {"epoch": 2, "train_seconds": 21.0, "samples_per_second": 300.0}],
        "generator": [{"epoch": 7, "train_seconds": 60.0, "samples_per_second": 50.0,
                       "budget_share": 1.0002}],
        "none": [],
    }  # fmt: skip
    seconds, rates, epochs, share = mod.stage_records(logs)
    assert seconds == {"denoiser": 21.0, "generator": 60.0, "none": None}
    assert rates == {"denoiser": 200.0, "generator": 50.0, "none": None}
    assert epochs == {"denoiser": 2, "generator": 7, "none": None}
    assert share == {"denoiser": None, "generator": 1.0002, "none": None}


def test_training_again_skips_the_stages_that_have_finished(tiny_cfg, tmp_path, monkeypatch,
                                                             capsys):  # fmt: skip
    import argparse

    pretrain = load_benchmark("pretrain")
    monkeypatch.setattr(pretrain, "load_config", lambda path: tiny_cfg)
    args = argparse.Namespace(dataset="walks", data_root=None, device="cpu")
    pretrain._train(args, tmp_path)
    before = (tmp_path / "generator.safetensors").read_bytes()
    pretrain._train(args, tmp_path)  # a resume of a finished stage would be refused
    assert "the generator stage has finished" in capsys.readouterr().out
    assert (tmp_path / "generator.safetensors").read_bytes() == before


# Walkthrough 67, fixer F9: ``reproduce.py --out DIR`` in full mode left its training in the
# repository (finetune.py and pretrain.py wrote ``runs/``, ``benchmarks/results/`` and
# ``models/`` of the repository whatever the folder). Both scripts now take ``--runs``,
# ``--results`` and ``--models``, and reproduce.py passes them under ``--out``.


# ----------------------------------------------------------------------------- pretrain.py


def test_pretrain_writes_its_rows_meta_and_models_where_it_is_told(
    repo, tiny_run, tmp_path, monkeypatch, capsys
):
    """HEAD's pretrain.py has no --runs/--results/--models: it published into the
    repository's models/ and wrote its rows there."""
    out = tmp_path / "out"
    shutil.copytree(tiny_run, out / "runs" / "walks")
    before = _files(repo)
    elsewhere = ["--runs", str(out / "runs"), "--results", str(out / "results")]
    with pytest.raises(SystemExit):  # it publishes: not into the repository's models/
        _pretrain(monkeypatch, repo, *elsewhere)
    assert "--models missing" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # names the repository's commits
        _pretrain(monkeypatch, repo, *elsewhere, "--models", str(out / "models"),
                  "--keep-replaced", "old")  # fmt: skip
    assert "--keep-replaced keeps a row of the repository's" in capsys.readouterr().err
    _pretrain(monkeypatch, repo, *elsewhere, "--models", str(out / "models"))
    assert _files(repo) == before
    published = out / "models" / "walks" / "generator.safetensors"
    assert published.is_file() and (published.parent / "denoiser.safetensors").is_file()
    (row,) = json.loads((out / "results" / "pretrained_walks.json").read_text())
    assert row["checkpoint"] == str(published)
    assert (out / "results" / "meta" / "pretrained_walks.json").is_file()


def test_pretrain_with_models_alone_is_refused_and_leaves_the_repository_as_it_is(
    repo, tiny_run, tmp_path, monkeypatch, capsys
):
    """The review's reproducer (``--run-dir /tmp/fr --models /tmp/m``): HEAD's pretrain.py
    published into /tmp/m and replaced the repository's ``pretrained`` row with that
    checkpoint, and its meta/pretrained_walks.json."""
    out = tmp_path / "out"
    shutil.copytree(tiny_run, out / "fr")
    before = _files(repo)
    with pytest.raises(SystemExit) as exit_:
        _pretrain(monkeypatch, repo, "--run-dir", str(out / "fr"), "--models", str(out / "m"))
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "--runs, --results and --models go together" in err
    assert "--runs and --results missing" in err
    assert _files(repo) == before
    assert not (out / "m").exists()
