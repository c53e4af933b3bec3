"""A fine-tuning run's config (rl/presets.py): what each method reads, the equal-budget
protocol and the seed, resolved from a tiny start checkpoint."""

import dataclasses
import typing

import numpy as np
import pytest
import torch
import yaml

from trajpref.config import FinetuneConfig, OptimConfig, load_config, to_dict
from trajpref.data import load_dataset
from trajpref.errors import ConfigError, IgnoredWarning
from trajpref.models import checkpoint as ckpt
from trajpref.rl.presets import (
    CONTROL_READS,
    READ_WHEN,
    RL_ONLY,
    equal_budget_args,
    equal_budget_overrides,
    finetune_config,
)
from trajpref.train.stages import build_finetune_stage
from trajpref.types import Scene, collate


def _other_value(name: str):
    """A valid value of a FinetuneConfig field other than its default."""
    default = getattr(FinetuneConfig(), name)
    if name == "reward":  # a name: any reward's (sda's is built in)
        return "sda"
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


def test_the_rl_methods_refuse_a_setting_that_their_other_settings_leave_unread(tiny_run):
    start = str(tiny_run / "generator.safetensors")
    refused = {
        ("rlhf", None, ("finetune.set_bandwidth=0.1",)):
            r"^finetune\.set_bandwidth: a setting of the set-aware reward \(finetune\.reward="
            r"set\), and this run's reward is score, so it has no effect; leave it out or set "
            r"finetune\.reward=set$",
        ("rlhf", None, ("finetune.reward=sda", "finetune.set_alpha=2", "finetune.set_bandwidth=1")):
            r"^finetune\.set_bandwidth, finetune\.set_alpha: settings of the set-aware reward "
            r".* reward is sda, so they have no effect; leave them out",
        ("rlhf-res", None, ("finetune.sda_radius=3",)):
            r"^finetune\.sda_radius: a setting of the SDA reward \(finetune\.reward=sda\)",
        ("rlhf", None, ("finetune.reward=sda", "finetune.score_every=3")):
            r"^finetune\.score_every: .* reward is sda, which computes no diffusion score",
        ("rlhf", "paper", ("finetune.explore_std=0.2",)):
            r"^finetune\.explore_std: .* this run's likelihood is mean, which does not explore",
        ("rlhf-res", None, ("finetune.likelihood=mean", "finetune.explore=smooth")):
            r"^finetune\.explore: .*finetune\.likelihood=sample",
        ("rlhf-res", None, ("finetune.clip=0.1",)):
            r"^finetune\.clip: a setting of the clipped PPO ratio .* its ratio is always 1",
        ("rlhf", None, ("finetune.baseline=antithetic", "finetune.value_target=reward",
                        "finetune.gamma=0.9")):
            r"^finetune\.gamma: .* advantage is antithetic .* value target the reward",
        # two rules at once: both named
        ("rlhf", None, ("finetune.sda_drift=1", "finetune.clip=0.1")):
            r"^finetune\.sda_drift: .*; finetune\.clip: ",
        # named at its default value: still no effect, still refused
        ("rlhf", None, ("finetune.set_alpha=1.0",)): r"^finetune\.set_alpha: ",
    }  # fmt: skip
    for (method, preset, overrides), message in refused.items():
        with pytest.raises(ConfigError, match=message):
            finetune_config(start, method, preset, overrides=list(overrides))
    accepted = [
        ("rlhf", None, ("finetune.reward=set", "finetune.set_bandwidth=0.1",
                        "finetune.set_alpha=2")),
        ("rlhf-res", None, ("finetune.reward=sda", "finetune.sda_radius=3", "finetune.sda_drift=1",
                            "finetune.sda_tolerance=0.3", "finetune.reward_clip=2")),
        ("rlhf", None, ("finetune.reward=set", "finetune.score_every=3")),
        ("rlhf-res", None, ("finetune.explore=smooth", "finetune.explore_std=0.1")),
        ("rlhf", None, ("finetune.ppo_epochs=2", "finetune.clip=0.1")),
        ("rlhf", None, ("finetune.ratio_against=reference", "finetune.clip=0.1")),
        ("rlhf", None, ("finetune.baseline=antithetic", "finetune.gae_lambda=0.5")),
        ("rlhf", None, ("finetune.value_target=reward", "finetune.gae_lambda=0.5")),
        ("rlhf", "paper", ("finetune.clip=0.1",)),
        # the preset's own values are not the user's: its score_every and clip stay
        ("rlhf-res", "paper", ("finetune.reward=sda",)),
        ("rlhf", "paper", ("finetune.ratio_against=rollout",)),
    ]  # fmt: skip
    for method, preset, overrides in accepted:
        finetune_config(start, method, preset, overrides=list(overrides))


def test_a_yaml_file_that_changes_an_unread_setting_is_refused(tiny_run, tmp_path):
    start = str(tiny_run / "generator.safetensors")
    changed = tmp_path / "changed.yaml"
    changed.write_text("finetune:\n  set_bandwidth: 0.3\n")
    with pytest.raises(ConfigError, match=r"^finetune\.set_bandwidth: .* reward is score"):
        finetune_config(start, "rlhf", config=changed)
    cfg = finetune_config(start, "rlhf", config=changed, overrides=["finetune.reward=set"])
    assert cfg.finetune.set_bandwidth == 0.3
    # an RL run's own finetune_config.yaml (every key, at its values) is fine
    own = tmp_path / "finetune_config.yaml"
    own.write_text(yaml.safe_dump(to_dict(finetune_config(start, "rlhf-res", "paper"))))
    assert finetune_config(start, "rlhf-res", config=own).finetune.likelihood == "mean"


def test_the_benchmarks_fine_tuning_methods_are_all_accepted(tiny_run):
    """The published tables' runs (benchmarks/equal_budget.py, benchmarks/reproduce.py, the
    paper preset) set no setting that they leave unread."""
    from bench import load_benchmark

    start = str(tiny_run / "generator.safetensors")
    jobs = {**load_benchmark("equal_budget").METHODS, **load_benchmark("reproduce").TRAIN_ARGS}
    for args in jobs.values():
        sets = [args[i + 1] for i, a in enumerate(args) if a == "--set"]
        for method in args[args.index("--methods") + 1 :]:
            if method.startswith("--"):
                break
            finetune_config(start, method, overrides=sets, equal_budget=4)
    for method in ("rlhf", "rlhf-res"):
        finetune_config(start, method, "paper")


def test_every_conditional_setting_is_an_rl_setting():
    keys = [k for rule in READ_WHEN for k in rule.keys]
    assert set(keys) <= set(RL_ONLY) and len(keys) == len(set(keys))


# one config under which each rule reads its keys, and one under which it does not
_READ_WHEN_CASES = {
    "set_bandwidth": (["finetune.reward=set"], ["finetune.reward=score"]),
    "sda_radius": (["finetune.reward=sda"], ["finetune.reward=score"]),
    "score_every": (["finetune.reward=score"], ["finetune.reward=sda"]),
    "explore_std": (["finetune.likelihood=sample"], ["finetune.likelihood=mean"]),
    "clip": (["finetune.ratio_against=reference"], ["finetune.ratio_against=rollout"]),
    "gamma": (["finetune.baseline=antithetic", "finetune.value_target=return"],
              ["finetune.baseline=antithetic", "finetune.value_target=reward"]),
    "kl_form": (["finetune.kl_coef=0.1"], ["finetune.kl_coef=0"]),
}  # fmt: skip


def _walks_with_a_group(train):
    """Three synthetic walks and a scene of two persons walking side by side, 0.8 apart and
    drifting 0.04 apart per step (0.28 over the history): an SDA group at the default
    thresholds (radius 1.5, drift 0.5) that half of either threshold breaks up."""
    t_h, t_f = train.scenes[0].history.shape[1], train.scenes[0].future.shape[1]
    t = np.arange(t_h + t_f, dtype=np.float32)[:, None]  # [T, 1]
    pair = np.stack([t * [0.4, 0.0], t * [0.4, 0.04] + [0.0, 0.8]]).astype(np.float32)
    scene = Scene(pair[:, :t_h], pair[:, t_h:], np.zeros(2, np.int64), "pair")  # [2, T, 2]
    return collate([*train.scenes[:3], scene])


@pytest.mark.parametrize("rule", range(len(READ_WHEN)))
def test_an_unread_setting_leaves_the_rl_loss_as_it_was(tiny_run, walks, rule):
    """What READ_WHEN claims, on a policy moved away from its reference: under the settings
    where a rule does not read its keys, changing one leaves the loss bit for bit as it was;
    under those where it reads them, the loss moves."""
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = _walks_with_a_group(train)
    rule = READ_WHEN[rule]
    reads, unread = _READ_WHEN_CASES[rule.keys[0]]

    def loss(*overrides: str) -> torch.Tensor:
        cfg = load_config(None, ["finetune.method=rlhf", *overrides], base=start["config"])
        stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
        gen = torch.Generator().manual_seed(1)
        with torch.no_grad():  # the policy leaves the reference, so ratios and KL are not 1, 0
            for p in stage.objective.policy.parameters():
                p.add_(0.005 * torch.randn(p.shape, generator=gen))
        value, _ = stage.objective(batch, torch.Generator().manual_seed(0))
        return value.detach()

    assert rule.reads(load_config(None, reads).finetune)
    assert not rule.reads(load_config(None, unread).finetune)
    for key in rule.keys:
        value = _other_value(key)
        base, other = loss(*unread), loss(*unread, f"finetune.{key}={value}")
        assert torch.equal(base, other), key
        assert not torch.equal(loss(*reads), loss(*reads, f"finetune.{key}={value}")), key


def test_a_yaml_value_that_the_preset_would_replace_is_refused(tiny_run, tmp_path):
    start = str(tiny_run / "generator.safetensors")
    mine = tmp_path / "mine.yaml"
    mine.write_text("finetune:\n  clip: 0.1\n  lr: 1.0e-4\n  policy_weight: 0.5\n")
    with pytest.raises(ConfigError, match=r"^finetune\.clip \(0\.1 in .*mine\.yaml, 0\.2 in the "
                       r"preset\), finetune\.policy_weight \(0\.5 .*, 1\.0 in the preset\): "
                       r"--preset sets these keys after the --config file, so the file's values "
                       r"have no effect"):  # fmt: skip
        finetune_config(start, "rlhf", "paper", config=mine)
    # --set changes a preset's value; the file's keys the preset does not set stay the file's
    ft = finetune_config(start, "rlhf", "paper", config=mine, overrides=[
        "finetune.clip=0.1", "finetune.policy_weight=0.5"]).finetune  # fmt: skip
    assert (ft.clip, ft.policy_weight, ft.lr, ft.kl_form) == (0.1, 0.5, 1e-4, "paper")
    # a paper run's own finetune_config.yaml (every key) with the preset again is fine, and
    # --method still wins over the file's method
    own = tmp_path / "finetune_config.yaml"
    own.write_text(yaml.safe_dump(to_dict(finetune_config(start, "rlhf", "paper"))))
    assert finetune_config(start, "rlhf", "paper", config=own).finetune.kl_form == "paper"
    with pytest.warns(IgnoredWarning, match=r"not read: finetune\.method=rlhf \(--method rlhf-res "
                      r"chooses the method\)$"):  # fmt: skip
        res = finetune_config(start, "rlhf-res", "paper", config=own, overrides=[
            "finetune.policy_weight=1.0", "finetune.value_weight=5.0"]).finetune  # fmt: skip
    assert (res.method, res.policy_weight) == ("rlhf-res", 1.0)


def test_a_finetune_file_with_a_key_written_twice_is_refused(tiny_run, tmp_path):
    """finetune --config reads its file as train --config does (config.read_yaml): YAML
    would keep the last of two finetune: sections without a word."""
    start = str(tiny_run / "generator.safetensors")
    twice = tmp_path / "twice.yaml"
    twice.write_text("finetune:\n  clip: 0.3\nfinetune:\n  lr: 0.0001\n")
    with pytest.raises(ConfigError, match=r"finetune is given twice"):
        finetune_config(start, "rlhf", config=twice)
    with pytest.raises(ConfigError, match=r"finetune is given twice"):
        finetune_config(start, "rlhf", "paper", config=twice)
