"""A hand-crafted reward: Social Distance Accuracy (SDA), the paper's Sec. 8.1 ablation after
Fan et al. (ICONIP 2023), as read in docs/sda.md.

Social groups come from the observed motion only. Two persons of one scene are linked when,
over all T_h observed steps, they stay within ``radius`` of each other and the offset between
them moves by at most ``drift`` (the integral of their velocity difference: they walk, or
stand, together). A group is a connected component of the links (single linkage), so a
triad in a V or a line is one group even when its outer members are farther apart. A sample
is rewarded, per step, for keeping each group mate at the distance observed between them:

    e_i(t) = mean over mates j of | |y_i(t) - y_j(t)| - dbar_ij |,   r_i(t) = 1 - e_i(t) / tol

with y the agents' samples of the same index k (one joint future of the scene) and dbar_ij
the mean observed distance. 1 is a perfectly kept formation, 0 an error of one tolerance, as
the diffusion score's r is 1 for a perfect sample and 0 for one as typical as the ground
truth. An agent without a group gets the constant 1 (nothing to keep): the same for all its
samples, so the reward expresses no preference among them. Nothing here reads the future.

Shapes: history [N, T_h, 2], scene [N], futures [K, N, T_f, 2] in absolute coordinates (the
data's units) -> [K, N, T_f].
"""

from __future__ import annotations

import torch

from trajpref.types import AGENT_PERSON

LONE_REWARD = 1.0
"""The reward of an agent with no group mate, at every step of every sample."""


def candidate_pairs(scene: torch.Tensor, agent_type: torch.Tensor | None = None):
    """Ordered pairs (i, j), i != j, of persons in the same scene: two [E] index tensors."""
    same = scene[:, None] == scene[None, :]  # [N, N]
    same.fill_diagonal_(False)
    if agent_type is not None:
        person = agent_type == AGENT_PERSON  # [N]
        same &= person[:, None] & person[None, :]
    i, j = same.nonzero(as_tuple=True)  # [E] each
    return i, j


def group_links(history: torch.Tensor, i: torch.Tensor, j: torch.Tensor, radius: float,
                drift: float) -> torch.Tensor:  # fmt: skip
    """Which of the pairs (i, j) walk together over the history: [E] bool."""
    offset = history[i] - history[j]  # [E, T_h, 2]
    near = offset.norm(dim=-1).amax(-1) <= radius  # [E]
    moved = (offset - offset[:, -1:]).norm(dim=-1).amax(-1)  # [E] the offset's drift
    return near & (moved <= drift)


def components(num_nodes: int, i: torch.Tensor, j: torch.Tensor) -> torch.Tensor:
    """Connected components of the symmetric edge list (i, j): [num_nodes] int64 labels, each
    the smallest node index of its component."""
    labels = torch.arange(num_nodes, device=i.device)  # [N]
    while True:  # min-label propagation; at most the largest component's diameter rounds
        new = labels.scatter_reduce(0, i, labels[j], reduce="amin")  # [N]
        if torch.equal(new, labels):
            return labels
        labels = new


def social_groups(history: torch.Tensor, scene: torch.Tensor, radius: float, drift: float,
                  agent_type: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
    """Each agent's group label [N] (the smallest agent index of its group; a lone agent is
    its own group). Only persons are grouped (the NBA ball stays alone)."""
    i, j = candidate_pairs(scene, agent_type)
    keep = group_links(history, i, j, radius, drift)  # [E]
    return components(history.shape[0], i[keep], j[keep])


def sda_reward(history: torch.Tensor, scene: torch.Tensor, futures: torch.Tensor,
               radius: float, drift: float, tolerance: float,
               agent_type: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
    """The per-step SDA reward r [K, N, T_f] of futures [K, N, T_f, 2]; higher is better."""
    n = history.shape[0]
    i, j = candidate_pairs(scene, agent_type)
    keep = group_links(history, i, j, radius, drift)  # [E]
    labels = components(n, i[keep], j[keep])  # [N]
    mates = labels[i] == labels[j]  # [E] same group, linked directly or through others
    i, j = i[mates], j[mates]  # [M] ordered mate pairs
    observed = (history[i] - history[j]).norm(dim=-1).mean(-1)  # [M] dbar_ij
    dist = (futures[:, i] - futures[:, j]).norm(dim=-1)  # [K, M, T_f]
    err = (dist - observed[None, :, None]).abs()  # [K, M, T_f]
    total = futures.new_zeros(futures.shape[:-1]).index_add_(1, i, err)  # [K, N, T_f]
    count = torch.bincount(i, minlength=n).clamp(min=1).to(futures.dtype)  # [N]
    return LONE_REWARD - total / count[None, :, None] / tolerance
