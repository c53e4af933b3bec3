"""The leapfrog generator G (Eq. 1): mu, sigma, S <- G(X); Y^tau = mu + sigma * S."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from trajpref.config import ModelConfig
from trajpref.models.encoder import (
    SceneFeatures,
    SocialEncoder,
    agent_site,
    heading_rotation,
    rotate_features,
    scale_features,
    speed_factor,
)
from trajpref.models.layers import SetAttention, mlp


@dataclass
class GeneratorOutput:
    """Distribution parameters in normalised units, relative to each agent's last position."""

    mean: torch.Tensor
    """mu [N, T_f, 2]."""
    log_sigma: torch.Tensor
    """log sigma [K, N]: one scale per sample and agent (the paper's sigma in R^{K x P})."""
    shifts: torch.Tensor
    """S [K, N, T_f, 2], normalised to unit spread over the K samples of each agent."""
    context: torch.Tensor
    """[N, H] the social encoding (the critic's value head shares it)."""

    def initial_sample(self) -> torch.Tensor:
        """Y^tau = mu + sigma * S: [K, N, T_f, 2]."""
        return self.mean[None] + self.log_sigma.exp()[..., None, None] * self.shifts


def time_projection(t_fut: int, rank: int) -> torch.Tensor:
    """The [T_f, T_f] orthogonal projection onto the polynomials t, ..., t^rank of the future
    steps t = 1..T_f (no constant: a path starts at the last observed position). Rank 0 gives
    the identity (no projection)."""
    if rank == 0:
        return torch.eye(t_fut)
    t = torch.arange(1, t_fut + 1, dtype=torch.float64) / t_fut  # [T_f], scaled for conditioning
    powers = torch.stack([t**j for j in range(1, rank + 1)], 1)  # [T_f, r]
    basis, _ = torch.linalg.qr(powers)  # [T_f, r], orthonormal columns
    return (basis @ basis.T).float()  # [T_f, T_f]


def velocity_path(hist: torch.Tensor, t_fut: int) -> torch.Tensor:
    """The constant-velocity path v t, t = 1..T_f, of each agent from its last observed
    velocity v (the backward difference ``hist[:, -1, 2:]``), relative to its last position:
    hist [N, T_h, 4] (the model's history features: positions, then velocities) ->
    [N, T_f, 2]. Linear in ``hist``, so it turns and scales with the agent's frame."""
    steps = torch.arange(1, t_fut + 1, dtype=hist.dtype, device=hist.device)  # [T_f]
    return hist[:, -1, None, 2:] * steps[None, :, None]  # [N, T_f, 2]


class Generator(nn.Module):
    """Social encoder + heads for the mean, the K scales and the K shifts (LED's initializer)."""

    def __init__(self, cfg: ModelConfig):
        super().__init__()
        self.cfg = cfg
        self.samples = samples = cfg.samples
        h, w, tf = cfg.generator_encoder_width, cfg.generator_width, cfg.t_fut
        layers = cfg.generator_encoder_layers if cfg.generator_social else 0  # 0: own history only
        self.encoder = SocialEncoder(cfg.t_hist, h, layers, cfg.heads,
                                     temporal=cfg.history_encoder == "temporal",
                                     site=cfg.scene_position,
                                     pair_distance=cfg.pair_distance,
                                     roles=cfg.agent_roles,
                                     dropout=cfg.encoder_dropout)  # fmt: skip
        p = cfg.generator_dropout
        self.dropout = nn.Dropout(p) if p > 0 else nn.Identity()
        self.mean_head = mlp([h, w, w, tf * 2], dropout=p)
        if cfg.query_layers:  # K tokens that attend to each other, one shared read-out
            qw = cfg.query_width
            self.query_in = nn.Linear(h + tf * 2, qw)
            self.queries = nn.Parameter(torch.randn(samples, qw))  # [K, W_q]
            self.query_blocks = nn.Sequential(
                *(SetAttention(qw, cfg.heads) for _ in range(cfg.query_layers))
            )
            self.query_out = nn.Sequential(nn.LayerNorm(qw), nn.Linear(qw, tf * 2 + 1))
        else:
            self.sigma_head = mlp([h + tf * 2, w, samples], dropout=p)
            self.shift_head = mlp([h + tf * 2, w, w, samples * tf * 2], dropout=p)
        for name, value in self.config_buffers().items():  # no part of the state dict
            self.register_buffer(name, value, persistent=False)

    def config_buffers(self) -> dict[str, torch.Tensor]:
        """The buffers computed from the config, not stored in the state dict: the [T_f, T_f]
        ``time_projection`` onto smooth paths (the identity when ``future_rank`` is 0).
        Loading (``checkpoint.built_for_loading``), which builds the module on the meta
        device, sets them again from this."""
        return {"time_projection": time_projection(self.cfg.t_fut, self.cfg.future_rank)}

    def forward(self, features: SceneFeatures) -> GeneratorOutput:
        rot = None
        if self.cfg.agent_frame == "heading":
            rot = heading_rotation(features.hist)  # [N, 2, 2]
        # [N, 4] place and heading in the scene's coordinates, before any frame change
        site = agent_site(features, rot) if self.cfg.scene_position else None
        if rot is not None:
            features = rotate_features(features, rot)
        c = None
        if self.cfg.max_speed > 0:
            c = speed_factor(features.hist, self.cfg.max_speed)  # [N]
            features = scale_features(features, c)
        ctx = self.encoder(features, site)  # [N, H], or [N + M, H] with context-only agents
        if features.targets is not None:  # only the batch's own agents are predicted
            n = features.targets
            ctx = ctx[:n]  # [N, H]
            rot = None if rot is None else rot[:n]  # [N, 2, 2]
            c = None if c is None else c[:n]  # [N]
        n, tf = ctx.shape[0], self.cfg.t_fut
        dropped = self.dropout(ctx)  # [N, H]; ctx itself when not training
        mean = self.mean_head(dropped).view(n, tf, 2)  # [N, T_f, 2]
        if self.cfg.future_rank:
            mean = self.time_projection @ mean  # [N, T_f, 2]
        if self.cfg.mean_prior == "velocity":  # the head predicts the departure from v t
            mean = mean + velocity_path(features.hist[:n], tf)  # [N, T_f, 2]
        z = torch.cat([dropped, mean.detach().flatten(1)], -1)  # [N, H + 2T_f]
        log_sigma, raw = self._heads(z)  # [K, N], [K, N, T_f, 2]
        if self.cfg.max_log_sigma is not None:  # a sampling setting (ModelConfig.max_log_sigma)
            log_sigma = log_sigma.clamp(max=self.cfg.max_log_sigma)  # [K, N]
        if self.cfg.future_rank:
            raw = self.time_projection @ raw  # [K, N, T_f, 2]
        raw = raw - raw.mean(0, keepdim=True)
        spread = raw.pow(2).mean(dim=(0, 2, 3), keepdim=True).add(1e-6).sqrt()  # [1, N, 1, 1]
        shifts = raw / spread  # [K, N, T_f, 2]
        if c is not None:  # back to the agent's own speed
            mean = mean * c[:, None, None]  # [N, T_f, 2]
            log_sigma = log_sigma + c.log()[None]  # [K, N]
        if self.cfg.spread_scale != 1.0:  # a sampling setting (ModelConfig.spread_scale)
            log_sigma = log_sigma + math.log(self.cfg.spread_scale)  # [K, N]
        if rot is not None:  # back to the scene frame, where the denoiser works
            mean = mean @ rot  # [N, T_f, 2]
            shifts = shifts @ rot[None]  # [K, N, T_f, 2]
        return GeneratorOutput(mean, log_sigma, shifts, ctx)

    def _heads(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """z [N, H + 2T_f] -> log sigma [K, N] and the raw (uncentred) shifts [K, N, T_f, 2]."""
        n, tf, k = z.shape[0], self.cfg.t_fut, self.samples
        if not self.cfg.query_layers:
            log_sigma = self.sigma_head(z).T  # [K, N]
            return log_sigma, self.shift_head(z).view(n, k, tf, 2).transpose(0, 1)
        # dropout once, on the shared projection ([N, W_q]): masks on the [N, K, 4 W_q]
        # hidden layers inside the blocks cost more than the rest of a training step
        tokens = self.dropout(self.query_in(z))[:, None] + self.queries  # [N, K, W_q]
        out = self.query_out(self.query_blocks(tokens))  # [N, K, 2T_f + 1]
        raw = out[..., :-1].reshape(n, k, tf, 2).transpose(0, 1)  # [K, N, T_f, 2]
        return out[..., -1].T, raw  # [K, N], [K, N, T_f, 2]
