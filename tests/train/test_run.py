"""The run record: each session of a stage writes where and how it ran beside its config."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shlex
import sys
from pathlib import Path

import pytest
import torch

from trajpref.errors import ConfigError, DataError
from trajpref.train import read_metrics, run
from trajpref.train.run import record_session, run_record_path, train_stage


def test_a_stage_records_its_threads_seed_and_command(tiny_cfg, tmp_path):
    train_stage("diffusion", tiny_cfg, tmp_path, device="cpu", progress=False, max_steps=1)
    sessions = json.loads(run_record_path(tmp_path, "denoiser").read_text())
    assert len(sessions) == 1
    entry = sessions[0]
    assert entry["threads"] == torch.get_num_threads() and entry["seed"] == tiny_cfg.seed
    assert entry["device"] == "cpu" and entry["world_size"] == 1 and not entry["resumed"]
    assert entry["torch"] == torch.__version__ and entry["command"].startswith("python")


def test_a_resumed_stage_appends_a_second_session(tiny_cfg, tmp_path):
    train_stage("diffusion", tiny_cfg, tmp_path, device="cpu", progress=False, max_steps=1)
    train_stage("diffusion", tiny_cfg, tmp_path, device="cpu", progress=False,
                resume=str(tmp_path / "denoiser_last.pt"))  # fmt: skip
    sessions = json.loads(run_record_path(tmp_path, "denoiser").read_text())
    assert [s["resumed"] for s in sessions] == [False, True]


def test_an_unreadable_record_is_started_again_with_a_warning(tmp_path):
    run_record_path(tmp_path, "generator").write_text("{not json")
    with pytest.warns(UserWarning, match="starting it again"):
        record_session(tmp_path, "generator", 3, torch.device("cpu"), 1, resumed=False)
    sessions = json.loads(run_record_path(tmp_path, "generator").read_text())
    assert [s["seed"] for s in sessions] == [3]


def test_a_dataset_folder_given_relative_is_stored_absolute(tiny_cfg, tmp_path, monkeypatch):
    # a run started in the data's parent folder must be usable from anywhere: its config
    # and its checkpoint name the folder by its absolute path
    import dataclasses
    from pathlib import Path

    from trajpref.config import load_config
    from trajpref.models import checkpoint as ckpt

    walks = Path(tiny_cfg.data.dataset)
    monkeypatch.chdir(walks.parent)
    relative = dataclasses.replace(
        tiny_cfg, data=dataclasses.replace(tiny_cfg.data, dataset=walks.name)
    )
    out = tmp_path / "run"
    train_stage("diffusion", relative, out, device="cpu", progress=False, max_steps=1)
    assert load_config(out / "denoiser_config.yaml").data.dataset == str(walks.resolve())
    payload = ckpt.load(out / "denoiser.safetensors")
    assert payload["config"]["data"]["dataset"] == str(walks.resolve())
    assert relative.data.dataset == walks.name  # the caller's config is not changed


def test_a_resume_is_checked_against_the_run_that_wrote_the_state(tiny_cfg, tmp_path):
    from trajpref.train.run import check_resume, run_identity

    state = {"epoch": 2, "identity": run_identity(tiny_cfg, "finetune", "abc")}
    last = tmp_path / "finetune_last.pt"
    # what may change: the schedule's length, the budget, the arithmetic
    longer = dataclasses.replace(tiny_cfg, finetune=dataclasses.replace(
        tiny_cfg.finetune, epochs=9, max_minutes=5.0, precision="bf16"))  # fmt: skip
    check_resume(state, run_identity(longer, "finetune", "abc"), 9, tmp_path, last, "finetune")
    with pytest.raises(ConfigError, match=r"\(start: 'abc' -> 'xyz'\); resume with the "
                       r"checkpoint it starts from as it was"):  # fmt: skip
        check_resume(state, run_identity(tiny_cfg, "finetune", "xyz"), 9, tmp_path, last,
                     "finetune")  # fmt: skip
    other = dataclasses.replace(tiny_cfg, finetune=dataclasses.replace(
        tiny_cfg.finetune, method="rlhf", lr=0.05))  # fmt: skip
    with pytest.raises(ConfigError, match=r"finetune\.lr: .* -> 0\.05; finetune\.method: "):
        check_resume(state, run_identity(other, "finetune", "abc"), 9, tmp_path, last,
                     "finetune")  # fmt: skip
    with pytest.raises(ConfigError, match="finished 3 epochs and this run has 3: nothing left"):
        check_resume(state, state["identity"], 3, tmp_path, last, "finetune")
    # a state from before states recorded their run is not compared
    check_resume({"epoch": 2}, run_identity(other, "finetune", "xyz"), 9, tmp_path, last,
                 "finetune")  # fmt: skip


def test_epochs_done_reads_a_resume_state(tiny_cfg, tmp_path):
    from trajpref.train.run import epochs_done

    assert epochs_done(tmp_path / "denoiser_last.pt") == 0  # no state yet
    train_stage("diffusion", tiny_cfg, tmp_path, device="cpu", progress=False, max_steps=1)
    assert epochs_done(tmp_path / "denoiser_last.pt") == 1


# --- resumes: the command to follow, the data, the time budget; a replaced run's record


def _record(out, name, command, **session):
    out.mkdir(parents=True, exist_ok=True)
    run_record_path(out, name).write_text(json.dumps([{"command": command, **session}]))


def test_the_resume_advice_keeps_the_seed_and_the_launcher_it_ran_with(tmp_path):
    from trajpref.train.run import resume_command

    out, last = tmp_path / "ft", tmp_path / "ft" / "finetune_last.pt"
    # a run without --seed ran with the seed it recorded (once the start's): the advice says it
    _record(out, "finetune", "python /venv/bin/trajpref finetune --method rlhf --out o",
            seed=1, world_size=1)  # fmt: skip
    # (the recorded /venv/bin/trajpref is no script PATH finds: the advice names its path)
    assert resume_command(out, "finetune", last) == (
        f"/venv/bin/trajpref finetune --method rlhf --out o --seed 1 --resume {last}"
    )
    _record(out, "finetune", "python /venv/bin/trajpref finetune --seed=4 --out o", seed=4)
    assert resume_command(out, "finetune", last) == (
        f"/venv/bin/trajpref finetune --seed=4 --out o --resume {last}"
    )
    # torchrun (and python -m trajpref.cli) record the module's file: the advice resumes it,
    # with the same number of processes
    _record(out, "finetune", "python /x/site-packages/trajpref/cli.py train generator --out o "
            "--resume o/old.pt", seed=0, world_size=2)  # fmt: skip
    assert resume_command(out, "finetune", last) == (
        f"torchrun --nproc_per_node=2 -m trajpref.cli train generator --out o --seed 0 "
        f"--resume {last}"
    )
    # a script that resumes by itself is given as it ran
    _record(out, "finetune", "python /x/benchmarks/cli.py --seed 2", seed=2)
    assert resume_command(out, "finetune", last) == "python /x/benchmarks/cli.py --seed 2"


def test_a_refused_resume_gives_the_command_that_started_the_run(tiny_cfg, tmp_path):
    # finetune --config reads only the finetune section, so a finetune_config.yaml cannot
    # restore a data.* override or the seed: the refusal names the recorded command instead
    from trajpref.train.run import check_resume, run_identity

    out, last = tmp_path / "ft", tmp_path / "ft" / "finetune_last.pt"
    state = {"epoch": 0, "identity": run_identity(tiny_cfg, "finetune", "abc")}
    other = dataclasses.replace(tiny_cfg, seed=9)
    with pytest.raises(ConfigError, match=r"resume with its config as it was \(the options it "
                       r"was started with; .*finetune_config\.yaml holds"):  # fmt: skip
        check_resume(state, run_identity(other, "finetune", "abc"), 9, out, last, "finetune")
    _record(out, "finetune", "python /venv/bin/trajpref finetune --method rlhf --from 'a b' "
            f"--out {out} --set data.max_agents=6 --resume {out}/old.pt")  # fmt: skip
    want = (f"as the command that started it did: /venv/bin/trajpref finetune --method rlhf "
            f"--from 'a b' --out {out} --set data.max_agents=6 --resume {last}; only "
            "finetune.")  # fmt: skip
    with pytest.raises(ConfigError, match=re.escape(want)):
        check_resume(state, run_identity(other, "finetune", "abc"), 9, out, last, "finetune")
    # a script that resumes by itself is named as it ran
    _record(out, "finetune", "python benchmarks/finetune.py --dataset zara1")
    with pytest.raises(ConfigError, match="did: python benchmarks/finetune.py --dataset zara1;"):
        check_resume(state, run_identity(other, "finetune", "abc"), 9, out, last, "finetune")
    # a pretraining stage's --config reads its whole file: named first, the command beside it
    state = {"epoch": 0, "identity": run_identity(tiny_cfg, "denoiser")}
    _record(out, "denoiser", "python /venv/bin/trajpref train diffusion --out x --seed 3")
    want = (f"resume with its config as it was (--config {out / 'denoiser_config.yaml'}) or as "
            f"the command that started it did: /venv/bin/trajpref train diffusion --out x --seed 3 "
            f"--resume {out / 'denoiser_last.pt'}; only denoiser.")  # fmt: skip
    with pytest.raises(ConfigError, match=re.escape(want)):
        check_resume(state, run_identity(other, "denoiser"), 9, out, out / "denoiser_last.pt",
                     "denoiser")  # fmt: skip


def test_following_the_refusals_advice_resumes_the_fine_tuning_run(
    tiny_run, tmp_path, monkeypatch, capsys
):
    from trajpref.cli import main

    out = tmp_path / "ft"
    argv = ["finetune", "--method", "control", "--from", str(tiny_run / "generator.safetensors"),
            "--out", str(out), "--seed", "4", "--set", "data.max_agents=6", "--set",
            "finetune.epochs=1", "--set", "finetune.steps_per_epoch=1", "--set",
            "finetune.eval_max_scenes=2", "--device", "cpu", "--no-progress"]  # fmt: skip
    monkeypatch.setattr(sys, "argv", ["/venv/bin/trajpref", *argv])  # what the record keeps
    assert main(argv) == 0
    # the advice of before: the run's own finetune_config.yaml, which finetune --config reads
    # only the finetune section of (the seed and data.max_agents are lost)
    old = ["finetune", "--method", "control", "--from", str(tiny_run / "generator.safetensors"),
           "--out", str(out), "--config", str(out / "finetune_config.yaml"), "--set",
           "finetune.epochs=2", "--resume", str(out / "finetune_last.pt"), "--device", "cpu",
           "--no-progress"]  # fmt: skip
    assert main(old) == 2
    err = capsys.readouterr().err
    assert "(data.max_agents: 6 -> 8; seed: 4 -> " in err
    command = err.split("as the command that started it did: ", 1)[1].split("; only ")[0]
    args = shlex.split(command)
    assert args[0] == "/venv/bin/trajpref"  # the recorded script (not on PATH), by its path
    assert args[-2:] == ["--resume", str(out / "finetune_last.pt")]
    assert main([*args[1:], "--set", "finetune.epochs=2"]) == 0  # a longer schedule may change
    assert [s["resumed"] for s in json.loads((out / "finetune_run.json").read_text())] == [
        False, True]  # fmt: skip


def _walks_copy(tmp_path):
    from synthetic import write_dataset

    return write_dataset(tmp_path / "data")


def test_a_resume_on_changed_data_is_refused_and_names_the_file(tiny_cfg, tmp_path):
    import os

    from trajpref.train.run import data_fingerprint

    data = _walks_copy(tmp_path)
    cfg = dataclasses.replace(tiny_cfg, data=dataclasses.replace(tiny_cfg.data, dataset=str(data)))
    out = tmp_path / "run"
    train_stage("diffusion", cfg, out, device="cpu", progress=False, max_steps=1)
    last = str(out / "denoiser_last.pt")
    # copied or touched files are the same data: the resume goes on
    walk = data / "train" / "walk1.txt"
    os.utime(walk, ns=(1, 1))
    # the same lines, fewer of them: other windows
    walk.write_text("".join(walk.read_text().splitlines(keepends=True)[:-6]))
    with pytest.raises(ConfigError, match=r"the data differ from those the state was trained on "
                       r"\(train walk1\.txt: \d+ windows, [0-9a-f]{16} -> \d+ windows, "
                       r"[0-9a-f]{16}\); a run resumes on its own data"):  # fmt: skip
        train_stage("diffusion", cfg, out, device="cpu", progress=False, resume=last)
    assert [s["resumed"] for s in json.loads(run_record_path(out, "denoiser").read_text())] == [
        False]  # nothing written  # fmt: skip
    # a state written before states recorded their data resumes as it did
    state = torch.load(last, weights_only=True)
    identity = json.loads(state["identity"])
    assert set(identity["data_files"]) == {"train", "val"}
    del identity["data_files"]
    state["identity"] = json.dumps(identity, sort_keys=True)
    torch.save(state, last)
    train_stage("diffusion", cfg, out, device="cpu", progress=False, resume=last)
    # and the checkpoint records which data it was trained on
    from trajpref.data import run_splits
    from trajpref.models import checkpoint as ckpt
    from trajpref.train.run import data_digest

    meta = ckpt.load(out / "denoiser.safetensors")["meta"]
    assert meta["data_hash"] == data_digest(data_fingerprint(*run_splits(cfg.data)))


def test_a_fingerprint_ignores_file_times_and_tells_splits_and_files_apart(tiny_cfg, tmp_path):
    import os
    import shutil

    from trajpref.data import run_splits
    from trajpref.train.run import data_fingerprint

    data = _walks_copy(tmp_path)
    cfg = dataclasses.replace(tiny_cfg.data, dataset=str(data))
    before = data_fingerprint(*run_splits(cfg))
    assert list(before) == ["train", "val"]
    assert list(before["train"]) == ["walk0.txt", "walk1.txt", "walk2.txt"]
    copy = shutil.copytree(data, tmp_path / "copy")  # new times, same content
    for path in copy.rglob("*.txt"):
        os.utime(path, ns=(7, 7))
    assert data_fingerprint(*run_splits(dataclasses.replace(cfg, dataset=str(copy)))) == before
    (data / "val" / "walk0.txt").write_text((data / "train" / "walk0.txt").read_text())
    after = data_fingerprint(*run_splits(cfg))
    assert after["train"] == before["train"] and after["val"] != before["val"]


def test_a_state_from_before_the_folders_interval_and_units_resumes(tiny_cfg, tmp_path):
    # data.frame_interval and data.units were added after resume states recorded their run:
    # at their defaults they stay out of the identity, so an older state resumes; once set,
    # a change is refused as any other
    from trajpref.config import to_dict
    from trajpref.train.run import check_resume, run_identity

    old = to_dict(tiny_cfg)
    for key in ("frame_interval", "units"):
        del old["data"][key]  # what a state of before the keys recorded
    keep = {k: old[k] for k in ("data", "model", "diffusion", "seed")}
    own = {k: v for k, v in old["denoiser"].items() if k not in run.RESUME_FREE}
    state = {"epoch": 0, "identity": json.dumps({**keep, "denoiser": own, "start": None},
                                                sort_keys=True, default=str)}  # fmt: skip
    last = tmp_path / "denoiser_last.pt"
    check_resume(state, run_identity(tiny_cfg, "denoiser"), 2, tmp_path, last, "denoiser")
    set_ = dataclasses.replace(tiny_cfg, data=dataclasses.replace(tiny_cfg.data,
                                                                  frame_interval=0.1))  # fmt: skip
    state = {"epoch": 0, "identity": run_identity(set_, "denoiser")}
    other = dataclasses.replace(tiny_cfg, data=dataclasses.replace(tiny_cfg.data,
                                                                   frame_interval=0.2))  # fmt: skip
    with pytest.raises(ConfigError, match=r"data\.frame_interval: 0\.1 -> 0\.2"):
        check_resume(state, run_identity(other, "denoiser"), 2, tmp_path, last, "denoiser")


def test_a_state_whose_scene_ids_had_float_noise_resumes(tiny_cfg, tmp_path):
    # seconds read every 4 steps: the ids of before 2026-12-06 read 12.700000000000001, now
    # 12.7; a state that fingerprinted the old ids resumes on the same data, and is refused on
    # other data as any state is
    from decimal import Decimal

    from trajpref.data import run_splits, text
    from trajpref.train.run import data_fingerprint

    data = tmp_path / "logs"
    for split in ("train", "val"):
        rows = [f"{Decimal('12.3') + k * Decimal('0.1')},{a},{0.1 * k + a:.3f},{a}"
                for k in range(100) for a in (1, 2)]  # fmt: skip
        (data / split).mkdir(parents=True)
        (data / split / "log.csv").write_text("timestamp,id,x,y\n" + "\n".join(rows) + "\n")
    cfg = dataclasses.replace(tiny_cfg, data=dataclasses.replace(
        tiny_cfg.data, dataset=str(data), time_step=4.0))  # fmt: skip
    out = tmp_path / "run"
    train_stage("diffusion", cfg, out, device="cpu", progress=False, max_steps=1)
    last = out / "denoiser_last.pt"
    with text.exact_frame_labels():
        before = data_fingerprint(*run_splits(cfg.data))
    assert before != data_fingerprint(*run_splits(cfg.data))  # the ids changed
    state = torch.load(last, weights_only=True)
    identity = json.loads(state["identity"])
    state["identity"] = json.dumps({**identity, "data_files": before}, sort_keys=True)
    torch.save(state, last)
    train_stage("diffusion", cfg, out, device="cpu", progress=False, resume=str(last))
    torch.save(state, last)  # the old state again, on changed data
    log = data / "train" / "log.csv"
    log.write_text("".join(log.read_text().splitlines(keepends=True)[:-10]))
    with pytest.raises(ConfigError, match="the data differ from those the state was trained on"):
        train_stage("diffusion", cfg, out, device="cpu", progress=False, resume=str(last))


def test_a_checkpoint_records_the_pace_and_units_it_trained_at(tiny_cfg, tmp_path):
    from trajpref.models import checkpoint as ckpt

    data = dataclasses.replace(tiny_cfg.data, frame_interval=0.1, units="m", time_step=0.5)
    cfg = dataclasses.replace(tiny_cfg, data=data)
    train_stage("diffusion", cfg, tmp_path, device="cpu", progress=False, max_steps=1)
    meta = ckpt.load(tmp_path / "denoiser.safetensors")["meta"]
    assert meta["data_timing"] == {"frame_interval": pytest.approx(0.05), "interval_from": "given",
                                   "time_step": 0.5, "units": "m",
                                   "agent_types": [0]}  # fmt: skip


def test_finetune_refuses_a_config_resolved_from_another_start(tiny_run, tmp_path):
    from trajpref.rl.presets import finetune_config
    from trajpref.train.run import finetune

    start = tiny_run / "generator.safetensors"
    cfg = finetune_config(str(start), "control", overrides=["finetune.epochs=1"])
    for section, change in (("model", {"max_speed": 0.123}), ("diffusion", {"num_steps": 11})):
        other = dataclasses.replace(cfg, **{section: dataclasses.replace(
            getattr(cfg, section), **change)})  # fmt: skip
        key = f"{section}.{next(iter(change))}"
        with pytest.raises(ConfigError, match=rf"the config was not resolved from this start "
                           rf"\({re.escape(key)} = .* in the start, .*config\)"):  # fmt: skip
            finetune(other, start, tmp_path / section, device="cpu", progress=False)
        assert not (tmp_path / section).exists()  # checked before anything is written


def test_fine_tuning_validates_its_start_once_as_epoch_0_never_kept(tiny_run, tmp_path, capsys):
    from trajpref.models import checkpoint as ckpt
    from trajpref.rl.presets import finetune_config
    from trajpref.train import read_metrics
    from trajpref.train.run import finetune

    start = tiny_run / "generator.safetensors"
    small = ["finetune.steps_per_epoch=1", "finetune.eval_max_scenes=2"]
    cfg = finetune_config(str(start), "control", overrides=["finetune.epochs=1", *small])
    out = tmp_path / "ft"
    summary = finetune(cfg, start, out, device="cpu", progress=False)
    rows = read_metrics(out, "finetune", start=True)
    assert [(r["epoch"], r.get("start", False)) for r in rows] == [(0, True), (1, False)]
    first = rows[0]
    assert first["step"] == 0 and "best" not in first and "lr" not in first
    assert summary["start"] == {k[4:]: v for k, v in first.items()
                                if k.startswith("val_") and k != "val_seconds"}  # fmt: skip
    assert [r["epoch"] for r in read_metrics(out, "finetune")] == [1]  # no epoch by default
    assert ckpt.load(out / "finetune.safetensors")["meta"]["epoch"] == 1
    said = capsys.readouterr().out
    assert "[finetune] start (epoch 0, not trained): val_min_ade=" in said
    assert "[finetune] kept epoch 1 against its start (epoch 0, the same validation scenes): " \
           f"min_ade {first['val_min_ade']:.4f} -> " in said  # fmt: skip
    # the same validation as the stage's own, on the untouched start
    from trajpref.data import load_dataset
    from trajpref.train.stages import build_finetune_stage

    val = load_dataset(cfg.data.dataset, "val")
    own = build_finetune_stage(cfg, ckpt.load(start), val, torch.device("cpu")).validate()
    assert own == summary["start"]
    # a resume does not validate the start again, and still sets the kept epoch against it
    longer = dataclasses.replace(cfg, finetune=dataclasses.replace(cfg.finetune, epochs=2))
    resumed = finetune(longer, start, out, device="cpu", progress=False,
                       resume=str(out / "finetune_last.pt"))  # fmt: skip
    rows = read_metrics(out, "finetune", start=True)
    assert [r["epoch"] for r in rows] == [0, 1, 2] and sum("start" in r for r in rows) == 1
    assert resumed["start"] == summary["start"]
    assert "kept epoch" in capsys.readouterr().out


def test_a_resume_whose_time_budget_is_spent_is_refused(tiny_cfg, tmp_path):
    from trajpref.train.run import finished

    denoiser = dataclasses.replace(tiny_cfg.denoiser, epochs=50, max_minutes=1e-6)
    cfg = dataclasses.replace(tiny_cfg, denoiser=denoiser)
    summary = train_stage("diffusion", cfg, tmp_path, device="cpu", progress=False)
    assert summary["budget_reached"] and summary["steps"] == 1
    last = tmp_path / "denoiser_last.pt"
    assert finished(last, cfg.denoiser)  # a script that trains or resumes skips it
    with pytest.raises(
        ConfigError,
        match=r"the budget of 1e-06 min is spent \(the state has "
        r"trained .* min\): nothing left to train \(raise denoiser\.max_minutes",
    ):
        train_stage("diffusion", cfg, tmp_path, device="cpu", progress=False, resume=str(last))
    assert len(read_metrics(tmp_path, "denoiser")) == 1  # no step, no validation added
    # a larger budget, or none, trains on
    more = dataclasses.replace(cfg, denoiser=dataclasses.replace(denoiser, max_minutes=10.0))
    assert not finished(last, more.denoiser)
    train_stage("diffusion", more, tmp_path, device="cpu", progress=False, resume=str(last),
                max_steps=2)  # fmt: skip
    assert len(read_metrics(tmp_path, "denoiser")) == 2


def test_a_new_run_in_a_used_folder_moves_the_earlier_runs_record_aside(tiny_cfg, tmp_path, capsys):
    out = tmp_path / "run"
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False,
                resume=str(out / "denoiser_last.pt"))  # fmt: skip
    first = json.loads(run_record_path(out, "denoiser").read_text())
    assert [s["resumed"] for s in first] == [False, True]  # one run's sessions
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    assert [s["resumed"] for s in json.loads(run_record_path(out, "denoiser").read_text())] == [
        False]  # fmt: skip
    # the earlier run's record and log, aside with the same number
    assert json.loads((out / "denoiser_run.replaced-1.json").read_text()) == first
    assert (out / "denoiser_metrics.replaced-1.jsonl").is_file()
    assert "moved aside to denoiser_metrics.replaced-1.jsonl and denoiser_run.replaced-1.json" \
        in capsys.readouterr().err  # fmt: skip
    # and its resume state: a new run stopped before its first epoch left the earlier run's
    # state beside its own config (a CLI walkthrough of 2026-12-06)
    old = torch.load(out / "denoiser_last.replaced-1.pt", weights_only=True)
    assert old["step"] > torch.load(out / "denoiser_last.pt", weights_only=True)["step"] == 1
    # a record left without a log (a run stopped before its first epoch) keeps them paired
    (out / "denoiser_metrics.jsonl").unlink()
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    assert (out / "denoiser_run.replaced-2.json").is_file()
    assert not (out / "denoiser_metrics.replaced-2.jsonl").exists()
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    assert {p.name for p in out.glob("*replaced-3*")} == {
        "denoiser_run.replaced-3.json",
        "denoiser_metrics.replaced-3.jsonl",
        "denoiser_last.replaced-3.pt",
        "denoiser.replaced-3.safetensors",  # its checkpoint too, with the same number
    }


def test_the_resume_advice_repeats_a_torchrun_launch_as_it_was_recorded(tmp_path):
    """The run record keeps the launcher's own command line (--standalone, --nnodes, the
    rendezvous): the advice repeats it, and for several machines says to run it on each."""
    from trajpref.train.run import resume_command

    out, last = tmp_path / "d", tmp_path / "d" / "denoiser_last.pt"
    _record(out, "denoiser", "python /x/trajpref/cli.py train diffusion --out o", seed=0,
            world_size=2, launcher=".venv/bin/torchrun --standalone --nproc_per_node 2 -m "
            "trajpref.cli")  # fmt: skip
    assert resume_command(out, "denoiser", last) == (
        f".venv/bin/torchrun --standalone --nproc_per_node 2 -m trajpref.cli train diffusion "
        f"--out o --seed 0 --resume {last}"
    )
    _record(out, "denoiser", "python /x/trajpref/cli.py train diffusion --out o", seed=0,
            world_size=16, nodes=2, launcher="torchrun --nnodes 2 --node_rank 0 "
            "--nproc_per_node 8 --master_addr h -m trajpref.cli")  # fmt: skip
    assert resume_command(out, "denoiser", last) == (
        "torchrun --nnodes 2 --node_rank 0 --nproc_per_node 8 --master_addr h -m trajpref.cli "
        f"train diffusion --out o --seed 0 --resume {last} (on each of the 2 machines, with "
        "the launcher options it was started with there)"
    )


def test_a_state_that_processes_wrote_under_the_old_batching_is_refused(tiny_cfg, tmp_path):
    """Before the processes shared each batch, N processes took 1/N of the steps: such a
    state (no world_size in it; its run record says how many wrote it) cannot continue under
    the current rule, and a resume says so instead of mixing the two."""
    out = tmp_path / "old"
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    last = out / "denoiser_last.pt"
    state = torch.load(last, weights_only=True)
    state.pop("world_size", None), state.pop("rank_generators", None)
    torch.save(state, last)
    record = json.loads(run_record_path(out, "denoiser").read_text())
    record[-1]["world_size"] = 2
    run_record_path(out, "denoiser").write_text(json.dumps(record))
    with pytest.raises(ConfigError, match="written on 2 processes by an earlier trajpref"):
        train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, resume=str(last))
    record[-1]["world_size"] = 1  # one process's older state resumes as before
    run_record_path(out, "denoiser").write_text(json.dumps(record))
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, resume=str(last))
    assert torch.load(last, weights_only=True)["world_size"] == 1


@pytest.mark.parametrize(("t_hist", "t_fut"), [(10, 20), (8, 20)])
def test_windows_longer_than_the_files_are_refused_before_anything_is_written(
    tiny_cfg, tmp_path, t_hist, t_fut
):
    # model.t_hist / model.t_fut cut the data (the walks' files hold 24 frames): a DataError
    # from the reader, before config.yaml and the run record are written
    model = dataclasses.replace(tiny_cfg.model, t_hist=t_hist, t_fut=t_fut)
    cfg = dataclasses.replace(tiny_cfg, model=model)
    out = tmp_path / "run"
    said = rf"too few frames: 24 unique frames, a window needs {t_hist + t_fut}"
    with pytest.raises(DataError, match=said):
        train_stage("diffusion", cfg, out, device="cpu", progress=False, max_steps=1)
    assert not out.exists() or not any(out.iterdir())


def test_shorter_windows_train_and_the_checkpoint_records_them(tiny_cfg, tmp_path):
    model = dataclasses.replace(tiny_cfg.model, t_hist=4, t_fut=6)
    out = tmp_path / "run"
    train_stage("diffusion", dataclasses.replace(tiny_cfg, model=model), out, device="cpu",
                progress=False, max_steps=1)  # fmt: skip
    from trajpref.models.checkpoint import windows_of

    assert windows_of(out / "denoiser.safetensors") == (4, 6)


def test_the_advice_starts_trajpref_as_it_was_started(tmp_path, monkeypatch):
    """``program_launcher``: the trajpref script by name only where PATH finds it (else by its
    path), a module run with its interpreter (by name where PATH finds that one), anything
    else as ``trajpref``; the run record's advice alike, ``python -m trajpref`` included."""
    from trajpref.train.run import program_launcher, resume_command

    python = sys.executable
    script = tmp_path / "venv" / "bin" / "trajpref"
    script.parent.mkdir(parents=True)
    script.write_text("#!/bin/sh\n")
    script.chmod(0o755)
    main_py = "/x/site-packages/trajpref/__main__.py"
    monkeypatch.setenv("PATH", str(tmp_path))  # neither found
    assert program_launcher(str(script), python) == [str(script)]
    assert program_launcher(main_py, python) == [python, "-m", "trajpref"]
    assert program_launcher("/x/trajpref/cli.py", python) == [python, "-m", "trajpref.cli"]
    assert program_launcher("/venv/bin/pytest", python) == ["trajpref"]  # cli.main from Python
    monkeypatch.setenv("PATH", os.pathsep.join([str(script.parent), str(Path(python).parent)]))
    assert program_launcher(str(script), python) == ["trajpref"]
    assert program_launcher(main_py, python) == [Path(python).name, "-m", "trajpref"]
    out, last = tmp_path / "d", tmp_path / "d" / "denoiser_last.pt"
    _record(out, "denoiser", f"python {main_py} train diffusion --out o", seed=0, world_size=1)
    assert resume_command(out, "denoiser", last) == (
        f"{Path(python).name} -m trajpref train diffusion --out o --seed 0 --resume {last}"
    )
    monkeypatch.setenv("PATH", str(tmp_path))  # the record's "python" is not the one PATH finds
    assert resume_command(out, "denoiser", last) == (
        f"{python} -m trajpref train diffusion --out o --seed 0 --resume {last}"
    )
    monkeypatch.setenv("PATH", os.pathsep.join([str(script.parent), str(Path(python).parent)]))
    _record(out, "denoiser", f"python {script} train diffusion --out o", seed=0)
    assert resume_command(out, "denoiser", last).startswith("trajpref train diffusion")
