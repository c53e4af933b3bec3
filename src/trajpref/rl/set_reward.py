"""A set-aware reward: each sample's marginal gain in a quality-weighted determinantal point
process (DPP) over the K samples of an agent.

With endpoint similarity S_ij = exp(-|e_i - e_j|^2 / (b h^2)) (h^2 the median squared
distance between the agent's endpoints) and quality weights w_i = exp(alpha z_i / 2) (z the
sample's score standardised over the K), the kernel L = diag(w) S diag(w) + eps I scores a set
by log det L: high when its samples are both plausible and far apart, -> -inf for copies of
one sample. A sample's marginal gain log det L - log det L_{-i} = -log (L^{-1})_ii rewards it
for what it adds to the set that the others do not already cover. Ground-truth-free given the
quality (the diffusion score of the samples).

Shapes: ends [K, N, 2], quality [K, N] (higher is better) -> [K, N] or [N].
"""

from __future__ import annotations

import torch

JITTER = 1e-4
"""Added to L's diagonal: keeps L invertible when samples coincide."""


def dpp_kernel(ends: torch.Tensor, quality: torch.Tensor, bandwidth: float = 0.5,
               alpha: float = 1.0) -> torch.Tensor:  # fmt: skip
    """L [N, K, K] of each agent's K samples."""
    e = ends.transpose(0, 1)  # [N, K, 2]
    d2 = torch.cdist(e, e).pow(2)  # [N, K, K]
    h2 = d2.flatten(1).median(1).values.clamp(min=1e-12)  # [N]
    sim = torch.exp(-d2 / (bandwidth * h2[:, None, None]))  # [N, K, K]
    z = (quality - quality.mean(0)) / quality.std(0).clamp(min=1e-12)  # [K, N]
    w = torch.exp(alpha * z.T / 2)  # [N, K]
    eye = torch.eye(ends.shape[0], dtype=ends.dtype, device=ends.device)
    return w[:, :, None] * sim * w[:, None, :] + JITTER * eye  # [N, K, K]


def set_log_det(ends: torch.Tensor, quality: torch.Tensor, bandwidth: float = 0.5,
                alpha: float = 1.0) -> torch.Tensor:  # fmt: skip
    """log det L per agent: [N]. Higher is a better set."""
    return torch.linalg.slogdet(dpp_kernel(ends, quality, bandwidth, alpha)).logabsdet


def marginal_gains(ends: torch.Tensor, quality: torch.Tensor, bandwidth: float = 0.5,
                   alpha: float = 1.0) -> torch.Tensor:  # fmt: skip
    """Each sample's marginal gain -log (L^{-1})_ii: [K, N]."""
    inv = torch.linalg.inv(dpp_kernel(ends, quality, bandwidth, alpha))  # [N, K, K]
    return -torch.log(torch.diagonal(inv, dim1=1, dim2=2).clamp(min=1e-12)).T  # [K, N]
