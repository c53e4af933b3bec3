"""Resume identity across versions (walkthrough 62, item 1): a state written before a config
field existed resumes when the field's default reproduces the old behaviour; a key it lacks is
compared with the field's default, not with null."""

from __future__ import annotations

import dataclasses
import json

import pytest

from trajpref.config import to_dict
from trajpref.errors import ConfigError
from trajpref.train import run
from trajpref.train.run import check_resume, run_identity


def _older_state(cfg, name: str, missing: list[tuple[str, str]]) -> dict:
    """A resume state of stage ``name`` whose identity was written before the keys
    ``missing`` ((section, key) pairs) existed."""
    identity = json.loads(run_identity(cfg, name))
    for section, key in missing:
        del identity[section][key]
    return {"epoch": 0, "identity": json.dumps(identity, sort_keys=True)}


def test_a_state_lacking_a_key_at_its_non_null_default_resumes(tiny_cfg, tmp_path):
    # model.context_agents (default False) and generator.lr stand for a field added since
    assert to_dict(tiny_cfg)["model"]["context_agents"] is False  # the default
    state = _older_state(tiny_cfg, "generator", [("model", "context_agents"), ("generator", "lr")])
    last = tmp_path / "generator_last.pt"
    check_resume(state, run_identity(tiny_cfg, "generator"), 2, tmp_path, last, "generator")


def test_a_state_lacking_a_key_is_refused_when_the_run_sets_it_off_its_default(tiny_cfg, tmp_path):
    from trajpref.train.run import identity_defaults

    assert tiny_cfg.model.hidden != identity_defaults("generator")["model"]["hidden"]
    state = _older_state(tiny_cfg, "generator", [("model", "hidden")])
    last = tmp_path / "generator_last.pt"
    with pytest.raises(ConfigError, match=r"\(model\.hidden: absent \(default 128\) -> 16\)"):
        check_resume(state, run_identity(tiny_cfg, "generator"), 2, tmp_path, last, "generator")


def test_a_key_whose_default_changed_since_compares_with_the_old_default(tiny_cfg, tmp_path):
    # model.stochastic_steps defaults to False now; a state from before the key ran with the
    # ancestral steps (checkpoint.LEGACY_DEFAULTS), so resuming at the new default is a change
    assert tiny_cfg.model.stochastic_steps is False
    state = _older_state(tiny_cfg, "generator", [("model", "stochastic_steps")])
    last = tmp_path / "generator_last.pt"
    with pytest.raises(ConfigError, match=r"model\.stochastic_steps: absent \(default True\) "
                       r"-> False"):  # fmt: skip
        check_resume(state, run_identity(tiny_cfg, "generator"), 2, tmp_path, last, "generator")
    ancestral = dataclasses.replace(tiny_cfg, model=dataclasses.replace(
        tiny_cfg.model, stochastic_steps=True))  # fmt: skip
    check_resume(state, run_identity(ancestral, "generator"), 2, tmp_path, last, "generator")


def test_a_key_this_version_does_not_know_is_said_to_come_from_a_newer_one(tiny_cfg, tmp_path):
    identity = json.loads(run_identity(tiny_cfg, "denoiser"))
    identity["model"]["history_jitter"] = 0.0
    state = {"epoch": 0, "identity": json.dumps(identity, sort_keys=True)}
    last = tmp_path / "denoiser_last.pt"
    with pytest.raises(ConfigError, match=r"model\.history_jitter: 0\.0 -> not a key of this "
                       r"trajpref \(a newer version wrote the state\?\)"):  # fmt: skip
        check_resume(state, run_identity(tiny_cfg, "denoiser"), 2, tmp_path, last, "denoiser")


def test_identity_defaults_have_the_identitys_layout():
    from trajpref.train.run import identity_defaults

    for name in ("denoiser", "generator", "finetune"):
        defaults = identity_defaults(name)
        assert set(defaults) == {"data", "model", "diffusion", "seed", name, "start"}
        assert not set(defaults[name]) & set(run.RESUME_FREE)


def test_a_run_trained_before_a_field_existed_resumes_through_train_stage(tiny_cfg, tmp_path):
    # the walkthrough's path: train, then resume with a version that added a field
    import torch

    from trajpref.train.run import train_stage

    out = tmp_path / "run"
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    last = out / "denoiser_last.pt"
    state = torch.load(last, weights_only=True)
    identity = json.loads(state["identity"])
    del identity["model"]["context_agents"]  # what a state of before the field recorded
    state["identity"] = json.dumps(identity, sort_keys=True)
    torch.save(state, last)
    longer = dataclasses.replace(tiny_cfg, denoiser=dataclasses.replace(tiny_cfg.denoiser,
                                                                        epochs=3))  # fmt: skip
    train_stage("diffusion", longer, out, device="cpu", progress=False, resume=str(last))
    assert torch.load(last, weights_only=True)["epoch"] == 2
