"""Named settings of the fine-tuning stage (``paper`` is the equations as written), and the
resolution of a fine-tuning run's config from its starting checkpoint."""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from trajpref.config import (
    BUILTIN_DATASETS,
    ExperimentConfig,
    FinetuneConfig,
    load_config,
    read_yaml,
    resolve_config,
    to_dict,
    uses_rl,
)
from trajpref.errors import ConfigError, IgnoredWarning
from trajpref.models import checkpoint
from trajpref.rl.objective import loss_samples
from trajpref.rl.rewards import BUILTIN_REWARDS, SCORE_REWARDS, check_reward

PAPER_WEIGHTS = {"rlhf": (1.0, 5.0), "rlhf-res": (0.3, 1.5)}
"""(policy, value) weights of Eq. 17 (alpha_p, alpha_v) and Eq. 20 (beta_p, beta_v): the
RL methods' weights that ``--preset`` sets (a method without an entry takes no preset)."""

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
        raise ConfigError(f"method {method!r} takes no preset (rl.presets.PAPER_WEIGHTS has "
                          f"no weights for it); choose {', '.join(PAPER_WEIGHTS)}")  # fmt: skip
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


@dataclass(frozen=True)
class ReadWhen:
    """RL settings that the RL methods read only under some other setting (a reward, a
    likelihood, a PPO update): given without it, they have no effect."""

    keys: tuple[str, ...]
    """The ``FinetuneConfig`` fields."""
    reads: Callable[[FinetuneConfig], bool]
    """Whether a run with this config reads them."""
    owner: str
    """What they belong to, as the error names it."""
    unread: Callable[[FinetuneConfig], str]
    """Why this run does not read them (from its config)."""
    fix: str
    """What to do instead of leaving them out."""


READ_WHEN = (
    ReadWhen(("set_bandwidth", "set_alpha"), lambda ft: ft.reward == "set",
             "the set-aware reward (finetune.reward=set)",
             lambda ft: f"this run's reward is {ft.reward}", "or set finetune.reward=set"),
    ReadWhen(("sda_radius", "sda_drift", "sda_tolerance"), lambda ft: ft.reward == "sda",
             "the SDA reward (finetune.reward=sda)",
             lambda ft: f"this run's reward is {ft.reward}", "or set finetune.reward=sda"),
    # sda and a registered reward (rl.rewards.register_reward) compute no diffusion score
    ReadWhen(("score_every",), lambda ft: ft.reward in SCORE_REWARDS,
             "the diffusion score (finetune.reward=score or set)",
             lambda ft: f"this run's reward is {ft.reward}, which computes no diffusion score",
             "or choose finetune.reward=score or set"),
    ReadWhen(("explore_std", "explore"), lambda ft: ft.likelihood == "sample",
             "the sample likelihood's exploration (finetune.likelihood=sample)",
             lambda ft: f"this run's likelihood is {ft.likelihood}, which does not explore",
             "or set finetune.likelihood=sample"),
    # with one update on its own rollout and the ratio p_theta / p_old, the ratio is 1
    ReadWhen(("clip",), lambda ft: ft.ratio_against == "reference" or ft.ppo_epochs > 1,
             "the clipped PPO ratio (finetune.ratio_against=reference or ppo_epochs > 1)",
             lambda ft: "this run takes one update per rollout with the ratio against the "
             "rollout policy (ppo_epochs=1, ratio_against=rollout): its ratio is always 1",
             "or set finetune.ppo_epochs above 1 (or finetune.ratio_against=reference)"),
    # the antithetic baseline replaces the TD advantage, and a reward value target no return
    ReadWhen(("gamma", "gae_lambda"),
             lambda ft: ft.baseline == "critic" or ft.value_target == "return",
             "the TD advantage and return (finetune.baseline=critic or value_target=return)",
             lambda ft: "this run's advantage is antithetic (baseline=antithetic) and its "
             "value target the reward (value_target=reward)",
             "or set finetune.value_target=return"),
    # a coefficient of 0 multiplies the KL term away, whatever its form
    ReadWhen(("kl_form",), lambda ft: ft.kl_coef > 0,
             "the KL penalty (finetune.kl_coef > 0)",
             lambda ft: "this run's finetune.kl_coef is 0, so its reward has no KL term",
             "or set finetune.kl_coef above 0"),
)  # fmt: skip
"""What the RL methods read only under another setting: ``finetune_config`` refuses a run
that names one of these keys (or whose YAML file changes one) where it is not read (a
preset's own values are not refused). Every other RL_ONLY key is read by both RL methods
(``rlhf-res`` refuses ``reward=set`` itself). A registered reward reads none of the
conditional keys, as ``sda`` reads none but its own: its own settings are its closure's."""


NO_AUGMENTATION = {"rotate": False, "flip": False, "reverse": False, "reverse_context": False,
                   "scale_min": 1.0, "scale_max": 1.0, "history_noise": 0.0,
                   "drop_agents": 0.0}  # fmt: skip
"""``DataConfig`` values that leave every training scene as the dataset has it."""

NO_SCALING = {"scale_min": 1.0, "scale_max": 1.0}
"""``DataConfig`` values that leave every training scene at the dataset's scale: ``sda``'s
radius, drift and tolerance are distances, which a scaled scene would stretch (rotation and
mirroring leave distances alone)."""


def own_reward_data(cfg: ExperimentConfig) -> tuple[ExperimentConfig, str | None]:
    """-> (the config a fine-tuning run trains with, a one-line note or None). A registered
    reward (``rl.rewards.register_reward``; not ``score``, ``set`` or ``sda``) is promised
    the dataset's own coordinates: its run trains without data augmentation (no rotation,
    mirror, time reversal, scaling, jitter or dropped agents, whatever the start trained
    with), so that a map-, goal- or direction-based reward is not handed a rotated or
    mirrored scene. ``sda`` trains without scaled scenes (``NO_SCALING``): its thresholds are
    distances. Other runs are returned as they are."""
    ft = cfg.finetune
    if not uses_rl(ft.method) or ft.reward in SCORE_REWARDS:
        return cfg, None
    if ft.reward in BUILTIN_REWARDS:  # sda: distances against fixed thresholds
        fixed, why, what = (NO_SCALING, "its thresholds are distances in the data's units",
                            "scaled scenes")  # fmt: skip
    else:
        fixed, why, what = (NO_AUGMENTATION, "a registered reward, given the data's own "
                            "coordinates", "augmentation")  # fmt: skip
    changed = [k for k, v in fixed.items() if getattr(cfg.data, k) != v]
    if not changed:
        return cfg, None
    data = dataclasses.replace(cfg.data, **fixed)
    off = ", ".join(f"data.{k}" for k in changed)
    note = (f"[finetune] reward {ft.reward!r} is {why}: this run trains without {what} "
            f"({off} off)")  # fmt: skip
    return dataclasses.replace(cfg, data=data), note


EQUAL_BUDGET_WARMUP = 4
"""The equal-budget protocol's warm-up steps, the same for every method. Chosen when the RL
methods fitted ~16-30 steps in 4 CPU minutes (the default 20 would have left them below the
full rate); the kept eth runs fit many more (runs/eth-rlhf-s0 152 steps, eth-rlhf-res-s0 145,
the control eth-control-s0 1,594), so there it is a small share of every run."""

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
    return set(override_key_list(overrides))


def override_key_list(overrides: list[str]) -> list[str]:
    """The keys of ``key=value`` overrides, in the order given."""
    return [text.partition("=")[0].strip() for text in overrides]


PRETRAINING = ("generator", "denoiser")
"""The config sections of the pretraining stages (``check_no_pretraining_keys``)."""


def check_no_pretraining_keys(overrides: list[str]) -> None:
    """ConfigError naming the first of a user's own ``overrides`` that sets a pretraining
    stage (``generator.*``, ``denoiser.*``), which fine-tuning never reads. For the command
    line's ``--set`` only: a config shared with training (the demo's) may hold them."""
    stages = [k for k in override_key_list(overrides) if k.partition(".")[0] in PRETRAINING]
    if stages:
        raise ConfigError(f"{stages[0]}: fine-tuning does not read the pretraining stages' "
                          "settings (generator.*, denoiser.*); its own are finetune.* "
                          "(finetune.epochs, finetune.lr, ...: trajpref config show lists "
                          "them)")  # fmt: skip


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


def _check_reads(cfg: ExperimentConfig, method: str, overrides: list[str],
                 preset: str | None = None) -> None:  # fmt: skip
    """Refuse settings the method does not read: the control with an RL-only setting named in
    ``overrides`` or changed from its default (by a YAML file), an RL method with a setting
    of ``READ_WHEN`` that its other settings leave unread (named or changed alike; a value
    the ``preset`` sets is its own), RLHF-ReS with the set-aware reward."""
    default, named = FinetuneConfig(), _override_keys(overrides)

    def given(key: str, preset_keys: tuple[str, ...] = ()) -> bool:
        return f"finetune.{key}" in named or (
            key not in preset_keys and getattr(cfg.finetune, key) != getattr(default, key)
        )

    if not uses_rl(method):
        changed = [k for k in RL_ONLY if given(k)]
        if changed:
            keys = ", ".join(f"finetune.{k}" for k in changed)
            raise ConfigError(
                f"{keys}: the control reads no RL setting (it trains the supervised loss "
                f"alone: no reward, policy, value, exploration or PPO update), so "
                f"{'this has' if len(changed) == 1 else 'these have'} no effect; leave "
                f"{'it' if len(changed) == 1 else 'them'} out"
            )
        return
    check_reward(cfg.finetune.reward)  # a name registered in this process, or a built-in
    if loss_samples(method) == "best" and cfg.finetune.reward == "set":
        name = "RLHF-ReS" if method == "rlhf-res" else f"--method {method}"
        raise ConfigError(
            "finetune.reward=set rewards each sample by what it adds to its K samples' set, "
            f"and {name} trains only each scene's best-scored sample, which undoes the set "
            "view (docs/rlhf.md): use it with --method rlhf"
        )
    preset_keys = tuple(PRESETS[preset]) if preset else ()
    unread = []
    for rule in READ_WHEN:
        changed = [k for k in rule.keys if given(k, preset_keys)]
        if changed and not rule.reads(cfg.finetune):
            one = len(changed) == 1
            unread.append(
                f"{', '.join(f'finetune.{k}' for k in changed)}: "
                f"{'a setting' if one else 'settings'} of {rule.owner}, and "
                f"{rule.unread(cfg.finetune)}, so {'it has' if one else 'they have'} no "
                f"effect; leave {'it' if one else 'them'} out {rule.fix}"
            )
    if unread:
        raise ConfigError("; ".join(unread))


def _check_file_under_preset(cfg: ExperimentConfig, config: str | Path, base: dict[str, Any],
                             preset_keys: set[str], overrides: list[str]) -> None:  # fmt: skip
    """Refuse a ``--config`` file whose finetune section gives a key that the preset sets
    (and ``overrides`` does not) another value: the preset, applied after the file, would
    replace it without a word."""
    loaded = read_yaml(resolve_config(config)) or {}
    given = loaded.get("finetune") if isinstance(loaded, dict) else None
    if not isinstance(given, dict):
        return
    from_file = load_config(config, [], base=base, sections=("finetune",)).finetune
    named = _override_keys(overrides)
    lost = [k for k in sorted(given) if f"finetune.{k}" in preset_keys
            and f"finetune.{k}" not in named
            and getattr(from_file, k) != getattr(cfg.finetune, k)]  # fmt: skip
    if lost:
        one = len(lost) == 1
        pairs = ", ".join(f"finetune.{k} ({getattr(from_file, k)!r} in {config}, "
                          f"{getattr(cfg.finetune, k)!r} in the preset)" for k in lost)  # fmt: skip
        raise ConfigError(
            f"{pairs}: --preset sets {'this key' if one else 'these keys'} after the --config "
            f"file, so the file's {'value has' if one else 'values have'} no effect; change "
            f"a preset's value with --set (e.g. --set finetune.{lost[0]}="
            f"{getattr(from_file, lost[0])}), or leave {'it' if one else 'them'} out of the file"
        )


UNREAD_SHOWN = 6
"""How many of a ``--config`` file's unread values ``unread_file_note`` names (then a count)."""


def _as_yaml(value: Any) -> str:
    """A value as a ``--set`` takes it: ``true``, ``null``, ``0.5``, ``eth``."""
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


def unread_file_note(config: str | Path, cfg: ExperimentConfig, method: str,
                     overrides: list[str]) -> str | None:  # fmt: skip
    """The one line that says what a fine-tuning run's ``--config`` file gives that the run
    does not read (None when it reads all of it): its values of the data, network, noise
    schedule and seed that differ from the run's (the start's, or ``overrides``'; a key the
    overrides name is theirs), its ``finetune.method`` where ``--method`` chooses another,
    and that a file without a finetune section changes nothing. The pretraining stages'
    sections are the start's training and are not named."""
    path = resolve_config(config)
    loaded = read_yaml(path) or {}
    if not isinstance(loaded, dict):
        return None
    shown = str(config) if Path(config).suffix else path.name  # a shipped name: eth.yaml
    named, now = _override_keys(overrides), to_dict(cfg)
    unread = []
    for section, value in loaded.items():
        if section in ("data", "model", "diffusion") and isinstance(value, dict):
            for key, given in value.items():
                if f"{section}.{key}" not in named and given != now[section].get(key):
                    unread.append(f"{section}.{key}={_as_yaml(given)} (the run's: "
                                  f"{_as_yaml(now[section].get(key))})")  # fmt: skip
        elif section == "seed" and "seed" not in named and value != cfg.seed:
            unread.append(f"seed={value} (the run's: {cfg.seed}; --seed {value} sets it)")
    own = loaded.get("finetune")
    if isinstance(own, dict) and own.get("method", method) != method:
        unread.append(f"finetune.method={own['method']} (--method {method} chooses the method)")
    if isinstance(own, dict) and not unread:
        return None
    head = f"{shown}: fine-tuning reads a --config file's finetune section alone"
    if not isinstance(own, dict):
        head += " and this file has none, so it changes nothing in this run"
    if not unread:
        return head
    more = len(unread) - UNREAD_SHOWN
    listed = ", ".join(unread[:UNREAD_SHOWN]) + (f" and {more} more" if more > 0 else "")
    advice = []
    if any(u.startswith(("data.", "seed=")) for u in unread):
        advice.append("the data and the seed are set with --set data.KEY=VALUE and --seed")
    if any(u.startswith(("model.", "diffusion.")) for u in unread):
        advice.append("the network and its noise schedule (model.*, diffusion.*) are the "
                      "start's")  # fmt: skip
    return f"{head}; not read: {listed}" + (f" ({'; '.join(advice)})" if advice else "")


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
    changes) a setting it does not read (``RL_ONLY``), an RL method whose ``reward`` is
    neither built in nor registered in this process (``rl.rewards.check_reward``: the CLI
    cannot register one), an RL method given a setting its other
    settings leave unread (``READ_WHEN``: e.g. ``set_bandwidth`` without ``reward=set``),
    RLHF-ReS with the set-aware reward, a ``config`` file that gives a key of the preset
    another value (the preset would replace it), and any ``model.*`` or ``diffusion.*``
    change (the network is the start's). A ``config`` file's values that the run does not
    read (its other sections, a method other than ``method``) are named in one warning
    (``unread_file_note``; on the first process alone under torchrun)."""
    payload = start if isinstance(start, dict) else checkpoint.load(start)
    if payload["kind"] != "generator":
        where = "the start" if isinstance(start, dict) else str(start)
        raise ConfigError(f"{where}: fine-tuning starts from a generator checkpoint")
    if preset and not uses_rl(method):
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
    _check_reads(cfg, method, overrides or [], preset)
    if preset and config is not None:
        # --method wins over a file's method, with or without a preset (the note names it)
        preset_keys = _override_keys(preset_overrides(preset, method)) - {"finetune.method"}
        _check_file_under_preset(cfg, config, base, preset_keys, overrides or [])
    if config is not None and os.environ.get("RANK", "0") == "0":
        note = unread_file_note(config, cfg, method, overrides or [])
        if note is not None:
            warnings.warn(note, IgnoredWarning, stacklevel=2)
    return cfg
