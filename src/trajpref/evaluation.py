"""The one evaluation loop, shared by every model, every stage's validation and the CLI."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Literal, Protocol

import numpy as np
import torch
from tqdm.auto import tqdm

from trajpref.data.loader import SceneLoader
from trajpref.data.registry import ETH_UCY, NAMES, sgan_folds
from trajpref.data.trajnet import from_trajnet, require_future
from trajpref.device import resolve_device
from trajpref.errors import ConfigError, DataError, TrajprefError
from trajpref.io import bar_options
from trajpref.metrics import (
    BinnedMetrics,
    CollisionAccumulator,
    CollisionFlags,
    MetricAccumulator,
    SlotMetrics,
    check_bin_edges,
    check_collision_radius,
    collision_flags,
    default_collision_radius,
)
from trajpref.score.scorer import ScoreAccumulator, ScoreResult, TrajectoryScorer, score_result
from trajpref.score.selection import gather
from trajpref.types import AGENT_BALL, AGENT_PERSON, Batch, TrajectoryDataset, collate

COLLISION_KEYS = ("col_i_pct", "col_ii_pct", "col_gt_pct", "col_agents", "col_radius")
"""The collision keys of ``evaluate``'s result (None when the collision metrics are off)."""

AGENT_SETS = ("all", "persons", "primary")
"""Which agents ``evaluate``'s metrics average over (its ``agents``; the CLI's ``--agents``):
``all`` (every predicted agent, NBA's ball included: the published numbers), ``persons``
(``agent_type`` ``AGENT_PERSON`` only: NBA's players, as SocialVAE scores its NBA split; the
ball stays in each scene as a neighbour the model reads, and leaves every metric), or
``primary`` (each scene's first agent only: TrajNet++'s primary pedestrian, as its evaluator
scores; TrajNet++ scenes only, ``trajnet_scenes``)."""


class Predictor(Protocol):
    """Anything that samples futures: ``predict(batch, K, generator)`` returns a floating-point
    torch tensor [K, N, T_f, 2] of absolute positions (the data's coordinates, not offsets),
    exactly K samples of every agent of the batch, finite, on the batch's device, its random
    draws taken from ``generator`` (a seeded CPU ``torch.Generator``) so that a seed repeats
    them. The evaluation pass checks each batch's output (``check_prediction``)."""

    name: str

    def predict(
        self, batch: Batch, num_samples: int, generator: torch.Generator | None = None
    ) -> torch.Tensor: ...


class NotAPredictor(TrajprefError, TypeError):
    """What the evaluation loop was handed is not a loaded predictor or dataset (a model's
    name, a dataset's name)."""


class PredictionError(DataError):
    """A predictor's ``predict`` returned something the evaluation cannot score: not a torch
    tensor, not floating point, not [K, N, T_f, 2] for the batch and the K asked, on another
    device than the batch's, or holding NaN / infinite values (``check_prediction``)."""


class NonFinitePrediction(PredictionError):
    """A predictor returned NaN or infinite positions (``check_prediction``): a model that
    diverged, not a wrong interface; training's validation scores it as never the best."""


def check_prediction(model: object, pred: object, batch: Batch, num_samples: int) -> None:
    """``PredictionError`` (a ``DataError``) naming the predictor's class unless ``pred``,
    what ``model.predict(batch, num_samples, generator)`` returned, is a floating-point torch
    tensor of shape exactly [num_samples, N, T_f, 2] (N and T_f the batch's, ``batch.future``
    [N, T_f, 2]), on the batch's device, and finite. What the one evaluation pass
    (``sampled_batches``) checks of every batch, before a metric reads it."""
    who = f"{type(model).__name__}.predict"
    n, t_f = batch.num_agents, int(batch.future.shape[1])
    want = (num_samples, n, t_f, 2)
    spec = f"[K, N, T_f, 2] = {list(want)}"
    if isinstance(pred, np.ndarray):
        raise PredictionError(f"{who} returned a numpy array; predictors return a torch tensor "
                              f"{spec} on the batch's device: convert it with "
                              "torch.from_numpy(pred).to(batch.history)")  # fmt: skip
    if not isinstance(pred, torch.Tensor):
        raise PredictionError(f"{who} returned {type(pred).__name__}, not a torch tensor "
                              f"{spec}")  # fmt: skip
    if not pred.is_floating_point():
        raise PredictionError(f"{who} returned a tensor of dtype "
                              f"{str(pred.dtype).removeprefix('torch.')}: positions must be "
                              "floating point (pred.float(), or build them from batch.history, "
                              "float32)")  # fmt: skip
    shape = tuple(pred.shape)
    if shape != want:
        raise PredictionError(f"{who} returned shape {list(shape)} for a batch of N = {n} "
                              f"agents, T_f = {t_f} future steps and K = {num_samples} samples "
                              f"asked: it must be {spec}{_shape_hint(shape, want)}")  # fmt: skip
    if pred.device != batch.history.device:
        raise PredictionError(f"{who} returned a tensor on {pred.device}, the batch is on "
                              f"{batch.history.device}: return it on the batch's device "
                              "(.to(batch.history.device))")  # fmt: skip
    bad = ~torch.isfinite(pred)  # [K, N, T_f, 2]
    if bool(bad.any()):
        agents = bad.flatten(2).any(-1)  # [K, N]
        k, a = (int(i) for i in agents.nonzero()[0])
        scene = int(batch.scene[a])
        sid = batch.scene_ids[scene] if scene < len(batch.scene_ids) else f"#{scene}"
        found = (("NaN", torch.isnan(pred)), ("infinite", torch.isinf(pred)))
        kinds = " and ".join(word for word, where in found if bool(where.any()))
        raise NonFinitePrediction(f"{who} returned {kinds} values ({int(agents.sum())} of "
                              f"{agents.numel()} agent-samples; the first: sample {k} of agent "
                              f"{a} in this batch, of scene {sid}): every predicted position "
                              "must be finite")  # fmt: skip


def _shape_hint(shape: tuple, want: tuple) -> str:
    """What a wrong prediction shape most likely is, for ``check_prediction``'s message."""
    k, n, t_f, _ = want
    if len(shape) == 4 and shape[1:] == want[1:]:
        return (f"; it gave {shape[0]} samples where evaluate asked for K = {k} "
                "(evaluate's num_samples; the metrics are minADE_K / minFDE_K over exactly "
                "these K)")  # fmt: skip
    if len(shape) == 4 and shape == (n, k, t_f, 2):
        return "; it looks like [N, K, T_f, 2]: put the samples first, pred.transpose(0, 1)"
    if shape == want[1:]:
        return "; the sample axis is missing: stack the K samples along a first axis"
    if len(shape) == 4 and shape[:2] == want[:2] and shape[3] == 2:
        return f"; it gave {shape[2]} future steps where the batch's future has {t_f}"
    if len(shape) == 4 and shape[:3] == want[:3]:
        return f"; its last axis holds {shape[3]} coordinates where positions are (x, y)"
    return ""


def check_inputs(model: object, dataset: object) -> None:
    """``NotAPredictor`` unless ``model`` has a ``predict`` method and ``dataset`` is a
    ``TrajectoryDataset``: before any work, and saying how to load each from its name."""
    if not callable(getattr(model, "predict", None)):
        hint = ""
        if isinstance(model, str):
            hint = (f": load it first, trajpref.models.registry.load_predictor({model!r}), "
                    "and pass what it returns")  # fmt: skip
        raise NotAPredictor(f"model must be a predictor (an object with predict(batch, K, "
                            f"generator)), got {type(model).__name__}{hint}")  # fmt: skip
    if not isinstance(dataset, TrajectoryDataset):
        hint = ""
        if isinstance(dataset, str):
            hint = (f": load it first, trajpref.data.load_dataset({dataset!r}, split), and "
                    "pass what it returns")  # fmt: skip
        raise NotAPredictor(f"dataset must be a TrajectoryDataset, got "
                            f"{type(dataset).__name__}{hint}")  # fmt: skip


def data_folds(dataset: TrajectoryDataset) -> tuple[str, ...]:
    """The ETH/UCY folds whose data ``dataset`` is: a fold's name (``dataset.info.name``), or
    a folder holding Social-GAN's test files of folds (``registry.sgan_folds``); empty
    otherwise."""
    name = dataset.info.name
    if name in ETH_UCY:
        return (name,)
    return () if name in NAMES else sgan_folds(name)


def _trained_folds(model: object, scorer: object) -> list[tuple[str, str]]:
    """``(role, fold)`` for the model and scorer (a selecting predictor's base and scorer
    included) whose ``timing`` (``models.timing.attach_timing``: a loaded checkpoint's
    record) says they were trained on an ETH/UCY fold."""
    found = []
    for role, obj in (("model", model), ("model", getattr(model, "base", None)),
                      ("scorer", getattr(model, "scorer", None)), ("scorer", scorer)):  # fmt: skip
        timing = getattr(obj, "timing", None)
        fold = timing.get("trained_on") if isinstance(timing, dict) else None
        if isinstance(fold, str) and fold in ETH_UCY and (role, fold) not in found:
            found.append((role, fold))
    return found


def check_fold_overlap(model: object, dataset: TrajectoryDataset, scorer: object = None) -> None:
    """ConfigError when the model (or scorer) was trained on an ETH/UCY fold other than the
    data's (``data_folds``): Social-GAN's leave-one-out training files of one fold hold most
    of the other folds' windows (84 % of the rows of zara1's test file are in the zara2
    fold's training files), so such a model has seen this data, whatever the split. What the
    CLI's ``evaluate`` refuses without ``--allow-overlap``; models without a record
    (``timing`` None: cv, a model built in code) pass."""
    folds = data_folds(dataset)
    if not folds:
        return
    found = [(role, fold) for role, fold in _trained_folds(model, scorer)
             if any(f != fold for f in folds)]  # fmt: skip
    if not found:
        return
    where = dataset.info.name
    own = " and ".join(folds)
    if where not in ETH_UCY:
        where = f"{where} (it holds {own}'s Social-GAN test files)"
    trained = "; ".join(f"the {role} was trained on the {fold} fold, whose leave-one-out "
                        f"training files (the other four scenes') hold most of {own}'s windows"
                        for role, fold in found)  # fmt: skip
    raise ConfigError(f"evaluate on {where}: {trained}, so this evaluates on data it trained "
                      f"on: evaluate each fold with its own fold's models, or pass "
                      "allow_overlap=True to evaluate it anyway")  # fmt: skip


@torch.no_grad()
def sampled_batches(
    model: Predictor, dataset: TrajectoryDataset, num_samples: int = 20, seed: int = 0,
    device: torch.device | str = "cpu", max_agents: int = 1024, progress: bool = True,
    desc: str = "sample",
) -> Iterator[tuple[Batch, torch.Tensor]]:  # fmt: skip
    """The one pass over a split: ``(batch, pred [K, N, T_f, 2])`` for every batch of whole
    scenes, in dataset order, with one seeded CPU generator for the whole pass. ``device`` as
    ``trajpref.device.resolve_device`` takes it (``auto``: CUDA when available, else the CPU;
    a device this machine lacks is a ``ConfigError``). Each batch's prediction is checked
    (``check_prediction``: K = ``num_samples`` samples of every agent, finite, ...)."""
    check_inputs(model, dataset)
    device = resolve_device(device)
    gen = torch.Generator().manual_seed(seed)  # CPU: draws are identical on every device
    loader = SceneLoader(dataset, max_agents=max_agents, shuffle=False)
    for batch in tqdm(loader, desc=desc, unit="batch", leave=False, **bar_options(progress)):
        batch = batch.to(device)
        pred = model.predict(batch, num_samples, gen)
        check_prediction(model, pred, batch, num_samples)
        yield batch, pred


def resolve_collision_radius(radius: float | None | Literal["auto"], units: str) -> float | None:
    """The collision radius to use: ``auto`` is TrajNet++'s 0.1 m for data in metres and None
    (collision metrics off) for other units; a number is a radius in the data's units."""
    if radius == "auto":
        return default_collision_radius(units)
    if radius is not None:
        try:
            check_collision_radius(radius)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    return radius


def bodies(batch: Batch) -> torch.Tensor:
    """[N] bool: the agents of a batch that can collide (``metrics.collision_flags``): every
    one but NBA's ball (``AGENT_BALL``), which a player holds without colliding with it."""
    return batch.agent_type != AGENT_BALL


def select_agents(batch: Batch, pred: torch.Tensor, keep: torch.Tensor,
                  result: ScoreResult | None = None
                  ) -> tuple[Batch, torch.Tensor, ScoreResult | None]:  # fmt: skip
    """The agents of a batch where ``keep`` [N] bool is True, and their samples pred
    [K, N, T_f, 2] -> (batch of N' agents, pred [K, N', T_f, 2], ``result`` over them): what
    ``evaluate(agents="persons" | "primary")`` computes its metrics on, after the model (and
    the scorer, ``result``: ``TrajectoryScorer.score`` of the whole batch) read every agent.
    Scenes without a kept agent are left out and the others numbered 0..B'-1 in order;
    context-only agents are left out (no metric reads them). N' and B' may be 0."""
    scene = batch.scene[keep]  # [N'] the kept agents' scenes, old numbers
    present = torch.bincount(scene, minlength=batch.num_scenes) > 0  # [B]
    renumber = torch.cumsum(present, 0) - 1  # [B] each kept scene's new index
    ids = [i for i, p in zip(batch.scene_ids, present.tolist(), strict=False) if p]
    view = Batch(history=batch.history[keep], future=batch.future[keep], scene=renumber[scene],
                 agent_type=batch.agent_type[keep], num_scenes=int(present.sum()),
                 scene_ids=ids)  # fmt: skip
    if result is not None:
        result = score_result(result.d_pred[:, keep], result.d_gt[keep], view.scene,
                              view.num_scenes)  # fmt: skip
    return view, pred[:, keep], result


def first_agents(batch: Batch) -> torch.Tensor:
    """[N] bool: each scene's first agent in the batch (whose scenes are whole, their agents
    in the scene's order): TrajNet++'s primary pedestrian for its scenes, which
    ``data.trajnet.read_trajnet`` lists first."""
    first = torch.ones_like(batch.scene, dtype=torch.bool)  # [N]
    first[1:] = batch.scene[1:] != batch.scene[:-1]
    return first


def trajnet_scenes(dataset: TrajectoryDataset) -> bool:
    """Whether every scene of ``dataset`` was read from a TrajNet++ ``.ndjson`` file
    (``data.trajnet.from_trajnet``: the reader records each scene's source row, frames and
    ids), so that each scene's first agent is its primary pedestrian."""
    return from_trajnet(dataset.scenes)


def _agent_mask(batch: Batch, agents: str) -> torch.Tensor | None:
    """[N] bool: the agents ``evaluate(agents=...)`` scores (None: all of them)."""
    if agents == "persons":
        return batch.agent_type == AGENT_PERSON
    if agents == "primary":
        return first_agents(batch)
    return None


@torch.no_grad()
def evaluate(
    model: Predictor, dataset: TrajectoryDataset, num_samples: int = 20, seed: int = 0,
    device: torch.device | str = "cpu", max_agents: int = 1024, progress: bool = True,
    scorer: TrajectoryScorer | None = None,
    collision_radius: float | None | Literal["auto"] = "auto",
    bins: tuple[int, ...] | None = None,
    allow_overlap: bool = False,
    agents: Literal["all", "persons", "primary"] = "all",
    slots: int | None = None,
) -> dict:  # fmt: skip
    """minADE_K / minFDE_K per agent and joint over a whole split; with a ``scorer``, also
    maxATS_K / maxFTS_K and the top-1 / top-5 recall of the ground-truth-free ranking.

    With a collision radius (``auto``: 0.1 m on data in metres, off otherwise; see
    ``resolve_collision_radius``), also Col-I / Col-II and the ground truth's own rate
    (``col_i_pct``, ``col_ii_pct``, ``col_gt_pct``, ``col_agents``, ``col_radius``;
    docs/social.md); when off, these keys hold None. With ``bins`` (upper edges of scene-size
    bins, e.g. ``metrics.SCENE_SIZE_EDGES``), ``out["bins"]`` maps each bin's label to the same
    metrics over its scenes (maxATS / maxFTS / meanATS with a scorer). With ``slots`` = R,
    ``out["slots"]`` maps each agent's place in its scene (``"1"`` .. ``"R"``, then ``">R"``
    for the rest) to minADE / minFDE (and Col-I / Col-II) over the agents in that place
    (``metrics.SlotMetrics``): Robo's leader, follower and approacher for R = 3, the roles
    its scenes list in that order; elsewhere a place is only the listing order. With
    ``agents="persons"`` the places count the persons alone.

    ``agents="persons"`` computes every metric over the agents of ``agent_type``
    ``AGENT_PERSON`` only (NBA's players: SocialVAE's protocol; ``AGENT_SETS``): the model and
    the scorer still read the whole scene, the ball as a neighbour, but per-agent metrics
    average over the persons, joint metrics over each scene's persons (scenes without one left
    out), collisions are counted among the persons, and scene-size bins count persons. The
    result then holds ``agent_set: "persons"`` (absent for ``all``, the result as before), so
    that it is never taken for the all-agents number; a split without a person is a
    ``DataError``.

    ``agents="primary"`` computes every metric over each scene's first agent only: TrajNet++'s
    primary pedestrian, the one agent per scene its evaluator scores (the model and the
    scorer still read the whole scene). Each scene then counts once, so joint metrics equal
    the per-agent ones; Col-I / Col-II test the primary's sample against every neighbour of
    its scene (their samples, their ground truth), over the primaries with a neighbour. The
    result holds ``agent_set: "primary"``. Only for TrajNet++ scenes (``trajnet_scenes``):
    elsewhere the first agent is merely the smallest id, so other data are a ``ConfigError``,
    as are ``bins`` (every scene would have one agent).

    ``model`` is a loaded predictor (``load_predictor(name)``), not a name: ``NotAPredictor``
    (a ``TypeError``) otherwise, before any work. What its ``predict`` returns for each batch
    is checked (``check_prediction``): a floating-point tensor [K, N, T_f, 2] with K =
    ``num_samples`` exactly, on the batch's device, finite; else a ``PredictionError`` (a
    ``DataError``) naming the predictor's class. ``device``: where the batches go, as
    ``trajpref.device.resolve_device`` takes it (``auto``, ``cpu``, ``cuda[:i]``; a device
    this machine lacks is a ``ConfigError`` before any work).

    A model (or ``scorer``) whose checkpoint says it was trained on one ETH/UCY fold
    (``model.timing["trained_on"]``), evaluated on another fold's data (a fold's name, or a
    folder holding another fold's Social-GAN test files), is a ConfigError before any work
    (``check_fold_overlap``: its leave-one-out training files hold most of that fold's
    windows); ``allow_overlap=True`` evaluates it anyway, as the CLI's ``--allow-overlap``.
    """
    check_inputs(model, dataset)
    device = resolve_device(device)  # before any work
    require_future(dataset, "evaluate")  # TrajNet++ test files: NaN metrics otherwise
    if agents not in AGENT_SETS:
        raise ConfigError(f"agents must be one of {', '.join(AGENT_SETS)}, got {agents!r}")
    persons = agents == "persons"
    if agents == "primary":
        if not trajnet_scenes(dataset):
            raise ConfigError(f"agents='primary' scores each scene's primary pedestrian, which "
                              f"only TrajNet++ scenes (.ndjson files) name; "
                              f"{dataset.info.name}/{dataset.info.split} is not TrajNet++ data, "
                              "so its first agent per scene would be an arbitrary one: use "
                              "agents='all' or 'persons' (--agents all|persons)")  # fmt: skip
        if bins is not None or slots is not None:
            raise ConfigError("agents='primary' does not combine with bins (--bins) or slots "
                              "(--slots): every scene has one primary, so every scene would "
                              "fall in the first bin, every agent in the first place")  # fmt: skip
    if persons and not any((s.agent_type == AGENT_PERSON).any() for s in dataset.scenes):
        raise DataError(f"agents='persons': {dataset.info.name}/{dataset.info.split} has no "
                        f"agent of agent_type {AGENT_PERSON} (person) to evaluate")  # fmt: skip
    if not allow_overlap:
        check_fold_overlap(model, dataset, scorer)
    radius = resolve_collision_radius(collision_radius, dataset.info.units)
    if bins is not None:
        try:
            check_bin_edges(bins)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    try:
        slot_acc = SlotMetrics(slots, radius) if slots is not None else None
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    acc = MetricAccumulator()
    col_acc = CollisionAccumulator(radius) if radius is not None else None
    bin_acc = BinnedMetrics(bins, radius) if bins is not None else None
    score_acc = ScoreAccumulator() if scorer is not None else None
    for batch, pred in sampled_batches(model, dataset, num_samples, seed, device, max_agents,
                                       progress, f"evaluate {dataset.info.name}"):  # fmt: skip
        res = scorer.score(batch, pred) if scorer is not None else None  # every agent read
        flags = None
        if col_acc is not None and agents == "primary":  # against every neighbour
            flags = collision_flags(pred, batch.future, batch.scene, radius,
                                    bodies=bodies(batch))  # fmt: skip
        keep = _agent_mask(batch, agents)  # [N] or None
        if keep is not None:  # the metrics below over the kept agents alone
            batch, pred, res = select_agents(batch, pred, keep, res)  # pred [K, N', T_f, 2]
            if flags is not None:  # each kept agent's flags, [N'] each
                flags = CollisionFlags(**{k: v[keep] for k, v in vars(flags).items()})
            if batch.num_agents == 0:  # no such agent in these scenes
                continue
        acc.update(pred, batch.future, batch.scene, batch.num_scenes)
        if col_acc is not None:
            if flags is None:  # among the agents kept
                flags = collision_flags(pred, batch.future, batch.scene, radius,
                                        bodies=bodies(batch))  # fmt: skip
            col_acc.add(flags)
        if score_acc is not None:
            score_acc.update(scorer, batch, pred, result=res)
        if bin_acc is not None:
            values = None
            if res is not None:  # per scene: [B] each
                values = {"max_ats": res.ats.amax(0), "max_fts": res.fts.amax(0),
                          "mean_ats": res.ats.mean(0)}  # fmt: skip
            bin_acc.update(pred, batch.future, batch.scene, batch.num_scenes, values, flags)
        if slot_acc is not None:
            slot_acc.update(pred, batch.future, batch.scene, batch.num_scenes, flags)
    out: dict = acc.compute()
    if col_acc is not None:
        out.update(col_acc.compute())
    else:
        out.update(dict.fromkeys(COLLISION_KEYS))
    if score_acc is not None:
        out.update(score_acc.compute())
    if bin_acc is not None:
        out["bins"] = bin_acc.compute()
    if slot_acc is not None:
        out["slots"] = slot_acc.compute()
    if agents != "all":
        out["agent_set"] = agents
    return out


@torch.no_grad()
def predict_dataset(
    model: Predictor, dataset: TrajectoryDataset, num_samples: int = 20, seed: int = 0,
    device: torch.device | str = "cpu", max_agents: int = 1024, progress: bool = True,
    scorer: TrajectoryScorer | None = None,
) -> dict[str, np.ndarray]:  # fmt: skip
    """Samples for a whole split, as the arrays ``trajpref predict`` saves.

    Returns ``history`` [N, T_h, 2], ``future`` [N, T_f, 2], ``pred`` [K, N, T_f, 2],
    ``scene`` [N] (scene index per agent, in dataset order), ``agent_type`` [N] and
    ``scene_id`` [B] (each scene's source and first frame, e.g. ``crowds_zara01.txt@frame=120``,
    as unicode strings, so a prediction maps back to the file it came from). With a
    ``scorer``, each scene's samples are reordered best first by the ground-truth-free
    ranking, and ``order`` [K, B] (original indices) and ``residual`` [K, B] are added. A
    selecting model (``SelectingPredictor``) adds ``kept`` [K, N]: each kept sample's index
    among the samples it drew, in ``pred``'s order (after the ranking, when there is one).
    Where every scene carries its agents' ids in the source data (``Scene.agent_id``: text
    track files and TrajNet++ files do), ``agent_id`` [N] is added (``source_agent_ids``).
    """
    check_inputs(model, dataset)
    device = resolve_device(device)  # before any work
    parts: dict[str, list[np.ndarray]] = {k: [] for k in ("history", "future", "pred", "scene")}
    parts["agent_type"] = []
    offset = 0
    for batch, pred in sampled_batches(model, dataset, num_samples, seed, device, max_agents,
                                       progress, f"predict {dataset.info.name}"):  # fmt: skip
        kept = getattr(model, "last_kept", None)  # [K, N] a selection's indices, if any
        if scorer is not None:
            total = scorer.scene_residual(batch, pred)  # [K, B]
            order = total.argsort(0)  # [K, B] best first
            pred = gather(pred, order[:, batch.scene])  # each scene's samples, best first
            if kept is not None:
                kept = kept.gather(0, order[:, batch.scene])  # [K, N] in the ranked order
            parts.setdefault("order", []).append(order.T.cpu().numpy())  # [B, K]
            parts.setdefault("residual", []).append(total.gather(0, order).T.cpu().numpy())
        if kept is not None:
            parts.setdefault("kept", []).append(kept.cpu().numpy())  # [K, N]
        parts["history"].append(batch.history.cpu().numpy())
        parts["future"].append(batch.future.cpu().numpy())
        parts["pred"].append(pred.cpu().numpy())
        parts["scene"].append(batch.scene.cpu().numpy() + offset)
        parts["agent_type"].append(batch.agent_type.cpu().numpy())
        offset += batch.num_scenes
    out = {k: np.concatenate(v, axis=1 if k in ("pred", "kept") else 0) for k, v in parts.items()}
    for key in ("order", "residual"):
        if key in out:
            out[key] = out[key].T  # [K, B]
    out["scene_id"] = np.array([s.scene_id for s in dataset.scenes], dtype=str)  # [B]
    ids = source_agent_ids(dataset, len(out["scene"]))  # [N] or None
    if ids is not None:
        out["agent_id"] = ids
    return out


def source_agent_ids(dataset: TrajectoryDataset, agents: int) -> np.ndarray | None:
    """[N] each predicted agent's id in the source data, in ``predict_dataset``'s order (the
    scenes in dataset order, each scene's agents in its order), from the scenes' ``agent_id``
    [P] where every scene carries one; None otherwise. Exact whatever the files mix: int64
    where every id is an integer, float64 where every id is a number float64 holds exactly
    (integers below 2**53 beside fractions such as 2.5), else every id as its text
    (``_id_text``: names, ids beyond int64, or integers from 2**53 on beside fractions, which
    float64 would round into each other)."""
    parts = [s.agent_id for s in dataset.scenes]
    if not parts or any(p is None for p in parts):
        return None
    arrays = [np.asarray(p).reshape(-1) for p in parts]  # [P_b] each
    if sum(len(a) for a in arrays) != agents:
        return None
    kinds = {a.dtype.kind for a in arrays}
    if kinds <= set("iu"):
        return np.concatenate(arrays).astype(np.int64)  # [N]
    if kinds <= set("iuf") and all(
            a.dtype.kind == "f" or (np.abs(a) < 2**53).all() for a in arrays):  # fmt: skip
        ids = np.concatenate([a.astype(np.float64) for a in arrays])  # [N] every one exact
        whole = np.isfinite(ids).all() and (ids == np.round(ids)).all()
        return ids.astype(np.int64) if whole else ids
    return np.concatenate([_id_text(a) for a in arrays])  # [N] every id as its text


def _id_text(ids: np.ndarray) -> np.ndarray:
    """[P] ids as exact text: integers as digits, floats as their shortest text without an
    exponent (``17``, ``2.5``, not ``17.0``), strings as they are."""
    if ids.dtype.kind == "f":
        return np.array([np.format_float_positional(v, trim="-") for v in ids.tolist()], str)
    return ids.astype(str)


@torch.no_grad()
def time_predictors(
    predictors: dict[str, Predictor],
    dataset: TrajectoryDataset,
    num_samples: int,
    scenes: int = 100,
    warmup: int = 2,
) -> dict[str, float]:
    """Milliseconds per scene of each predictor, timed side by side: the same ``scenes`` scenes
    (evenly spaced over the split), one scene per call, the predictors interleaved scene by
    scene so that a change in machine load hits them alike. ``warmup`` calls per predictor
    come first and are not counted. Returns ``{name: ms}`` plus ``"scenes"``."""
    if not predictors:
        raise ConfigError("time_predictors needs at least one predictor")
    if scenes < 1 or len(dataset) == 0:
        raise ConfigError("time_predictors needs at least one scene")
    batches = [collate([scene]) for scene in dataset.evenly_spaced(scenes)]
    for model in predictors.values():
        for b in batches[:warmup]:
            model.predict(b, num_samples, torch.Generator().manual_seed(0))
    total = dict.fromkeys(predictors, 0.0)
    for i, batch in enumerate(batches):
        for name, model in predictors.items():
            gen = torch.Generator().manual_seed(i)
            start = time.perf_counter()
            model.predict(batch, num_samples, gen)
            total[name] += time.perf_counter() - start
    return {name: 1000 * t / len(batches) for name, t in total.items()} | {"scenes": len(batches)}
