"""Displacement metrics for K sampled futures.

Per-agent metrics (minADE_K, minFDE_K) pick the best of K for each agent separately, and ADE
and FDE pick their own best; this is how the paper's tables and LED count. Joint (scene-level)
metrics pick one sample k per scene for all its agents.

Collision rates (Col-I, Col-II) follow TrajNet++'s test, on each agent's best sample, between
the agents that have a body (``bodies``: the caller leaves out NBA's ball); bins split every
metric by the number of agents in a scene (docs/social.md).

Shapes: pred [K, N, T_f, 2], future [N, T_f, 2], scene [N] (scene index per agent, 0..B-1).
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass

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


# ----------------------------------------------------------------------------- collisions

COLLISION_RADIUS = 0.1
"""TrajNet++'s person radius, in metres (``trajnetplusplustools.metrics.collision``): two
agents collide when their centres come within twice this distance (0.2 m, inclusive)."""

COLLISION_PARTS = 2
"""Points per step interval checked besides the steps themselves, as TrajNet++'s
``inter_parts``: 2 checks each step and the midpoint between consecutive steps."""

METRE_UNITS = frozenset({"m", "metre", "metres", "meter", "meters"})
"""The unit names for which the default collision radius (metres) applies."""

_PAIR_CHUNK = 1 << 16
"""Agent pairs tested at a time (bounds the memory of a scene with very many agents)."""


def default_collision_radius(units: str) -> float | None:
    """``COLLISION_RADIUS`` for data in metres; None (collision metrics off) for anything
    else, e.g. SDD's pixels or a user folder's ``unknown``: a radius in metres means nothing
    there, so such data needs an explicit radius in its own units."""
    return COLLISION_RADIUS if units.lower() in METRE_UNITS else None


def check_collision_radius(radius: float) -> None:
    """ValueError unless ``radius`` is a finite number > 0 (a Python or numpy number; not a
    bool, nor text such as ``'0.1'``, which ``float`` would read but no distance takes)."""
    try:
        value = float(radius)
    except (TypeError, ValueError):
        value = math.nan
    if isinstance(radius, (bool, str, bytes)) or not (math.isfinite(value) and value > 0):
        raise ValueError(f"the collision radius must be a finite number > 0, got {radius!r}")


def interpolate_steps(path: torch.Tensor, parts: int = COLLISION_PARTS) -> torch.Tensor:
    """Positions at every step and at ``parts - 1`` evenly spaced points on the straight
    segment between consecutive steps: [..., T, 2] -> [..., (T - 1) * parts + 1, 2]."""
    if parts < 1:
        raise ValueError(f"parts must be >= 1, got {parts}")
    frac = torch.arange(parts, dtype=path.dtype, device=path.device) / parts  # [parts]
    start = path[..., :-1, None, :]  # [..., T-1, 1, 2]
    inner = start + frac[:, None] * (path[..., 1:, None, :] - start)  # [..., T-1, parts, 2]
    return torch.cat([inner.flatten(-3, -2), path[..., -1:, :]], -2)  # [..., (T-1)*parts+1, 2]


def collides(
    a: torch.Tensor, b: torch.Tensor, radius: float = COLLISION_RADIUS,
    parts: int = COLLISION_PARTS,
) -> torch.Tensor:  # fmt: skip
    """TrajNet++'s collision test of paths a and b [..., T, 2] over the same T steps ->
    [...] bool: True where the two centres come within ``2 * radius`` (inclusive) at a step or
    at one of the ``parts - 1`` points linearly interpolated between two steps.

    This is ``trajnetplusplustools.metrics.collision(path1, path2, T, radius, parts)`` for two
    paths on the same frames, vectorised. One difference: a single-step path (T = 1) is
    checked at its one position, where TrajNet++'s loop over step intervals checks nothing.
    """
    if a.shape != b.shape or a.ndim < 2 or a.shape[-1] != 2:
        raise ValueError(f"paths must both be [..., T, 2], got {tuple(a.shape)} and "
                         f"{tuple(b.shape)}")  # fmt: skip
    check_collision_radius(radius)
    # the interpolated gap between a and b is the gap between their interpolations
    gap = interpolate_steps(a - b, parts)  # [..., T', 2]
    return torch.linalg.vector_norm(gap, dim=-1).amin(-1) <= 2 * radius  # [...]


def best_sample(pred: torch.Tensor, future: torch.Tensor) -> torch.Tensor:
    """Each agent's best sample, by its ADE against its own ground truth: [N] in 0..K-1
    (the first on a tie)."""
    return ade_fde(pred, future)[0].argmin(0)  # [N]


def neighbour_pairs(scene: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Every ordered pair (i, j), i != j, of agents in the same scene: two [P] index tensors
    (P = sum over scenes of n (n - 1)). ``scene`` [N] need not be sorted."""
    order = torch.argsort(scene, stable=True)  # [N] agents grouped by scene
    ordered = scene[order]  # [N]
    _, sizes = torch.unique_consecutive(ordered, return_counts=True)  # [B']
    starts = torch.cumsum(sizes, 0) - sizes  # [B'] first sorted position of each scene
    group = torch.repeat_interleave(torch.arange(len(sizes), device=scene.device), sizes)  # [N]
    reps = sizes[group]  # [N] partners per sorted agent, itself included
    i = torch.repeat_interleave(torch.arange(len(scene), device=scene.device), reps)  # [sum n^2]
    offset = torch.arange(len(i), device=scene.device) - torch.repeat_interleave(
        torch.cumsum(reps, 0) - reps, reps
    )  # [sum n^2] position of the partner within the scene
    j = starts[group[i]] + offset  # [sum n^2]
    keep = i != j
    return order[i[keep]], order[j[keep]]


@dataclass
class CollisionFlags:
    """Per-agent collision outcomes of one batch (every tensor [N] bool)."""

    col_i: torch.Tensor
    """Col-I: the agent's best sample collides with a neighbour's sample of the same index."""
    col_ii: torch.Tensor
    """Col-II: the agent's best sample collides with a neighbour's ground truth."""
    col_gt: torch.Tensor
    """The agent's ground truth collides with a neighbour's ground truth (the data's own rate,
    a floor for Col-II: tracks annotated closer than 2 radii)."""
    has_neighbour: torch.Tensor
    """The agent is not the ball and its scene has at least one other agent that is not the
    ball (the rates' denominator)."""


def collision_flags(
    pred: torch.Tensor, future: torch.Tensor, scene: torch.Tensor,
    radius: float = COLLISION_RADIUS, parts: int = COLLISION_PARTS,
    bodies: torch.Tensor | None = None,
) -> CollisionFlags:  # fmt: skip
    """Col-I, Col-II and the ground truth's own collisions of every agent.

    Reads nothing but the samples pred [K, N, T_f, 2], the ground truth future [N, T_f, 2],
    scene [N] (which agents are neighbours: those of the same scene) and, when given,
    bodies [N] bool (the agents that can collide; None: all). Agent i's best sample k_i
    (``best_sample``, by ADE) is tested against each neighbour j's sample k_i (Col-I) and
    against j's ground truth (Col-II), with ``collides``. An agent alone in its scene has no
    neighbour and never collides. An agent without a body (NBA's ball: ``evaluation.bodies``)
    is neither tested nor a neighbour (a player holding the ball does not collide with it),
    and it is out of the denominator (``has_neighbour`` False).
    """
    _check(pred, future)
    n = pred.shape[1]
    if scene.shape != (n,):
        raise ValueError(f"scene must be [N] = [{n}], got {tuple(scene.shape)}")
    if bodies is not None and bodies.shape != (n,):
        raise ValueError(f"bodies must be [N] = [{n}], got {tuple(bodies.shape)}")
    body = torch.ones(n, dtype=torch.bool, device=pred.device)  # [N] agents that can collide
    if bodies is not None:
        body = bodies.to(device=pred.device, dtype=torch.bool)  # [N]
    k_best = best_sample(pred, future)  # [N]
    pi, pj = neighbour_pairs(scene)  # [P], [P]
    keep = body[pi] & body[pj]  # [P] pairs of two bodies
    pi, pj = pi[keep], pj[keep]  # [P'']
    hits = {key: torch.zeros(n, dtype=torch.long, device=pred.device) for key in
            ("col_i", "col_ii", "col_gt")}  # fmt: skip
    for lo in range(0, len(pi), _PAIR_CHUNK):
        i, j = pi[lo : lo + _PAIR_CHUNK], pj[lo : lo + _PAIR_CHUNK]  # [P']
        own = pred[k_best[i], i]  # [P', T_f, 2] agent i's best sample
        tests = {
            "col_i": collides(own, pred[k_best[i], j], radius, parts),  # [P']
            "col_ii": collides(own, future[j], radius, parts),  # [P']
            "col_gt": collides(future[i], future[j], radius, parts),  # [P']
        }
        for key, hit in tests.items():
            hits[key].index_add_(0, i, hit.long())
    sizes = torch.bincount(scene[body], minlength=int(scene.max()) + 1 if n else 0)  # bodies
    return CollisionFlags(**{k: v > 0 for k, v in hits.items()},
                          has_neighbour=body & (sizes[scene] > 1))  # fmt: skip


class CollisionAccumulator:
    """Running Col-I / Col-II / ground-truth collision rates over batches.

    Rates are percentages of the agents that have at least one neighbour (agents alone in
    their scene, and agents without a body, are left out of numerator and denominator;
    ``col_agents`` counts the rest).
    """

    def __init__(self, radius: float = COLLISION_RADIUS, parts: int = COLLISION_PARTS) -> None:
        check_collision_radius(radius)
        self.radius = radius
        self.parts = parts
        self.counts = {"col_i": 0, "col_ii": 0, "col_gt": 0}
        self.agents = 0

    def update(self, pred: torch.Tensor, future: torch.Tensor, scene: torch.Tensor,
               bodies: torch.Tensor | None = None) -> None:  # fmt: skip
        self.add(collision_flags(pred, future, scene, self.radius, self.parts, bodies))

    def add(self, flags: CollisionFlags, mask: torch.Tensor | None = None) -> None:
        """Count ``flags`` (optionally only the agents where ``mask`` [N] is True)."""
        keep = flags.has_neighbour if mask is None else flags.has_neighbour & mask  # [N]
        for key in self.counts:
            self.counts[key] += int((getattr(flags, key) & keep).sum())
        self.agents += int(keep.sum())

    def compute(self) -> dict[str, float | int]:
        """``col_i_pct``, ``col_ii_pct``, ``col_gt_pct`` (NaN when no agent had a neighbour),
        ``col_agents`` and ``col_radius``."""
        out: dict[str, float | int] = {
            f"{key}_pct": 100 * count / self.agents if self.agents else float("nan")
            for key, count in self.counts.items()
        }
        out["col_agents"] = self.agents
        out["col_radius"] = self.radius
        return out


# ----------------------------------------------------------------------------- scene-size bins

SCENE_SIZE_EDGES = (5, 10, 20)
"""Upper edges of the scene-size bins (agents per scene): <= 5, 6-10, 11-20, > 20 (§8.5)."""


def as_integer(value) -> int | None:
    """``value`` as a Python int when it is an integer (an ``int``, a numpy integer, a 0-d
    integer tensor), else None: never a bool (nor numpy's or torch's), a float or text. What
    the count arguments of the public API accept, so that ``np.int64(20)`` from a planner's
    arrays counts as 20 (``models.predictor`` takes it from here: metrics imports no other
    trajpref module)."""
    if isinstance(value, bool) or (isinstance(value, torch.Tensor) and value.dtype == torch.bool):
        return None  # numpy's bool refuses operator.index itself
    try:
        return operator.index(value)
    except TypeError:
        return None


def check_bin_edges(edges: tuple[int, ...]) -> tuple[int, ...]:
    """``edges`` as a tuple of Python ints; ValueError unless they are strictly increasing
    integers >= 1 (Python or numpy integers, in a tuple, a list or a 1-d array; not bools nor
    floats)."""
    try:
        values = [as_integer(e) for e in edges] if not isinstance(edges, (str, bytes)) else [None]
    except TypeError:  # not a sequence (a bare number, a 0-d array)
        values = [None]
    if (
        not values
        or any(v is None or v < 1 for v in values)
        or any(b <= a for a, b in zip(values, values[1:], strict=False))
    ):
        raise ValueError(f"bin edges must be strictly increasing integers >= 1, got {edges}")
    return tuple(values)


def bin_labels(edges: tuple[int, ...] = SCENE_SIZE_EDGES) -> list[str]:
    """Names of the bins: (5, 10, 20) -> ['<=5', '6-10', '11-20', '>20']."""
    edges = check_bin_edges(edges)
    labels = [f"<={edges[0]}"]
    for lo, hi in zip(edges, edges[1:], strict=False):
        labels.append(f"{lo + 1}" if hi == lo + 1 else f"{lo + 1}-{hi}")
    return [*labels, f">{edges[-1]}"]


def size_bin(sizes: torch.Tensor, edges: tuple[int, ...] = SCENE_SIZE_EDGES) -> torch.Tensor:
    """The bin of each scene size: [B] agents per scene -> [B] in 0..len(edges)."""
    edges = check_bin_edges(edges)
    bounds = torch.tensor(edges, dtype=sizes.dtype, device=sizes.device)  # [E]
    return torch.bucketize(sizes, bounds)  # [B]: edges[b-1] < size <= edges[b]


class BinnedMetrics:
    """Metrics per scene-size bin: minADE/minFDE per agent and joint, the collision rates
    (when a radius is given) and per-scene values passed in (e.g. maxATS), each averaged over
    the scenes of its bin."""

    def __init__(
        self, edges: tuple[int, ...] = SCENE_SIZE_EDGES,
        collision_radius: float | None = COLLISION_RADIUS, parts: int = COLLISION_PARTS,
    ) -> None:  # fmt: skip
        self.edges = check_bin_edges(edges)
        self.labels = bin_labels(self.edges)
        self.metrics = [MetricAccumulator() for _ in self.labels]
        self.collisions = (
            None if collision_radius is None
            else [CollisionAccumulator(collision_radius, parts) for _ in self.labels]
        )  # fmt: skip
        self.value_sums: list[dict[str, float]] = [{} for _ in self.labels]

    def update(
        self, pred: torch.Tensor, future: torch.Tensor, scene: torch.Tensor, num_scenes: int,
        scene_values: dict[str, torch.Tensor] | None = None, flags: CollisionFlags | None = None,
        bodies: torch.Tensor | None = None,
    ) -> None:  # fmt: skip
        """One batch. ``scene_values``: name -> [B] per-scene numbers to average per bin;
        ``flags``: this batch's ``collision_flags`` when already computed; ``bodies`` [N] bool:
        read by ``collision_flags`` when it computes them (the agents that can collide)."""
        _check(pred, future)
        which = size_bin(torch.bincount(scene, minlength=num_scenes), self.edges)  # [B]
        if self.collisions is not None and flags is None:
            radius, parts = self.collisions[0].radius, self.collisions[0].parts
            flags = collision_flags(pred, future, scene, radius, parts, bodies)
        for b in which.unique().tolist():
            in_bin = which == b  # [B]
            agents = in_bin[scene]  # [N]
            renumber = torch.cumsum(in_bin, 0) - 1  # [B] scene index within the bin
            self.metrics[b].update(pred[:, agents], future[agents], renumber[scene[agents]],
                                   int(in_bin.sum()))  # fmt: skip
            if self.collisions is not None:
                self.collisions[b].add(flags, agents)
            for key, values in (scene_values or {}).items():
                total = self.value_sums[b].get(key, 0.0)
                self.value_sums[b][key] = total + float(values[in_bin].sum())

    def compute(self) -> dict[str, dict[str, float | int]]:
        """label -> that bin's metrics, plus ``scenes`` and ``agents``; a bin without scenes
        holds only ``{"scenes": 0, "agents": 0}``."""
        out: dict[str, dict[str, float | int]] = {}
        for b, label in enumerate(self.labels):
            acc = self.metrics[b]
            if acc.agents == 0:
                out[label] = {"scenes": 0, "agents": 0}
                continue
            row = acc.compute()
            if self.collisions is not None:
                row.update(self.collisions[b].compute())
            row.update({k: v / acc.scenes for k, v in self.value_sums[b].items()})
            out[label] = row
        return out


# ----------------------------------------------------------------------------- agent slots


def agent_slot(scene: torch.Tensor, num_scenes: int) -> torch.Tensor:
    """Each agent's place in its scene, counted from 0 in batch order: scene [N] -> [N].

    Datasets whose scenes list their agents in fixed roles (Robo: leader, follower,
    approacher; ``ModelConfig.agent_roles``) give each role its place; elsewhere the place is
    only the order the agents were listed in (ascending agent id in a text file)."""
    counts = torch.bincount(scene, minlength=num_scenes)  # [B]
    starts = torch.cumsum(counts, 0) - counts  # [B] first packed index of each scene
    order = torch.argsort(scene, stable=True)  # [N] agents grouped by scene, order kept
    slot = torch.empty_like(scene)
    slot[order] = torch.arange(scene.numel(), device=scene.device) - starts[scene[order]]
    return slot


def slot_labels(slots: int) -> list[str]:
    """Names of the places reported by ``SlotMetrics``: 3 -> ['1', '2', '3', '>3']. ``slots``
    a Python or numpy integer >= 1 (not a bool nor a float: ValueError)."""
    count = as_integer(slots)
    if count is None or count < 1:
        raise ValueError(f"slots must be an integer >= 1, got {slots!r}")
    return [*(str(s) for s in range(1, count + 1)), f">{count}"]


class SlotMetrics:
    """minADE/minFDE (and the collision rates, when flags are passed) per agent's place in
    its scene: places 1..``slots`` each on their own, the agents after them together.

    Per-agent metrics only: one scene has one agent in a place, so a joint metric per place
    would equal the per-agent one. Collision flags are the batch's own (each agent tested
    against every neighbour of its scene), counted for the agents of each place."""

    def __init__(self, slots: int, collision_radius: float | None = None) -> None:
        self.labels = slot_labels(slots)
        self.slots = as_integer(slots)
        self.sums = [{"min_ade": 0.0, "min_fde": 0.0} for _ in self.labels]
        self.agents = [0 for _ in self.labels]
        self.collisions = (
            None if collision_radius is None
            else [CollisionAccumulator(collision_radius) for _ in self.labels]
        )  # fmt: skip

    def update(
        self, pred: torch.Tensor, future: torch.Tensor, scene: torch.Tensor, num_scenes: int,
        flags: CollisionFlags | None = None,
    ) -> None:  # fmt: skip
        """One batch. With a collision radius, ``flags`` are this batch's
        ``collision_flags`` at that radius (required then; ignored without one)."""
        _check(pred, future)
        if self.collisions is not None and flags is None:
            raise ValueError("SlotMetrics with a collision radius needs each batch's flags")
        ade, fde = min_ade_fde(pred, future)  # [N] each
        group = agent_slot(scene, num_scenes).clamp(max=self.slots)  # [N] 0..slots
        for g in group.unique().tolist():
            members = group == g  # [N]
            self.sums[g]["min_ade"] += float(ade[members].sum())
            self.sums[g]["min_fde"] += float(fde[members].sum())
            self.agents[g] += int(members.sum())
            if self.collisions is not None:
                self.collisions[g].add(flags, members)

    def compute(self) -> dict[str, dict[str, float | int]]:
        """label -> ``agents``, ``min_ade``, ``min_fde`` (and the collision keys); a place
        without agents holds only ``{"agents": 0}``."""
        out: dict[str, dict[str, float | int]] = {}
        for g, label in enumerate(self.labels):
            n = self.agents[g]
            if n == 0:
                out[label] = {"agents": 0}
                continue
            row: dict[str, float | int] = {"agents": n}
            row.update({k: v / n for k, v in self.sums[g].items()})
            if self.collisions is not None:
                row.update(self.collisions[g].compute())
            out[label] = row
        return out
