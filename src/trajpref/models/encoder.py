"""The social context encoder: histories of all agents of a scene -> one vector per agent."""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass

import torch
from torch import nn

from trajpref.data.transforms import (
    backward_velocity,
    observed_context,
    observed_pace,
    to_model_frame,
)
from trajpref.errors import ConfigError, DataError
from trajpref.models.layers import SocialAttention, mlp
from trajpref.types import AGENT_PERSON, Batch


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
    position: torch.Tensor
    """[N, 2] each agent's last observed position in the scene's own coordinates (not
    relative to anything), divided by the scale: only ``ModelConfig.scene_position`` reads it."""
    targets: int | None = None
    """With context-only agents (``scene_features(..., context=True)``): the first
    ``targets`` rows are the batch's agents, the rows after them its context-only agents, and
    every per-agent field above has N + M rows. None: every row is one of the batch's agents."""
    pairs: torch.Tensor | None = None
    """[B, P(i), P(j)] True where agent i may attend to agent j under a neighbour radius
    (``ModelConfig.neighbour_radius``): their last observed positions lie within it (a slot
    always pairs with itself; padding is hidden by ``mask`` as well). Computed from the
    untransformed positions, so ``rotate_features`` and ``scale_features`` carry it through
    as it is. None: every pair of a scene (no radius)."""


def scene_features(batch: Batch, scale: float, context: bool = False,
                   context_frames: int | None = None,
                   radius: float | None = None) -> SceneFeatures:  # fmt: skip
    """Features in units of ``scale`` (the data scale stored with each model). With
    ``context`` the batch's context-only agents (``Batch.context``) seen in at least the last
    ``context_frames`` history frames (None: all of them; ``transforms.observed_context``)
    join their scenes after the batch's agents (``SceneFeatures.targets``); a batch without
    any gives the same features as without ``context``. ``radius`` (data units, as the
    batch's coordinates; None: off) limits who attends to whom to the pairs within it
    (``SceneFeatures.pairs``, ``ModelConfig.neighbour_radius``)."""
    if context and batch.num_context:
        frames = batch.history.shape[1] if context_frames is None else context_frames
        batch = observed_context(batch, frames)
    if context and batch.num_context:
        return _features_with_context(batch, scale, radius)
    rel = to_model_frame(batch.history, batch, scale)  # [N, T_h, 2]
    vel = backward_velocity(batch.history) / scale  # [N, T_h, 2]
    slot, mask = batch.padded_index()
    position = batch.origin / scale  # [N, 2]
    geom = _pair_geometry(position, vel[:, -1], batch.scene, slot, mask)  # [B, P, P, 4]
    return SceneFeatures(torch.cat([rel, vel], -1), geom, mask, batch.scene, slot,
                         batch.agent_type, position,
                         pairs=_within(geom, radius, scale))  # fmt: skip


def check_neighbour_radius(value, name: str = "neighbour_radius") -> float | None:
    """``value`` as a float distance > 0 (an int or a numpy number counts), or None (off);
    ``ConfigError`` for anything else (a bool, a string, a tensor, NaN, inf, zero or less)."""
    if value is None:
        return None
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)  # numpy's count
    radius = float(value) if number else math.nan
    if not (math.isfinite(radius) and radius > 0):
        raise ConfigError(f"{name} must be None (every pair of a scene attends) or a finite "
                          f"distance > 0 in the data's units, got {value!r}")  # fmt: skip
    return radius


def _within(geom: torch.Tensor, radius: float | None, scale: float) -> torch.Tensor | None:
    """[B, P(i), P(j)] True where j's last position lies within ``radius`` (data units) of
    i's, from the pair geometry [B, P, P, 4] in model units (before any frame change); None
    when ``radius`` is None. A slot is at distance 0 from itself, so it always pairs with
    itself (padded slots included: no row of the attention is left empty)."""
    if radius is None:
        return None
    limit = radius / scale  # model units
    return geom[..., :2].square().sum(-1) <= limit * limit  # [B, P(i), P(j)]


def _pair_geometry(position, velocity, scene, slot, mask) -> torch.Tensor:
    """[B, P(i), P(j), 4] j's last position and velocity [R, 2] relative to i's, padded."""
    b, p = mask.shape
    state = torch.cat([position, velocity], -1)  # [R, 4] last position, velocity
    padded = state.new_zeros(b, p, 4)
    padded[scene, slot] = state
    return padded[:, None, :, :] - padded[:, :, None, :]  # [B, P(i), P(j), 4]: j relative to i


def _features_with_context(batch: Batch, scale: float, radius: float | None) -> SceneFeatures:
    """``scene_features`` over the batch's N agents followed by its M context-only agents."""
    n, m, b = batch.num_agents, batch.num_context, batch.num_scenes
    hist = torch.cat([batch.history, batch.context], 0)  # [N + M, T_h, 2]
    rel = (hist - hist[:, -1:]) / scale  # [N + M, T_h, 2]
    vel = backward_velocity(hist) / scale  # [N + M, T_h, 2]
    sizes = batch.scene_sizes()  # [B]
    extra = torch.bincount(batch.context_scene, minlength=b)  # [B]
    slot_t, _ = batch.padded_index()  # [N]
    ctx_start = torch.cumsum(extra, 0) - extra  # [B]
    arange = torch.arange(m, device=hist.device)
    slot_c = arange - ctx_start[batch.context_scene] + sizes[batch.context_scene]  # [M]
    slot = torch.cat([slot_t, slot_c])  # [N + M]
    scene = torch.cat([batch.scene, batch.context_scene])  # [N + M]
    total = sizes + extra  # [B]
    p_max = int(total.max().item())
    mask = torch.arange(p_max, device=hist.device)[None, :] < total[:, None]  # [B, P]
    types = torch.cat([batch.agent_type, batch.agent_type.new_full((m,), AGENT_PERSON)])  # [N+M]
    position = hist[:, -1] / scale  # [N + M, 2]
    geom = _pair_geometry(position, vel[:, -1], scene, slot, mask)  # [B, P, P, 4]
    return SceneFeatures(torch.cat([rel, vel], -1), geom, mask, scene, slot, types,
                         position, targets=n, pairs=_within(geom, radius, scale))  # fmt: skip


class SocialEncoder(nn.Module):
    """Per-agent MLP over the history, then attention across the agents of each scene.

    ``temporal`` adds a GRU over the history's steps; its last state joins the MLP's
    embedding (``ModelConfig.history_encoder``). ``site`` adds an embedding of each agent's
    place and heading in the scene's coordinates, passed to ``forward`` as [N, 4]
    (``ModelConfig.scene_position``). ``roles`` > 0 adds an embedding of each agent's slot
    in its scene (``ModelConfig.agent_roles``). ``dropout`` > 0 drops, during training, each
    agent's embedding before the attention layers and their residual updates
    (``ModelConfig.encoder_dropout``)."""

    def __init__(self, t_hist: int, hidden: int, layers: int, heads: int, num_types: int = 2,
                 temporal: bool = False, site: bool = False,
                 pair_distance: bool = False, roles: int = 0,
                 dropout: float = 0.0):  # fmt: skip
        super().__init__()
        self.drop = nn.Dropout(dropout) if dropout > 0 else nn.Identity()
        self.pair_distance = pair_distance
        self.embed = mlp([t_hist * 4, hidden, hidden])
        self.temporal = nn.GRU(4, hidden, batch_first=True) if temporal else None
        self.site_embed = mlp([4, hidden, hidden]) if site else None
        self.type_embed = nn.Embedding(num_types, hidden)
        self.role_embed = nn.Embedding(roles, hidden) if roles else None
        edges = 6 if pair_distance else 4
        self.layers = nn.ModuleList(SocialAttention(hidden, heads, edges, dropout)
                                    for _ in range(layers))  # fmt: skip
        self.norm = nn.LayerNorm(hidden)

    def forward(self, f: SceneFeatures, site: torch.Tensor | None = None) -> torch.Tensor:
        """-> context [N, H]. ``site`` [N, 4] is required exactly when the encoder was built
        with ``site=True``."""
        if (site is None) != (self.site_embed is None):
            raise ValueError("SocialEncoder: pass site [N, 4] exactly when built with site=True")
        h = self.embed(f.hist.flatten(1)) + self.type_embed(f.agent_type)  # [N, H]
        if self.site_embed is not None:
            h = h + self.site_embed(site)  # [N, H]
        if self.role_embed is not None:
            roles = self.role_embed.num_embeddings
            # the padded width is the largest scene's size, slot.max() + 1: a shape, which
            # torch.export can prove from its bound on P where the slots' values it cannot
            if f.mask.shape[1] > roles:
                raise DataError(f"a scene has {f.mask.shape[1]} agents, but this model "
                                f"knows {roles} agent roles (ModelConfig.agent_roles): it "
                                f"predicts scenes of at most {roles} agents, listed in its "
                                "training data's order")  # fmt: skip
            h = h + self.role_embed(f.slot)  # [N, H]
        if self.temporal is not None:
            _, last = self.temporal(f.hist)  # last: [1, N, H]
            h = h + last[0].to(h.dtype)  # under autocast the GRU may run in another dtype
        h = self.drop(h)  # [N, H]; h itself when not training or without dropout
        b, p = f.mask.shape
        padded = h.new_zeros(b, p, h.shape[-1])  # [B, P, H]
        padded[f.scene, f.slot] = h
        geom = with_distance(f.geom) if self.pair_distance else f.geom  # [B, P, P, 4 or 6]
        attend = f.mask  # [B, P(j)]: every agent of the scene, padding hidden
        if f.pairs is not None and len(self.layers):  # a neighbour radius: [B, P(i), P(j)]
            eye = torch.eye(p, dtype=torch.bool, device=f.mask.device)  # [P, P]
            attend = (f.pairs & f.mask[:, None, :]) | eye  # a padded row keeps itself
        for layer in self.layers:
            padded = layer(padded, geom, attend)
        return self.norm(padded[f.scene, f.slot])  # [N, H]


def with_distance(geom: torch.Tensor, eps: float = 1e-3) -> torch.Tensor:
    """Pair features [..., 4] (j's position and velocity relative to i) with two more: the
    pair's distance sqrt(|dp|^2 + eps^2) and its closing speed dp . dv / distance (the
    distance's rate of change; negative when approaching) -> [..., 6]. Both are invariant
    to rotations and scale with the scene, so the heading frame and the speed clamp keep
    them consistent; eps keeps an agent's pair with itself finite."""
    dp, dv = geom[..., :2], geom[..., 2:]
    dist = (dp.square().sum(-1, keepdim=True) + eps**2).sqrt()  # [..., 1]
    closing = (dp * dv).sum(-1, keepdim=True) / dist  # [..., 1]
    return torch.cat([geom, dist, closing], -1)


def heading_rotation(hist: torch.Tensor, eps: float = 1e-4) -> torch.Tensor:
    """Per-agent rotations R [N, 2, 2] that turn each agent's observed displacement (first to
    last observed position) onto +x: ``R @ d = (|d|, 0)``. An agent that has not moved
    (|d| < ``eps``, in model units) keeps the scene's axes (R = I).

    ``hist`` [N, T_h, 4] are the scene features' histories (positions relative to the last
    observation, then velocities). Row vectors turn with ``x @ R.mT`` into the agent's frame
    and with ``x @ R`` back."""
    d = -hist[:, 0, :2]  # [N, 2] displacement over the observed window
    norm = d.norm(dim=-1, keepdim=True)  # [N, 1]
    unit = torch.where(norm > eps, d / norm.clamp_min(eps), torch.tensor([1.0, 0.0]).to(d))
    c, s = unit[:, 0], unit[:, 1]  # [N]
    return torch.stack([torch.stack([c, s], -1), torch.stack([-s, c], -1)], -2)  # [N, 2, 2]


def agent_site(f: SceneFeatures, rot: torch.Tensor | None) -> torch.Tensor:
    """[N, 4] where each agent is and which way it heads, in the scene's own coordinates: its
    last observed position (``f.position``) and the unit vector of its observed displacement,
    taken from its heading rotation ``rot`` [N, 2, 2] (whose first row it is; computed from
    ``f.hist`` when None). An agent that has not moved heads along +x."""
    rot = heading_rotation(f.hist) if rot is None else rot  # [N, 2, 2]
    return torch.cat([f.position, rot[:, 0]], -1)  # [N, 4]


def rotate_features(f: SceneFeatures, rot: torch.Tensor) -> SceneFeatures:
    """The features in each agent's own frame: its history turned by its R [N, 2, 2], and its
    neighbours' relative positions and velocities (``geom`` row i) turned by agent i's R."""
    n, t = f.hist.shape[:2]
    hist = (f.hist.view(n, t, 2, 2) @ rot[:, None].mT).view(n, t, 4)  # [N, T_h, 4]
    b, p = f.mask.shape
    padded = torch.eye(2, dtype=rot.dtype, device=rot.device).repeat(b, p, 1, 1)  # [B, P, 2, 2]
    padded[f.scene, f.slot] = rot
    geom = (f.geom.view(b, p, p, 2, 2) @ padded[:, :, None].mT).view(b, p, p, 4)  # [B, P, P, 4]
    return dataclasses.replace(f, hist=hist, geom=geom)


def speed_factor(hist: torch.Tensor, max_speed: float) -> torch.Tensor:
    """Per-agent factors c [N] >= 1 that bring each agent's observed displacement per step
    (first to last observed position, model units) down to at most ``max_speed``: c = 1 for
    an agent at or below it, speed / max_speed above. ``hist`` [N, T_h, 4] are the model's
    history features (positions relative to the last observation, in model units, first)."""
    return (observed_pace(hist[..., :2]) / max_speed).clamp_min(1.0)  # [N]


def scale_features(f: SceneFeatures, c: torch.Tensor) -> SceneFeatures:
    """The features of each agent divided by its factor c [N]: its history, and its
    neighbours' relative positions and velocities (``geom`` row i) as agent i sees them."""
    b, p = f.mask.shape
    padded = c.new_ones(b, p)  # [B, P]
    padded[f.scene, f.slot] = c
    hist = f.hist / c[:, None, None]  # [N, T_h, 4]
    geom = f.geom / padded[:, :, None, None]  # [B, P(i), P(j), 4]
    return dataclasses.replace(f, hist=hist, geom=geom)
