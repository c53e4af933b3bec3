"""The command line's finish: score metrics in evaluate's text, strict JSON, `config show`,
the resume command after Ctrl-C, and only rank 0 reporting."""

from __future__ import annotations

import json
import math
import os
import re
import shlex
import warnings
from pathlib import Path

import pytest
import torch
from helpers import _run

import trajpref.cli as cli
from trajpref.config import ExperimentConfig, config_entries
from trajpref.train.run import train_stage


def test_evaluate_prints_the_score_metrics_in_text_too(capsys, walks, tiny_run):
    argv = ["evaluate", "--dataset", walks, "--model", "cv", "--samples", "6", "--no-progress",
            "--device", "cpu", "--scorer", tiny_run / "denoiser.safetensors"]  # fmt: skip
    code, text, _ = _run(capsys, *argv)
    assert code == 0
    code, js, _ = _run(capsys, *argv, "--json")
    res = json.loads(js)
    line = next(x for x in text.splitlines() if "maxATS" in x)
    found = dict(re.findall(r"(maxATS|maxFTS|meanATS) (-?\d+\.\d+)", line))
    assert float(found["maxATS"]) == pytest.approx(res["max_ats"], abs=1e-4)
    assert float(found["maxFTS"]) == pytest.approx(res["max_fts"], abs=1e-4)
    assert float(found["meanATS"]) == pytest.approx(res["mean_ats"], abs=1e-4)
    recalls = [float(v) for v in re.findall(r"(\d\.\d{3})/(\d\.\d{3})", line)[0]]
    assert recalls == pytest.approx([res["top1_recall_ats"], res["top5_recall_ats"]], abs=1e-3)


def test_non_finite_metrics_are_null_in_json_with_a_warning(capsys, monkeypatch, walks, tmp_path):
    def fake_evaluate(*args, **kwargs):
        return {"min_ade": math.inf, "min_fde": math.nan, "joint_min_ade": 1.0,
                "joint_min_fde": 2.0, "agents": 3, "scenes": 1}  # fmt: skip

    monkeypatch.setattr(cli, "evaluate", fake_evaluate)
    out_file = tmp_path / "r.json"
    code, out, err = _run(capsys, "evaluate", "--dataset", walks, "--json", "--out", out_file)
    assert code == 0
    for text in (out, out_file.read_text()):
        assert "Infinity" not in text and "NaN" not in text
        res = json.loads(text)
        assert res["min_ade"] is None and res["min_fde"] is None and res["joint_min_ade"] == 1.0
    assert (
        err.strip() == "trajpref: warning: min_ade, min_fde not finite: the JSON output holds null"
    )


def test_a_model_trained_in_other_units_or_at_another_step_is_named_in_one_warning(
    capsys, walks, tiny_run
):
    base = ["evaluate", "--dataset", walks, "--no-progress", "--device", "cpu"]
    # a published pedestrian model (metres, 0.4 s) on pixel data read at 0.1 s steps
    code, _, err = _run(capsys, *base, "--model", "zara1/generator", "--units", "px",
                        "--frame-interval", "0.1", "--samples", "20")  # fmt: skip
    assert code == 0
    assert err.strip() == (
        "trajpref: warning: zara1/generator was trained on the zara1 fold (leave-one-out: the "
        "other four scenes): this data is in px, the model's in m; this data steps 0.1 s, the "
        "model's 0.4 s (--time-step 4 reads it at the model's step)"
    )
    # the same data described as the model's: silent; so is a model trained on a user folder
    # (its units were not recorded) and the constant-velocity baseline (each at its own K)
    for model, k in (("zara1/generator", 20), (tiny_run / "generator.safetensors", 4),
                     ("cv", 4)):  # fmt: skip
        code, _, err = _run(capsys, *base, "--model", model, "--units", "m", "--frame-interval",
                            "0.4", "--samples", k)  # fmt: skip
        assert (code, err) == (0, ""), model


def test_the_models_own_read_step_counts_in_the_step_check(capsys, walks, monkeypatch):
    # a model trained on zara1 read every 2 frame steps (data.time_step) predicts 0.8 s steps
    header = {"config": {"data": {"dataset": "zara1", "time_step": 2.0}}}
    monkeypatch.setattr(cli.ckpt, "header_of", lambda spec: header)
    monkeypatch.setattr(cli.ckpt, "resolve_path", lambda spec: spec)
    from trajpref.data import load_dataset

    data = load_dataset(str(walks), "test", frame_interval=0.8, units="m")
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        cli._warn_if_trained_otherwise("m.safetensors", data)
    assert seen == []  # 0.8 s data for a 0.8 s model
    data = load_dataset(str(walks), "test", frame_interval=0.4)
    with pytest.warns(UserWarning, match=r"the model's 0\.8 s \(--time-step 2 reads it"):
        cli._warn_if_trained_otherwise("m.safetensors", data)


def test_lone_walkers_collision_rates_say_why_they_are_nan(capsys, tmp_path):
    from synthetic import straight_rows, write_tracks

    write_tracks(tmp_path / "alone" / "a.txt", straight_rows(24, agents=1))
    code, out, err = _run(capsys, "evaluate", "--dataset", tmp_path / "alone", "--model", "cv",
                          "--units", "m", "--no-progress")  # fmt: skip
    assert code == 0
    assert "not finite (no agent has a neighbour): printed as n/a" in err


def test_options_that_change_nothing_say_so(capsys, walks):
    base = ["evaluate", "--dataset", walks, "--model", "cv", "--samples", "4", "--keep", "2",
            "--no-progress", "--device", "cpu"]  # fmt: skip
    code, _, err = _run(capsys, *base, "--select", "kmeans", "--drop", "0.2")
    assert code == 0
    assert (
        err.strip() == "trajpref: warning: --select kmeans does not read --drop: it changes nothing"
    )
    code, _, err = _run(capsys, *base, "--select", "kmeans")
    assert (code, err) == (0, "")
    code, _, err = _run(capsys, *base, "--select", "facility", "--bandwidth", "1",
                        "--select-temperature", "1")  # fmt: skip
    assert code == 0  # facility reads its bandwidth, not a temperature (it reads no score)
    assert err.strip() == ("trajpref: warning: --select facility does not read "
                           "--select-temperature: it changes nothing")  # fmt: skip


def test_a_built_in_dataset_ignores_folder_descriptions_and_says_so(capsys, data_root):
    code, out, err = _run(capsys, "data", "stats", "--dataset", "zara1", "--units", "px",
                          "--data-root", data_root)  # fmt: skip
    assert code == 0 and "units: m" in out
    assert (
        "--frame-interval and --units describe a folder dataset; zara1 knows its own (m, "
        "0.4 s), so they are ignored" in err
    )
    # the default's own value, given explicitly, is given all the same
    code, _, err = _run(capsys, "data", "stats", "--dataset", "zara1", "--frame-interval", "0.4",
                        "--data-root", data_root)  # fmt: skip
    assert code == 0 and "so they are ignored" in err
    code, _, err = _run(capsys, "data", "stats", "--dataset", "zara1", "--data-root", data_root)
    assert code == 0 and "ignored" not in err
    # evaluate checks its data options twice (the command, then the model's loading)
    code, _, err = _run(capsys, "evaluate", "--dataset", "zara1", "--model", "cv", "--samples",
                        "1", "--data-root", data_root, "--no-progress")  # fmt: skip
    assert code == 0 and "ignored" not in err


def test_config_show_prints_every_key_with_its_docstring(capsys):
    code, out, _ = _run(capsys, "config", "show", "--set", "data.max_agents=64")
    assert code == 0
    lines = out.splitlines()
    entries = config_entries(ExperimentConfig())
    assert len(entries) > 60
    for key, _, doc in entries:
        i = next(i for i, x in enumerate(lines) if x.startswith(f"{key} = "))
        assert doc and lines[i + 1].startswith("    ")  # a docstring follows every key
        assert " ".join(lines[i + 1].split()) in doc
    assert "data.max_agents = 64" in lines  # --set applies
    assert "finetune.reward_clip = 5.0" in lines and "data.val_dataset = null" in lines
    assert "# finetune: Stage 3: RLHF / RLHF-ReS fine-tuning." in lines


TRAIN_ARGS = ["train", "diffusion", "--set", "data.dataset=walks", "--no-progress"]


def _interrupting_train(write_state: bool):
    """A stand-in for train_stage: Ctrl-C arrives, after an epoch ended or before."""

    def fake(stage, cfg, out, *args, **kwargs):
        if write_state:
            Path(out).mkdir(parents=True, exist_ok=True)
            torch.save({"stage": "denoiser"}, Path(out) / "denoiser_last.pt")
        raise KeyboardInterrupt

    return fake


def test_ctrl_c_prints_the_exact_resume_command(capsys, monkeypatch, tmp_path):
    run = tmp_path / "my run"  # a space: the command must be quoted to be pasted back
    monkeypatch.setattr(cli, "train_stage", _interrupting_train(True))
    code, out, err = _run(capsys, *TRAIN_ARGS, "--out", run)
    assert code == 130 and out == ""
    first, command = err.strip().splitlines()
    assert first == "trajpref: interrupted; to continue from the last finished epoch:"
    assert shlex.split(command) == ["trajpref", *TRAIN_ARGS, "--out", str(run), "--resume",
                                    str(run / "denoiser_last.pt")]  # fmt: skip
    # a run started with --resume: the old value is replaced, not repeated
    os.utime(run / "denoiser_last.pt", (0, 0))  # (the fake writes it again below)
    code, _, err = _run(capsys, *TRAIN_ARGS, "--out", run, "--resume", tmp_path / "old_last.pt")
    command = shlex.split(err.strip().splitlines()[1])
    assert command.count("--resume") == 1 and command[-1] == str(run / "denoiser_last.pt")
    # under torchrun: the same launcher and number of processes
    monkeypatch.setenv("WORLD_SIZE", "2")
    os.utime(run / "denoiser_last.pt", (0, 0))
    code, _, err = _run(capsys, *TRAIN_ARGS, "--out", run)
    command = shlex.split(err.strip().splitlines()[1])
    assert command[:4] == ["torchrun", "--nproc_per_node=2", "-m", "trajpref.cli"]


def test_ctrl_c_before_an_epoch_ends(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(cli, "train_stage", _interrupting_train(False))
    code, _, err = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r")
    assert code == 130 and "nothing to resume" in err
    # an old state from an earlier run is not offered; the state this run started from is
    old = tmp_path / "r" / "denoiser_last.pt"
    old.parent.mkdir()
    torch.save({}, old)
    os.utime(old, (0, 0))  # written long before this run started
    code, _, err = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r")
    assert "nothing to resume" in err
    code, _, err = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r", "--resume", "a_last.pt")
    assert shlex.split(err.strip().splitlines()[1])[-2:] == ["--resume", "a_last.pt"]


def test_only_rank_0_reports(capsys, monkeypatch, tmp_path):
    summary = {"best": {"score": math.inf}, "train_seconds": 1.0}
    monkeypatch.setattr(cli, "train_stage", lambda *a, **k: {**summary, "rank": 1})
    code, out, err = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r")
    assert code == 0 and out == "" and err == ""
    monkeypatch.setattr(cli, "train_stage", _interrupting_train(True))
    monkeypatch.setenv("RANK", "1")
    code, out, err = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r")
    assert code == 130 and out == "" and err == ""
    monkeypatch.setattr(cli, "train_stage", lambda *a, **k: {**summary, "rank": 0})
    monkeypatch.setenv("RANK", "0")
    code, out, _ = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r")
    assert out.startswith("trained diffusion in 1 s (training time over all sessions); best "
                          "validation: score=inf")  # fmt: skip
    summary["best"] = {"score": 0.123456, "val_denoise_loss": 0.123456, "epoch": 7}
    (tmp_path / "r" / "denoiser.safetensors").write_bytes(b"")
    code, out, _ = _run(capsys, *TRAIN_ARGS, "--out", tmp_path / "r")
    assert out.strip() == (
        "trained diffusion in 1 s (training time over all sessions); best validation at epoch "
        f"7: score=0.1235 val_denoise_loss=0.1235; kept {tmp_path / 'r' / 'denoiser.safetensors'}"
    )


def test_a_run_reports_its_rank(tiny_cfg, tmp_path):
    summary = train_stage("diffusion", tiny_cfg, tmp_path / "r", device="cpu", progress=False,
                          max_steps=1)  # fmt: skip
    assert summary["rank"] == 0 and math.isfinite(summary["best"]["score"])


def test_unit_names_that_mean_metres_are_not_a_mismatch(capsys, tmp_path):
    from synthetic import straight_rows, write_tracks

    write_tracks(tmp_path / "d" / "a.txt", straight_rows(20))
    code, _, err = _run(capsys, "evaluate", "--dataset", tmp_path / "d", "--units", "Meters",
                        "--model", "zara1/generator", "--samples", "2",
                        "--no-progress")  # fmt: skip
    assert code == 0 and "this data is in" not in err
    code, _, err = _run(capsys, "evaluate", "--dataset", tmp_path / "d", "--units", "ft",
                        "--model", "zara1/generator", "--samples", "2",
                        "--no-progress")  # fmt: skip
    assert code == 0 and "this data is in ft, the model's in m" in err


def test_the_step_hint_keeps_the_time_step_given_and_names_an_assumed_interval(capsys, tmp_path):
    from synthetic import write_dataset

    long = write_dataset(tmp_path / "long", frames=44)
    # read every 2 frames at the assumed 0.4 s: the files' own interval is not known, so no
    # --time-step number is advised (--time-step 1 was wrong whenever 2 was right, e.g. for
    # 10 Hz files read at --time-step 4); the interval is asked for instead
    code, _, err = _run(capsys, "evaluate", "--dataset", long, "--samples", "2", "--no-progress",
                        "--model", "zara1/generator", "--units", "m", "--time-step",
                        "2")  # fmt: skip
    assert code == 0 and err.strip().endswith(
        "this data steps 0.8 s, the model's 0.4 s (0.4 s between frames is assumed: give the "
        "files' own with --frame-interval; --time-step 0.4 / that interval then reads them at "
        "the model's step)"
    )
    # with the interval given, the hint is a number again
    code, _, err = _run(capsys, "evaluate", "--dataset", long, "--samples", "2", "--no-progress",
                        "--model", "zara1/generator", "--units", "m", "--time-step", "2",
                        "--frame-interval", "0.1")  # fmt: skip
    assert code == 0 and err.strip().endswith(
        "this data steps 0.2 s, the model's 0.4 s (--time-step 4 reads it at the model's step)"
    )


def test_the_sampling_flags_say_when_a_generator_takes_no_denoising_step(
    capsys, monkeypatch, walks, tiny_run
):
    gen = tiny_run / "generator.safetensors"
    base = ["evaluate", "--dataset", walks, "--model", gen, "--samples", "4", "--no-progress",
            "--device", "cpu", "--stochastic"]  # fmt: skip
    code, _, err = _run(capsys, *base)
    assert (code, err) == (0, "")  # tau > 0: the flag acts
    load = cli.load_predictor

    def without_steps(*args, **kwargs):
        model = load(*args, **kwargs)
        model.tau = 0
        return model

    monkeypatch.setattr(cli, "load_predictor", without_steps)
    code, _, err = _run(capsys, *base)
    assert code == 0
    assert err.strip() == (
        f"trajpref: warning: {gen} takes no denoising step (model.tau 0): its "
        "samples are the generator's own, and --stochastic changes nothing"
    )


def test_the_denoiser_stage_answers_to_its_file_name_and_subcommands_are_named(
    capsys, tmp_path, monkeypatch
):
    code, _, err = _run(capsys, "data")
    assert code == 2 and "the following arguments are required: COMMAND" in err
    seen = []
    # main() builds its parser on each call, so the parser takes the patched command
    monkeypatch.setattr(cli, "cmd_train", lambda args: seen.append(args.stage) or 0)
    code, _, _ = _run(capsys, "train", "denoiser", "--out", tmp_path / "r")
    assert code == 0 and seen == ["diffusion"]


def _state_then_signal(signum):
    """A stand-in for train_stage: an epoch's state is written, then ``signum`` arrives."""
    import signal

    def fake(stage, cfg, out, *args, **kwargs):
        Path(out).mkdir(parents=True, exist_ok=True)
        torch.save({"stage": "denoiser"}, Path(out) / "denoiser_last.pt")
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        os.kill(os.getpid(), signum)  # its handler raises before the next line
        raise AssertionError("the signal did not stop training")

    return fake


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_the_resume_advice_starts_trajpref_as_this_process_was_started(
    capsys, monkeypatch, tmp_path, signame
):
    """Batch walkthrough 2026-12-06: the advice always began `trajpref ...`, which fails under
    an un-activated /path/.venv/bin/trajpref (not on PATH) and where `python -m trajpref` ran
    it. It starts the program as it was started now, after Ctrl-C and SIGTERM alike."""
    import signal
    import sys

    signum = getattr(signal, signame)
    code_wanted = {"SIGINT": 130, "SIGTERM": 143}[signame]
    monkeypatch.setattr(cli, "train_stage", _state_then_signal(signum))
    empty = tmp_path / "bin"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))  # neither trajpref nor python found by name
    run = tmp_path / "run"
    tail = [*TRAIN_ARGS, "--out", str(run), "--resume", str(run / "denoiser_last.pt")]
    script = tmp_path / "venv" / "bin" / "trajpref"
    module = tmp_path / "site-packages" / "trajpref" / "__main__.py"
    for argv0, launcher in ((str(script), [str(script)]),
                            (str(module), [sys.executable, "-m", "trajpref"]),
                            (str(module.with_name("cli.py")),
                             [sys.executable, "-m", "trajpref.cli"])):  # fmt: skip
        monkeypatch.setattr(sys, "argv", [argv0, *TRAIN_ARGS, "--out", str(run)])
        code, _, err = _run(capsys, *TRAIN_ARGS, "--out", run)
        assert code == code_wanted
        assert shlex.split(err.strip().splitlines()[1]) == [*launcher, *tail], err
    # the trajpref script that PATH finds is `trajpref`, as typed
    script.parent.mkdir(parents=True)
    script.write_text("#!/bin/sh\n")
    script.chmod(0o755)
    monkeypatch.setenv("PATH", str(script.parent))
    monkeypatch.setattr(sys, "argv", [str(script), *TRAIN_ARGS, "--out", str(run)])
    code, _, err = _run(capsys, *TRAIN_ARGS, "--out", run)
    assert shlex.split(err.strip().splitlines()[1]) == ["trajpref", *tail]


def test_an_error_closes_the_commands_bars_but_not_the_callers(tmp_path, capsys):
    """``cli.main`` called in-process (a notebook, a wrapper): an error closed every tqdm bar
    of the process, the caller's own too; now only those the command opened."""
    from io import StringIO

    from tqdm import tqdm

    from trajpref.cli import _close_bars, _open_bars

    mine = tqdm(total=10, disable=False, file=StringIO())
    try:
        earlier = _open_bars()
        assert mine in earlier
        theirs = tqdm(total=10, disable=False, file=StringIO())
        _close_bars(earlier)
        assert theirs not in _open_bars() and mine in _open_bars()
        code = cli.main(["evaluate", "--dataset", str(tmp_path / "nothing"), "--model", "cv"])
        assert code == 2 and mine in _open_bars()
    finally:
        mine.close()
