"""The social context encoder: histories of all agents of a scene -> one vector per agent."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from trajpref.data.transforms import backward_velocity, to_model_frame
from trajpref.models.layers import SocialAttention, mlp
from trajpref.types import Batch


@dataclass
class SceneFeatures:
    """Normalised history features of a batch, computed once and shared by the networks."""

    hist: torch.Tensor
    """[N, T_h, 4] positions relative to the last observation and backward velocities."""
    geom: torch.Tensor
    """[B, P, P, 4] j's last position and velocity relative to i's, padded per scene."""
    mask: torch.Tensor
    """[B, P] True where a slot holds an agent."""
    scene: torch.Tensor
    """[N] scene index per agent."""
    slot: torch.Tensor
    """[N] slot of each agent in its scene."""
    agent_type: torch.Tensor
    """[N] agent-type flags."""


def scene_features(batch: Batch, scale: float) -> SceneFeatures:
    """Features in units of ``scale`` (the data scale stored with each model)."""
    rel = to_model_frame(batch.history, batch, scale)  # [N, T_h, 2]
    vel = backward_velocity(batch.history) / scale  # [N, T_h, 2]
    slot, mask = batch.padded_index()
    b, p = mask.shape
    state = torch.cat([batch.origin / scale, vel[:, -1]], -1)  # [N, 4] last position, velocity
    padded = state.new_zeros(b, p, 4)
    padded[batch.scene, slot] = state
    geom = padded[:, None, :, :] - padded[:, :, None, :]  # [B, P(i), P(j), 4]: j relative to i
    return SceneFeatures(torch.cat([rel, vel], -1), geom, mask, batch.scene, slot,
                         batch.agent_type)  # fmt: skip


class SocialEncoder(nn.Module):
    """Per-agent MLP over the history, then attention across the agents of each scene."""

    def __init__(self, t_hist: int, hidden: int, layers: int, heads: int, num_types: int = 2):
        super().__init__()
        self.embed = mlp([t_hist * 4, hidden, hidden])
        self.type_embed = nn.Embedding(num_types, hidden)
        self.layers = nn.ModuleList(SocialAttention(hidden, heads) for _ in range(layers))
        self.norm = nn.LayerNorm(hidden)

    def forward(self, f: SceneFeatures) -> torch.Tensor:
        """-> context [N, H]."""
        h = self.embed(f.hist.flatten(1)) + self.type_embed(f.agent_type)  # [N, H]
        b, p = f.mask.shape
        padded = h.new_zeros(b, p, h.shape[-1])  # [B, P, H]
        padded[f.scene, f.slot] = h
        for layer in self.layers:
            padded = layer(padded, f.geom, f.mask)
        return self.norm(padded[f.scene, f.slot])  # [N, H]
