"""Traps a researcher met fine-tuning their own model with ``trajpref finetune`` (walkthrough
of 2026-12-06): an earlier run's checkpoints left beside a new run's config, advice that
--equal-budget refuses, a demo that warns about its own warm-up, a --config whose sections
are silently not read, a did-you-mean that names the opposite setting, and ``trajpref models``
refusing a run's own checkpoint."""

from __future__ import annotations

import dataclasses
import shutil
import warnings

import pytest
import torch
import yaml

from trajpref.config import FinetuneConfig, OptimConfig, load_config, to_dict
from trajpref.errors import ConfigError, TrajprefError
from trajpref.io import read_checkpoint_header
from trajpref.models import zoo
from trajpref.rl.presets import finetune_config
from trajpref.train import run
from trajpref.train.loop import warmup_note
from trajpref.train.run import finetune, train_stage

SMALL = ["data.max_agents=6", "finetune.epochs=1", "finetune.steps_per_epoch=1",
         "finetune.eval_max_scenes=2", "finetune.warmup_steps=1"]  # fmt: skip
"""A fine-tuning run of one step, validated on two scenes."""


def _start(tiny_run):
    return str(tiny_run / "generator.safetensors")


def _method(path) -> str | None:
    return (read_checkpoint_header(path).get("meta") or {}).get("method")


def test_a_new_fine_tuning_run_sets_the_earlier_runs_checkpoints_aside(
    tiny_run, tmp_path, monkeypatch, capsys
):
    """Walkthrough: from a copy of an rlhf-res run folder, `finetune --method control` stopped
    after the start's validation left the folder's config saying control beside the rlhf-res
    run's finetune.safetensors (which evaluate then reported as rlhf-res); and a run with
    ema_epochs left its finetune_raw.safetensors beside a later run's for good."""
    start, out = _start(tiny_run), tmp_path / "res"
    first = finetune_config(start, "rlhf-res", overrides=[*SMALL, "finetune.ema_epochs=1"])
    finetune(first, start, out, device="cpu", progress=False)
    assert (out / "finetune_raw.safetensors").is_file()

    def stopped(*args, **kwargs):  # Ctrl-C after the start's validation: before any checkpoint
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "fit", stopped)
    control = finetune_config(start, "control", overrides=SMALL)
    with pytest.raises(KeyboardInterrupt):
        finetune(control, start, out, device="cpu", progress=False)
    assert yaml.safe_load((out / "finetune_config.yaml").read_text())["finetune"]["method"] == (
        "control")  # fmt: skip
    assert not (out / "finetune.safetensors").exists()  # no other run's model beside it
    assert not (out / "finetune_raw.safetensors").exists()
    err = capsys.readouterr().err
    assert ("and its checkpoints to finetune.replaced-1.safetensors and "
            "finetune_raw.replaced-1.safetensors; this run writes its own") in err  # fmt: skip
    # the earlier run's files stay paired under one number
    assert {p.name for p in out.glob("*.replaced-1.*")} == {
        "finetune.replaced-1.safetensors", "finetune_raw.replaced-1.safetensors",
        "finetune_metrics.replaced-1.jsonl", "finetune_run.replaced-1.json",
        "finetune_last.replaced-1.pt"}  # fmt: skip
    assert _method(out / "finetune.replaced-1.safetensors") == "rlhf-res"

    monkeypatch.undo()  # the control, run to its end without a moving average
    finetune(control, start, out, device="cpu", progress=False)
    assert _method(out / "finetune.safetensors") == "control"
    assert not (out / "finetune_raw.safetensors").exists()  # not the rlhf-res run's control
    assert _method(out / "finetune_raw.replaced-1.safetensors") == "rlhf-res"


def test_the_generator_stage_sets_the_earlier_runs_checkpoints_aside(
    tiny_cfg, tiny_run, tmp_path, capsys
):
    out = tmp_path / "run"
    out.mkdir()
    shutil.copy(tiny_run / "denoiser.safetensors", out / "denoiser.safetensors")
    keep = dataclasses.replace(tiny_cfg, generator=dataclasses.replace(
        tiny_cfg.generator, keep_checkpoints=True, epochs=3))  # fmt: skip
    train_stage("generator", keep, out, device="cpu", progress=False)
    kept = sorted(p.name for p in out.glob("generator_epoch*.safetensors"))
    assert kept == [f"generator_epoch00{e}.safetensors" for e in (1, 2, 3)]
    capsys.readouterr()
    train_stage("generator", tiny_cfg, out, device="cpu", progress=False)
    left = [p.name for p in out.glob("generator_epoch*") if ".replaced-" not in p.name]
    assert left == []  # none of the other run's epochs beside this run's files
    assert sorted(p.name for p in out.glob("generator_epoch*.replaced-1.safetensors")) == [
        f"generator_epoch00{e}.replaced-1.safetensors" for e in (1, 2, 3)]  # fmt: skip
    assert (out / "generator.replaced-1.safetensors").is_file()
    assert (out / "denoiser.safetensors").is_file()  # another stage's file: left alone
    assert not list(out.glob("denoiser*.replaced-*"))
    err = capsys.readouterr().err
    assert ("its checkpoints to generator.replaced-1.safetensors and 3 "
            "generator_epoch<E>.replaced-1.safetensors") in err  # fmt: skip


def test_a_start_among_the_runs_own_checkpoints_is_refused(tiny_run, tmp_path):
    start, out = _start(tiny_run), tmp_path / "res"
    cfg = finetune_config(start, "control", overrides=SMALL)
    finetune(cfg, start, out, device="cpu", progress=False)
    again = str(out / "finetune.safetensors")
    with pytest.raises(ConfigError, match=r"^--from .*finetune\.safetensors: a checkpoint of the "
                       r"fine-tuning run in .*: copy it out of the folder first, or choose "
                       r"another --out$"):  # fmt: skip
        finetune(finetune_config(again, "control", overrides=SMALL), again, out, device="cpu",
                 progress=False)  # fmt: skip
    copy = tmp_path / "start.safetensors"
    shutil.copy(again, copy)
    finetune(finetune_config(str(copy), "control", overrides=SMALL), str(copy), out,
             device="cpu", progress=False)  # fmt: skip


def test_an_equal_budget_run_is_advised_with_equal_budget(tiny_run, tmp_path, monkeypatch, capsys):
    """The advice of a run its budget ended, and of a resume with the budget spent, named the
    --set keys that --equal-budget refuses beside it; on two threads the run said nothing."""
    start, out = _start(tiny_run), tmp_path / "eq"
    overrides = ["data.max_agents=6", "finetune.eval_max_scenes=2"]
    cfg = finetune_config(start, "control", overrides=overrides, equal_budget=1e-6)
    monkeypatch.setattr(torch, "get_num_threads", lambda: 2)  # the README's command, 2 cores
    finetune(cfg, start, out, device="cpu", progress=False, equal_budget=1e-6)
    monkeypatch.setattr(torch, "get_num_threads", lambda: 1)  # whatever this host's test run has
    captured = capsys.readouterr()
    said = captured.out + captured.err
    assert "the equal budget (--equal-budget 1e-06: 1e-06 min of cpu time" in said
    assert "resume with a larger --equal-budget" in said
    assert "--set finetune.max_minutes" not in said
    assert run.equal_budget_threads_note(2) in captured.err
    assert "--equal-budget on 2 threads" in run.equal_budget_threads_note(2)
    last = str(out / "finetune_last.pt")
    spent = r"nothing left to train \(resume with --equal-budget above 1e-06 to train longer: "
    with pytest.raises(ConfigError, match=spent + r"it sets finetune\.max_minutes\)$"):
        finetune(cfg, start, out, device="cpu", progress=False, resume=last, equal_budget=1e-6)
    # without the option, the --set keys are the advice, as before
    with pytest.raises(ConfigError, match=r"\(raise finetune\.max_minutes to train longer\)$"):
        finetune(cfg, start, out, device="cpu", progress=False, resume=last)
    # one thread: no note
    capsys.readouterr()
    finetune(cfg, start, tmp_path / "one", device="cpu", progress=False, equal_budget=1e-6)
    assert "threads" not in capsys.readouterr().err


def test_a_warm_up_of_one_step_or_one_that_ends_with_the_run_says_so_right():
    one = dataclasses.replace(OptimConfig(), warmup_steps=1, lr=3e-4)
    assert warmup_note("finetune", one, 1) is None  # its first step runs at the full rate
    assert warmup_note("finetune", dataclasses.replace(one, warmup_steps=0), 1) is None
    ends = warmup_note("finetune", dataclasses.replace(one, warmup_steps=4), 4)
    assert "reaches finetune.lr=0.0003 only at the last step and never decays" in ends
    assert "N=1)" in ends and "climbs" not in ends  # N differs from the value set
    longer = warmup_note("finetune", dataclasses.replace(one, warmup_steps=20), 15)
    assert "never reaches finetune.lr=0.0003 (it climbs to about 0.00022)" in longer
    assert "N=1, a tenth of the steps)" in longer
    assert warmup_note("finetune", dataclasses.replace(one, warmup_steps=20), 21) is None


def test_the_demos_fine_tuning_warm_up_ends_before_its_steps():
    """`make demo` warned about its own config: warmup_steps 20 of its 15 steps."""
    from trajpref.demo import DEFAULT_CONFIG

    ft = load_config(DEFAULT_CONFIG, []).finetune
    total = ft.epochs * ft.steps_per_epoch * ft.ppo_epochs
    assert warmup_note("finetune", ft, total) is None
    assert ft.warmup_steps < FinetuneConfig().warmup_steps


def test_a_config_files_unread_sections_and_method_are_named(tiny_run, tmp_path):
    start = _start(tiny_run)
    with pytest.warns(UserWarning) as caught:
        finetune_config(start, "rlhf", config="eth")
    note = str(caught[0].message)
    assert note.startswith("eth.yaml: fine-tuning reads a --config file's finetune section "
                           "alone and this file has none, so it changes nothing in this run; "
                           "not read: data.dataset=eth (the run's: ")  # fmt: skip
    assert "--set data.KEY=VALUE" in note and "are the start's" in note
    mine = tmp_path / "mine.yaml"
    mine.write_text("seed: 3\ndata:\n  dataset: eth\nfinetune:\n  method: rlhf-res\n  lr: 1.0e-4\n")
    with pytest.warns(UserWarning) as caught:
        cfg = finetune_config(start, "rlhf", config=mine)
    note = str(caught[0].message)
    assert cfg.finetune.method == "rlhf" and cfg.finetune.lr == 1e-4  # its finetune section read
    assert "seed=3 (the run's: 0; --seed 3 sets it)" in note
    assert "finetune.method=rlhf-res (--method rlhf chooses the method)" in note
    # keys that --set and --seed give are theirs, and the same method is read: no note; nor
    # for a run's own finetune_config.yaml with its method
    own = tmp_path / "finetune_config.yaml"
    own.write_text(
        yaml.safe_dump(to_dict(finetune_config(start, "rlhf-res", overrides=["finetune.lr=1e-5"])))
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        finetune_config(start, "rlhf-res", config=mine, overrides=["data.dataset=eth"], seed=3)
        assert finetune_config(start, "rlhf-res", config=own).finetune.lr == 1e-5


def test_the_cli_prints_the_unread_note(tiny_run, tmp_path, capsys):
    from trajpref.cli import main

    code = main(["finetune", "--method", "rlhf", "--from", _start(tiny_run), "--config", "eth",
                 "--out", str(tmp_path / "x"), "--resume", str(tmp_path / "x" / "nothing.pt"),
                 "--device", "cpu", "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2  # the resume state that is not there, after the note
    assert "trajpref: warning: eth.yaml: fine-tuning reads a --config file's finetune" in err


@pytest.mark.parametrize(("key", "meant"), [
    ("finetune.reward_weight", "finetune.policy_weight"),
    ("finetune.kl_weight", "finetune.kl_coef"),
    ("finetune.vf_coef", "finetune.value_weight"),
    ("finetune.learning_rate", "finetune.lr"),
    ("generator.max_grad_norm", "generator.grad_clip"),
    ("finetune.batch_size", "data.max_agents"),
    ("data.batch_size", "data.max_agents"),
    ("finetune.polcy_weight", "finetune.policy_weight"),  # a typo: difflib, as before
])  # fmt: skip
def test_did_you_mean_names_the_setting_meant(key, meant):
    """`--set finetune.reward_weight=2` suggested finetune.reg_weight, the regulariser."""
    with pytest.raises(ConfigError, match=rf"unknown config key {key} \(did you mean {meant}\?\)"):
        load_config(None, [f"{key}=2"])


def test_models_shows_a_runs_own_checkpoint(tiny_run, tmp_path, capsys):
    """`trajpref models res/finetune.safetensors` said "neither a checkpoint file nor a
    published model"."""
    from trajpref.cli import main

    path = tiny_run / "generator.safetensors"
    assert main(["models", str(path)]) == 0
    card = capsys.readouterr().out
    assert card.startswith(f"# {path}\n") and "A **generator** checkpoint" in card
    assert "not a published model" in card and "Kept: epoch 2" in card
    entry = zoo.entry(str(path))
    assert entry["kind"] == "generator" and entry["indexed"] is False
    assert entry["hash"] == read_checkpoint_header(path)["hash"]
    with pytest.raises(TrajprefError, match=r"a folder: name a checkpoint file in it"):
        zoo.card(str(tiny_run))
    with pytest.raises(TrajprefError, match=r"a resume state"):
        zoo.card(str(tiny_run / "generator_last.pt"))
