"""A trained diffusion predictor: denoiser (+ generator) + schedule, behind ``predict``."""

from __future__ import annotations

import torch
from torch import nn

from trajpref.config import DiffusionConfig, ModelConfig
from trajpref.diffusion.samplers import denoise, sample_full
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import ConfigError
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import SceneFeatures, scene_features
from trajpref.models.generator import Generator
from trajpref.types import Batch

SAMPLERS = ("leapfrog", "full")


class DiffusionPredictor(nn.Module):
    """Samples futures with the leapfrog sampler (generator + tau denoising steps) or the full
    S-step sampler from noise, both with the same denoiser.

    ``scale`` is the data scale: networks see coordinates divided by it.
    """

    def __init__(
        self,
        model_cfg: ModelConfig,
        diffusion_cfg: DiffusionConfig,
        scale: float,
        denoiser: Denoiser,
        generator: Generator | None = None,
        tau: int = 5,
        sampler: str = "leapfrog",
    ):
        super().__init__()
        if sampler not in SAMPLERS:
            raise ConfigError(f"unknown sampler {sampler!r}; choose {' or '.join(SAMPLERS)}")
        if sampler == "leapfrog" and generator is None:
            raise ConfigError("the leapfrog sampler needs a generator checkpoint")
        self.model_cfg = model_cfg
        self.schedule = DDPMSchedule(**vars(diffusion_cfg))
        self.scale = float(scale)
        self.denoiser = denoiser
        self.generator = generator
        self.tau = tau
        self.sampler = sampler
        self.name = f"diffusion-{sampler}"

    @property
    def device(self) -> torch.device:
        return next(self.denoiser.parameters()).device

    def features(self, batch: Batch) -> SceneFeatures:
        return scene_features(batch, self.scale)

    def eps_fn(self, context: torch.Tensor):
        return lambda y, s: self.denoiser(y, s, context)

    def sample_normalised(
        self, batch: Batch, num_samples: int, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """[K, N, T_f, 2] samples in normalised units, relative to each last observation."""
        f = self.features(batch)
        context = self.denoiser.context(f)  # [N, H]
        if self.sampler == "full":
            shape = (num_samples, batch.num_agents, self.model_cfg.t_fut, 2)
            return sample_full(self.schedule, self.eps_fn(context), shape, generator,
                               batch.history.device)  # fmt: skip
        assert self.generator is not None
        if num_samples > self.generator.samples:
            raise ConfigError(
                f"this generator emits K = {self.generator.samples} samples; "
                f"asked for {num_samples} (use --sampler full for more)"
            )
        y_tau = self.generator(f).initial_sample()[:num_samples]  # [K, N, T_f, 2]
        return denoise(self.schedule, self.eps_fn(context), y_tau, self.tau, generator)

    @torch.no_grad()
    def predict(
        self, batch: Batch, num_samples: int = 20, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Absolute future positions [K, N, T_f, 2]."""
        rel = self.sample_normalised(batch, num_samples, generator)  # [K, N, T_f, 2]
        return rel * self.scale + batch.origin[None, :, None, :]
