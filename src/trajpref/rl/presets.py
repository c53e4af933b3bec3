"""Named settings of the fine-tuning stage (``paper`` is the equations as written), and the
resolution of a fine-tuning run's config from its starting checkpoint."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from trajpref.config import (
    BUILTIN_DATASETS,
    ExperimentConfig,
    FinetuneConfig,
    load_config,
    to_dict,
)
from trajpref.errors import ConfigError
from trajpref.models import checkpoint

PAPER_WEIGHTS = {"rlhf": (1.0, 5.0), "rlhf-res": (0.3, 1.5)}
"""(policy, value) weights of Eq. 17 (alpha_p, alpha_v) and Eq. 20 (beta_p, beta_v)."""

PRESETS: dict[str, dict[str, object]] = {
    "paper": {
        "kl_form": "paper",
        "ratio_against": "reference",
        "likelihood": "mean",
        "score_every": 3,
        "gae_lambda": 0.0,
        "value_target": "reward",
        "adv_norm": "none",
        "reward_clip": None,
        "clip": 0.2,
        "value_clip": 0.2,
    },
}
"""Overrides of ``FinetuneConfig`` per preset; the policy/value weights follow the method."""


def preset_overrides(preset: str, method: str) -> list[str]:
    """``key=value`` overrides (for ``config.load_config``) of a preset and method."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; choose {', '.join(PRESETS)}")
    if method not in PAPER_WEIGHTS:
        raise ConfigError(f"unknown method {method!r}; choose {', '.join(PAPER_WEIGHTS)}")
    pw, vw = PAPER_WEIGHTS[method]
    values = {**PRESETS[preset], "method": method, "policy_weight": pw, "value_weight": vw}
    return [f"finetune.{k}={'null' if v is None else v}" for k, v in values.items()]


CONTROL_READS = ("method", "reg_weight")
"""The ``FinetuneConfig`` fields of its own (beside ``OptimConfig``'s, which every method
reads) that the control reads: it trains L_reg alone on clean rollouts."""

RL_ONLY = ("policy_weight", "value_weight", "clip", "value_clip", "kl_coef", "kl_form", "gamma",
           "gae_lambda", "value_target", "adv_norm", "reward_clip", "score_every",
           "detach_critic", "likelihood", "explore_std", "explore", "ratio_against", "reward",
           "set_bandwidth", "set_alpha", "sda_radius", "sda_drift", "sda_tolerance",
           "ppo_epochs", "reg_on", "baseline")  # fmt: skip
"""The ``FinetuneConfig`` fields that only the RL methods read (their policy and value
losses, the reward, the exploration and the PPO updates): the control has none of these, so
``finetune_config`` refuses a control whose config changes one of them."""

EQUAL_BUDGET_WARMUP = 4
"""The equal-budget protocol's warm-up steps, the same for every method (the default 20 would
leave the RL methods, which fit ~16-30 steps in 4 CPU minutes, below the full rate)."""

EQUAL_BUDGET_VALIDATIONS = 4
"""The equal-budget protocol validates after every budget / this many CPU minutes (4 minutes:
every minute, as ``benchmarks/equal_budget.py``)."""


def equal_budget_overrides(minutes: float, warmup: int = EQUAL_BUDGET_WARMUP,
                           eval_minutes: float | None = None) -> list[str]:  # fmt: skip
    """The equal-budget protocol's ``key=value`` overrides (for ``config.load_config``):
    ``minutes`` of this process's CPU time on training steps (``budget_clock=cpu``:
    validation excluded, and other jobs on the machine do not eat into it), no epoch limit,
    validation after every ``eval_minutes`` of that time (default ``minutes /
    EQUAL_BUDGET_VALIDATIONS``: every method gets as many checkpoints to choose from),
    ``warmup`` steps. ``trajpref finetune --equal-budget MINUTES`` applies them."""
    if not (math.isfinite(minutes) and minutes > 0):
        raise ConfigError(f"the equal budget (--equal-budget) must be a number of CPU minutes "
                          f"> 0, got {minutes}")  # fmt: skip
    if eval_minutes is None:
        eval_minutes = minutes / EQUAL_BUDGET_VALIDATIONS
    return [f"finetune.max_minutes={minutes}", "finetune.budget_clock=cpu",
            "finetune.epochs=100000", f"finetune.eval_every_minutes={eval_minutes}",
            f"finetune.warmup_steps={warmup}"]  # fmt: skip


def equal_budget_args(minutes: float, warmup: int, eval_minutes: float) -> list[str]:
    """``--set key=value`` arguments of ``benchmarks/finetune.py`` for the equal-budget table's
    runs (``benchmarks/equal_budget.py`` and ``benchmarks/reproduce.py``): the overrides of
    ``equal_budget_overrides``."""
    overrides = equal_budget_overrides(minutes, warmup, eval_minutes)
    return [arg for override in overrides for arg in ("--set", override)]


def _override_keys(overrides: list[str]) -> set[str]:
    """The keys of ``key=value`` overrides."""
    return {text.partition("=")[0].strip() for text in overrides}


def _undescribed(data: dict[str, Any], overrides: list[str]) -> list[str]:
    """Overrides that drop the start's folder description (``data.frame_interval``,
    ``data.units``) when ``overrides`` move fine-tuning to a built-in dataset, which knows its
    own and refuses one; a description the overrides give themselves stays theirs."""
    given = {k: v for k, _, v in (o.partition("=") for o in overrides)}
    dataset = given.get("data.dataset", "").strip()
    if dataset not in BUILTIN_DATASETS:
        return []
    return [f"data.{key}=null" for key in ("frame_interval", "units")
            if data.get(key) is not None and f"data.{key}" not in given]  # fmt: skip


def _check_reads(cfg: ExperimentConfig, method: str, overrides: list[str]) -> None:
    """Refuse settings the method does not read: the control with an RL-only setting named in
    ``overrides`` or changed from its default (by a YAML file), RLHF-ReS with the set-aware
    reward."""
    if method == "control":
        default, named = FinetuneConfig(), _override_keys(overrides)
        changed = [k for k in RL_ONLY if f"finetune.{k}" in named
                   or getattr(cfg.finetune, k) != getattr(default, k)]  # fmt: skip
        if changed:
            keys = ", ".join(f"finetune.{k}" for k in changed)
            raise ConfigError(
                f"{keys}: the control reads no RL setting (it trains the supervised loss "
                f"alone: no reward, policy, value, exploration or PPO update), so "
                f"{'this has' if len(changed) == 1 else 'these have'} no effect; leave "
                f"{'it' if len(changed) == 1 else 'them'} out"
            )
    if method == "rlhf-res" and cfg.finetune.reward == "set":
        raise ConfigError(
            "finetune.reward=set rewards each sample by what it adds to its K samples' set, "
            "and RLHF-ReS trains only each scene's best-scored sample, which undoes the set "
            "view (docs/rlhf.md): use it with --method rlhf"
        )


def finetune_config(
    start: str | Path | dict[str, Any],
    method: str,
    preset: str | None = None,
    config: str | Path | None = None,
    overrides: list[str] | None = None,
    seed: int | None = None,
    equal_budget: float | None = None,
) -> ExperimentConfig:
    """The config of a fine-tuning run from the generator checkpoint ``start`` (a path or a
    loaded payload), resolved in this order: the checkpoint's own config with today's
    fine-tuning defaults (a finetune section written by an earlier run is not carried over),
    the YAML file's finetune section, the preset, the method, the seed (None: 0, the default
    of every config, whatever seed the start was trained with), the equal-budget protocol
    (``equal_budget`` CPU minutes: ``equal_budget_overrides``; an override of one of its keys
    is then refused), then ``overrides``.

    Refused: a preset for the control, a control whose overrides name (or whose YAML file
    changes) a setting it does not read (``RL_ONLY``), RLHF-ReS with the set-aware reward,
    and any ``model.*`` or ``diffusion.*`` change (the network is the start's)."""
    payload = start if isinstance(start, dict) else checkpoint.load(start)
    if payload["kind"] != "generator":
        where = "the start" if isinstance(start, dict) else str(start)
        raise ConfigError(f"{where}: fine-tuning starts from a generator checkpoint")
    if preset and method == "control":
        raise ConfigError("the control takes no preset (it has no policy or value loss)")
    extra = preset_overrides(preset, method) if preset else [f"finetune.method={method}"]
    extra.append(f"seed={0 if seed is None else seed}")
    if equal_budget is not None:
        budget = equal_budget_overrides(equal_budget)
        clash = sorted(_override_keys(budget) & _override_keys(overrides or []))
        if clash:
            raise ConfigError(f"--equal-budget sets {', '.join(clash)}: leave "
                              f"{'it' if len(clash) == 1 else 'them'} out of --set (or set "
                              "the budget's keys yourself, without --equal-budget)")  # fmt: skip
        extra += budget
    # the start's resolved config (a file older than a changed default keeps its own value)
    resolved = to_dict(checkpoint.config_of(payload))
    base = {k: v for k, v in resolved.items() if k != "finetune"}
    extra += _undescribed(base.get("data", {}), overrides or [])
    cfg = load_config(config, [*extra, *(overrides or [])], base=base, sections=("finetune",))
    if cfg.finetune.method != method:
        raise ConfigError(f"finetune.method={cfg.finetune.method} contradicts --method {method}; "
                          "choose the method with --method alone")  # fmt: skip
    now = to_dict(cfg)
    for section in ("model", "diffusion"):  # the network and its schedule come from the start
        changed = [k for k, v in now[section].items() if v != resolved[section].get(k)]
        if changed:
            k = changed[0]
            raise ConfigError(
                f"{section}.{k}: fine-tuning keeps the network of the checkpoint it starts from "
                f"({section}.{k} = {resolved[section].get(k)!r} there, {now[section][k]!r} "
                f"asked); a sampling setting of the result can be changed afterwards "
                f"(`trajpref evaluate --spread-scale/--max-speed`, or "
                f"models.checkpoint.set_generator_setting)"
            )
    _check_reads(cfg, method, overrides or [])
    return cfg
