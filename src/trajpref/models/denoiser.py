"""The noise-prediction network eps_theta(y_s, s, context(X)) of the diffusion model D."""

from __future__ import annotations

import torch
from torch import nn

from trajpref.config import ModelConfig
from trajpref.models.encoder import SceneFeatures, SocialEncoder
from trajpref.models.layers import ResidualBlock, mlp, timestep_embedding


class Denoiser(nn.Module):
    """Predicts the noise in a noisy future y_s [..., N, T_f, 2] (normalised, relative to each
    agent's last observation) given the step s and the social context of the histories.

    A residual MLP over the T_f * 2 future numbers, conditioned by FiLM on the context and the
    step: cheap enough that the generator stage, which runs ~100 denoiser passes per agent and
    step, trains on a CPU.
    """

    def __init__(self, cfg: ModelConfig):
        super().__init__()
        self.cfg = cfg
        self.encoder = SocialEncoder(cfg.t_hist, cfg.hidden, cfg.encoder_layers, cfg.heads,
                                     roles=cfg.denoiser_roles)  # fmt: skip
        self.t_embed = mlp([cfg.hidden, cfg.hidden, cfg.hidden])
        cond = 2 * cfg.hidden
        self.inp = nn.Linear(cfg.t_fut * 2, cfg.denoiser_width)
        self.blocks = nn.ModuleList(
            ResidualBlock(cfg.denoiser_width, cond) for _ in range(cfg.denoiser_blocks)
        )
        self.out = nn.Sequential(nn.LayerNorm(cfg.denoiser_width),
                                 nn.Linear(cfg.denoiser_width, cfg.t_fut * 2))  # fmt: skip

    def context(self, features: SceneFeatures) -> torch.Tensor:
        """[N, H]: computed once per batch, reused across steps and samples. The denoiser
        never reads context-only agents (``ModelConfig.context_agents`` is the generator's)."""
        if features.targets is not None:
            raise ValueError("Denoiser.context: features with context-only agents are the "
                             "generator's; build the denoiser's without them")  # fmt: skip
        return self.encoder(features)

    def forward(self, y: torch.Tensor, s: torch.Tensor | int, context: torch.Tensor):
        """y [..., N, T_f, 2], s int / 0-d / [..., N] steps, context [N, H] -> eps like y.

        With one step for the whole tensor (sampling), the conditioning is computed once per
        agent and broadcast over the leading sample axes instead of once per sample.
        """
        s = torch.as_tensor(s, device=y.device)
        if s.ndim == 0:
            t_emb = self.t_embed(timestep_embedding(s, self.cfg.hidden))  # [H]
            c = torch.cat([context, t_emb.expand(context.shape[0], -1)], -1)  # [N, 2H]
        else:
            t_emb = self.t_embed(timestep_embedding(s, self.cfg.hidden))  # [..., N, H]
            c = torch.cat([context.expand(*s.shape, -1), t_emb], -1)  # [..., N, 2H]
        x = self.inp(y.flatten(-2))  # [..., N, W]
        for block in self.blocks:
            x = block(x, c)
        return self.out(x).view(y.shape)  # [..., N, T_f, 2]


class DenoiserShapes:
    """The window shape and device of an object that holds a ``denoiser`` (the predictor and
    the scorer): T_h and T_f are the denoiser's config's, the device its weights'."""

    denoiser: Denoiser

    @property
    def t_hist(self) -> int:
        """T_h, the observed steps per agent the denoiser was trained on."""
        return self.denoiser.cfg.t_hist

    @property
    def t_fut(self) -> int:
        """T_f, the future steps per sample the denoiser predicts and scores."""
        return self.denoiser.cfg.t_fut

    @property
    def device(self) -> torch.device:
        """Where the denoiser's weights are (and where prediction and scoring run)."""
        return next(self.denoiser.parameters()).device
