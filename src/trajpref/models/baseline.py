"""The constant-velocity baseline."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from trajpref.errors import ConfigError, DataError
from trajpref.models.predictor import as_integer
from trajpref.types import WINDOW, Batch


@dataclass
class ConstantVelocity:
    """Extrapolate each agent's last observed velocity (a backward difference).

    With K = 1 the prediction is deterministic. With K > 1, sample 0 is the same deterministic
    extrapolation and samples 1..K-1 perturb the velocity's heading by a Gaussian angle and its
    speed by a log-normal factor, both fixed per sample and agent. The default spreads were
    chosen by a grid search on the five ETH/UCY validation splits (see docs/baseline.md).
    """

    heading_std_deg: float = 15.0
    """Std of the heading perturbation of samples 1..K-1, in degrees."""
    speed_log_std: float = 0.4
    """Std of the log speed factor of samples 1..K-1."""
    horizon: int = WINDOW[1]
    """Future steps ``predict_scene`` / ``predict_scenes`` extrapolate, which have no future
    to take the length of (12, the published models' T_f); a batch's own future length
    otherwise (``evaluate`` on data cut into other windows)."""

    def __post_init__(self) -> None:
        if self.heading_std_deg < 0 or self.speed_log_std < 0:
            raise ConfigError("heading_std_deg and speed_log_std must be >= 0")
        if isinstance(self.horizon, bool) or not isinstance(self.horizon, int) or self.horizon < 1:
            raise ConfigError(f"horizon must be an integer >= 1 (future steps), got "
                              f"{self.horizon!r}")  # fmt: skip

    name = "cv"
    frame_interval = None
    """Seconds per step: None, as for a model whose checkpoint does not know it (the baseline
    extrapolates at whatever step its histories have; ``DiffusionPredictor.frame_interval``)."""
    units = None
    """Coordinate units: None, unknown (it works in any; ``DiffusionPredictor.units``)."""
    t_hist = None
    """Observed steps it needs: None, any number from 2 (``predict_scene`` takes any T_h)."""

    @torch.no_grad()
    def predict(
        self, batch: Batch, num_samples: int = 1, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Absolute future positions [K, N, T_f, 2]. The velocity is the last two observed
        positions' difference: a history of fewer than 2 steps is a ``DataError``."""
        count = as_integer(num_samples)  # numpy integers count too
        if count is None or count < 1:
            raise ConfigError(f"num_samples must be an integer >= 1, got {num_samples!r}")
        num_samples = count
        if batch.history.ndim != 3 or batch.history.shape[1] < 2:
            raise DataError(f"constant velocity needs at least 2 observed steps (its velocity "
                            f"is the last two positions' difference): history [N, T_h, 2] "
                            f"with T_h >= 2, got {list(batch.history.shape)}")  # fmt: skip
        t_fut = batch.future.shape[1]
        vel = batch.history[:, -1] - batch.history[:, -2]  # [N, 2]
        vel = vel[None].expand(num_samples, -1, -1).clone()  # [K, N, 2]
        if num_samples > 1:
            shape = (num_samples - 1, batch.num_agents)
            angle = torch.randn(shape, generator=generator, dtype=torch.float32) * math.radians(
                self.heading_std_deg
            )
            speed = torch.exp(
                torch.randn(shape, generator=generator, dtype=torch.float32) * self.speed_log_std
            )
            angle, speed = angle.to(vel), speed.to(vel)  # [K-1, N]
            cos, sin = torch.cos(angle), torch.sin(angle)
            vx, vy = vel[1:, :, 0], vel[1:, :, 1]  # [K-1, N]
            vel[1:] = torch.stack([cos * vx - sin * vy, sin * vx + cos * vy], -1) * speed[..., None]
        steps = torch.arange(1, t_fut + 1, dtype=vel.dtype, device=vel.device)  # [T_f]
        return batch.origin[None, :, None, :] + vel[:, :, None, :] * steps[:, None]  # [K,N,T_f,2]
