"""The critic V_psi: a 2-layer MLP value head on the policy's social encoding (Sec. 5)."""

from __future__ import annotations

import torch
from torch import nn

from trajpref.models.layers import mlp


class Critic(nn.Module):
    """V(X, Y)[k, n, t]: the value of each future step of each sample (Eq. 11)."""

    def __init__(self, hidden: int, t_fut: int, width: int = 256):
        super().__init__()
        self.head = mlp([hidden + t_fut * 2, width, t_fut])

    def forward(self, context: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """context [N, H], y [K, N, T_f, 2] (normalised) -> V [K, N, T_f]."""
        k = y.shape[0]
        x = torch.cat([context.expand(k, -1, -1), y.flatten(-2)], -1)  # [K, N, H + 2T_f]
        return self.head(x)
