"""The command line: JSON interfaces, and bad input giving one line and a non-zero status."""

import json
import subprocess
import sys

import numpy as np
import pytest
from synthetic import straight_rows, write_tracks

from trajpref.cli import main


@pytest.fixture
def folder(tmp_path):
    """A user dataset: a folder with train/ and test/ sub-folders."""
    root = tmp_path / "mydata"
    write_tracks(root / "train" / "a.txt", straight_rows(30, agents=3))
    write_tracks(root / "test" / "b.txt", straight_rows(22, agents=2))
    return root


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


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
