"""Named settings of the fine-tuning stage (``paper`` is the equations as written), and the
resolution of a fine-tuning run's config from its starting checkpoint."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trajpref.config import ExperimentConfig, load_config, to_dict
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


def equal_budget_args(minutes: float, warmup: int, eval_minutes: float) -> list[str]:
    """``--set key=value`` arguments of ``benchmarks/finetune.py`` for the equal-budget table's
    runs (``benchmarks/equal_budget.py`` and ``benchmarks/reproduce.py``): ``minutes`` of this
    process's CPU time on training steps, no epoch limit, validation after every
    ``eval_minutes`` of that time, ``warmup`` steps."""
    overrides = [f"finetune.max_minutes={minutes}", "finetune.budget_clock=cpu",
                 "finetune.epochs=100000", f"finetune.eval_every_minutes={eval_minutes}",
                 f"finetune.warmup_steps={warmup}"]  # fmt: skip
    return [arg for override in overrides for arg in ("--set", override)]


def finetune_config(
    start: str | Path | dict[str, Any],
    method: str,
    preset: str | None = None,
    config: str | Path | None = None,
    overrides: list[str] | None = None,
    seed: int | None = None,
) -> ExperimentConfig:
    """The config of a fine-tuning run from the generator checkpoint ``start`` (a path or a
    loaded payload), resolved in this order: the checkpoint's own config with today's
    fine-tuning defaults (a finetune section written by an earlier run is not carried over),
    the YAML file's finetune section, the preset, the method, the seed, then ``overrides``."""
    payload = start if isinstance(start, dict) else checkpoint.load(start)
    if payload["kind"] != "generator":
        where = "the start" if isinstance(start, dict) else str(start)
        raise ConfigError(f"{where}: fine-tuning starts from a generator checkpoint")
    if preset and method == "control":
        raise ConfigError("the control takes no preset (it has no policy or value loss)")
    extra = preset_overrides(preset, method) if preset else [f"finetune.method={method}"]
    if seed is not None:
        extra.append(f"seed={seed}")
    # the start's resolved config (a file older than a changed default keeps its own value)
    resolved = to_dict(checkpoint.config_of(payload))
    base = {k: v for k, v in resolved.items() if k != "finetune"}
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
    return cfg
