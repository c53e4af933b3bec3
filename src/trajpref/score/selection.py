"""Keep K' of K sampled futures, for planners that act on a few: by coverage alone, by the
diffusion score alone, or by both (drop the worst-scored, then cover what is left).

Selection never reads the ground truth: the score's residual is computed from the histories
and the samples only. Items are selected independently: each agent (``per="agent"``, what
the per-agent minADE/minFDE count) or each scene (``per="scene"``: one set of K' sample indices
shared by all its agents, what the joint metrics count).

Shapes: pred [K, N, T_f, 2], residual [K, N] (one number per sample and agent, lower is more
human-like), the result idx [K', N] (sample indices per agent, in selection order).

Methods are named in ``Method`` and dispatched by their exact name: each has its own branch in
``_select`` and its own entry in ``USES_SCORE`` (a name's prefix or suffix means nothing to
the code; an unknown name is an error). Adding one: docs/selection.md, "Adding a method".
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import numbers
import os
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from trajpref.config import check_choices
from trajpref.data import transforms
from trajpref.errors import ConfigError, TrajprefError
from trajpref.metrics import scene_sum
from trajpref.models import zoo
from trajpref.models.predictor import as_integer, check_seed
from trajpref.score.scorer import (
    TrajectoryScorer,
    reads_agent_types,
    scene_batch,
    score_timesteps,
    warn_ball_count,
    warn_untyped,
)
from trajpref.types import AGENT_BALL, Batch

Method = Literal["first", "random", "kmeans", "fps", "facility", "medoids", "top",
                 "score-first", "score-kmeans", "score-fps", "score-facility",
                 "score-medoids"]  # fmt: skip
METHODS: tuple[str, ...] = typing.get_args(Method)
USES_SCORE = {"first": False, "random": False, "kmeans": False, "fps": False, "facility": False,
              "medoids": False, "top": True, "score-first": True, "score-kmeans": True,
              "score-fps": True, "score-facility": True, "score-medoids": True}  # fmt: skip
"""Whether each method reads the diffusion score (the others select by the samples alone);
written out per method, as ``_select``'s branches are."""
SCORE_FREE = {"top": "first", "score-first": "first", "score-kmeans": "kmeans",
              "score-fps": "fps", "score-facility": "facility",
              "score-medoids": "medoids"}  # fmt: skip
"""Each score method's counterpart without the score (``trust_speed`` falls back to it)."""
DROPPING = ("score-first", "score-kmeans", "score-fps", "score-facility", "score-medoids")
"""The score methods that drop the ``drop`` worst-scored samples, then select among the rest."""
WEIGHTED = ("score-facility", "score-medoids")
"""The score methods that weight each sample as a target by exp(-z / temperature)."""
FACILITY = ("facility", "score-facility")
"""The methods that read ``bandwidth`` (facility location)."""
if set(USES_SCORE) != set(METHODS) or set(SCORE_FREE) != {m for m in METHODS if USES_SCORE[m]}:
    raise AssertionError("score.selection: USES_SCORE and SCORE_FREE must name every method "
                         "of Method")  # fmt: skip


@dataclass
class SelectionConfig:
    """How to keep K' of K samples."""

    keep: int = 5
    """K', the samples kept per agent (or per scene). The defaults below are an early choice
    on zara1's and eth's validation splits, and the CLI's (``--keep`` selects with them); the
    settings chosen since for each published generator are ``chosen_selection(model)`` (and
    ``cheap=True`` for its cheap setting), as ``benchmarks/selection_chosen.json`` and the
    README's selection table name them (zara1's: ``drop=0.2, bandwidth=1.0,
    trust_speed=0.445, score_every=3``, 34 score steps)."""
    method: Method = "score-facility"
    """Without the score: ``first`` (the generator's first K'), ``random``, or coverage of
    the endpoints by ``kmeans``, ``fps`` (farthest-point) or ``facility`` (greedy facility
    location) or ``medoids`` (weighted K'-medoids: the K' samples that minimise the mean
    distance from every sample to its nearest kept one, the minFDE_K' the set would have if
    the truth were one of the K). With it: ``top`` (the K' best-scored), or ``score-first`` /
    ``score-kmeans`` / ``score-fps`` / ``score-facility`` / ``score-medoids``: drop the
    ``drop`` worst-scored, then the same (``score-facility`` and ``score-medoids`` also
    weight each sample as a target by its score)."""
    drop: float = 0.3
    """Fraction of the K samples the score-coverage methods drop before covering (at most
    K - K' are dropped)."""
    per: Literal["agent", "scene"] = "agent"
    """Select per agent, or one set of sample indices per scene (for joint metrics)."""
    final: bool = False
    """Score by the final step's residual (FTS order) instead of the whole future (ATS)."""
    iters: int = 10
    """k-means iterations."""
    bandwidth: float = 0.5
    """Facility location: the similarity exp(-d^2 / (bandwidth * h^2)), h^2 the median
    squared distance between an item's samples."""
    temperature: float = 2.0
    """score-facility and score-medoids: sample weights exp(-z / temperature), z the residual
    standardised over the item's K samples."""
    seed: int = 0
    """Seed of the ``random`` method's own generator (it never draws from the sampler's, so
    every method sees the same candidates). In ``SelectingPredictor.predict`` given a
    generator, the draws come from a generator seeded with this and that generator's state
    (``derived_generator``), so the caller's seed decides them too."""
    trust_speed: float = 0.0
    """Score methods only: an agent observed faster than this (the scorer's model units per
    observed step, first to last observed position, as ``model.max_speed`` measures it) is
    selected by the method's score-free counterpart (``SCORE_FREE``): the scorer never saw
    such a pace. With ``per="scene"`` a scene with any such agent falls back. 0: off.
    Model units, not metres: metres per step divided by ``scorer.scale`` (zara1's 0.445 is
    0.655 m per 0.4 s step); ``chosen_selection`` holds each published model's value."""
    score_every: int | None = 9
    """Score methods only: the score's steps are every this many of the scorer's S diffusion
    steps, from ``score_from`` (9: 12 of 100, the CLI's ``--score-every`` default, so that
    ``select_for_scene(scorer, h, s, SelectionConfig(keep=5))`` keeps what ``--keep 5``
    keeps; 3: the paper's 34). None: the scorer's own steps (``TrajectoryScorer.steps``;
    ``from_checkpoint`` builds the paper's 34 unless given ``steps``)."""
    score_from: int = 0
    """Score methods only: the first score step (0, the lowest noise level), as
    ``--score-from``; not read with ``score_every`` None."""

    def __post_init__(self) -> None:
        check_choices(self)
        for name in ("keep", "iters", "seed", "score_every", "score_from"):
            value = as_integer(getattr(self, name))  # numpy integers count as integers
            if value is not None:
                setattr(self, name, value)
        for name in ("drop", "bandwidth", "temperature", "trust_speed"):  # before comparing
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise ConfigError(f"selection {name} must be a number, got {value!r}")
            setattr(self, name, float(value))
        if isinstance(self.final, np.bool_):  # a planner's numpy flag
            self.final = bool(self.final)
        if not isinstance(self.final, bool):
            raise ConfigError(f"selection final must be True or False, got {self.final!r}")
        self.seed = check_seed(self.seed, "selection seed")
        if isinstance(self.keep, bool) or not isinstance(self.keep, int) or self.keep < 1:
            raise ConfigError(f"selection keep must be an integer >= 1, got {self.keep!r}")
        if not 0 <= self.drop < 1:
            raise ConfigError(f"selection drop must lie in [0, 1), got {self.drop!r}")
        if isinstance(self.iters, bool) or not isinstance(self.iters, int) or self.iters < 0:
            raise ConfigError(f"selection iters must be an integer >= 0, got {self.iters!r}")
        if not all(math.isfinite(v) and v > 0 for v in (self.bandwidth, self.temperature)):
            raise ConfigError(f"selection bandwidth and temperature must be finite and > 0, "
                              f"got {self.bandwidth} and {self.temperature}")  # fmt: skip
        if not self.trust_speed >= 0:
            raise ConfigError(f"selection trust_speed must be >= 0, got {self.trust_speed}")
        every = self.score_every
        if every is not None and (isinstance(every, bool) or not isinstance(every, int)
                                  or every < 1):  # fmt: skip
            raise ConfigError(f"selection score_every must be an integer >= 1 or None (the "
                              f"scorer's own steps), got {every!r}")  # fmt: skip
        if isinstance(self.score_from, bool) or not isinstance(self.score_from, int) or (
                self.score_from < 0):  # fmt: skip
            raise ConfigError(f"selection score_from must be an integer >= 0, "
                              f"got {self.score_from!r}")  # fmt: skip
        if self.score_from and every is None:
            raise ConfigError("selection score_from needs score_every (None keeps the scorer's "
                              "own steps)")  # fmt: skip

    @property
    def uses_score(self) -> bool:
        """Whether the method reads the diffusion score (and so needs a scorer)."""
        return USES_SCORE.get(self.method, False)

    def unread(self) -> list[str]:
        """The settings given away from their defaults that this method does not read (the
        score's drop and pace gate without the score, a temperature outside the weighted
        methods, a bandwidth outside facility location)."""
        reads = {"drop": self.method in DROPPING, "trust_speed": self.uses_score,
                 "temperature": self.method in WEIGHTED,
                 "bandwidth": self.method in FACILITY,
                 "score_every": self.uses_score, "score_from": self.uses_score}  # fmt: skip
        return [k for k, read in reads.items() if not read and getattr(self, k) != getattr(
            SelectionConfig, k)]  # fmt: skip


_FACILITY = {"method": "score-facility", "drop": 0.2, "temperature": 2.0, "score_every": 3}
CHOSEN: dict[str, dict[str, dict]] = {
    "zara1/generator": {"chosen": {**_FACILITY, "bandwidth": 1.0, "trust_speed": 0.4450},
                        "cheap": {"score_every": 100}},
    "eth/generator": {"chosen": {**_FACILITY, "bandwidth": 1.0, "trust_speed": 0.4255},
                      "cheap": {"score_every": 50}},
    "robo/generator": {"chosen": {**_FACILITY, "bandwidth": 0.5, "trust_speed": 0.2801},
                       "cheap": {"score_every": 100, "score_from": 99}},
    "robo-mix/generator": {"chosen": {**_FACILITY, "bandwidth": 1.0, "trust_speed": 0.2796},
                           "cheap": {"score_every": 100}},
    "eth/generator-pace": {"chosen": {**_FACILITY, "drop": 0.3, "bandwidth": 0.5,
                                      "trust_speed": 0.4255}},
}  # fmt: skip
"""The selection settings chosen on the validation splits for the published generators that
have them, each scored by its dataset's denoiser (``DATASET/denoiser``): ``chosen`` at the
paper's 34 score steps, and ``cheap`` (what changes from it: the most score steps within 2x
the prediction's cost), the README selection table's rows that
``benchmarks/selection_chosen.json`` names. ``trust_speed`` is the 99th percentile of the
scorer's training split's observed pace in model units per step (metres per step /
``scorer.scale``), as ``benchmarks/selection.py --trust-quantile 0.99`` printed it for those
rows (rounded to 4 digits; their meta files record it, and a test checks both)."""


CHOSEN_SAMPLES = 20
"""K, the samples each generator of ``CHOSEN`` emits (its ``model.samples``; a test checks
the files): what ``chosen_selection``'s ``keep`` is chosen from."""


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):
        return False


def model_spec(model: object, call: str) -> str | os.PathLike:
    """What names ``model``: a str or a path as given, or for a loaded model (what
    ``models.registry.load_predictor`` returns, or a scorer from ``from_checkpoint``) the name
    or path it was loaded by (its ``checkpoint``). ConfigError for anything else, naming
    ``call``."""
    if isinstance(model, (str, os.PathLike)):
        return model
    spec = getattr(model, "checkpoint", None)
    if isinstance(spec, (str, os.PathLike)):
        return spec
    got = "None" if model is None else type(model).__name__
    raise ConfigError(f"{call}: model is a published name such as 'zara1/generator', a "
                      "checkpoint path or a model loaded by name with "
                      f"trajpref.models.registry.load_predictor; got {got}, which names no "
                      "checkpoint")  # fmt: skip


def published_name(model: str | os.PathLike) -> str:
    """The published name of ``model``: a name as given (``zara1/generator``), or the name of
    the published model a checkpoint path is: the zoo's own file (``.../zoo/zara1/
    generator.safetensors``, or ``models/zara1/generator.safetensors`` in the repository) or
    a copy of it (the same weights hash in the same ``DATASET/NAME.safetensors`` layout).
    Anything else is returned as given. A loaded model stands for the name or path it was
    loaded by (``model_spec``)."""
    text = str(model_spec(model, "published_name"))
    path = Path(text).expanduser()
    if zoo.is_name(text) or not path.is_file():
        return text
    published = zoo.published()
    for name, file in published.items():
        if _same_file(path, file):
            return name
    name = f"{path.parent.name}/{path.stem}"
    if name in published:
        try:
            same = zoo.header(path).get("hash") == zoo.header(published[name]).get("hash")
        except (TrajprefError, OSError, ValueError, AttributeError):
            same = False
        if same:
            return name
    return text


def chosen_selection(model: str | os.PathLike, keep: int = 5, cheap: bool = False,
                     per: Literal["agent", "scene"] = "agent") -> SelectionConfig:  # fmt: skip
    """The ``SelectionConfig`` chosen for the published generator ``model`` (``CHOSEN``), for
    ``select_for_scene`` with its dataset's scorer, keeping ``keep``: the chosen setting at 34
    score steps, or with ``cheap`` its cheap setting (1 or 2 score steps). ``model`` is a
    published name or the path of a published model's file (``published_name``). ConfigError
    for a model without chosen settings (the list names those with them), and for a ``keep``
    that is not an integer in 1..K (``CHOSEN_SAMPLES``, the samples the generator emits). A
    model loaded by ``models.registry.load_predictor`` stands for the name or path it was
    loaded by (``model_spec``; anything else that is no str or path is a ConfigError)."""
    model = model_spec(model, "chosen_selection")
    name = published_name(model)
    entry = CHOSEN.get(name)
    if entry is None or (cheap and "cheap" not in entry):
        have = sorted(CHOSEN) if not cheap else sorted(k for k, v in CHOSEN.items() if "cheap" in v)
        what = "cheap " if cheap else ""
        hint = ""
        path = Path(str(model))
        guess = f"{path.parent.name}/{path.stem}"
        if entry is None and not path.is_file() and path.suffix and guess in CHOSEN:
            hint = f" (no such file here; the published model is named {guess})"
        raise ConfigError(f"no chosen {what}selection setting for {str(model)!r}{hint}; "
                          f"published generators with one: {', '.join(have)}")  # fmt: skip
    count = as_integer(keep)  # np.int64(5) from a planner's arrays counts as 5
    if count is None or not 1 <= count <= CHOSEN_SAMPLES:
        raise ConfigError(f"chosen_selection keep: how many of the K = {CHOSEN_SAMPLES} "
                          f"samples {name} emits to keep, an integer in 1..{CHOSEN_SAMPLES}, "
                          f"got {keep!r}")  # fmt: skip
    settings = {**entry["chosen"], **(entry["cheap"] if cheap else {})}
    return SelectionConfig(keep=count, per=per, **settings)


def check_selection(cfg: object, call: str) -> SelectionConfig:
    """``cfg`` when it is a ``SelectionConfig``; else a ConfigError naming ``call`` and how to
    make one (a dict of its fields: ``SelectionConfig(**fields)``)."""
    if isinstance(cfg, SelectionConfig):
        return cfg
    hint = ("; make one, SelectionConfig(keep=5) or chosen_selection('zara1/generator') for a "
            "published model's chosen setting")  # fmt: skip
    if isinstance(cfg, dict):
        hint = "; make one from the dict of its fields, SelectionConfig(**fields)"
    got = "None" if cfg is None else type(cfg).__name__
    raise ConfigError(f"{call}: cfg must be a SelectionConfig, got {got}{hint}")


def _pairwise(x: torch.Tensor, centers: torch.Tensor) -> torch.Tensor:
    """Squared distances x [K, M, F] to centers [C, M, F] -> [K, C, M]."""
    return (x[:, None] - centers[None]).pow(2).sum(-1)


def _farthest_points(x: torch.Tensor, valid: torch.Tensor, first: torch.Tensor, keep: int):
    """Greedy farthest-point picks among the valid samples, starting from ``first`` [M]:
    x [K, M, F], valid [K, M] -> idx [keep, M]."""
    m = torch.arange(x.shape[1], device=x.device)
    idx = [first]
    gap = (x - x[first, m][None]).pow(2).sum(-1)  # [K, M] distance to the chosen set
    for _ in range(keep - 1):
        gap = gap.masked_fill(~valid, -1.0)
        gap[torch.stack(idx), m[None].expand(len(idx), -1)] = -1.0  # never twice
        nxt = gap.argmax(0)  # [M]
        idx.append(nxt)
        gap = torch.minimum(gap, (x - x[nxt, m][None]).pow(2).sum(-1))
    return torch.stack(idx)


def _kmeans(x: torch.Tensor, valid: torch.Tensor, first: torch.Tensor, keep: int, iters: int):
    """k-means on the valid samples (farthest-point initialisation from ``first``); each
    cluster is represented by its valid member nearest the centre, distinct across clusters.
    x [K, M, F], valid [K, M] -> idx [keep, M]."""
    k, m_items, _ = x.shape
    m = torch.arange(m_items, device=x.device)
    centers = x[_farthest_points(x, valid, first, keep), m[None]]  # [C, M, F]
    w = valid.to(x.dtype)  # [K, M]
    for _ in range(iters):
        assign = _pairwise(x, centers).argmin(1)  # [K, M]
        onehot = torch.nn.functional.one_hot(assign, keep).to(x.dtype) * w[..., None]  # [K,M,C]
        count = onehot.sum(0)  # [M, C]
        total = torch.einsum("kmc,kmf->cmf", onehot, x)  # [C, M, F]
        mean = total / count.T[..., None].clamp(min=1)
        centers = torch.where(count.T[..., None] > 0, mean, centers)  # empty: keep the old one
    dist = _pairwise(x, centers).masked_fill(~valid[:, None], math.inf)  # [K, C, M]
    idx = []
    taken = torch.zeros(k, m_items, dtype=torch.bool, device=x.device)
    for c in range(keep):
        pick = dist[:, c].masked_fill(taken, math.inf).argmin(0)  # [M]
        taken[pick, m] = True
        idx.append(pick)
    return torch.stack(idx)


def _facility(x: torch.Tensor, valid: torch.Tensor, weight: torch.Tensor, keep: int,
              bandwidth: float) -> torch.Tensor:  # fmt: skip
    """Greedy facility location: pick valid samples maximising sum_j weight_j max_{i in S}
    sim(i, j). x [K, M, F], valid and weight [K, M] -> idx [keep, M]."""
    k, m_items, _ = x.shape
    m = torch.arange(m_items, device=x.device)
    d2 = (x[:, None] - x[None]).pow(2).sum(-1)  # [K(i), K(j), M]
    h2 = d2.flatten(0, 1).median(0).values.clamp(min=1e-12)  # [M]
    sim = torch.exp(-d2 / (bandwidth * h2))  # [K(i), K(j), M]
    cover = x.new_zeros(k, m_items)  # [K(j), M] how well each sample is covered so far
    idx = []
    for _ in range(keep):
        gain = ((sim - cover[None]).clamp(min=0) * weight[None]).sum(1)  # [K(i), M]
        pick = gain.masked_fill(~valid, -1.0).argmax(0)  # [M]
        valid = valid.clone()
        valid[pick, m] = False
        cover = torch.maximum(cover, sim[pick, :, m].T)
        idx.append(pick)
    return torch.stack(idx)


def _medoids(x: torch.Tensor, valid: torch.Tensor, weight: torch.Tensor, keep: int,
             passes: int) -> torch.Tensor:  # fmt: skip
    """Weighted K'-medoids: valid samples S minimising sum_j weight_j min_{i in S} |x_i - x_j|
    (Euclidean, as minFDE measures), greedily, then up to ``passes`` rounds of the best single
    swap per item (PAM's swap step). x [K, M, F], valid and weight [K, M] -> idx [keep, M]."""
    k, m_items, _ = x.shape
    m = torch.arange(m_items, device=x.device)
    d = (x[:, None] - x[None]).pow(2).sum(-1).sqrt()  # [K(i), K(j), M]
    wd = d * weight[None]  # [K(i), K(j), M] weighted distance of target j to candidate i
    near = torch.full((k, m_items), math.inf, dtype=x.dtype, device=x.device)  # [K(j), M]
    free = valid.clone()  # [K, M] candidates not yet kept
    idx = []
    for _ in range(keep):  # greedy: add the candidate that lowers the cost most
        cost = torch.minimum(near[None], wd).sum(1)  # [K(i), M]
        pick = cost.masked_fill(~free, math.inf).argmin(0)  # [M]
        free[pick, m] = False
        near = torch.minimum(near, wd[pick, :, m].T)
        idx.append(pick)
    idx = torch.stack(idx)  # [keep, M]
    by_item = wd.permute(0, 2, 1)  # [K(i), M, K(j)]
    slots = torch.arange(keep, device=x.device)[:, None, None]  # [keep, 1, 1]
    for _ in range(passes):  # swap: replace one kept sample by one candidate, best gain
        kept_wd = by_item[idx, m[None]]  # [keep, M, K(j)]
        now = kept_wd.min(0).values.sum(-1)  # [M] the current cost
        others = torch.full_like(kept_wd, math.inf)  # [keep, M, K(j)] nearest kept but the p-th
        if keep > 1:
            two = kept_wd.topk(2, dim=0, largest=False)  # the nearest two kept, [2, M, K(j)]
            others = torch.where(slots == two.indices[0], two.values[1], two.values[0])
        cost = torch.minimum(others[:, None], by_item[None]).sum(-1)  # [keep, K, M]
        cost = cost.masked_fill(~free[None], math.inf)
        best, flat = cost.flatten(0, 1).min(0)  # [M]
        better = best < now - 1e-9 * now.abs().clamp(min=1.0)  # [M]
        if not bool(better.any()):
            break
        pos, cand = (flat // k)[better], (flat % k)[better]  # the items that improve
        items = m[better]
        free[idx[pos, items], items] = True
        free[cand, items] = False
        idx[pos, items] = cand
    return idx


MEDOID_PASSES = 3
"""Swap rounds of ``medoids`` after its greedy picks (K = 20, K' = 5: the swaps settle in one
or two)."""


def select_indices(features: torch.Tensor, keep: int, cfg: SelectionConfig,
                   residual: torch.Tensor | None = None,
                   generator: torch.Generator | None = None,
                   trusted: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
    """The core: ``keep`` of K samples per item. features [K, M, F] (what coverage is measured
    on), residual [K, M] (lower is better; needed by the score methods) -> idx [keep, M].
    ``trusted`` [M] bool (score methods; None: all): the other items are selected by the
    method's score-free counterpart."""
    k, m_items, _ = features.shape
    if keep > k:
        raise ConfigError(f"cannot keep {keep} of {k} samples")
    method = cfg.method
    if USES_SCORE.get(method) and residual is None:
        raise ConfigError(f"selection {method!r} needs the diffusion score (a scorer)")
    if trusted is not None and USES_SCORE.get(method) and not bool(trusted.all()):
        with_score = _select(features, keep, cfg, residual, generator)  # [keep, M]
        free = dataclasses.replace(cfg, method=SCORE_FREE[method])
        without = _select(features, keep, free, None, generator)  # [keep, M]
        return torch.where(trusted.to(features.device)[None], with_score, without)
    return _select(features, keep, cfg, residual, generator)


def _select(features: torch.Tensor, keep: int, cfg: SelectionConfig,
            residual: torch.Tensor | None,
            generator: torch.Generator | None) -> torch.Tensor:  # fmt: skip
    """``select_indices`` for every item by ``cfg.method``: [K, M, F] -> [keep, M]. Each
    method has its own branch, matched by its exact name; a name without one is an error."""
    k, m_items, _ = features.shape
    method = cfg.method
    device = features.device
    if method == "first":
        return torch.arange(keep, device=device)[:, None].expand(-1, m_items)
    if method == "random":
        noise = torch.rand((k, m_items), generator=generator, dtype=torch.float32).to(device)
        return noise.argsort(0)[:keep]
    if method == "top":
        return residual.argsort(0)[:keep]
    valid = torch.ones(k, m_items, dtype=torch.bool, device=device)  # [K, M]
    if method in DROPPING:
        kept = max(keep, k - int(cfg.drop * k))  # the best `kept` by the score stay
        order = residual.argsort(0)  # [K, M] best first
        valid = torch.zeros_like(valid).scatter_(0, order[:kept], True)
        first = order[0]  # cover outward from the best-scored sample
    else:  # start from the sample nearest the mean of all K
        first = (features - features.mean(0, keepdim=True)).pow(2).sum(-1).argmin(0)  # [M]
    if method == "score-first":  # the generator's own order, skipping the worst-scored
        rank = torch.arange(k, device=device)[:, None] + k * (~valid).to(torch.int64)  # [K, M]
        return rank.argsort(0)[:keep]
    if method in ("kmeans", "score-kmeans"):
        return _kmeans(features, valid, first, keep, cfg.iters)
    if method in ("fps", "score-fps"):
        return _farthest_points(features, valid, first, keep)
    if method in ("facility", "score-facility"):
        weight = _target_weight(residual, cfg, features)  # [K, M]
        return _facility(features, valid, weight, keep, cfg.bandwidth)
    if method in ("medoids", "score-medoids"):
        weight = _target_weight(residual, cfg, features)  # [K, M]
        return _medoids(features, valid, weight, keep, MEDOID_PASSES)
    raise ConfigError(f"selection method {method!r} has no branch in score.selection._select "
                      f"(the methods: {', '.join(METHODS)})")  # fmt: skip


def _target_weight(residual: torch.Tensor | None, cfg: SelectionConfig,
                   features: torch.Tensor) -> torch.Tensor:  # fmt: skip
    """Each sample's weight as a target of the coverage methods [K, M]: exp(-z / T) for
    ``score-facility`` and ``score-medoids`` (z the residual standardised over the item's K
    samples, T ``cfg.temperature``), 1 for the score-free ``facility`` and ``medoids``."""
    if cfg.method not in WEIGHTED:
        return torch.ones(features.shape[:2], dtype=features.dtype, device=features.device)
    if residual.shape[0] < 2:  # one sample has no spread: z = 0 (std would warn and be NaN)
        return torch.ones_like(residual)
    z = (residual - residual.mean(0)) / residual.std(0).clamp(min=1e-12)  # [K, M]
    return torch.exp(-z / cfg.temperature)


def select_samples(pred: torch.Tensor, cfg: SelectionConfig, residual: torch.Tensor | None = None,
                   batch: Batch | None = None,
                   generator: torch.Generator | None = None,
                   trusted: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
    """Keep ``cfg.keep`` of the K samples pred [K, N, T_f, 2] -> idx [K', N].

    Coverage is measured on the endpoints. ``residual`` [K, N] is each sample's residual
    per agent. With ``per="scene"`` (``batch`` needed for the scene index), a scene's agents
    share one set of indices, chosen on their stacked endpoints and summed residuals.
    ``trusted`` [N] bool (None: all): agents whose score is used (``within_pace``); a scene
    is trusted when all its agents are."""
    ends = pred[..., -1, :]  # [K, N, 2]
    if cfg.per == "agent":
        return select_indices(ends, cfg.keep, cfg, residual, generator, trusted)
    if batch is None:
        raise ConfigError("per-scene selection needs the batch (its scene index)")
    slot, mask = batch.padded_index()  # [N], [B, P]
    k = pred.shape[0]
    b, p = mask.shape
    feats = ends.new_zeros(k, b, p, 2)  # padding is zero for every sample: no distance
    feats[:, batch.scene, slot] = ends
    scene_res = None if residual is None else scene_sum(residual, batch.scene, b)  # [K, B]
    scene_ok = None  # a scene with any untrusted agent falls back
    if trusted is not None:
        scene_ok = scene_sum((~trusted).to(ends.dtype), batch.scene, b) == 0  # [B]
    idx = select_indices(feats.flatten(2), cfg.keep, cfg, scene_res, generator, scene_ok)
    return idx[:, batch.scene]  # [K', N]


def batch_observed_pace(batch: Batch, scale: float) -> torch.Tensor:
    """Each agent's observed displacement per step [N], first to last observed position, in
    model units (data units / ``scale``): the measure of ``model.max_speed``;
    ``data.transforms.observed_pace`` of the batch's histories."""
    return transforms.observed_pace(batch.history, scale)  # [N]


def within_pace(batch: Batch, scale: float, trust_speed: float) -> torch.Tensor | None:
    """Agents [N] bool whose ``batch_observed_pace`` is at most ``trust_speed``; None when the
    gate is off (``trust_speed`` 0)."""
    if trust_speed <= 0:
        return None
    return batch_observed_pace(batch, scale) <= trust_speed


def score_steps(scorer: TrajectoryScorer, cfg: SelectionConfig) -> TrajectoryScorer:
    """``scorer`` at the selection's score steps (``cfg.score_every`` from ``cfg.score_from``;
    ``score_every`` None: its own steps), sharing its denoiser."""
    if cfg.score_every is None:
        return scorer
    steps = score_timesteps(scorer.schedule.num_steps, cfg.score_every, cfg.score_from)
    return scorer.with_steps(steps)


@torch.no_grad()
def select_with_scorer(pred: torch.Tensor, cfg: SelectionConfig, batch: Batch,
                       scorer: TrajectoryScorer | None,
                       generator: torch.Generator | None = None) -> torch.Tensor:  # fmt: skip
    """``select_samples`` with the residual and the pace gate computed by ``scorer`` at the
    config's score steps (``score_steps``; only for the methods that read the score):
    pred [K, N, T_f, 2] -> idx [K', N]."""
    return _select_scored(pred, cfg, batch, scorer, generator)[0]


def _select_scored(pred: torch.Tensor, cfg: SelectionConfig, batch: Batch,
                   scorer: TrajectoryScorer | None, generator: torch.Generator | None
                   ) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:  # fmt: skip
    """``select_with_scorer``, with what it computed on the way: idx [K', N], the residual
    [K, N] (None for a method that reads no score) and ``scored`` [N] bool, the agents whose
    indices were chosen with the score (``select_samples``' fallback: an agent outside the
    pace gate, or with ``per="scene"`` any agent of its scene, is chosen by the method's
    score-free counterpart; every agent, for a method that reads no score)."""
    residual = trusted = None
    if cfg.uses_score:
        if scorer is None:  # select_indices' own check, before the scorer is used
            raise ConfigError(f"selection {cfg.method!r} needs the diffusion score (a scorer)")
        d = score_steps(scorer, cfg).residual(batch, pred)  # [K, N, T_f]
        residual = d[..., -1] if cfg.final else d.sum(-1)  # [K, N]
        trusted = within_pace(batch, scorer.scale, cfg.trust_speed)  # [N] or None
    idx = select_samples(pred, cfg, residual, batch, generator, trusted)  # [K', N]
    n = pred.shape[1]
    scored = torch.full((n,), cfg.uses_score, dtype=torch.bool, device=pred.device)  # [N]
    if trusted is not None:
        scored = trusted.to(pred.device)
        if cfg.per == "scene":  # a scene falls back as a whole when any agent of it does
            whole = scene_sum((~scored).to(pred.dtype), batch.scene, batch.num_scenes) == 0
            scored = whole[batch.scene]  # [N]
    return idx, residual, scored


class SceneSelection(typing.NamedTuple):
    """What ``select_for_scene(..., return_info=True)`` returns (numpy arrays, or tensors
    when an input was one)."""

    idx: typing.Any
    """[K', P] int64 sample indices per agent, in selection order (the default return)."""
    residual: typing.Any
    """[K, P] float32 each sample's residual per agent at ``cfg``'s score steps, summed over
    the future steps (the last step only with ``cfg.final``): lower is more human-like; the
    numbers the selection read. None for a method that reads no score (nothing is scored)."""
    trusted: typing.Any
    """[P] bool: the agents whose samples were chosen with the score. False for an agent
    observed faster than ``cfg.trust_speed`` (model units per step, ``within_pace``), which
    falls back to the method's score-free counterpart (``SCORE_FREE``; with
    ``cfg.per="scene"`` every agent, when any does), and for every agent of a method that reads
    no score. Its ``residual`` is still there, but the selection did not use it."""


def select_for_scene(scorer: TrajectoryScorer, history, samples, cfg: SelectionConfig,
                     agent_type=None, *, frame_interval: float | None = None,
                     units: str | None = None, return_info: bool = False):  # fmt: skip
    """Keep ``cfg.keep`` of the K sampled futures of ONE scene given only its history (the
    planning use, beside ``rank_samples``): history [P, T_h, 2], samples [K, P, T_f, 2]
    (numpy arrays or tensors, in the scorer's units and lengths; the scorer checks them, and
    its score is computed only for the methods that read it, at ``cfg``'s score steps: with
    the defaults, what ``trajpref predict --keep`` keeps). Returns idx [K', P], sample
    indices per agent in selection order (with ``cfg.per="scene"`` the P columns are equal):
    numpy when neither input is a tensor, else a tensor. Take the futures with
    ``samples[idx, np.arange(P)]``. ``chosen_selection`` gives each published model's chosen
    ``cfg``. ``agent_type``, ``frame_interval`` and ``units``: as ``rank_samples`` (a
    selection that reads the score of a scorer trained with the ball flagged, given no
    ``agent_type``, warns). The checks are
    ``rank_samples``' (``scene_batch``; samples that do not continue the history, in another
    frame or given as offsets, are a ``DataError``). A scene without agents (history
    [0, T_h, 2], samples [K, 0, T_f, 2]: an empty view) gives idx [K', 0] (``cfg.keep``
    still at most K) without running the scorer.

    ``return_info=True`` returns a ``SceneSelection`` ``(idx, residual, trusted)`` instead
    of idx alone, from the same pass (nothing is scored twice): ``residual`` [K, P], each
    sample's residual per agent as the selection read it (None for a method that reads no
    score), and ``trusted`` [P] bool, the agents whose samples were chosen with the score
    (False: chosen by coverage alone, as for an agent observed faster than
    ``cfg.trust_speed``). The kept samples' residuals: ``residual[idx, np.arange(P)]``. A
    ``cfg`` that is no ``SelectionConfig`` (None, a dict) is a ``ConfigError``."""
    cfg = check_selection(cfg, "select_for_scene")
    batch, pred = scene_batch(scorer, history, samples, agent_type, frame_interval=frame_interval,
                              units=units, allow_empty=True)  # pred [K, P, T_f, 2]  # fmt: skip
    if agent_type is None and batch.num_agents and cfg.uses_score and reads_agent_types(scorer):
        warn_untyped(scorer, "select_for_scene", stacklevel=3)  # the ball scored as a player
    if agent_type is not None and batch.num_agents and cfg.uses_score:  # one ball a scene
        balls = int((batch.agent_type == AGENT_BALL).sum())
        warn_ball_count(scorer, "select_for_scene", [(0, balls)], stacklevel=3)
    if batch.num_agents == 0:  # an empty view: K' rows of no agent's indices
        if cfg.keep > pred.shape[0]:
            raise ConfigError(f"cannot keep {cfg.keep} of {pred.shape[0]} samples")
        idx = torch.empty(cfg.keep, 0, dtype=torch.int64, device=pred.device)  # [K', 0]
        residual = pred.new_zeros(pred.shape[0], 0) if cfg.uses_score else None  # [K, 0]
        scored = torch.zeros(0, dtype=torch.bool, device=pred.device)  # [0]
    else:
        generator = torch.Generator().manual_seed(cfg.seed)
        idx, residual, scored = _select_scored(pred, cfg, batch, scorer, generator)  # [K', P]
    as_tensor = isinstance(history, torch.Tensor) or isinstance(samples, torch.Tensor)
    out = [idx, residual, scored] if as_tensor else [
        None if t is None else t.cpu().numpy() for t in (idx, residual, scored)]  # fmt: skip
    return SceneSelection(*out) if return_info else out[0]


def derived_generator(generator: torch.Generator, seed: int,
                      content: torch.Tensor | None = None) -> torch.Generator:  # fmt: skip
    """A new CPU generator seeded from ``generator``'s current state, ``seed`` and ``content``
    (a tensor, e.g. a batch's histories), without drawing from ``generator``: the same state,
    seed and content give the same draws, and the sampler's stream (what later batches draw
    from it) is left as it was. ``content`` tells batches apart where the sampler draws
    nothing from ``generator`` (the published generators), whose state then never moves."""
    state = generator.get_state().cpu().numpy().tobytes()
    if content is not None:
        state += content.detach().to("cpu", torch.float32).contiguous().numpy().tobytes()
    digest = hashlib.blake2b(state + f"|{seed}".encode(), digest_size=8).digest()
    return torch.Generator().manual_seed(int.from_bytes(digest, "little") >> 1)


def gather(pred: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """pred [K, N, ...] at idx [K', N] -> [K', N, ...]."""
    shape = (*idx.shape, *pred.shape[2:])
    return pred.gather(0, idx.reshape(*idx.shape, *([1] * (pred.ndim - 2))).expand(shape))


class SelectingPredictor:
    """A predictor that draws K samples from ``base`` and keeps K' of them (``cfg.keep``):
    ``predict(batch, K', generator)`` returns [K', N, T_f, 2]. The ground truth is never read.
    Any object with ``predict(batch, K, generator)`` can be the base."""

    def __init__(self, base, cfg: SelectionConfig, candidates: int = 20,
                 scorer: TrajectoryScorer | None = None):  # fmt: skip
        cfg = check_selection(cfg, "SelectingPredictor")
        if cfg.uses_score and scorer is None:
            raise ConfigError(f"selection {cfg.method!r} needs a scorer")
        if cfg.keep > candidates:
            raise ConfigError(f"cannot keep {cfg.keep} of {candidates} samples")
        ours = (getattr(base, "t_hist", None), getattr(base, "t_fut", None))
        if scorer is not None and None not in ours and ours != (scorer.t_hist, scorer.t_fut):
            raise ConfigError(f"the model reads windows of {ours[0]} observed + {ours[1]} future "
                              f"frames, the scorer {scorer.t_hist} + {scorer.t_fut}: a scorer "
                              "scores futures of its own length; give one trained on the "
                              "same window lengths")  # fmt: skip
        self.base = base
        self.cfg = cfg
        self.candidates = candidates
        self.scorer = scorer
        self.name = f"{getattr(base, 'name', 'model')}+{cfg.method}{cfg.keep}"
        self.generator = torch.Generator().manual_seed(cfg.seed)
        """The ``random`` method's draws when ``predict`` is given no generator (and
        ``select``'s default): seeded once, so they go on from call to call."""
        self.last_kept: torch.Tensor | None = None
        """[K', N] the indices, among the K samples drawn, of those the last ``predict`` kept
        (``trajpref predict --keep`` saves them as ``kept``)."""

    @property
    def t_hist(self) -> int | None:
        """The base predictor's T_h (None: any, as the constant-velocity baseline)."""
        return getattr(self.base, "t_hist", None)

    @property
    def t_fut(self) -> int | None:
        """The base predictor's T_f (None: any)."""
        return getattr(self.base, "t_fut", None)

    @torch.no_grad()
    def select(self, batch: Batch, pred: torch.Tensor,
               generator: torch.Generator | None = None) -> torch.Tensor:  # fmt: skip
        """Indices [K', N] of the samples pred [K, N, T_f, 2] to keep; ``generator``: the
        ``random`` method's draws (None: the object's own, ``self.generator``)."""
        draws = self.generator if generator is None else generator
        return select_with_scorer(pred, self.cfg, batch, self.scorer, draws)

    @torch.no_grad()
    def predict(self, batch: Batch, num_samples: int | None = None,
                generator: torch.Generator | None = None) -> torch.Tensor:  # fmt: skip
        """[K', N, T_f, 2]: K (``candidates``) samples drawn from the base predictor, and the
        K' (``cfg.keep``) of them the selection keeps, in its order; their indices among the
        K are left in ``last_kept``. The ``random`` method draws from a generator seeded with
        ``cfg.seed``, the batch's histories and ``generator``'s state after the base's draws
        (``derived_generator``:
        ``generator`` itself is not drawn from, so every method sees the same candidates), so
        that the same seed repeats a whole pass (``evaluate(seed=...)``), whether the object
        is new or reused; without a ``generator``, from the object's own
        (``self.generator``)."""
        if num_samples is not None and num_samples != self.cfg.keep:
            raise ConfigError(f"this selector keeps {self.cfg.keep} samples, asked for "
                              f"{num_samples}")  # fmt: skip
        pred = self.base.predict(batch, self.candidates, generator)  # [K, N, T_f, 2]
        draws = None  # the object's own generator
        if generator is not None and self.cfg.method == "random":  # the others draw nothing
            draws = derived_generator(generator, self.cfg.seed, batch.history)
        self.last_kept = self.select(batch, pred, draws)  # [K', N]
        return gather(pred, self.last_kept)
