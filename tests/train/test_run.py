"""The run record: each session of a stage writes where and how it ran beside its config."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from trajpref.errors import ConfigError
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
