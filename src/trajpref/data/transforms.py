"""Coordinate frames, leak-free velocities and training augmentation."""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from trajpref.types import Batch


def backward_velocity(positions: torch.Tensor) -> torch.Tensor:
    """Backward differences v_t = x_t - x_{t-1} with v_0 = 0, so no feature sees the future.

    positions [..., T, 2] -> velocities [..., T, 2] (per frame, in the data's units).
    """
    vel = torch.zeros_like(positions)
    vel[..., 1:, :] = positions[..., 1:, :] - positions[..., :-1, :]
    return vel


def observed_pace(history: torch.Tensor, scale: float = 1.0) -> torch.Tensor:
    """Each agent's observed displacement per step, first to last observed position, divided
    by ``scale``: history [..., N, T_h, 2] -> [..., N]. The one measure of an agent's pace
    that the generator's speed clamp (``model.max_speed``), the selection's pace gate
    (``SelectionConfig.trust_speed``) and the studies that set them all use (model units when
    ``scale`` is the model's data scale)."""
    if history.shape[-2] < 2:
        raise ValueError(f"a pace needs at least two observed steps, got {history.shape[-2]}")
    moved = history[..., -1, :] - history[..., 0, :]  # [..., N, 2]
    return moved.norm(dim=-1) / (history.shape[-2] - 1) / scale  # [..., N]


def to_model_frame(positions: torch.Tensor, batch: Batch, scale: float) -> torch.Tensor:
    """The networks' frame: relative to each agent's last observed position, divided by the
    data scale. Absolute positions [..., N, T, 2] -> same shape."""
    return (positions - batch.origin[:, None, :]) / scale


def from_model_frame(y: torch.Tensor, batch: Batch, scale: float) -> torch.Tensor:
    """Inverse of ``to_model_frame``: [..., N, T, 2] in the networks' frame -> absolute."""
    return y * scale + batch.origin[:, None, :]


def scene_centroids(batch: Batch) -> torch.Tensor:
    """Each scene's mean last observed position: [B, 2]."""
    sizes = batch.scene_sizes().clamp(min=1).to(batch.history.dtype)  # [B]
    total = batch.history.new_zeros(batch.num_scenes, 2)  # [B, 2]
    return total.index_add_(0, batch.scene, batch.origin) / sizes[:, None]


def augment(
    batch: Batch,
    generator: torch.Generator | None = None,
    rotate: bool = True,
    flip: bool = False,
    scale_range: tuple[float, float] | None = None,
    reverse: bool = False,
    history_noise: float = 0.0,
    drop_agents: float = 0.0,
    reverse_context: bool = False,
) -> Batch:
    """Random rigid transform per scene (all agents of a scene move together).

    Each scene is rotated by a uniform angle about its mean last observed position, optionally
    mirrored (x -> -x) with probability 1/2, and optionally scaled by a factor drawn uniformly
    from ``scale_range``. Relative geometry between agents is kept (up to the scale). With
    ``reverse`` each scene is also played backwards in time with probability 1/2
    (``reverse_time``); its coin is drawn after the others, so they do not depend on it.
    With ``history_noise`` > 0, Gaussian noise of that std is added to every observed position
    but the last, after the scene's transform. With ``drop_agents`` > 0, agents are then left
    out at that rate (``drop_agents``). Context-only agents (``Batch.context``) move with their
    scene; a reversed scene has none, or with ``reverse_context`` those of the reversed window
    (``Batch.context_reverse``); their jitter and drop are drawn last of all, so the draws for
    the batch's agents do not depend on them. The batch handed back has no
    ``context_reverse``.
    """
    device = batch.history.device
    b = batch.num_scenes
    angle = (torch.rand(b, generator=generator) * 2 * math.pi if rotate else torch.zeros(b)).to(
        device
    )  # [B]
    cos, sin = torch.cos(angle), torch.sin(angle)
    rot = torch.stack([torch.stack([cos, -sin], -1), torch.stack([sin, cos], -1)], -2)  # [B,2,2]
    if flip:
        mirror = (torch.rand(b, generator=generator) < 0.5).to(device)  # [B]
        sign = torch.where(mirror, -1.0, 1.0)  # [B]
        rot = rot * torch.stack([sign, torch.ones_like(sign)], -1)[:, None, :]  # scale x column
    if scale_range is not None:
        lo, hi = scale_range
        factor = (lo + (hi - lo) * torch.rand(b, generator=generator)).to(device)  # [B]
        rot = rot * factor[:, None, None]
    if reverse:
        backwards = torch.rand(b, generator=generator) < 0.5  # [B]
        batch = reverse_time(batch, backwards.to(device), keep_context=reverse_context)
    else:
        batch = replace(batch, context_reverse=None, context_reverse_scene=None)
    batch = transform_scenes(batch, rot)
    if history_noise > 0:
        n, t_h, _ = batch.history.shape
        noise = torch.randn(n, t_h - 1, 2, generator=generator) * history_noise  # [N, T_h-1, 2]
        jittered = batch.history[:, :-1] + noise.to(batch.history)  # [N, T_h - 1, 2]
        batch = replace(batch, history=torch.cat([jittered, batch.history[:, -1:]], 1))
    if drop_agents > 0:
        batch = drop_agents_at_random(batch, drop_agents, generator)
    if batch.context is not None:  # drawn after everything else, so the draws above stay
        m, t_h = batch.num_context, batch.context.shape[1]
        if history_noise > 0:
            noise = torch.randn(m, t_h - 1, 2, generator=generator) * history_noise
            jittered = batch.context[:, :-1] + noise.to(batch.context)  # [M, T_h - 1, 2]
            batch = replace(batch, context=torch.cat([jittered, batch.context[:, -1:]], 1))
        if drop_agents > 0:  # context-only agents left out at the same rate
            keep = (torch.rand(m, generator=generator) >= drop_agents).nonzero()[:, 0]  # [M']
            batch = _context_subset(batch, keep.to(batch.scene.device))
    return batch


def drop_agents_at_random(
    batch: Batch, p: float, generator: torch.Generator | None = None
) -> Batch:
    """The batch without a random subset of its agents: each agent is left out with
    probability ``p`` (one uniform draw per agent, on the CPU), as a target and as everyone's
    neighbour. A scene whose agents were all drawn keeps its first one, so every scene keeps
    at least one agent and the scene indices stay valid. Context-only agents are kept
    (``augment`` drops them at the same rate after its other draws)."""
    if not 0.0 <= p < 1.0:
        raise ValueError(f"drop_agents needs a rate in [0, 1), got {p}")
    n = batch.num_agents
    keep = (torch.rand(n, generator=generator) >= p).to(batch.scene.device)  # [N]
    sizes = batch.scene_sizes()  # [B]
    firsts = torch.cumsum(sizes, 0) - sizes  # [B] index of each scene's first agent
    kept = torch.zeros_like(sizes).index_add_(0, batch.scene, keep.long())  # [B]
    empty = (kept == 0) & (sizes > 0)  # [B] scenes that would lose every agent
    keep[firsts[empty]] = True
    idx = keep.nonzero().squeeze(1)  # [N'] in order, so scenes stay non-decreasing
    return replace(batch, history=batch.history[idx], future=batch.future[idx],
                   scene=batch.scene[idx], agent_type=batch.agent_type[idx])  # fmt: skip


def seen_run(context: torch.Tensor) -> torch.Tensor:
    """[M] how many frames each row of ``context`` [M, T_h, 2] (NaN where not seen) was seen
    in without a break up to its last frame: what ``observed_context`` keeps a row by."""
    seen = torch.isfinite(context).all(-1)  # [M, T_h]
    return seen.flip(1).to(torch.int64).cumprod(1).sum(1)  # [M]


def observed_context(batch: Batch, min_frames: int) -> Batch:
    """The batch with only the context-only agents seen in at least the last ``min_frames``
    history frames without a break, their earlier frames (not seen, or seen before the break)
    set to the first position of that run: an agent that entered the view holds still until
    it did. With ``min_frames`` = T_h only agents seen over the whole history are kept, as
    they are."""
    if batch.context is None:
        return batch
    t_h = batch.context.shape[1]
    if not 1 <= min_frames <= t_h:
        raise ValueError(f"min_frames must lie in 1..{t_h}, got {min_frames}")
    run = seen_run(batch.context)  # [M]
    keep = (run >= min_frames).nonzero()[:, 0]  # [M']
    batch = _context_subset(batch, keep)
    if batch.context is None or min_frames == t_h:
        return batch
    run = run[keep]  # [M']
    first = t_h - run  # [M'] index of the run's first frame
    steps = torch.arange(t_h, device=run.device)  # [T_h]
    src = torch.maximum(steps[None, :], first[:, None])  # [M', T_h] frame each one copies
    filled = batch.context.gather(1, src[..., None].expand(-1, -1, 2))  # [M', T_h, 2]
    return replace(batch, context=filled)


def _context_subset(batch: Batch, idx: torch.Tensor) -> Batch:
    """The batch with only the context-only agents ``idx`` [M'] (increasing) kept."""
    if len(idx) == 0:
        return batch.without_context()
    return replace(batch, context=batch.context[idx], context_scene=batch.context_scene[idx])


def reverse_time(batch: Batch, scenes: torch.Tensor, keep_context: bool = False) -> Batch:
    """The batch with the scenes flagged in ``scenes`` [B] bool played backwards in time.

    An agent's window of T_h + T_f positions is reversed and cut again at T_h: its new history
    is its last T_h positions in reverse order, its new future the first T_f in reverse order.
    Agents of unflagged scenes are unchanged. A flagged scene loses its context-only agents,
    or with ``keep_context`` takes those of the reversed window (``Batch.context_reverse``)
    in their place. The batch handed back has no ``context_reverse``, so applying it twice
    gives the batch back up to context-only agents.
    """
    if scenes.shape != (batch.num_scenes,):
        raise ValueError(f"reverse_time needs one flag per scene ({batch.num_scenes}), "
                         f"got shape {tuple(scenes.shape)}")  # fmt: skip
    t_h = batch.history.shape[1]
    window = torch.cat([batch.history, batch.future], dim=1)  # [N, T_h + T_f, 2]
    flagged = scenes[batch.scene][:, None, None]  # [N, 1, 1]
    window = torch.where(flagged, window.flip(1), window)  # [N, T_h + T_f, 2]
    rev, rev_scene = batch.context_reverse, batch.context_reverse_scene
    batch = replace(batch, history=window[:, :t_h], future=window[:, t_h:],
                    context_reverse=None, context_reverse_scene=None)  # fmt: skip
    if batch.context is not None:
        batch = _context_subset(batch, (~scenes[batch.context_scene]).nonzero()[:, 0])
    if keep_context and rev is not None:
        take = scenes[rev_scene].nonzero()[:, 0]  # [M'] those of flagged scenes
        parts = [(rev[take], rev_scene[take])]
        if batch.context is not None:
            parts.append((batch.context, batch.context_scene))
        ctx = torch.cat([c for c, _ in parts])  # [M, T_h, 2]
        ctx_scene = torch.cat([i for _, i in parts])  # [M]
        order = torch.sort(ctx_scene, stable=True).indices  # [M] scene order kept
        if len(order):
            batch = replace(batch, context=ctx[order], context_scene=ctx_scene[order])
    return batch


def transform_scenes(batch: Batch, mats: torch.Tensor) -> Batch:
    """Apply one linear map per scene, mats [B, 2, 2], about the scene's centroid (the
    targets' mean last observed position; context-only agents move with their scene)."""
    out = replace(batch, history=transform_positions(batch.history, batch, mats),
                  future=transform_positions(batch.future, batch, mats))  # fmt: skip
    if batch.context is not None:
        c = scene_centroids(batch)[batch.context_scene][:, None, :]  # [M, 1, 2]
        r = mats[batch.context_scene]  # [M, 2, 2]
        out = replace(out, context=(batch.context - c) @ r.transpose(-1, -2) + c)
    return out


def transform_positions(positions: torch.Tensor, batch: Batch, mats: torch.Tensor) -> torch.Tensor:
    """Positions [..., N, T, 2] of the batch's agents mapped by their scene's mats [B, 2, 2]
    about the scene's mean last observed position (as ``transform_scenes`` maps the batch)."""
    c = scene_centroids(batch)[batch.scene][:, None, :]  # [N, 1, 2]
    r = mats[batch.scene]  # [N, 2, 2]
    return (positions - c) @ r.transpose(-1, -2) + c


def scene_speeds(batch: Batch, steps: int = 4) -> torch.Tensor:
    """Each scene's typical observed speed [B], in data units per step: the median over its
    agents of their mean step length over the last ``steps`` observed steps."""
    hist = batch.history[:, -(steps + 1) :]  # [N, steps+1, 2]
    speed = (hist[:, 1:] - hist[:, :-1]).norm(dim=-1).mean(-1)  # [N]
    out = speed.new_zeros(batch.num_scenes)
    for b in range(batch.num_scenes):
        out[b] = speed[batch.scene == b].median()
    return out


def speed_normaliser(batch: Batch, speed_ref: float) -> torch.Tensor:
    """Per-scene maps [B, 2, 2] that shrink a scene moving faster than ``speed_ref`` (data
    units per step) to that speed, and leave slower scenes as they are (factor <= 1)."""
    factor = (speed_ref / scene_speeds(batch).clamp(min=1e-6)).clamp(max=1.0)  # [B]
    eye = torch.eye(2, dtype=batch.history.dtype, device=batch.history.device)
    return factor[:, None, None] * eye  # [B, 2, 2]
