"""Fine-tuning's rewards by ``finetune.reward`` name: the built-in ones and those a user
registers from Python (``register_reward``; docs/rlhf.md, "A reward of your own").

``score`` and ``set`` are the diffusion score's (they need the frozen denoiser and the ground
truth's residual, Eq. 6: ``rl.objective`` computes them). Every other reward is hand-crafted:
a plain callable (``HandcraftedReward``) given the batch with its future hidden and the
sampled futures in absolute coordinates. ``sda`` is the built-in one; a user's is registered
under a name of its own, for this process only: a checkpoint records the reward's name
(``meta.reward``) and nothing else, and loading one never runs code, so the command line,
which cannot register Python code, runs the built-in rewards only.
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import torch

from trajpref.config import FinetuneConfig
from trajpref.errors import ConfigError, RewardError
from trajpref.rl import sda
from trajpref.types import Batch

HandcraftedReward = Callable[[Batch, torch.Tensor, FinetuneConfig], torch.Tensor]
"""A per-step reward in place of the diffusion score, as a plain callable: (the batch with its
future hidden, futures [M, N, T_f, 2] in absolute coordinates, the fine-tuning config) -> r
[M, N, T_f], higher is better. A run trains on one reward: a registered one is not added to
the score (docs/rlhf.md, "A reward of your own")."""

SCORE_REWARDS = ("score", "set")
"""The rewards that are the diffusion score (and read ``finetune.score_every``)."""


def sda_step_reward(batch: Batch, futures: torch.Tensor, cfg: FinetuneConfig) -> torch.Tensor:
    """``finetune.reward=sda``: rl/sda.py's reward at the config's thresholds."""
    return sda.sda_reward(batch.history, batch.scene, futures, cfg.sda_radius, cfg.sda_drift,
                          cfg.sda_tolerance, batch.agent_type)  # fmt: skip


REWARDS: dict[str, HandcraftedReward] = {"sda": sda_step_reward}
"""The built-in hand-crafted rewards by ``finetune.reward`` name."""

BUILTIN_REWARDS = (*SCORE_REWARDS, *REWARDS)
"""Every built-in reward's name: a registered reward may not take one."""

_REGISTERED: dict[str, HandcraftedReward] = {}
"""The rewards registered in this process (``register_reward``), by name."""


def registered_rewards() -> tuple[str, ...]:
    """The names of the rewards registered in this process, sorted (built-ins not included)."""
    return tuple(sorted(_REGISTERED))


def _known() -> str:
    """The rewards this process can fine-tune with, as the errors name them."""
    mine = registered_rewards()
    return (f"the built-in rewards are {', '.join(BUILTIN_REWARDS)}; registered in this process: "
            f"{', '.join(mine) if mine else 'none'}")  # fmt: skip


def _check_name(name: object) -> str:
    """``name`` when a user's reward may be registered under it, else a ``ConfigError``."""
    if not FinetuneConfig.is_reward_name(name):
        raise ConfigError(f"register_reward: a reward's name is an ASCII letter, then letters, "
                          f"digits, '_' or '-' (it is given as --set finetune.reward=NAME), "
                          f"got {name!r}")  # fmt: skip
    if name in BUILTIN_REWARDS:
        builtin = ", ".join(BUILTIN_REWARDS)
        raise ConfigError(f"register_reward: {name!r} is a built-in reward ({builtin}); "
                          "register yours under another name")  # fmt: skip
    return str(name)


def register_reward(name: str, fn: HandcraftedReward, *, replace: bool = False) -> None:
    """Register ``fn`` as the reward ``name``: a run whose ``finetune.reward`` is ``name``
    (``rlhf`` or ``rlhf-res``) then trains on it, in this process.

    ``fn(batch, futures, cfg)`` gets the batch with its future hidden (NaN: it cannot read the
    ground truth), futures [M, N, T_f, 2] in absolute coordinates (the data's units and frame:
    its run trains without augmentation, ``rl.presets.own_reward_data``) and the run's
    ``FinetuneConfig``, and returns the per-step reward [M, N, T_f], higher is better,
    finite; ``finetune.reward_clip`` clips it as it clips ``sda``. Its own settings, if any,
    are its own (a closure, a ``functools.partial``): the config has none for it.

    Refused: a name that is not one (``FinetuneConfig.is_reward_name``), a built-in's name
    (``score``, ``set``, ``sda``), a name registered already unless ``replace`` (registering
    the same function again is a no-op), and an ``fn`` that is not callable with three
    arguments. ``unregister_reward`` or ``registered_reward`` (a context manager) take it back.
    """
    name = _check_name(name)
    if not callable(fn):
        raise TypeError(f"register_reward({name!r}, fn): fn must be a callable (batch, futures, "
                        f"cfg) -> reward [M, N, T_f], got {type(fn).__name__}")  # fmt: skip
    try:
        inspect.signature(fn).bind(None, None, None)
    except TypeError:
        raise TypeError(f"register_reward({name!r}, fn): fn must take three arguments (batch, "
                        f"futures, cfg), and {_describe(fn)} does not") from None  # fmt: skip
    except ValueError:  # no signature to read (some built-ins): it is called as it is
        pass
    held = _REGISTERED.get(name)
    if held is not None and held is not fn and not replace:
        raise ConfigError(f"register_reward: {name!r} is registered already (to "
                          f"{_describe(held)}); unregister_reward({name!r}) first, or pass "
                          "replace=True")  # fmt: skip
    _REGISTERED[name] = fn


def unregister_reward(name: str) -> None:
    """Take back the reward registered as ``name`` (a ``ConfigError`` when none is)."""
    if name in BUILTIN_REWARDS:
        raise ConfigError(f"unregister_reward: {name!r} is a built-in reward; only rewards "
                          "registered with register_reward can be unregistered")  # fmt: skip
    if name not in _REGISTERED:
        raise ConfigError(f"unregister_reward: no reward {name!r} is registered ({_known()})")
    del _REGISTERED[name]


@contextmanager
def registered_reward(name: str, fn: HandcraftedReward) -> Iterator[HandcraftedReward]:
    """``register_reward(name, fn)`` for the ``with`` block only: the name is free again
    after it, whatever the block raised (a name registered already is refused)."""
    register_reward(name, fn)
    try:
        yield fn
    finally:
        if _REGISTERED.get(name) is fn:
            del _REGISTERED[name]


def _describe(fn: object) -> str:
    """A callable as an error names it."""
    return getattr(fn, "__qualname__", None) or repr(fn)


def check_reward(name: str) -> None:
    """A ``ConfigError`` unless this process can fine-tune with the reward ``name`` (a
    built-in, or registered): it names the rewards there are and how to register one."""
    if name in BUILTIN_REWARDS or name in _REGISTERED:
        return
    close = difflib.get_close_matches(name, [*BUILTIN_REWARDS, *_REGISTERED], n=1, cutoff=0.6)
    hint = f" (did you mean {close[0]}?)" if close else ""
    raise ConfigError(
        f"finetune.reward={name}: no such reward in this process{hint}; {_known()}. A reward of "
        f"your own is registered from Python before fine-tuning, and again in a process that "
        f"resumes its run: trajpref.rl.register_reward({name!r}, fn), then "
        'rl.presets.finetune_config and train.finetune (docs/rlhf.md, "A reward of your own"); '
        "the trajpref command cannot register Python code, so it fine-tunes with the built-in "
        "rewards only"
    )


def handcrafted_reward(name: str) -> HandcraftedReward | None:
    """The callable of reward ``name``: None for the diffusion score's (``SCORE_REWARDS``),
    else the built-in or registered one (a ``ConfigError`` from ``check_reward`` if none)."""
    if name in SCORE_REWARDS:
        return None
    check_reward(name)
    return REWARDS.get(name) or _REGISTERED[name]


def hide_future(batch: Batch) -> Batch:
    """A copy of the batch with its future replaced by NaN: what a hand-crafted reward is
    given, so it cannot read the ground truth even by mistake, nor change the batch that the
    update goes on with (its tensors are copies)."""
    copied = {f.name: value.clone() for f in dataclasses.fields(batch)
              if isinstance(value := getattr(batch, f.name), torch.Tensor)}  # fmt: skip
    del copied["future"]
    return dataclasses.replace(batch, **copied, scene_ids=list(batch.scene_ids),
                               future=torch.full_like(batch.future, math.nan))  # fmt: skip


def call_reward(name: str, fn: HandcraftedReward, observed: Batch, futures: torch.Tensor,
                cfg: FinetuneConfig) -> torch.Tensor:  # fmt: skip
    """``fn(observed, futures, cfg)``, checked: a ``RewardError`` naming the reward unless it
    is a tensor of shape [M, N, T_f] (futures [M, N, T_f, 2]) with finite values, and then
    clipped to ``cfg.reward_clip``. -> [M, N, T_f] in the futures' dtype and device."""
    want = tuple(futures.shape[:-1])
    r = fn(observed, futures, cfg)
    if not isinstance(r, torch.Tensor):
        raise RewardError(f"reward {name!r} returned a {type(r).__name__}; it must return a "
                          f"tensor [M, N, T_f] = {list(want)}")  # fmt: skip
    if tuple(r.shape) != want:
        raise RewardError(f"reward {name!r} returned shape {list(r.shape)}; it must return "
                          f"[M, N, T_f] = {list(want)}: one value per sample, agent and future "
                          "step (futures are [M, N, T_f, 2])")  # fmt: skip
    r = r.detach().to(futures)
    bad = ~torch.isfinite(r)  # [M, N, T_f]
    if bool(bad.any()):
        raise RewardError(f"reward {name!r} returned {int(bad.sum())} non-finite values of "
                          f"{r.numel()} (NaN or inf); it must be finite everywhere (the batch's "
                          "future is NaN: a reward that reads it gets NaN)")  # fmt: skip
    return r.clamp(-cfg.reward_clip, cfg.reward_clip) if cfg.reward_clip is not None else r
