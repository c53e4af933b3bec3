"""An exponential moving average (EMA) of a module's weights, for validation and checkpoints.

The training loop keeps the raw weights for the optimiser and, when
``OptimConfig.ema_epochs`` is set, this average beside them; validation and the best
checkpoint then use the average (``WeightAverage.swapped_in``). The decay per step is fixed
by a time constant in epochs, so one setting means the same on folds of any size.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager

import torch
from torch import nn

from trajpref.errors import ConfigError


def ema_decay(epochs: float, steps_per_epoch: int) -> float:
    """The per-step decay of an average whose time constant is ``epochs`` epochs of
    ``steps_per_epoch`` optimiser steps: ``exp(-1 / (epochs * steps_per_epoch))``."""
    if not epochs > 0 or steps_per_epoch < 1:
        raise ConfigError(
            f"an EMA needs a time constant > 0 epochs and >= 1 step per epoch, got {epochs} "
            f"epochs and {steps_per_epoch} steps"
        )
    return math.exp(-1.0 / (epochs * steps_per_epoch))


def warmed_decay(decay: float, updates: int) -> float:
    """The decay used at the ``updates``-th update (1-based): ``min(decay, (1 + n) / (10 + n))``,
    so that the first updates are not dominated by the initial weights."""
    return min(decay, (1.0 + updates) / (10.0 + updates))


class WeightAverage:
    """EMA of a module's trained parameters (those that require gradients), kept in float32.
    Buffers and frozen parameters stay the module's own: constants such as a noise schedule's
    are not averaged into rounding noise. The parameters are looked up once, here: the
    optimiser and ``load_state_dict`` change them in place, so the references stay valid."""

    def __init__(self, module: nn.Module, decay: float):
        if not 0.0 <= decay < 1.0:
            raise ConfigError(f"EMA decay must be in [0, 1), got {decay}")
        self.decay = decay
        self.updates = 0
        self.params = {name: p for name, p in module.named_parameters() if p.requires_grad}
        self.shadow: dict[str, torch.Tensor] = {
            name: p.detach().float().clone() for name, p in self.params.items()
        }

    @torch.no_grad()
    def update(self) -> float:
        """Fold the module's current weights in; returns the decay used."""
        self.updates += 1
        d = warmed_decay(self.decay, self.updates)
        for name, avg in self.shadow.items():
            avg.mul_(d).add_(self.params[name].float(), alpha=1.0 - d)
        return d

    @contextmanager
    def swapped_in(self) -> Iterator[None]:
        """Within the block the module holds the averaged weights; the raw ones come back
        after it, exactly, even when the block raises."""
        with torch.no_grad():
            raw = {name: p.clone() for name, p in self.params.items()}
            for name, avg in self.shadow.items():
                self.params[name].copy_(avg)
        try:
            yield
        finally:
            with torch.no_grad():
                for name, value in raw.items():
                    self.params[name].copy_(value)

    def state_dict(self) -> dict[str, object]:
        """Tensors and plain values, for a resume state loaded with ``weights_only=True`` (the
        decay is not among them: it follows from the run's config)."""
        return {"updates": self.updates, "shadow": self.shadow}

    def load_state_dict(self, state: dict[str, object]) -> None:
        shadow = state["shadow"]
        if not isinstance(shadow, dict) or set(shadow) != set(self.shadow):
            raise ConfigError("the resume state's weight average does not fit this model")
        for key, value in shadow.items():
            self.shadow[key].copy_(value)
        self.updates = int(state["updates"])  # type: ignore[arg-type]
