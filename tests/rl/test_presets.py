"""A fine-tuning run's config (rl/presets.py): what each method reads, the equal-budget
protocol and the seed, resolved from a tiny start checkpoint."""

import dataclasses
import typing

import pytest
import torch
import yaml

from trajpref.config import FinetuneConfig, OptimConfig, load_config, to_dict
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.rl.presets import (
    CONTROL_READS,
    RL_ONLY,
    equal_budget_args,
    equal_budget_overrides,
    finetune_config,
)
from trajpref.train.stages import build_finetune_stage
from trajpref.types import collate


def _other_value(name: str):
    """A valid value of a FinetuneConfig field other than its default."""
    default = getattr(FinetuneConfig(), name)
    hint = typing.get_type_hints(FinetuneConfig)[name]
    if typing.get_origin(hint) is typing.Literal:
        return next(c for c in typing.get_args(hint) if c != default)
    if isinstance(default, bool):
        return not default
    if isinstance(default, int):
        return default + 1
    return default * 0.5 if default else 0.5


def test_every_finetune_setting_is_either_read_by_the_control_or_rl_only():
    own = {f.name for f in dataclasses.fields(FinetuneConfig)} - {
        f.name for f in dataclasses.fields(OptimConfig)
    }
    assert set(RL_ONLY).isdisjoint(CONTROL_READS)
    assert set(RL_ONLY) | set(CONTROL_READS) == own  # a new field must be classified


def test_the_control_loss_does_not_move_with_any_rl_only_setting(tiny_run, walks):
    """What RL_ONLY claims: changing one of its settings leaves the control's step as it was."""
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:3])

    def loss(*overrides: str) -> torch.Tensor:
        cfg = load_config(None, ["finetune.method=control", *overrides], base=start["config"])
        stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
        value, _ = stage.objective(batch, torch.Generator().manual_seed(0))
        return value.detach()

    base = loss()
    assert not torch.equal(loss("finetune.reg_weight=2"), base)  # a setting it reads
    for name in RL_ONLY:
        value = _other_value(name)
        text = "null" if value is None else value
        assert torch.equal(loss(f"finetune.{name}={text}"), base), name


def test_the_control_refuses_the_rl_settings_it_does_not_read(tiny_run, tmp_path):
    start = str(tiny_run / "generator.safetensors")
    refused = r"^finetune\.kl_coef, finetune\.reward: the control reads no RL setting .* these "
    with pytest.raises(ConfigError, match=refused + r"have no effect; leave them out$"):
        finetune_config(start, "control", overrides=["finetune.reward=set", "finetune.kl_coef=3"])
    # named with its default value: still no effect, still refused
    with pytest.raises(ConfigError, match=r"^finetune\.ppo_epochs: .* this has no effect"):
        finetune_config(start, "control", overrides=["finetune.ppo_epochs=1"])
    # a YAML file that changes one
    changed = tmp_path / "changed.yaml"
    changed.write_text("finetune:\n  score_every: 3\n")
    with pytest.raises(ConfigError, match=r"^finetune\.score_every: the control"):
        finetune_config(start, "control", config=changed)
    # a control run's own finetune_config.yaml (every key, RL ones at their defaults) is fine,
    # and so are the settings the control reads
    cfg = finetune_config(start, "control", overrides=["finetune.lr=1e-5"])
    own = tmp_path / "finetune_config.yaml"
    own.write_text(yaml.safe_dump(to_dict(cfg)))
    again = finetune_config(start, "control", config=own, overrides=["finetune.reg_weight=2"])
    assert again.finetune.lr == 1e-5 and again.finetune.reg_weight == 2
    # the RL methods take them
    assert finetune_config(start, "rlhf", overrides=["finetune.kl_coef=3"]).finetune.kl_coef == 3


def test_rlhf_res_refuses_the_set_aware_reward(tiny_run):
    start = str(tiny_run / "generator.safetensors")
    with pytest.raises(ConfigError, match=r"undoes the set view .*use it with --method rlhf"):
        finetune_config(start, "rlhf-res", overrides=["finetune.reward=set"])
    assert (
        finetune_config(start, "rlhf", overrides=["finetune.reward=set"]).finetune.reward == "set"
    )
    assert finetune_config(start, "rlhf-res", overrides=["finetune.reward=sda"]).finetune.reward


def test_equal_budget_applies_the_protocol_of_the_table(tiny_run):
    start = str(tiny_run / "generator.safetensors")
    for method in ("control", "rlhf", "rlhf-res"):
        ft = finetune_config(start, method, equal_budget=4).finetune
        assert (ft.max_minutes, ft.budget_clock, ft.epochs, ft.eval_every_minutes,
                ft.warmup_steps) == (4.0, "cpu", 100000, 1.0, 4)  # fmt: skip
    # the benchmarks' arguments are the same overrides
    assert equal_budget_args(4.0, 4, 1.0) == [
        a for o in equal_budget_overrides(4.0) for a in ("--set", o)
    ]
    assert equal_budget_args(4.0, 4, 1.0)[1::2] == [
        "finetune.max_minutes=4.0", "finetune.budget_clock=cpu", "finetune.epochs=100000",
        "finetune.eval_every_minutes=1.0", "finetune.warmup_steps=4",
    ]  # fmt: skip
    with pytest.raises(ConfigError, match=r"--equal-budget sets finetune\.warmup_steps: leave "
                       r"it out of --set"):  # fmt: skip
        finetune_config(start, "rlhf", overrides=["finetune.warmup_steps=8"], equal_budget=4)
    with pytest.raises(ConfigError, match=r"must be a number of CPU minutes > 0, got 0"):
        finetune_config(start, "rlhf", equal_budget=0)


def test_the_seed_defaults_to_0_not_to_the_starts(tiny_run, tmp_path):
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["seed"] = 7
    start = tmp_path / "seed7.safetensors"
    ckpt.save(start, payload)
    assert finetune_config(str(start), "rlhf").seed == 0
    assert finetune_config(str(start), "rlhf", seed=3).seed == 3
    assert finetune_config(str(start), "rlhf", overrides=["seed=5"], seed=3).seed == 5


def test_a_folder_models_description_is_dropped_for_a_built_in_dataset(tiny_run, tmp_path):
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["data"].update(frame_interval=0.1, units="m")  # trained on a folder
    start = tmp_path / "folder.safetensors"
    ckpt.save(start, payload)
    cfg = finetune_config(str(start), "rlhf", overrides=["data.dataset=zara1"])
    assert (cfg.data.dataset, cfg.data.frame_interval, cfg.data.units) == ("zara1", None, None)
    # on another folder, or on its own, the description stays
    cfg = finetune_config(str(start), "rlhf", overrides=[f"data.dataset={tmp_path}"])
    assert (cfg.data.frame_interval, cfg.data.units) == (0.1, "m")
    assert finetune_config(str(start), "rlhf").data.frame_interval == 0.1
    # given for a built-in dataset by the user, it is still refused
    with pytest.raises(ConfigError, match="zara1 is a built-in one"):
        finetune_config(str(start), "rlhf", overrides=["data.dataset=zara1",
                                                       "data.units=m"])  # fmt: skip
