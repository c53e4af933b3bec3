"""The command line: JSON interfaces, and bad input giving one line and a non-zero status."""

import argparse
import csv
import dataclasses
import json
import subprocess
import sys
import typing
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import ZARA1, _run, _scene
from synthetic import straight_rows, write_tracks

from trajpref import cli, config
from trajpref.cli import build_parser, main
from trajpref.config import ExperimentConfig, FinetuneConfig, builtin_configs, load_config, to_dict
from trajpref.data import hold_out_scene, load_dataset
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.rl.presets import PRESETS


@pytest.fixture
def folder(tmp_path):
    """A user dataset: a folder with train/ and test/ sub-folders."""
    root = tmp_path / "mydata"
    write_tracks(root / "train" / "a.txt", straight_rows(30, agents=3))
    write_tracks(root / "test" / "b.txt", straight_rows(22, agents=2))
    return root


def test_data_stats_json(capsys, folder):
    code, out, _ = _run(capsys, "data", "stats", "--dataset", folder, "--split", "test", "--json")
    assert code == 0
    stats = json.loads(out)
    assert stats["scenes"] == 3 and stats["agents"] == 6 and stats["split"] == "test"


def test_protocol_option_reaches_stats_and_evaluate(capsys, tmp_path):
    rows = straight_rows(20) + [(10 * f, 9, 0.0, 0.5 * f) for f in range(20, 40)]  # + a loner
    write_tracks(tmp_path / "d" / "a.txt", rows)
    counts = {}
    for protocol in ("all", "sgan"):
        code, out, _ = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--json",
                            "--protocol", protocol)  # fmt: skip
        stats = json.loads(out)
        assert code == 0 and stats["protocol"] == protocol
        counts[protocol] = (stats["scenes"], stats["agents"])
        code, out, _ = _run(capsys, "evaluate", "--dataset", tmp_path / "d", "--samples", "1",
                            "--json", "--protocol", protocol, "--no-progress")  # fmt: skip
        res = json.loads(out)
        assert code == 0 and res["protocol"] == protocol and res["agents"] == counts[protocol][1]
    assert counts == {"all": (2, 3), "sgan": (1, 2)}
    code, _, err = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--protocol", "x")
    assert code == 2 and "invalid choice: 'x'" in err


def test_time_step_option_reaches_stats(capsys, tmp_path):
    write_tracks(tmp_path / "d" / "a.txt", [(f * 10, 1, f * 0.1, 0) for f in range(80)])
    code, out, _ = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--json",
                        "--frame-interval", "0.1", "--time-step", "4")  # fmt: skip
    stats = json.loads(out)
    assert code == 0 and stats["scenes"] == 1
    code, _, err = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--time-step", "0")
    assert code == 2 and "time_step must be a number of frame steps" in err


def test_frame_interval_of_trajnet_files_is_theirs_unless_given(capsys, tmp_path):
    # the CLI passed its 0.4 s default as if given; a value given was overridden silently
    (tmp_path / "d").mkdir()
    lines = [json.dumps({"scene": {"id": 1, "p": 1, "s": 0, "e": 20, "fps": 5}})]
    lines += [json.dumps({"track": {"f": f, "p": 1, "x": f / 10, "y": 0}}) for f in range(21)]
    (tmp_path / "d" / "a.ndjson").write_text("\n".join(lines) + "\n")
    code, out, err = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--json")
    assert code == 0 and json.loads(out)["frame_interval"] == 0.2 and err == ""
    code, out, err = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--json",
                          "--frame-interval", "0.5")  # fmt: skip
    assert code == 0 and json.loads(out)["frame_interval"] == 0.2
    assert "the frame interval given (0.5 s, --frame-interval) is ignored" in err


def test_evaluate_json_and_out_file(capsys, folder, tmp_path):
    out_file = tmp_path / "res" / "eval.json"
    code, out, _ = _run(
        capsys,
        "evaluate",
        "--dataset",
        folder,
        "--model",
        "cv",
        "--samples",
        "1",
        "--json",
        "--no-progress",
        "--out",
        out_file,
        "--device",
        "cpu",
    )
    assert code == 0
    res = json.loads(out)
    # agents walk straight lines, so constant velocity is exact
    assert res["min_ade"] == pytest.approx(0, abs=1e-5)
    assert res["min_fde"] == pytest.approx(0, abs=1e-5)
    assert {"joint_min_ade", "joint_min_fde", "agents", "scenes"} <= set(res)
    assert json.loads(out_file.read_text()) == res


def test_predict_writes_the_documented_arrays(capsys, folder, tmp_path):
    out = tmp_path / "pred.npz"
    code, _, _ = _run(
        capsys, "predict", "--dataset", folder, "--samples", "5", "--out", out, "--no-progress"
    )
    assert code == 0
    with np.load(out) as z:
        assert z["history"].shape == (6, 8, 2)
        assert z["future"].shape == (6, 12, 2)
        assert z["pred"].shape == (5, 6, 12, 2)
        assert z["scene"].tolist() == [0, 0, 1, 1, 2, 2]
        # each scene names its file and first frame; strings load without pickle
        assert z["scene_id"].shape == (3,)
        assert all("@frame=" in s for s in z["scene_id"].tolist())
        assert len(set(z["scene_id"].tolist())) == 3
        # absolute coordinates: the first sample (plain CV) continues the straight line
        np.testing.assert_allclose(z["pred"][0], z["future"], atol=1e-4)


def test_plot_writes_png(capsys, folder, tmp_path):
    out = tmp_path / "scene.png"
    code, _, _ = _run(capsys, "plot", "--dataset", folder, "--scene", "1", "--out", out)
    assert code == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


BAD_FILES = {
    "malformed": ("0\t1\t1.0\n", "bad.txt:1: expected 4 columns"),
    "non_number": ("0\t1\t1.0\t2.0\n10\t1\tx\t2\n", "bad.txt:2: not a number"),
    "nan": ("0\t1\tnan\t2.0\n", "bad.txt:1: NaN or infinite"),
    "duplicate": ("0\t1\t1\t2\n0\t1\t1\t2\n", "bad.txt:2: duplicate row"),
    "empty": ("", "bad.txt: empty file"),
    "too_few_frames": ("".join(f"{f}\t1\t{f}\t0\n" for f in range(5)), "bad.txt: too few frames"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
@pytest.mark.parametrize("command", ["evaluate", "predict"])
def test_bad_input_is_one_line_nonzero_and_writes_nothing(capsys, tmp_path, case, command):
    content, message = BAD_FILES[case]
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "bad.txt").write_text(content)
    out = tmp_path / "out.npz"
    argv = [command, "--dataset", tmp_path / "data", "--no-progress"]
    if command == "predict":
        argv += ["--out", out]
    code, stdout, err = _run(capsys, *argv)
    assert code != 0
    assert stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert message in lines[0]
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data"]


def test_missing_folder_and_bad_options(capsys, tmp_path):
    code, _, err = _run(capsys, "evaluate", "--dataset", tmp_path / "nope")
    assert code != 0 and "no such folder" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run(capsys, "evaluate", "--dataset", "zara9")
    assert code != 0 and "unknown dataset 'zara9'" in err
    code, _, err = _run(capsys, "evaluate", "--dataset", tmp_path, "--model", tmp_path / "x.pt")
    assert code != 0 and "no such model" in err
    code, _, err = _run(capsys, "evaluate", "--dataset", tmp_path, "--samples", "0")
    assert code != 0 and "--samples" in err
    code, _, err = _run(capsys, "evaluate", "--dataset", tmp_path, "--device", "tpu")
    assert code != 0 and "unknown device" in err


def test_missing_data_root(capsys, monkeypatch):
    monkeypatch.delenv("TRAJPREF_DATA", raising=False)
    code, _, err = _run(capsys, "data", "stats", "--dataset", "zara1")
    assert code != 0 and "TRAJPREF_DATA" in err


@pytest.mark.realdata
def test_real_data_stats_and_evaluate(capsys, data_root):
    code, out, _ = _run(
        capsys, "data", "stats", "--dataset", "eth", "--data-root", data_root, "--json"
    )
    assert code == 0 and json.loads(out)["agents"] == 364
    code, out, _ = _run(
        capsys,
        "evaluate",
        "--dataset",
        "eth",
        "--data-root",
        data_root,
        "--samples",
        "1",
        "--json",
        "--no-progress",
    )
    res = json.loads(out)
    assert code == 0 and res["agents"] == 364 and res["scenes"] == 253
    assert 0.1 < res["min_ade"] < 2.0


def test_denoising_step_flags_pick_posterior_means_or_ancestral_noise(capsys, tiny_run, walks):
    base = ["evaluate", "--dataset", walks, "--split", "test", "--samples", "4", "--json",
            "--no-progress", "--model", tiny_run / "generator.safetensors"]  # fmt: skip
    results = {}
    for flag in ("", "--deterministic", "--stochastic"):
        code, out, _ = _run(capsys, *base, *([flag] if flag else []))
        assert code == 0
        results[flag] = json.loads(out)
    # a generator trained today has posterior-mean steps by default
    assert results[""]["min_ade"] == results["--deterministic"]["min_ade"]
    assert results["--stochastic"]["min_ade"] != results["--deterministic"]["min_ade"]
    code, _, err = _run(capsys, *base, "--deterministic", "--stochastic")
    assert code != 0 and "not allowed with argument" in err


def test_max_speed_clamps_a_generators_fast_agents_at_prediction(capsys, tiny_run, walks):
    base = ["evaluate", "--dataset", walks, "--split", "test", "--samples", "4", "--json",
            "--no-progress", "--model", tiny_run / "generator.safetensors"]  # fmt: skip
    results = {}
    for flag in ([], ["--max-speed", "0"], ["--max-speed", "1e6"], ["--max-speed", "1e-3"]):
        code, out, _ = _run(capsys, *base, *flag)
        assert code == 0
        results[" ".join(flag)] = json.loads(out)["min_ade"]
    # off, or above every agent: the file's own prediction; below every agent: another one
    assert results[""] == results["--max-speed 0"] == results["--max-speed 1e6"]
    assert results["--max-speed 1e-3"] != results[""]


@pytest.mark.parametrize(
    ("flag", "neutral", "binding"), [("--spread-scale", "1", "3"), ("--max-log-sigma", "1e6", "-8")]
)
def test_a_sampling_setting_changes_a_generators_samples_only_when_it_binds(
    capsys, tiny_run, walks, flag, neutral, binding
):
    base = ["evaluate", "--dataset", walks, "--split", "test", "--samples", "4", "--json",
            "--no-progress", "--model", tiny_run / "generator.safetensors"]  # fmt: skip
    results = {}
    for value in (None, neutral, binding):
        code, out, _ = _run(capsys, *base, *([flag, value] if value else []))
        assert code == 0
        results[value] = json.loads(out)["min_ade"]
    assert results[None] == results[neutral]  # the spread as trained, or a cap above it
    assert results[binding] != results[None]


def test_the_cli_imports_without_the_survey_web_server_packages():
    # training on a machine without starlette/uvicorn (a bare GPU image) must work: the web
    # server is imported only by `survey serve`
    code = ("import sys; sys.modules['uvicorn'] = None; sys.modules['starlette'] = None; "
            "import trajpref.cli; print('ok')")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"


def test_holdout_scene_evaluates_the_held_out_files_of_both_splits(capsys, walks):
    from trajpref.data import load_dataset

    train, val = load_dataset(str(walks), "train"), load_dataset(str(walks), "val")
    want = sum(s.num_agents for s in train.scenes + val.scenes if s.scene_id.startswith("walk0"))
    code, out, _ = _run(capsys, "evaluate", "--dataset", walks, "--split", "val", "--samples",
                        "1", "--json", "--no-progress", "--holdout-scene", "walk0")  # fmt: skip
    res = json.loads(out)
    assert code == 0 and res["holdout_scene"] == "walk0"
    assert res["agents"] == want and want > val.num_agents  # train's walk0 windows came in
    code, out, _ = _run(capsys, "evaluate", "--dataset", walks, "--split", "val", "--samples",
                        "1", "--no-progress", "--holdout-scene", "walk0")  # fmt: skip
    assert code == 0 and "(held-out scene walk0*)" in out
    code, out, _ = _run(capsys, "evaluate", "--dataset", walks, "--split", "val", "--json",
                        "--samples", "1", "--no-progress")  # fmt: skip
    assert "holdout_scene" not in json.loads(out)


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--split", "test", "--holdout-scene", "walk0"], "use it with --split val"),
        (["--split", "val", "--holdout-scene", ""], "needs a file-name prefix"),
        (["--split", "val", "--holdout-scene", "nope"], "its files: walk0.txt, walk1.txt"),
    ],
)
def test_holdout_scene_bad_input_is_one_clear_error(capsys, walks, extra, message):
    code, _, err = _run(capsys, "evaluate", "--dataset", walks, "--no-progress", *extra)
    assert code == 2 and message in err


def test_data_stats_counts_reversed_context_only_when_asked(capsys, tmp_path):
    rows = [(f * 10, 1, f, 0) for f in range(20)] + [(f * 10, 3, f, 2) for f in range(2, 20)]
    write_tracks(tmp_path / "d" / "a.txt", rows)
    code, out, _ = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--json")
    assert code == 0 and "context_agents_reversed" not in json.loads(out)
    code, out, _ = _run(capsys, "data", "stats", "--dataset", tmp_path / "d", "--json",
                        "--reverse-context")  # fmt: skip
    stats = json.loads(out)
    assert code == 0 and stats["context_agents"] == 1 and stats["context_agents_reversed"] == 1


FINETUNE_TINY = ["--set", "finetune.epochs=1", "--set", "finetune.steps_per_epoch=1", "--set",
                 "finetune.eval_max_scenes=2", "--device", "cpu", "--no-progress"]  # fmt: skip


def test_finetune_names_its_reward_and_evaluate_records_the_checkpoint(
    capsys, tiny_run, walks, tmp_path
):
    from trajpref.io import read_checkpoint_header
    from trajpref.models import checkpoint as ckpt

    start = tiny_run / "generator.safetensors"
    argv = ["finetune", "--method", "rlhf", "--from", start, "--out", tmp_path / "ft", "--set",
            "finetune.reward=set", *FINETUNE_TINY]  # fmt: skip
    code, out, _ = _run(capsys, *argv)
    last = out.strip().splitlines()[-1]  # after the loop's epoch lines
    assert code == 0 and last.startswith("fine-tuned (rlhf, set-aware reward) in ")
    tuned = tmp_path / "ft" / "finetune.safetensors"
    assert read_checkpoint_header(tuned)["meta"]["method"] == "rlhf"  # the stored value stays
    assert read_checkpoint_header(tuned)["meta"]["reward"] == "set"  # the file says its reward
    base = ["evaluate", "--dataset", walks, "--samples", "2", "--json", "--no-progress",
            "--device", "cpu"]  # fmt: skip
    code, out, _ = _run(capsys, *base, "--model", tuned, "--out", tmp_path / "e.json")
    res = json.loads(out)
    assert code == 0 and json.loads((tmp_path / "e.json").read_text()) == res
    assert res["model"] == str(tuned) and res["model_hash"] == ckpt.model_hash(tuned)
    assert res["weights_hash"] == read_checkpoint_header(tuned)["hash"]
    assert (res["finetune_method"], res["finetune_reward"]) == ("rlhf", "set")
    assert res["start_hash"] == read_checkpoint_header(start)["hash"]
    # a pretrained generator: its hashes, no fine-tuning fields; a sampling option changes
    # what predicts, so the model hash follows it
    code, out, _ = _run(capsys, *base, "--model", start)
    plain = json.loads(out)
    assert plain["model_hash"] == ckpt.model_hash(start) and "finetune_method" not in plain
    code, out, _ = _run(capsys, *base, "--model", start, "--max-speed", "1e-3")
    clamped = json.loads(out)
    assert clamped["model_hash"] != plain["model_hash"]
    assert clamped["weights_hash"] == plain["weights_hash"]
    code, out, _ = _run(capsys, *base, "--model", "cv")
    assert (json.loads(out)["model_hash"], json.loads(out)["weights_hash"]) == (None, None)


def test_a_folder_without_split_folders_warns_that_validation_reads_training(
    capsys, monkeypatch, tiny_run, walks, tmp_path
):
    import trajpref.cli as cli

    flat = tmp_path / "flat"
    flat.mkdir()
    for f in (walks / "train").iterdir():
        (flat / f.name).write_text(f.read_text())
    summary = {"best": {"score": 0.5}, "train_seconds": 1.0}
    monkeypatch.setattr(cli, "train_stage", lambda *a, **k: summary)
    monkeypatch.setattr(cli, "finetune", lambda *a, **k: summary)
    start = tiny_run / "generator.safetensors"
    runs = {
        "train": ["train", "diffusion", "--out", tmp_path / "t", "--device", "cpu"],
        "finetune": ["finetune", "--method", "rlhf", "--from", start, "--out", tmp_path / "f"],
    }
    for argv in runs.values():
        code, _, err = _run(capsys, *argv, "--set", f"data.dataset={flat}")
        assert code == 0 and len(err.strip().splitlines()) == 1
        assert err.startswith(f"trajpref: warning: {flat} has no train/ and val/ sub-folders, "
                              "so validation (and the choice of the kept checkpoint) reads "
                              "the training windows")  # fmt: skip
        assert "data.val_dataset=FOLDER" in err and "data.holdout_scene=PREFIX" in err
        # kept apart: split folders, another validation dataset, a held-out scene
        for extra in ([f"data.dataset={walks}"],
                      [f"data.dataset={flat}", f"data.val_dataset={walks}"],
                      [f"data.dataset={flat}", "data.holdout_scene=walk0"]):  # fmt: skip
            code, _, err = _run(capsys, *argv, *(a for e in extra for a in ("--set", e)))
            assert code == 0 and err == ""


def test_finetune_equal_budget_and_seed_reach_the_run_config(capsys, monkeypatch, tiny_run):
    import trajpref.cli as cli

    seen = []
    monkeypatch.setattr(cli, "finetune", lambda cfg, *a, **k: seen.append(cfg) or
                        {"best": {"score": 0.5}, "train_seconds": 1.0})  # fmt: skip
    argv = ["finetune", "--method", "control", "--from", tiny_run / "generator.safetensors",
            "--out", "unused", "--equal-budget", "2"]  # fmt: skip
    code, out, _ = _run(capsys, *argv)
    ft = seen[-1].finetune
    assert code == 0 and out.startswith("fine-tuned (control) in 1 s")
    assert (ft.max_minutes, ft.budget_clock, ft.eval_every_minutes, ft.warmup_steps,
            ft.epochs) == (2.0, "cpu", 0.5, 4, 100000)  # fmt: skip
    assert seen[-1].seed == 0  # not the start's: --seed's documented default
    _run(capsys, *argv, "--seed", "3")
    assert seen[-1].seed == 3


def test_finetune_help_explains_each_method_the_rewards_and_the_seed(capsys):
    code = main(["finetune", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert code == 0
    for part in ("rlhf: the policy and value losses on all K samples",
                 "rlhf-res: on each scene's best-scored sample k* only",
                 "control: the supervised generator loss alone", "set-aware reward",
                 "finetune.reward=set", "--equal-budget MINUTES", "the run's seed (default 0, "
                 "whatever seed the start was trained with)"):  # fmt: skip
        assert part in text, part


# --- under torchrun: what runs, what is printed once, the advice after SIGTERM or a failure


def _torchrun_env(monkeypatch, rank, world=2, local=None, nodes=None):
    """The variables torchrun sets for a worker (without starting any process group)."""
    monkeypatch.setenv("WORLD_SIZE", str(world))
    monkeypatch.setenv("RANK", str(rank))
    monkeypatch.setenv("LOCAL_WORLD_SIZE", str(local or world))
    monkeypatch.setenv("GROUP_WORLD_SIZE", str(nodes or 1))


def test_predict_and_evaluate_refuse_torchrun_and_rank_0_alone_says_why(
    capsys, monkeypatch, folder, tmp_path
):
    out = tmp_path / "pred.npz"
    argv = ["predict", "--dataset", folder, "--samples", "2", "--out", out, "--no-progress"]
    _torchrun_env(monkeypatch, rank=0)
    code, stdout, err = _run(capsys, *argv)
    assert code == 2 and stdout == "" and not out.exists()
    assert err.startswith("trajpref: error: trajpref predict runs in one process; under torchrun")
    _torchrun_env(monkeypatch, rank=1)  # the other ranks stop as well, silently
    code, stdout, err = _run(capsys, "evaluate", "--dataset", folder, "--json", "--no-progress")
    assert (code, stdout, err) == (2, "", "")


def test_an_error_is_printed_by_every_rank_that_meets_it(capsys, monkeypatch, folder, tmp_path):
    """Every rank prints its own error, ranks above 0 with their number: an error only rank 1
    met (a file missing on its machine) showed nothing but torchrun's exit code."""
    argv = ["train", "diffusion", "--dataset", folder, "--set", "denoiser.epoch=2",
            "--out", tmp_path / "r", "--no-progress"]  # fmt: skip
    _torchrun_env(monkeypatch, rank=1)
    code, out, err = _run(capsys, *argv)
    assert (code, out) == (2, "") and err.startswith("trajpref: error: [rank 1] ")
    assert err.count("trajpref: error:") == 1 and "denoiser.epochs" in err
    _torchrun_env(monkeypatch, rank=0)
    code, _, err = _run(capsys, *argv)
    assert code == 2 and err.count("trajpref: error:") == 1 and "denoiser.epochs" in err
    assert "[rank" not in err


def _state_then(exc_or_signal):
    """A stand-in for train_stage: an epoch's state is written, then ``exc_or_signal``
    (an exception to raise, or a signal sent to this process)."""
    import os
    import signal
    from pathlib import Path

    import torch

    def fake(stage, cfg, out, *args, **kwargs):
        Path(out).mkdir(parents=True, exist_ok=True)
        torch.save({"stage": "denoiser"}, Path(out) / "denoiser_last.pt")
        if isinstance(exc_or_signal, signal.Signals):
            os.kill(os.getpid(), exc_or_signal)  # its handler runs before the next line
            raise AssertionError("the signal did not stop training")
        raise exc_or_signal

    return fake


def test_sigterm_during_training_gets_the_resume_advice(capsys, monkeypatch, tmp_path):
    """A scheduler's cancel or preemption (SIGTERM, which torchrun forwards) is advised as
    Ctrl-C is (it ended the process silently)."""
    import shlex
    import signal

    import trajpref.cli as cli

    monkeypatch.setattr(cli, "train_stage", _state_then(signal.SIGTERM))
    run = tmp_path / "run"
    code, _, err = _run(capsys, "train", "diffusion", "--out", run, "--no-progress")
    first, command = err.strip().splitlines()
    assert code == 143
    assert first == "trajpref: terminated (SIGTERM); to continue from the last finished epoch:"
    assert shlex.split(command)[-2:] == ["--resume", str(run / "denoiser_last.pt")]
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored after the command


def test_the_resume_advice_under_torchrun_repeats_the_launcher_it_ran_under(capsys, monkeypatch,
                                                                           tmp_path):  # fmt: skip
    """Several machines: the launcher's own options (here read from a stand-in), with a note
    to run it on each machine; unreadable options: the per-machine count and --nnodes (not
    --nproc_per_node=WORLD_SIZE), and a note to add the launcher's options."""
    import shlex

    import trajpref.cli as cli

    run = tmp_path / "run"
    argv = ["train", "diffusion", "--out", run, "--no-progress"]
    monkeypatch.setattr(cli, "train_stage", _state_then(KeyboardInterrupt()))
    _torchrun_env(monkeypatch, rank=0, world=16, local=8, nodes=2)
    launcher = [".venv/bin/torchrun", "--nnodes", "2", "--node_rank", "0", "--nproc_per_node",
                "8", "--master_addr", "10.0.0.1", "--master_port", "29500", "-m",
                "trajpref.cli"]  # fmt: skip
    monkeypatch.setattr(cli, "launcher_command", lambda: launcher, raising=False)
    code, _, err = _run(capsys, *argv)
    lines = err.strip().splitlines()
    assert code == 130 and shlex.split(lines[1]) == [
        *launcher, *map(str, argv), "--resume", str(run / "denoiser_last.pt")]  # fmt: skip
    assert "on each of the 2 machines" in lines[2]
    monkeypatch.setattr(cli, "launcher_command", lambda: None, raising=False)
    code, _, err = _run(capsys, *argv)
    lines = err.strip().splitlines()
    assert shlex.split(lines[1])[:5] == ["torchrun", "--nnodes=2", "--nproc_per_node=8", "-m",
                                         "trajpref.cli"]  # fmt: skip
    assert "rendezvous" in lines[2]


def test_a_failed_process_under_torchrun_gets_the_resume_advice(capsys, monkeypatch, tmp_path):
    """Another rank died (killed, out of memory): this one's collective fails with a
    RuntimeError; rank 0 says how to continue, and torch's traceback follows."""
    import trajpref.cli as cli

    failure = RuntimeError("[gloo/transport/tcp/pair.cc:553] Connection closed by peer")
    monkeypatch.setattr(cli, "train_stage", _state_then(failure))
    _torchrun_env(monkeypatch, rank=0)
    with pytest.raises(RuntimeError, match="Connection closed"):
        main(["train", "diffusion", "--out", str(tmp_path / "run"), "--no-progress"])
    err = capsys.readouterr().err
    assert err.startswith("trajpref: a process of this run failed; to continue from the last")
    assert "--resume" in err


@pytest.mark.parametrize("command", ["evaluate", "predict"])
def test_a_scorer_trained_on_other_units_is_warned_of_as_plot_warns(capsys, walks, tmp_path,
                                                                   command):  # fmt: skip
    """evaluate --scorer and predict --rank --scorer ranked metres-trained scores on pixels
    without a word (plot and survey build warned)."""
    argv = [command, "--dataset", walks, "--units", "px", "--model", "cv", "--samples", "2",
            "--scorer", "zara1/denoiser", "--device", "cpu", "--no-progress", "--score-every",
            "100"]  # fmt: skip
    argv += ["--json"] if command == "evaluate" else ["--rank", "--out", tmp_path / "p.npz"]
    code, _, err = _run(capsys, *argv)
    assert code == 0
    assert ("trajpref: warning: zara1/denoiser was trained on the zara1 fold (leave-one-out: "
            "the other four scenes): this data is in px, the model's in m") in err  # fmt: skip


# One table of fine-tuning methods (config.FinetuneMethod, config.USES_RL,
# rl.objective.LOSS_SAMPLES): the CLI offers its names, and a name that reaches a dispatch
# without an entry there is an error, never trained as RLHF-ReS (the walkthrough's finding: a
# new method's name took the k* path of ``RLObjective.selection``).


def _finetune_parser() -> argparse.ArgumentParser:
    from trajpref.cli import build_parser

    for action in build_parser()._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices["finetune"]
    raise AssertionError("no finetune command")


def test_the_cli_offers_the_tables_methods():
    method = next(a for a in _finetune_parser()._actions if a.dest == "method")
    assert list(method.choices) == list(config.FINETUNE_METHODS)
    assert config.FINETUNE_METHODS == typing.get_args(config.FinetuneMethod)
    hints = typing.get_type_hints(FinetuneConfig)
    assert typing.get_args(hints["method"]) == config.FINETUNE_METHODS


# Walkthroughs 63-A and 63-B, the command line: the pace and units check on data that leave
# their interval or units unsaid, a folder without split sub-folders read as the model's own
# training windows, ``n/a`` collision rates, the data's reading in ``evaluate --out``, what
# ``--frame-interval`` means, and a legacy ``.pt`` checkpoint in the pace check.


ASSUMED = "this data's frame interval is only assumed (0.4 s between rows, none given)"


GIVE_INTERVAL = "--frame-interval (the seconds between an agent's consecutive rows)"


def _pretend(monkeypatch, header: dict) -> None:
    """Every checkpoint's header is ``header`` (the file itself is never read)."""
    monkeypatch.setattr(cli.ckpt, "header_of", lambda spec: header)
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
    monkeypatch.setattr(cli.ckpt, "header_of", lambda spec: header)
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


# The command line's finding of the library-extension walkthrough: the folder a config
# file's relative data path is read from (tests/test_own_data_training.py tests a path of one
# part, where the file's folder and the path's parent are the same).


def test_a_relative_dataset_of_two_parts_is_pointed_to_the_config_files_folder(
    tmp_path, monkeypatch, capsys, walks
):
    """``dataset: data/mall`` in project/rel.yaml, run elsewhere: the advice is to run from
    project/ (where data/mall resolves), not project/data/ (where it does not)."""
    home = tmp_path / "project"
    (home / "data").mkdir(parents=True)
    (home / "data" / "mall").symlink_to(walks)
    cfg = home / "rel.yaml"
    cfg.write_text("data:\n  dataset: data/mall\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    code = main(["train", "diffusion", "--config", str(cfg), "--out", str(tmp_path / "o"),
                 "--device", "cpu", "--no-progress"])  # fmt: skip
    err = " ".join(capsys.readouterr().err.split())
    assert code != 0
    assert f"beside which {home / 'data' / 'mall'} is" in err
    assert err.rstrip().endswith(f"or run trajpref from {home.resolve()}"), err
    assert f"run trajpref from {(home / 'data').resolve()}" not in err
    # the advice holds: from there, the path is the folder
    assert (home.resolve() / "data" / "mall" / "train").is_dir()
    assert not (tmp_path / "o").exists()


# The installed user's walkthrough (67): a shipped config written out as a YAML file to edit
# (``config show --yaml``), where a built-in dataset lies under an empty data root, the
# fine-tuning presets offered by the CLI, and the question on milliseconds in the CLI's advice
# on a frame interval above 10 s.


def _yaml_out(capsys, *argv: str) -> str:
    code = main(["config", "show", *argv, "--yaml"])
    out = capsys.readouterr().out
    assert code == 0
    return out


@pytest.mark.parametrize("name", builtin_configs())
def test_config_show_yaml_reads_back_to_the_same_config(name, tmp_path, capsys):
    """Every shipped config, printed as YAML, is read back by --config FILE to an equal
    config; the file starts with a comment saying what it was resolved from."""
    text = _yaml_out(capsys, "--config", name)
    assert text.startswith(f"# trajpref config show --config {name} --yaml ")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    assert load_config(str(path)) == load_config(name)


def test_config_show_yaml_applies_set_and_defaults(tmp_path, capsys):
    text = _yaml_out(capsys, "--config", "zara1", "--set", "seed=3",
                     "--set", "denoiser.epochs=7")  # fmt: skip
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    cfg = load_config(str(path))
    assert cfg == load_config("zara1", ["seed=3", "denoiser.epochs=7"])
    assert (cfg.seed, cfg.denoiser.epochs) == (3, 7)
    assert "--set seed=3 --set denoiser.epochs=7 --yaml" in text.splitlines()[0]
    defaults = tmp_path / "defaults.yaml"
    defaults.write_text(_yaml_out(capsys))
    assert load_config(str(defaults)) == load_config(None)


def test_config_show_without_yaml_is_unchanged(capsys):
    assert main(["config", "show", "--config", "zara1"]) == 0
    out = capsys.readouterr().out
    assert "data.dataset = zara1\n" in out and "  dataset: zara1" not in out


def test_the_cli_error_on_an_empty_data_root(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TRAJPREF_DATA", str(tmp_path))
    code = main(["data", "stats", "--dataset", "zara1", "--split", "test"])
    err = capsys.readouterr().err
    assert code != 0
    assert f"{tmp_path / 'eth_ucy' / 'zara1' / 'test'}: no such folder; zara1 is read" in err


def _option(parser, *path: str, flag: str):
    for name in path:
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        parser = sub.choices[name]
    return next(a for a in parser._actions if flag in a.option_strings)


def test_finetune_preset_choices_come_from_presets():
    assert _option(build_parser(), "finetune", flag="--preset").choices == list(PRESETS)


def test_the_cli_warning_asks_milliseconds(tmp_path, capsys, monkeypatch):
    """--frame-interval 400 is not refused (any number > 0 is a frame interval): the
    warning that the data steps otherwise asks whether it is in milliseconds."""
    test = tmp_path / "ds" / "test"
    test.mkdir(parents=True)
    rows = [f"{10 * f}\t{a}\t{0.4 * f + a:.2f}\t{a:.2f}" for f in range(24) for a in (1, 2)]
    (test / "a.txt").write_text("\n".join(rows) + "\n")
    code = main(["evaluate", "--model", "zara1/generator", "--dataset", str(tmp_path / "ds"),
                 "--frame-interval", "400", "--units", "m", "--samples", "4", "--device",
                 "cpu", "--no-progress"])  # fmt: skip
    err = " ".join(capsys.readouterr().err.split())
    assert code == 0, err
    assert (
        "this data steps 400 s, the model's 0.4 s (milliseconds? pass seconds, "
        "--frame-interval 0.4; else no --time-step reads it"
    ) in err, err


# A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
# and inputs the models read; feet given to a metre model are told the factor; a scene with no
# ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
# are types.


def test_evaluate_says_a_folder_scene_with_two_balls(capsys, tmp_path):
    history, types = _scene()
    xy = history[:, :1] + (history[:, 1:2] - history[:, :1]) * np.arange(20)[None, :, None]
    rows = ["time,agent,x,y,type"]
    for t in range(20):
        for i in range(11):
            rows.append(f"{t * 0.12:.2f},{i},{xy[i, t, 0]:.4f},{xy[i, t, 1]:.4f},"
                        f"{'BALL' if types[i] else 'PLAYER'}")  # fmt: skip
        rows.append(f"{t * 0.12:.2f},99,{xy[0, t, 0] + 2:.4f},{xy[0, t, 1] + 2:.4f},BALL")
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / "game.csv").write_text("\n".join(rows) + "\n")
    code = main(["evaluate", "--dataset", str(tmp_path), "--model", "nba/generator", "--units",
                 "m", "--samples", "20", "--no-progress", "--device", "cpu"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 0
    assert "of this data's 1 scene, 1 flags two or more (up to 2)" in err, err


# A paper author's review of `trajpref plot` (walkthrough 67): the ball hidden under its own
# ground truth and coloured as a player, no --keep, a ranked legend of twenty entries that
# did not say which way the score ranks, a standing agent's samples under its marker, agents
# numbered in one figure and not the other (their numbers on their paths), and SVG text drawn
# as outlines.


def _predicted(capsys, walks, tmp_path, flags, scene=0):
    """predict's samples of ``scene`` with ``flags`` [K', P, T_f, 2]."""
    npz = tmp_path / "p.npz"
    code, _, err = _run(capsys, "predict", "--dataset", walks, "--device", "cpu", "--no-progress",
                        *flags, "--out", npz)  # fmt: skip
    assert code == 0, err
    z = np.load(npz)
    return z["pred"][:, z["scene"] == scene]


def test_plot_keeps_k_prime_as_predict_keeps_them_and_says_so(capsys, walks, tmp_path, plot_calls):
    """plot had no --keep: a figure of the samples a selection keeps could not be made."""
    flags = ["--samples", "4", "--keep", "2", "--select", "facility", "--seed", "3"]
    want = _predicted(capsys, walks, tmp_path, flags)  # [2, P, T_f, 2]
    code, out, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--no-progress",
                          *flags, "--out", tmp_path / "f.png")  # fmt: skip
    assert (code, err) == (0, ""), err
    name, args, kwargs = plot_calls[-1]
    assert name == "plot_scene"
    np.testing.assert_allclose(args[2], want, atol=1e-6)
    assert "kept 2 of 4 by facility" in args[5]  # the title
    assert kwargs["selection"] == "kept 2 of 4 by facility"  # the legend's samples entry
    assert "minADE_2" in out
    # with --scorer: the kept samples ranked, at most K' of them
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--no-progress",
                        *flags, "--scorer", "zara1/denoiser", "--draw-samples", "5",
                        "--out", tmp_path / "g.png")  # fmt: skip
    assert code == 0, err
    name, args, kwargs = plot_calls[-1]
    assert name == "plot_scene_scored" and args[2].shape[0] == 2 and args[7] == 2
    assert kwargs["selection"] == "kept 2 of 4 by facility"
    # the selection's checks are predict's
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--samples", "4",
                        "--keep", "5", "--out", tmp_path / "h.png")  # fmt: skip
    assert code == 2 and "--keep must lie in 1..--samples (4)" in err
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--samples", "4",
                        "--drop", "0.5", "--no-progress", "--out", tmp_path / "h.png")  # fmt: skip
    assert code == 0 and "--drop only applies with --keep" in err


@pytest.mark.skipif("zara1/generator" not in zoo.published(),
                    reason="the package was built without its models")  # fmt: skip
def test_plot_keep_chosen_draws_predicts_chosen_samples(capsys, walks, tmp_path, plot_calls):
    flags = ["--model", "zara1/generator", "--keep", "3", "--chosen"]
    want = _predicted(capsys, walks, tmp_path, [*flags, "--max-scenes", "2"])
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--no-progress",
                        *flags, "--out", tmp_path / "f.png")  # fmt: skip
    assert code == 0, err  # (a warning: the synthetic data has no units)
    _, args, kwargs = plot_calls[-1]
    np.testing.assert_allclose(args[2], want, atol=1e-5)
    assert kwargs["selection"] == "kept 3 of 20 by score-facility (chosen)"
    assert "kept 3 of 20 by score-facility (chosen)" in args[5]


def test_plot_no_numbers(capsys, walks, tmp_path, plot_calls):
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--samples", "2",
                        "--no-progress", "--no-numbers", "--out", tmp_path / "f.png")  # fmt: skip
    assert code == 0, err
    assert plot_calls[-1][2]["numbers"] is False
