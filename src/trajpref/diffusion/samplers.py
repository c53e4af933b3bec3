"""Reverse-process samplers over any noise predictor ``eps_fn(y, s) -> eps``."""

from __future__ import annotations

from collections.abc import Callable

import torch

from trajpref.diffusion.schedule import DDPMSchedule

EpsFn = Callable[[torch.Tensor, int], torch.Tensor]


def denoise(
    schedule: DDPMSchedule,
    eps_fn: EpsFn,
    sample: torch.Tensor,
    start: int,
    generator: torch.Generator | None = None,
    stochastic: bool = True,
) -> torch.Tensor:
    """Run ancestral steps ``start-1, ..., 0`` from ``sample`` (Eq. 3).

    ``start = tau`` is the leapfrog sampler (the generator's Y^tau enters at step tau - 1 and
    is denoised tau times); ``start = S`` from Gaussian noise is the full (MID-style) sampler.
    With ``stochastic=False`` each step returns the posterior mean (no noise is drawn).
    Differentiable in ``sample`` (the generator stage backpropagates through it).
    """
    y = sample
    for s in schedule.timesteps(start):
        noise = None if stochastic else torch.zeros_like(y)
        y = schedule.step(eps_fn(y, s), s, y, generator=generator, noise=noise).prev_sample
    return y


def sample_full(
    schedule: DDPMSchedule,
    eps_fn: EpsFn,
    shape: tuple[int, ...],
    generator: torch.Generator | None = None,
    device: torch.device | str = "cpu",
) -> torch.Tensor:
    """All S steps from y_{S-1} ~ N(0, I)."""
    y = torch.randn(shape, generator=generator, dtype=torch.float32).to(device)
    return denoise(schedule, eps_fn, y, schedule.num_steps, generator)
