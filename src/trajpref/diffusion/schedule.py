"""DDPM noise schedule (Ho et al. 2020) with a linear beta, as the paper uses (Sec. 7.1).

The schedule holds no network: ``add_noise`` is the forward process D^f, ``step`` one ancestral
reverse step of D^r given the network's noise prediction. Step indices s run 0..S-1; s = 0 is
the least noisy. With S = 100 and beta linear from 1e-4 to 5e-2, alpha_bar at s = S-1 is about
0.08: the last step is not pure noise (that is how LED uses it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from torch import nn

from trajpref.errors import ConfigError

if TYPE_CHECKING:
    from trajpref.config import DiffusionConfig


@dataclass
class StepOutput:
    """The result of one reverse step."""

    prev_sample: torch.Tensor
    """y_{s-1}, same shape as the input sample."""
    pred_original_sample: torch.Tensor
    """The x_0 estimate implied by the noise prediction."""


def _extract(values: torch.Tensor, s: torch.Tensor, ndim: int) -> torch.Tensor:
    """values[s] reshaped to broadcast against a tensor of ``ndim`` dims whose leading dims
    match ``s``: s [*S] -> [*S, 1, ..., 1]."""
    out = values[s]
    return out.reshape(*out.shape, *([1] * (ndim - out.ndim)))


class DDPMSchedule(nn.Module):
    """Linear-beta DDPM schedule. Tensors are buffers, so they move with ``.to()``."""

    def __init__(self, num_steps: int = 100, beta_start: float = 1e-4, beta_end: float = 5e-2):
        super().__init__()
        if num_steps < 1:
            raise ConfigError("num_steps must be >= 1")
        if not 0 < beta_start <= beta_end < 1:
            raise ConfigError("need 0 < beta_start <= beta_end < 1")
        self.num_steps = num_steps
        self.beta_start = beta_start
        self.beta_end = beta_end
        betas = torch.linspace(beta_start, beta_end, num_steps, dtype=torch.float64)  # [S]
        alphas = 1.0 - betas
        alphas_cumprod = torch.cumprod(alphas, 0)  # alpha_bar_s
        alphas_cumprod_prev = torch.cat([torch.ones(1, dtype=torch.float64), alphas_cumprod[:-1]])
        # posterior q(y_{s-1} | y_s, y_0) variance (Ho et al. Eq. 7); at s = 0 it is 0
        posterior_var = betas * (1.0 - alphas_cumprod_prev) / (1.0 - alphas_cumprod)
        for name, value in {
            "betas": betas,
            "alphas": alphas,
            "alphas_cumprod": alphas_cumprod,
            "sqrt_alphas_cumprod": alphas_cumprod.sqrt(),
            "sqrt_one_minus_alphas_cumprod": (1.0 - alphas_cumprod).sqrt(),
            "posterior_variance": posterior_var,
            # Ho et al. Eq. 11: mean = (y_s - beta_s / sqrt(1 - abar_s) * eps) / sqrt(alpha_s)
            "eps_coef": betas / (1.0 - alphas_cumprod).sqrt(),
            "recip_sqrt_alphas": alphas.rsqrt(),
        }.items():
            self.register_buffer(name, value.float(), persistent=False)

    def extra_repr(self) -> str:
        return f"num_steps={self.num_steps}, beta=linear({self.beta_start}, {self.beta_end})"

    @classmethod
    def from_config(cls, cfg: DiffusionConfig) -> DDPMSchedule:
        """The schedule a ``DiffusionConfig`` describes."""
        return cls(cfg.num_steps, cfg.beta_start, cfg.beta_end)

    def _check_steps(self, s: torch.Tensor) -> None:
        if s.numel() and (int(s.min()) < 0 or int(s.max()) >= self.num_steps):
            raise ValueError(f"step indices must lie in 0..{self.num_steps - 1}")

    def add_noise(self, y0: torch.Tensor, noise: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        """Forward process (Eq. 2): y_s = sqrt(abar_s) y_0 + sqrt(1 - abar_s) z.

        ``s`` has the leading shape of ``y0`` (or is a scalar tensor); y0, noise [..., T_f, 2].
        """
        s = torch.as_tensor(s, device=y0.device)
        self._check_steps(s)
        a = _extract(self.sqrt_alphas_cumprod, s, y0.ndim)
        b = _extract(self.sqrt_one_minus_alphas_cumprod, s, y0.ndim)
        return a * y0 + b * noise

    def predict_original(self, sample: torch.Tensor, eps: torch.Tensor, s: torch.Tensor):
        """y_0 estimate from y_s and a noise prediction."""
        s = torch.as_tensor(s, device=sample.device)
        a = _extract(self.sqrt_alphas_cumprod, s, sample.ndim)
        b = _extract(self.sqrt_one_minus_alphas_cumprod, s, sample.ndim)
        return (sample - b * eps) / a

    def step(
        self,
        eps: torch.Tensor,
        s: int,
        sample: torch.Tensor,
        generator: torch.Generator | None = None,
        noise: torch.Tensor | None = None,
    ) -> StepOutput:
        """One ancestral reverse step y_s -> y_{s-1} (Eq. 3; Ho et al. Algorithm 2).

        ``s`` is one step index shared by the whole sample. At s = 0 no noise is added.
        ``noise`` overrides the draw from ``generator`` (for tests and common random numbers).
        """
        if not 0 <= s < self.num_steps:
            raise ValueError(f"step index {s} outside 0..{self.num_steps - 1}")
        mean = self.recip_sqrt_alphas[s] * (sample - self.eps_coef[s] * eps)
        x0 = self.predict_original(sample, eps, torch.tensor(s, device=sample.device))
        if s == 0:
            return StepOutput(mean, x0)
        if noise is None:
            noise = torch.randn(sample.shape, generator=generator, dtype=torch.float32).to(sample)
        return StepOutput(mean + self.posterior_variance[s].sqrt() * noise, x0)

    def timesteps(self, start: int | None = None) -> list[int]:
        """Step indices a sampler visits, in order: ``start-1, ..., 0``.

        ``start = S`` (the default) is the full chain from y_{S-1}; ``start = tau`` is the
        leapfrog sampler, whose initial sample stands at step tau - 1 and is denoised tau times.
        """
        start = self.num_steps if start is None else start
        if not 1 <= start <= self.num_steps:
            raise ValueError(f"start must lie in 1..{self.num_steps}")
        return list(range(start - 1, -1, -1))
