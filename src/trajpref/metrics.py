"""Displacement metrics for K sampled futures.

Per-agent metrics (minADE_K, minFDE_K) pick the best of K for each agent separately, and ADE
and FDE pick their own best; this is how the paper's tables and LED count. Joint (scene-level)
metrics pick one sample k per scene for all its agents.

Shapes: pred [K, N, T_f, 2], future [N, T_f, 2], scene [N] (scene index per agent, 0..B-1).
"""

from __future__ import annotations

import torch


def _check(pred: torch.Tensor, future: torch.Tensor) -> None:
    if pred.ndim != 4 or pred.shape[-1] != 2:
        raise ValueError(f"pred must be [K, N, T_f, 2], got {tuple(pred.shape)}")
    if future.shape != pred.shape[1:]:
        raise ValueError(
            f"future {tuple(future.shape)} does not match pred {tuple(pred.shape)} [K, N, T_f, 2]"
        )


def displacement(pred: torch.Tensor, future: torch.Tensor) -> torch.Tensor:
    """Euclidean error per step: [K, N, T_f, 2] x [N, T_f, 2] -> [K, N, T_f]."""
    _check(pred, future)
    return torch.linalg.vector_norm(pred - future[None], dim=-1)


def ade_fde(pred: torch.Tensor, future: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-sample, per-agent ADE and FDE: two [K, N] tensors."""
    err = displacement(pred, future)  # [K, N, T_f]
    return err.mean(-1), err[..., -1]


def min_ade_fde(pred: torch.Tensor, future: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-agent minADE_K and minFDE_K: two [N] tensors (each picks its own best k)."""
    ade, fde = ade_fde(pred, future)  # [K, N]
    return ade.min(0).values, fde.min(0).values


def scene_sum(values: torch.Tensor, scene: torch.Tensor, num_scenes: int) -> torch.Tensor:
    """Sum [..., N] over the agents of each scene: -> [..., B]."""
    out = values.new_zeros(*values.shape[:-1], num_scenes)
    return out.index_add_(values.ndim - 1, scene, values)


def joint_min_ade_fde(
    pred: torch.Tensor, future: torch.Tensor, scene: torch.Tensor, num_scenes: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Scene-level (joint) minADE_K and minFDE_K: two [B] tensors.

    For each scene, the mean over its agents of ADE (resp. FDE) of one sample k, minimised over
    k; all agents of a scene share that k.
    """
    ade, fde = ade_fde(pred, future)  # [K, N]
    sizes = torch.bincount(scene, minlength=num_scenes).to(ade.dtype)  # [B]
    if (sizes == 0).any():
        raise ValueError("every scene index in 0..num_scenes-1 must have at least one agent")
    scene_ade = scene_sum(ade, scene, num_scenes) / sizes  # [K, B]
    scene_fde = scene_sum(fde, scene, num_scenes) / sizes  # [K, B]
    return scene_ade.min(0).values, scene_fde.min(0).values


class MetricAccumulator:
    """Running sums of per-agent and joint minADE/minFDE over batches."""

    def __init__(self) -> None:
        self.sums = {"min_ade": 0.0, "min_fde": 0.0, "joint_min_ade": 0.0, "joint_min_fde": 0.0}
        self.agents = 0
        self.scenes = 0

    def update(
        self, pred: torch.Tensor, future: torch.Tensor, scene: torch.Tensor, num_scenes: int
    ) -> None:
        ade, fde = min_ade_fde(pred, future)  # [N]
        jade, jfde = joint_min_ade_fde(pred, future, scene, num_scenes)  # [B]
        self.sums["min_ade"] += float(ade.sum())
        self.sums["min_fde"] += float(fde.sum())
        self.sums["joint_min_ade"] += float(jade.sum())
        self.sums["joint_min_fde"] += float(jfde.sum())
        self.agents += int(ade.numel())
        self.scenes += int(num_scenes)

    def compute(self) -> dict[str, float | int]:
        if self.agents == 0:
            raise ValueError("no agents were evaluated")
        out: dict[str, float | int] = {
            "min_ade": self.sums["min_ade"] / self.agents,
            "min_fde": self.sums["min_fde"] / self.agents,
            "joint_min_ade": self.sums["joint_min_ade"] / self.scenes,
            "joint_min_fde": self.sums["joint_min_fde"] / self.scenes,
        }
        out["agents"] = self.agents
        out["scenes"] = self.scenes
        return out
