"""The one evaluation loop, shared by every model, every stage's validation and the CLI."""

from __future__ import annotations

import contextlib
import math
import os
import sys
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Protocol

import numpy as np
import torch
from tqdm.auto import tqdm

from trajpref.data.loader import SceneLoader
from trajpref.data.registry import (
    ETH_UCY,
    NAMES,
    SECONDS_STEPS,
    resolve_data_root,
    sgan_folds,
    split_folders,
    split_sources,
)
from trajpref.data.trajnet import from_trajnet, require_future
from trajpref.device import resolve_device
from trajpref.errors import (
    ConfigError,
    DataError,
    NonFinitePrediction,
    NotADataset,
    NotAPredictor,
    NotAScorer,
    OutOfRangeWarning,
    OverlapWarning,
    PredictionError,
    TrajprefError,
)
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
from trajpref.models.predictor import as_integer, check_seed
from trajpref.models.timing import (
    UNKNOWN_UNITS,
    VIA,
    lineage_others,
    observed_problems,
    shared_files,
    timing_problems,
    trained_otherwise,
    unstated_timing,
    window_digests,
)
from trajpref.score.scorer import (
    ScoreAccumulator,
    ScoreResult,
    TrajectoryScorer,
    reads_agent_types,
    score_result,
)
from trajpref.score.selection import gather
from trajpref.types import (
    AGENT_BALL,
    AGENT_PERSON,
    Batch,
    DatasetInfo,
    TrajectoryDataset,
    collate,
)

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
    them. The evaluation pass checks each batch's output (``check_prediction``). A ``name``
    attribute is optional (nothing here reads it)."""

    def predict(
        self, batch: Batch, num_samples: int, generator: torch.Generator | None = None
    ) -> torch.Tensor: ...


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
    """``NotAPredictor`` unless ``model`` has a ``predict`` method, ``NotADataset`` (a
    ``NotAPredictor`` too) unless ``dataset`` is a ``TrajectoryDataset``: before any work,
    and saying how to load each from its name; a ``DataError`` for a dataset without agents
    (no scenes), which has nothing to predict."""
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
        raise NotADataset(f"dataset must be a TrajectoryDataset, got "
                          f"{type(dataset).__name__}{hint}")  # fmt: skip
    check_windows(model, dataset)
    if dataset.num_agents == 0:
        info = dataset.info
        raise DataError(f"the dataset {info.name}/{info.split} holds no agents ({len(dataset)} "
                        "scenes): nothing to predict; load a split with scenes "
                        "(trajpref.data.load_dataset), or keep some in the subset you "
                        "made")  # fmt: skip


def check_windows(obj: object, dataset: TrajectoryDataset, role: str = "model") -> None:
    """``DataError`` before any work when ``dataset``'s windows are not the lengths ``obj`` (a
    predictor or a scorer) reads, its ``t_hist`` / ``t_fut`` (none: any lengths, as the
    constant-velocity baseline), saying how to read the data at its lengths."""
    want = (getattr(obj, "t_hist", None), getattr(obj, "t_fut", None))
    have = (dataset.info.t_hist, dataset.info.t_fut)
    if None in want or want == have:
        return
    info = dataset.info
    raise DataError(f"the {role} reads windows of {want[0]} observed + {want[1]} future frames, "
                    f"but {info.name}/{info.split} was read in windows of {have[0]} + "
                    f"{have[1]}: read it at the {role}'s lengths, load_dataset(..., "
                    f"options=ReadOptions(t_hist={want[0]}, t_fut={want[1]})) (the command "
                    "line does so by itself)")  # fmt: skip


def check_scorer(scorer: object, needs: str = "score") -> None:
    """``NotAScorer`` (a ``NotAPredictor``, a ``TypeError``) unless ``scorer`` is None or a
    scorer (a ``TrajectoryScorer``, or an object with its method ``needs``): a checkpoint's
    name or a predictor in its place says how to build one, before any work."""
    if scorer is None or isinstance(scorer, TrajectoryScorer):
        return
    if isinstance(scorer, (str, os.PathLike)):
        raise NotAScorer(f"scorer must be a TrajectoryScorer, got the name {str(scorer)!r}: "
                         f"build it first, TrajectoryScorer.from_checkpoint({str(scorer)!r}), "
                         "and pass what it returns")  # fmt: skip
    if callable(getattr(scorer, needs, None)):
        return
    if callable(getattr(scorer, "predict", None)):
        raise NotAScorer(f"scorer must be a TrajectoryScorer, got a predictor "
                         f"({type(scorer).__name__}), which samples futures: build the "
                         "scorer with TrajectoryScorer.from_checkpoint('DATASET/denoiser') "
                         "(or from the model's own checkpoint)")  # fmt: skip
    raise NotAScorer(f"scorer must be a TrajectoryScorer (TrajectoryScorer.from_checkpoint("
                     f"'DATASET/denoiser')), got {type(scorer).__name__}")  # fmt: skip


def check_num_samples(num_samples: object) -> int:
    """``num_samples`` as a Python int (a numpy integer counts); ConfigError unless an integer
    >= 1 (not a bool, nor a float such as 20.0)."""
    count = as_integer(num_samples)
    if count is None or count < 1:
        raise ConfigError(f"num_samples must be an integer >= 1, got {num_samples!r}")
    return count


def _own_device(obj: object) -> torch.device | None:
    """The device of ``obj``'s weights (``obj.device``, a selecting predictor's generator's),
    None for one that has none (the constant-velocity baseline computes on its inputs')."""
    for o in (obj, getattr(obj, "base", None)):
        device = getattr(o, "device", None) if o is not None else None
        if isinstance(device, (str, torch.device)):
            with contextlib.suppress(RuntimeError):
                return torch.device(device)
    return None


def _same_device(a: torch.device, b: torch.device) -> bool:
    """Whether two devices are one (``cuda`` is the current CUDA device, ``cuda:0`` at
    first)."""
    if a.type != b.type:
        return False
    if a.type != "cuda" or a.index == b.index:
        return True
    current = torch.cuda.current_device() if torch.cuda.is_available() else 0
    return (current if a.index is None else a.index) == (current if b.index is None else b.index)


def pass_device(model: object, device: torch.device | str | None, scorer: object = None,
                call: str = "evaluate") -> torch.device:  # fmt: skip
    """Where ``call``'s batches go: ``device`` as ``trajpref.device.resolve_device`` takes it,
    or for None the model's own device (``model.device``; else the scorer's; else the CPU,
    for the constant-velocity baseline). A one-line ConfigError, before any work, where the
    model's (or the scorer's) weights are on another device than that, or on one this machine
    cannot compute on (``meta``)."""
    held = [(who, d) for who, d in (("model", _own_device(model)),
                                    ("scorer", _own_device(scorer))) if d is not None]  # fmt: skip
    if device is None:
        if not held:
            return torch.device("cpu")
        who, own = held[0]
        try:
            resolved = resolve_device(own)
        except ConfigError as exc:
            move = ("model.to('cpu') or model.to('cuda')" if who == "model"
                    else "TrajectoryScorer.from_checkpoint(..., device='cpu')")  # fmt: skip
            raise ConfigError(f"{call}: the {who}'s weights are on {own}, where it cannot run "
                              f"({exc}): move it first, {move}") from None  # fmt: skip
    else:
        resolved = resolve_device(device)
    for who, own in held:
        if _same_device(own, resolved):
            continue
        if who == "scorer":
            raise ConfigError(f"{call}: the scorer's weights are on {own} and the batches go to "
                              f"{resolved}: build the scorer there, TrajectoryScorer."
                              f"from_checkpoint(..., device={str(resolved)!r})")  # fmt: skip
        raise ConfigError(f"{call}(device={str(resolved)!r}): the model's weights are on {own}: "
                          f"move it first, model.to({str(resolved)!r}), or leave device out "
                          "(None: the model's own device)")  # fmt: skip
    return resolved


def data_folds(dataset: TrajectoryDataset) -> tuple[str, ...]:
    """The ETH/UCY folds whose data ``dataset`` is: a fold's name (``dataset.info.name``), or
    a folder holding Social-GAN's test files of folds (``registry.sgan_folds``); empty
    otherwise."""
    name = dataset.info.name
    if name in ETH_UCY:
        return (name,)
    return () if name in NAMES else sgan_folds(name)


def lineage_folds(record: object) -> list[tuple[str, str | None]]:
    """``(fold, via)`` for each ETH/UCY fold that a ``models.timing.model_timing`` record's
    model was trained on, its own run's (``via`` None) first, then the other runs of its
    ``lineage`` (``timing.lineage_others``: a fine-tune's start, a generator's denoiser; ``via``
    names it), each fold once; a record without a lineage (a hand-made one, or older than it)
    gives its ``trained_on`` alone. Empty for no record."""
    if not isinstance(record, dict):
        return []
    found: list[tuple[str, str | None]] = []
    own = record.get("trained_on")
    lineage = record.get("lineage")
    if isinstance(lineage, list) and lineage and isinstance(lineage[-1], dict):
        own = lineage[-1].get("dataset")
    if isinstance(own, str) and own in ETH_UCY:
        found.append((own, None))
    for entry, via in lineage_others(record):
        fold = entry.get("dataset")
        if fold in ETH_UCY and all(fold != f for f, _ in found):
            found.append((fold, via))
    return found


def _trained_folds(model: object, scorer: object) -> list[tuple[str, str, str | None]]:
    """``(role, fold, via)`` for the model and scorer (a selecting predictor's base and scorer
    included) whose ``timing`` (``models.timing.attach_timing``: a loaded checkpoint's
    record) says they were trained on an ETH/UCY fold, through their own run (``via`` None)
    or another of their lineage (``lineage_folds``: a fine-tune's start, a generator's
    denoiser)."""
    found: list[tuple[str, str, str | None]] = []
    for role, obj in (("model", model), ("model", getattr(model, "base", None)),
                      ("scorer", getattr(model, "scorer", None)), ("scorer", scorer)):  # fmt: skip
        for fold, via in lineage_folds(getattr(obj, "timing", None)):
            if all((role, fold) != (r, f) for r, f, _ in found):
                found.append((role, fold, via))
    return found


def _who(role: str, via: str | None) -> str:
    """``the model``, or ``the model (through its denoiser)``: who a fold finding is of."""
    return f"the {role}" + (f" (through {via})" if via else "")


def check_fold_overlap(model: object, dataset: TrajectoryDataset, scorer: object = None) -> None:
    """ConfigError when the model (or scorer) was trained on an ETH/UCY fold other than the
    data's (``data_folds``): Social-GAN's leave-one-out training files of one fold hold most
    of the other folds' windows (84 % of the rows of zara1's test file are in the zara2
    fold's training files), so such a model has seen this data, whatever the split. Every
    run of the model's training lineage counts (``lineage_folds``: a fine-tune of a zara1
    generator on eth has seen zara1's windows through its start, and a generator trained
    through another fold's denoiser through it). What the CLI's ``evaluate`` refuses without
    ``--allow-overlap``; models without a record (``timing`` None: cv, a model built in
    code) pass."""
    folds, found = _fold_findings(model, dataset, scorer)
    if not found:
        return
    where = dataset.info.name
    own = " and ".join(folds)
    if where not in ETH_UCY:
        where = f"{where} (it holds {own}'s Social-GAN test files)"
    trained = "; ".join(f"{_who(role, via)} was trained on the {fold} fold, whose leave-one-out "
                        f"training files (the other four scenes') hold most of {own}'s windows"
                        for role, fold, via in found)  # fmt: skip
    raise ConfigError(f"evaluate on {where}: {trained}, so this evaluates on data it trained "
                      f"on: evaluate each fold with its own fold's models, or pass "
                      "allow_overlap=True to evaluate it anyway")  # fmt: skip


def _fold_findings(
    model: object, dataset: TrajectoryDataset, scorer: object = None
) -> tuple[tuple[str, ...], list[tuple[str, str, str | None]]]:
    """The data's folds (``data_folds``) and ``(role, fold, via)`` for the model and scorer
    trained on an ETH/UCY fold other than those (``_trained_folds``)."""
    folds = data_folds(dataset)
    if not folds:
        return folds, []
    return folds, [(role, fold, via) for role, fold, via in _trained_folds(model, scorer)
                   if any(f != fold for f in folds)]  # fmt: skip


def fold_overlap_note(model: object, dataset: TrajectoryDataset,
                      scorer: object = None) -> str | None:  # fmt: skip
    """What ``evaluate(allow_overlap=True)`` records as ``overlap`` of a model (or scorer)
    trained on another ETH/UCY fold than the data's (``check_fold_overlap``): ``zara2 model
    on zara1``, as the CLI's ``evaluate --allow-overlap`` records it (a folder's path after;
    ``through its denoiser`` and the like for a fold of its lineage); None when nothing
    overlaps."""
    folds, found = _fold_findings(model, dataset, scorer)
    if not found:
        return None
    name = dataset.info.name
    return fold_notes(found, folds, "" if name in ETH_UCY else f" ({name})")


def fold_notes(found, folds, tail: str = "") -> str:
    """The ``overlap`` record of fold findings ``found`` (``(role, fold, via)`` each) on the
    data's ``folds``: ``zara2 model on zara1``, ``tail`` after the folds (a folder's path),
    ``(through <via>)`` for a fold of the lineage; joined by ``; `` (Python's
    ``fold_overlap_note`` and the CLI's ``evaluate --allow-overlap``)."""
    return "; ".join(f"{fold} {role} on {' and '.join(folds)}{tail}"
                     + (f" (through {via})" if via else "")
                     for role, fold, via in found)  # fmt: skip


# ------------------------------------------- the data against what the model was trained on


@dataclass(frozen=True)
class ReadingWords:
    """How the data checks' advice names the ways of reading data: the command line's flags
    (``CLI_WORDS``) or Python's arguments (``PYTHON_WORDS``)."""

    time_step: str
    """Reading every n-th frame step, ``{}`` the number."""
    frame_interval: str
    """The seconds between an agent's consecutive rows, ``{}`` the number."""
    units: str
    """The data's units, ``{}`` their name."""
    joiner: str
    """Between the settings that read data as a model read its own."""
    time_step_name: str
    frame_interval_name: str
    units_name: str
    split: str
    """What picks the split that is read."""
    held_out: str
    """What reads a held-out scene's windows alone, ``{}`` the scene's file-name prefix."""


CLI_WORDS = ReadingWords("--time-step {}", "--frame-interval {}", "--units {}", " ",
                         "--time-step", "--frame-interval", "--units", "--split",
                         "--split val --holdout-scene {}")  # fmt: skip
"""The command line's flags, in the CLI's warnings."""
PYTHON_WORDS = ReadingWords("options=ReadOptions(time_step={})", "frame_interval={}",
                            "units={!r}", ", ", "ReadOptions.time_step",
                            "load_dataset's frame_interval", "load_dataset's units",
                            "load_dataset's split",
                            "hold_out_scene(train, val, {!r})[1]")  # fmt: skip
"""``load_dataset``'s arguments, in the warnings of ``evaluate`` and ``predict_dataset``."""

_INTERNAL = (os.path.dirname(os.path.abspath(__file__)),
             os.path.dirname(os.path.abspath(torch.__file__)))  # fmt: skip


def _user_level() -> int:
    """``warnings.warn``'s ``stacklevel`` for a warning issued by the caller of this function
    that names the first frame outside trajpref and torch (torch's ``no_grad`` wraps
    ``evaluate``): the user's line, so that a notebook shows each text once per line that
    called, whichever entry point it went through."""
    frame, level = sys._getframe(1), 1
    while frame.f_back is not None and frame.f_code.co_filename.startswith(_INTERNAL):
        frame, level = frame.f_back, level + 1
    return level


def same_path(a: str, b: str) -> bool:
    """Whether two paths name the same file or folder (False where either cannot be
    resolved)."""
    with contextlib.suppress(OSError, RuntimeError, TypeError, ValueError):
        return Path(a).expanduser().resolve() == Path(b).expanduser().resolve()
    return False


def flat_dataset(dataset: str) -> bool:
    """Whether a folder dataset (or one TrajNet++ file) has no ``train/ val/ test/``
    sub-folders, so that every split reads the same windows; False for a built-in name or
    what cannot be read (reading it says why)."""
    if dataset in NAMES:
        return False
    path = Path(dataset).expanduser()
    try:
        return path.is_file() or (path.is_dir() and not split_folders(path))
    except (TrajprefError, OSError):
        return False


def training_data_name(dataset: str) -> str:
    """How a warning names a model's training data (its ``data.dataset``): an ETH/UCY fold's
    model was trained on the other four scenes (leave-one-out), not on the fold's own."""
    if dataset in ETH_UCY:
        return f"the {dataset} fold (leave-one-out: the other four scenes)"
    return dataset


def step_hint(info: DatasetInfo, model: dict, words: ReadingWords = CLI_WORDS) -> str:
    """How to read ``info``'s data at the model's step (``model``: ``models.timing.
    model_timing``'s record): only advice that this data can take (the time step resamples
    text track files alone; the frame interval is not read where the data state their
    own). A frame interval given above ``SECONDS_STEPS``' ceiling (10 s) is first asked
    whether it is in milliseconds (``--frame-interval 400`` for 0.4 s), as
    ``models.timing.check_pace`` asks in Python."""
    hint = _reading_hint(info, model, words)
    frame = info.frame_interval / info.time_step  # seconds between the files' rows, as given
    if info.interval_from == "given" and frame > SECONDS_STEPS[1]:
        seconds = words.frame_interval.format(f"{frame / 1000:g}")
        return f"milliseconds? pass seconds, {seconds}; else {hint}"
    return hint


def _reading_hint(info: DatasetInfo, model: dict, words: ReadingWords) -> str:
    """``step_hint`` but for the question on milliseconds."""
    step, model_step, every = info.frame_interval, model["step"], info.time_step
    frame = step / every  # seconds between the files' frames, as read
    assumed = info.interval_from == "default"
    interval = (f"{frame:g} s between frames is assumed: give the files' own with "
                f"{words.frame_interval_name}")  # fmt: skip
    if not info.text_tracks:
        if info.interval_from == "dataset":
            return f"{words.time_step_name} does not resample {info.name}'s windows"
        fixed = f"{words.time_step_name} does not resample TrajNet++ scenes"
        if info.interval_from == "declared":
            return f"its TrajNet++ scenes declare {1 / frame:.4g} fps; {fixed}"
        return f"{interval}; {fixed}" if assumed else fixed
    ratio = every * model_step / step
    if not 0.1 <= ratio <= 100:  # beyond what a time step takes
        reads = (f"no {words.time_step_name} reads it at the model's step ({ratio:.4g} would be "
                 "needed)")  # fmt: skip
    else:
        reads = f"{words.time_step.format(f'{ratio:.4g}')} reads it at the model's step"
    model_frame = model_step / model["time_step"]
    if assumed and model["known"]:  # only the model's step is known: no time-step number
        return (f"{interval}; {words.time_step.format(f'{model_step:g} / that interval')} then "
                "reads them at the model's step")  # fmt: skip
    if assumed:  # both assume 0.4 s: the ratio of their time steps holds if the files step alike
        if same_path(model["trained_on"], info.name):
            return f"{reads} (the same files)"
        return (f"{reads} if these files step as the model's training files did (both assume "
                f"{frame:g} s between frames: {words.frame_interval_name} gives this "
                "data's)")  # fmt: skip
    if not model["known"]:
        return (f"{reads}, if the model's training files were {model_frame:g} s apart as "
                "assumed when it was trained")  # fmt: skip
    return reads


def model_reading(model: dict, words: ReadingWords = CLI_WORDS) -> str:
    """How the model read its training data (``model_timing``'s record), for the warning on
    data that leave their interval or units unsaid: a built-in dataset's step and units, or
    the settings that read a folder as the model read it (``--frame-interval 0.1
    --time-step 4 --units m``)."""
    step, every, units = model["step"], model["time_step"], model["units"]
    units = None if units in UNKNOWN_UNITS else units
    if model["interval_from"] == "dataset":
        read = "" if every == 1 else f" ({model['trained_on']} read every {every:g})"
        return f"the model's step is {step:g} s{read}" + (f", its units {units}" if units else "")
    flags, notes = [], []
    if model["known"] and step is not None:
        frame = step / every  # seconds between the rows of its files
        if model["interval_from"] == "given":
            flags.append(words.frame_interval.format(f"{frame:g}"))
        elif model["interval_from"] == "timestamps":
            notes.append(f"its files' time column gave {frame:g} s between rows")
        elif model["interval_from"] == "declared":
            notes.append(f"its TrajNet++ scenes declared {1 / frame:.4g} fps")
        notes.insert(0, f"{step:g} s per step")
    if every != 1:
        flags.append(words.time_step.format(f"{every:g}"))
    if units:
        flags.append(words.units.format(units))
    detail = f" ({'; '.join(notes)})" if notes else ""
    if not flags:
        return f"the model's step is {step:g} s{detail}"
    return f"the model read its data with {words.joiner.join(flags)}{detail}"


def unstated_problem(info: DatasetInfo, model: dict, missing: list[str],
                     words: ReadingWords = CLI_WORDS) -> str:  # fmt: skip
    """The phrase for data whose interval is only assumed or whose units are unknown
    (``timing.unstated_timing``'s ``missing``), where the model recorded its own: what the
    model read, and the settings that say this data's."""
    said = []
    if "interval" in missing:
        frame = info.frame_interval / info.time_step  # as assumed: seconds between rows
        said.append(f"frame interval is only assumed ({frame:g} s between rows, none given)")
    if "units" in missing:
        said.append("units are unknown" if not said else "its units are unknown")
    flags = []
    if "interval" in missing:
        flags.append(f"{words.frame_interval_name} (the seconds between an agent's consecutive "
                     "rows)")  # fmt: skip
    if "units" in missing:
        flags.append(words.units_name)
    return (f"this data's {' and '.join(said)}, while {model_reading(model, words)}: give this "
            f"data's with {' and '.join(flags)}")  # fmt: skip


def timing_warning(name: str, model: dict, info: DatasetInfo,
                   words: ReadingWords = CLI_WORDS) -> str | None:  # fmt: skip
    """The one warning's text when ``name`` was trained on data whose units or pace differ
    from this data's (``info``), as far as both are known (``models.timing.timing_problems``;
    ``model``: ``model_timing``'s record); a model trained on a folder before that record is
    compared only with the same folder read at another time step. Where nothing known differs
    but this data's interval is only assumed or its units unknown while the model recorded
    its own, the text names the model's and the settings that give this data's. None when
    there is nothing to say."""
    step = info.frame_interval if info.frame_interval > 0 else None
    problems = timing_problems(model, step, info.units, lambda m: step_hint(info, m, words))
    if model["step"] is None:  # a folder model without the record: its time step alone
        every = model["time_step"]
        if (info.text_tracks and same_path(model["trained_on"], info.name)
                and not math.isclose(info.time_step, every, rel_tol=0.01)):  # fmt: skip
            steps = "frame step" if info.time_step == 1 else "frame steps"
            problems.append(f"this data is read every {info.time_step:g} {steps} of its "
                            f"files, the model's (the same folder) every {every:g} "
                            f"({words.time_step.format(f'{every:g}')} reads it at the model's "
                            "step)")  # fmt: skip
    if not problems:  # nothing known differs: what this data leaves unsaid, if the model says
        missing = unstated_timing(model, info.interval_from == "default", info.units)
        if missing:
            problems.append(unstated_problem(info, model, missing, words))
    if not problems:
        return None
    return trained_otherwise(name, dict(model, trained_on=training_data_name(model["trained_on"])),
                             problems)  # fmt: skip


def training_windows(name: str, data: dict, info: DatasetInfo,
                     words: ReadingWords = CLI_WORDS) -> str | None:  # fmt: skip
    """One warning's text when this data (``info``) is the model's own training folder
    (``data``: its checkpoint's ``config.data``), read whole because it has no split
    sub-folders: whatever the split says, its windows are those the model trained on. None
    otherwise (a held-out scene read alone is another source, and so not this case)."""
    trained = data.get("dataset")
    if not isinstance(trained, str) or not same_path(trained, info.name):
        return None
    if not same_path(info.source, info.name) or not flat_dataset(trained):
        return None
    holdout = data.get("holdout_scene") or ""
    held = (f" (all but its held-out scene {holdout}*, which {words.held_out.format(holdout)} "
            "reads alone)" if holdout else "")  # fmt: skip
    return (f"{name} was trained on {trained}, which has no train/, val/ or test/ sub-folders: "
            f"whatever {words.split} says, this data is the windows it trained on{held}, so "
            "numbers on it are training numbers, not a test (give the folder train/ val/ test/ "
            "sub-folders and train on train/, or use files it did not train on)")  # fmt: skip


def held_out_split(data: dict, info: DatasetInfo, holdout: str) -> str | None:
    """For a held-out scene's windows (the CLI's ``--holdout-scene``: that scene's files of
    both splits of ``info``'s dataset): ``val`` when the model held out the same scene (it
    chose its epoch on them and never trained on them), ``train`` when it trained on that
    dataset without holding it out (its training files are most of these windows), None for
    a model of other data."""
    trained = data.get("dataset")
    if not isinstance(trained, str):
        return None
    if not (trained == info.name or same_path(trained, info.name)):
        return None
    return "val" if data.get("holdout_scene") == holdout else "train"


def own_split(data: dict, info: DatasetInfo, root: str | None) -> str | None:
    """``train`` or ``val`` when this data (``info``) is a split the model trained on or chose
    its epoch on, read from the same folder (``info.source``): the training dataset's own
    split by name (``--dataset zara1 --split train``), its split folder given as a path
    (``eth_ucy/zara1/train``, under the data root ``root`` or ``$TRAJPREF_DATA``), or a split
    sub-folder of the folder it trained on. None otherwise, and for data the model trained on
    in another way (``val_dataset``, a held-out scene) that this does not follow."""
    trained = data.get("dataset")
    if not isinstance(trained, str) or data.get("holdout_scene"):
        return None
    folders: dict[str, Path] = {}
    if trained in ETH_UCY:
        with contextlib.suppress(TrajprefError, OSError):
            base = resolve_data_root(root) / "eth_ucy" / trained
            folders = {split: base / split for split in ("train", "val")}
    elif trained not in NAMES:
        with contextlib.suppress(TrajprefError, OSError):
            folders = split_folders(Path(trained).expanduser())
    validated_elsewhere = bool(data.get("val_dataset"))  # it chose its epoch on another folder
    if trained in NAMES and info.name == trained and info.split in ("train", "val"):
        if info.split == "val" and validated_elsewhere:
            return None
        return info.split  # a built-in dataset's own split, whatever folder it was read from
    if validated_elsewhere:
        folders.pop("val", None)
    for split in ("train", "val"):
        if split in folders and same_path(str(folders[split]), str(info.source)):
            return split
    return None


def shared_split(data: dict, info: DatasetInfo) -> tuple[str, tuple[str, str]] | None:
    """``("train" | "val", (dataset, split))`` when built-in data (``info``: a name of
    ``NAMES``) holds windows of a built-in split the model trained on (its ``dataset``'s
    training split) or chose its epoch on (its ``val_dataset``'s, else its ``dataset``'s,
    validation split), across names (``registry.split_sources``: robo-mix is made of robo-sim
    and the official Robo val split; robo/generator chose its epoch on Robo's val split);
    None otherwise. ``own_split`` has named the same-name cases first."""
    trained, chosen = data.get("dataset"), data.get("val_dataset") or data.get("dataset")
    if info.name not in NAMES or not all(isinstance(d, str) and d in NAMES
                                         for d in (trained, chosen)):  # fmt: skip
        return None
    if data.get("holdout_scene"):
        return None
    here = split_sources(info.name, info.split)
    for kind, seen in (("train", split_sources(trained, "train")),
                       ("val", split_sources(chosen, "val"))):  # fmt: skip
        common = sorted(here & seen)
        if common:
            return kind, common[0]
    return None


def _overlap_text(name: str, split: str, what: str, where: str, advice: str) -> tuple[str, str]:
    """The warning's text that ``name`` trained on (``split`` ``train``) or chose its epoch
    on (``val``) these windows, ``what`` saying how, then ``advice``, and the form a result
    records (``overlap``), ``where`` in its parentheses."""
    role = "trained on" if split == "train" else "chose its epoch on"
    kind = "training" if split == "train" else "validation"
    return (f"{name} {role} these windows: {what}, its {kind} data, so numbers on it are "
            f"{kind} numbers, not a test{advice}", f"{role} these windows ({where})")  # fmt: skip


def _own_windows(name: str, data: dict, info: DatasetInfo, root: str | None,
                 holdout: str | None, words: ReadingWords,
                 val_known: bool) -> tuple[str, str] | None:  # fmt: skip
    """``check_trained_on``'s findings for one run's data config ``data``: the warning's text
    and the record's, None when this data is none of its training or validation windows."""
    try:
        if holdout:
            split = held_out_split(data, info, holdout)
            if split is None or (split == "val" and not val_known):
                return None
            what = ("the windows of its training files" if split == "train"
                    else "its own held-out validation scene")  # fmt: skip
            return _overlap_text(name, split,
                                 f"the held-out scene {holdout}* of {info.name} is {what}",
                                 f"held-out scene {holdout}* of {info.name}", "")  # fmt: skip
        own = training_windows(name, data, info, words)
        split = None if own is not None else own_split(data, info, root)
        shared = None if own is not None or split is not None else shared_split(data, info)
    except (KeyError, TypeError, AttributeError):
        return None
    if own is not None:
        return own, f"trained on these windows ({info.name} has no split sub-folders)"
    if split is not None and (split == "train" or val_known):
        trained = data["dataset"]
        return _overlap_text(
            name,
            split,
            f"{info.source or 'this data'} is the {split} split of {trained}",
            f"{split} split of {trained}",
            " (evaluate on the test split, or on files it did not train on)",
        )
    if split is not None:  # a validation split, and the record does not say where it chose
        shared = None
    if shared is None or (shared[0] == "val" and not val_known):
        return None
    split, (dataset, part) = shared
    what = f"{info.name}'s {info.split} split holds {dataset}'s {part} split"
    if (dataset, part) == (info.name, info.split):
        what = f"this is {dataset}'s {part} split"
    return _overlap_text(name, split, what, f"{dataset}'s {part} split",
                         " (evaluate on the test split)")  # fmt: skip


SHOWN_FILES = 3
"""How many same-content file pairs a warning names (``content_overlaps``), then a count."""


def content_overlaps(
    model: dict, digests: dict[str, str], info: DatasetInfo
) -> list[tuple[str, str | None, list[str], bool]]:
    """``(split, via, pairs, all)`` for each run of a ``model_timing`` record's ``lineage``
    (its own run first, ``via`` None, then the others named as ``timing.VIA`` names them)
    whose recorded ``files`` (``timing.split_files``, at training time since 2026-12) of its
    ``train`` or ``val`` split hold the windows of files of this data (``digests``:
    ``timing.window_digests`` of the data evaluated; ``info``: its split names them): the
    pairs as ``test/zara02_copy.csv = train/crowds_zara02_train.csv``, and whether they are
    all this data's files. Each file of this data is found once per split (the latest run).
    Empty for a record without digests (published checkpoints, files trained before)."""
    lineage = model.get("lineage") if isinstance(model, dict) else None
    if not isinstance(lineage, list) or not digests:
        return []
    out, found = [], set()
    last = len(lineage) - 1
    for i in range(last, -1, -1):
        entry = lineage[i]
        files = entry.get("files") if isinstance(entry, dict) else None
        if not isinstance(files, dict):
            continue
        via = None if i == last else VIA.get(entry.get("stage"), "its training lineage")
        for split in ("train", "val"):
            pairs = [(f, t) for f, t in shared_files(digests, files.get(split))
                     if (f, split) not in found]  # fmt: skip
            if not pairs:
                continue
            found.update((f, split) for f, _ in pairs)
            shown = [f"{info.split}/{f} = " + (f"{split}/{t}" if t else f"a file of its {split} "
                     "split") for f, t in pairs]  # fmt: skip
            out.append((split, via, shown, len(pairs) == len(digests)))
    return out


def _content_text(who: str, via: str | None, split: str, shown: list[str], whole: bool,
                  total: int) -> tuple[str, str]:  # fmt: skip
    """The warning and record of one ``content_overlaps`` finding of model ``who`` (through
    ``via``: ``its denoiser``, None for its own run)."""
    role = "trained on" if split == "train" else "chose its epoch on"
    kind = "training" if split == "train" else "validation"
    listed = ", ".join(shown[:SHOWN_FILES])
    if len(shown) > SHOWN_FILES:
        listed += f" and {len(shown) - SHOWN_FILES} more"
    some = "" if whole else f"{len(shown)} of this data's {total} files: "
    text = (f"{who} {role} these windows: this data holds files {via or 'the model'} {role}: "
            f"{some}"
            f"{listed} (the same windows under another name or folder), so numbers on it are "
            f"{'' if whole else 'partly '}{kind} numbers, not a test (evaluate on files it did "
            f"not {'train' if split == 'train' else 'choose its epoch'} on)")  # fmt: skip
    return text, f"{role} {'these' if whole else 'some of these'} windows ({listed})"


def check_trained_on(name: str, model: dict, data: dict | None, info: DatasetInfo,
                     root: str | None = None, holdout: str | None = None,
                     words: ReadingWords = CLI_WORDS, *, val_known: bool = True,
                     tail: str = "",
                     dataset: TrajectoryDataset | None = None) -> str | None:  # fmt: skip
    """The checks of one model (``name``; ``model``: ``models.timing.model_timing``'s record
    of its checkpoint; ``data``: the checkpoint's ``config.data``, None where unknown) against
    the data it is given (``info``), what the CLI's ``evaluate``, ``predict`` and ``plot`` and
    Python's ``evaluate`` and ``predict_dataset`` check: one ``OutOfRangeWarning`` when its
    training data's units or pace differ from this data's (``timing_warning``), and a second,
    an ``OverlapWarning`` (both ``TrajprefWarning``s), when this
    data is the model's own training folder read whole (``training_windows``), or a split it
    trained or chose its epoch on (``own_split``, ``shared_split``; ``root``: the data root,
    for a fold's split folder given as a path), or with ``holdout`` (a held-out scene's
    windows of both splits) whether it trained or chose its epoch on them
    (``held_out_split``). The other runs of the record's ``lineage`` (a fine-tune's start
    generator, a generator's denoiser: ``timing.lineage_others``) are checked alike, each
    finding once, named ``through`` that run. Returns the findings' short forms (joined by
    ``; ``), what a result records as ``overlap``; None otherwise. ``val_known`` False: the
    record does not say where the model chose its epoch (``val_dataset``), so the validation
    findings of its own run are left out. ``tail`` ends every warning's text (Python's
    ``check_against_training``: which model it is about, ``model_identity``). With
    ``dataset`` (the data ``info`` describes, its windows), the files of its split are
    compared by content with those the lineage's runs trained and chose their epoch on
    (``content_overlaps``: a copy of a training file in ``test/``, a training folder copied
    elsewhere), for the roles the path checks above have not found."""
    text = timing_warning(name, model, info, words)
    if text is not None:
        warnings.warn(text + tail, OutOfRangeWarning, stacklevel=_user_level())
    if data is None:
        return None
    runs: list[tuple[dict, str | None, bool]] = [(data, None, val_known)]
    runs += [(entry, via, True) for entry, via in lineage_others(model, data)]
    notes: list[str] = []
    seen: set[str] = set()  # the findings' records, without their run
    for run_data, via, known in runs:
        who = name if via is None else f"{name} (through {via})"
        found = _own_windows(who, run_data, info, root, holdout, words, known)
        if found is None or found[1] in seen:  # the same windows, named through another run
            continue
        seen.add(found[1])
        warnings.warn(found[0] + tail, OverlapWarning, stacklevel=_user_level())
        notes.append(found[1] if via is None else f"{found[1][:-1]}, through {via})")
    lineage = model.get("lineage") if isinstance(model, dict) else None
    recorded = isinstance(lineage, list) and any(
        isinstance(e, dict) and isinstance(e.get("files"), dict) for e in lineage
    )
    if dataset is not None and recorded:  # digests of this data only where the model has some
        roles = {n.split(" these windows", 1)[0].split(" some of", 1)[0] for n in seen}
        digests = window_digests(dataset)
        for split, via, shown, whole in content_overlaps(model, digests, info):
            role = "trained on" if split == "train" else "chose its epoch on"
            if role in roles:  # this data's windows already named by path
                continue
            who = name if via is None else f"{name} (through {via})"
            text, record = _content_text(who, via, split, shown, whole, len(digests))
            warnings.warn(text + tail, OverlapWarning, stacklevel=_user_level())
            notes.append(record if via is None else f"{record[:-1]}, through {via})")
    return "; ".join(notes) or None


def role_notes(role: str, note: str) -> str:
    """``check_trained_on``'s findings (``; ``-joined) as a result records them, each after
    ``role`` (``model``, ``scorer``)."""
    return "; ".join(f"{role} {part}" for part in note.split("; "))


def warn_observed_pace(checked: list[tuple[str, object]], dataset: TrajectoryDataset,
                       tail: str = "") -> bool:  # fmt: skip
    """Warn once per pass of each cause ``models.timing.observed_problems`` finds in the
    split's observed steps, for the first of ``checked`` (``(name, predictor or scorer)``, the
    model before its scorer; the constant-velocity baseline reads any units) that has it, as
    ``predict_scenes`` warns of a call's scenes: the 90th percentile of all its agents' pace
    above ``timing.PACE_LIMIT`` model units (data in other units, e.g. centimetres for a
    metre model, which the generator's speed clamp hides and the score does not), alone;
    else one agent jumping more than ``timing.JUMP_LIMIT`` in one step (a tracker id switch)
    or, where none, that percentile above ``timing.FAST_LIMIT`` for one without an input
    speed clamp (agents faster than training), and beside either, two agents of one window
    farther apart at its last observed frame than the model's own limit (``timing.wide_limit``
    of its training width) for one without a neighbour radius (a scene wider than training).
    ``tail`` ends each text (``check_trained_on``'s); returns whether it warned."""
    if not len(dataset) or not checked:
        return False
    history = np.concatenate([s.history for s in dataset.scenes])  # [N, T_h, 2]
    types = np.concatenate([s.agent_type for s in dataset.scenes])  # [N]
    sizes = [len(s.history) for s in dataset.scenes]  # [B] agents per window, in that order
    found: dict[str, str] = {}  # cause -> the text of the first that has it
    for name, obj in checked:
        for cause, text in observed_problems(obj, history, name, types, sizes).items():
            found.setdefault(cause, text)
    if "units" in found:  # every distance off: the others would only repeat it
        found = {"units": found["units"]}
    for text in found.values():
        warnings.warn(text + tail, OutOfRangeWarning, stacklevel=_user_level())
    return bool(found)


def warn_untyped_data(checked: list[tuple[str, object]], dataset: TrajectoryDataset,
                      tail: str = "") -> bool:  # fmt: skip
    """One warning when one of ``checked`` (``(name, predictor or scorer)``) learned from
    agent-type flags (NBA's ball, ``score.scorer.reads_agent_types``) and this data flag no
    ball (a folder without a type column, or players only: every agent is read as a person;
    a walkthrough measured minFDE 0.256 -> 0.319 m on NBA scenes whose ball was read that
    way), or flag some ball while some scenes have none or more than one (every scene of
    NBA's splits flags exactly one: a ball track with a gap drops out of its windows, a
    second agent flagged BALL is read as a second ball), saying how many. Data with one
    flagged ball in every scene, or models trained without flags, say nothing. ``tail`` ends
    the text (``check_trained_on``'s); returns whether it warned."""
    reader = next((name for name, obj in checked if reads_agent_types(obj)), None)
    if reader is None or not dataset.scenes:
        return False
    if not any(bool((s.agent_type != AGENT_PERSON).any()) for s in dataset.scenes):
        warnings.warn(f"{reader} was trained with agent types (the ball flagged "
                      f"{AGENT_BALL}), and this data flag no ball: every agent is read as "
                      "a person; if a ball is among them, a 5th column of BALL / PLAYER "
                      f"flags it (docs/data_format.md){tail}", OutOfRangeWarning,
                      stacklevel=_user_level())  # fmt: skip
        return True
    balls = np.array([int((s.agent_type == AGENT_BALL).sum()) for s in dataset.scenes])
    none, many = int((balls == 0).sum()), int((balls > 1).sum())
    if not none and not many:
        return False
    verb = {1: "flags"}  # "1 flags", "2 flag"
    found = [f"{none} {verb.get(none, 'flag')} no ball" if none else "",
             f"{many} {verb.get(many, 'flag')} two or more (up to {int(balls.max())})"
             if many else ""]  # fmt: skip
    scenes = f"{len(balls)} scene{'' if len(balls) == 1 else 's'}"
    warnings.warn(f"{reader} was trained with the ball flagged (agent_type {AGENT_BALL}; "
                  f"one in every scene of NBA's splits), and of this data's {scenes}, "
                  f"{' and '.join(f for f in found if f)}: it reads each as flagged, a scene "
                  "it never saw; the ball is one agent, flagged BALL in a 5th column and seen "
                  f"in every frame of a window (docs/data_format.md){tail}", OutOfRangeWarning,
                  stacklevel=_user_level())  # fmt: skip
    return True


_RECORD = {"trained_on": None, "step": None, "known": False, "interval_from": None,
           "time_step": 1.0, "units": "unknown", "agent_types": None, "val_dataset": None,
           "holdout_scene": None, "lineage": None}  # fmt: skip
"""``models.timing.model_timing``'s keys, with the values of a record that says nothing."""


def _record(obj: object) -> dict | None:
    """``obj.timing`` (``models.timing.attach_timing``: what a loaded checkpoint recorded of
    its training data) with every key of ``model_timing``'s record, None without one."""
    timing = getattr(obj, "timing", None)
    if not isinstance(timing, dict) or not isinstance(timing.get("trained_on"), str):
        return None
    return {**_RECORD, **timing}


def _checked(model: object, scorer: object) -> list[tuple[str, object, dict]]:
    """``(name, object, record)`` for the model (a selecting predictor's generator) and the
    scorers (``scorer``, a selecting predictor's own) that carry a checkpoint's record
    (``_record``); a scorer whose record is the model's (the same training data: the same
    findings) is left out."""
    found: list[tuple[str, object, dict]] = []
    candidates = (("the model", getattr(model, "base", model)),
                  ("the scorer", getattr(model, "scorer", None)),
                  ("the scorer", scorer))  # fmt: skip
    for name, obj in candidates:
        record = _record(obj) if obj is not None else None
        if record is None or any(obj is o or record == r for _, o, r in found):
            continue
        found.append((name, obj, record))
    return found


def model_identity(obj: object, record: dict) -> str:
    """Which model or scorer a Python data-check warning is about, beyond its role: the
    checkpoint it was loaded from where the object names one (a ``checkpoint`` string or
    path), else what its record (``_record``: ``models.timing.model_timing``) says of it: its
    stage and training data, e.g. ``a fine-tune trained on zara1, held-out scene
    crowds_zara02*``. Two models of one loop are then two texts, each warned of once
    (Python's default filter shows a text once per line that issues it)."""
    source = getattr(obj, "checkpoint", None)
    if isinstance(source, (str, os.PathLike)) and str(source):
        return str(source)
    lineage = record.get("lineage")
    own = lineage[-1] if isinstance(lineage, list) and lineage else {}
    stage = own.get("stage") if isinstance(own, dict) else None
    stage = {"finetune": "fine-tune"}.get(stage, stage) or "checkpoint"
    parts = [f"a {stage} trained on {record['trained_on']}"]
    if record.get("holdout_scene"):
        parts.append(f"held-out scene {record['holdout_scene']}*")
    if record.get("val_dataset") and record["val_dataset"] != record["trained_on"]:
        parts.append(f"its epoch chosen on {record['val_dataset']}'s val split")
    return ", ".join(parts)


def check_against_training(model: object, dataset: TrajectoryDataset,
                           scorer: object = None) -> str | None:  # fmt: skip
    """What ``evaluate`` and ``predict_dataset`` check, before any work, of the data against
    what the model and scorer were trained on, as the CLI's ``evaluate`` and ``predict`` do:
    for each that carries its checkpoint's record (``timing``: ``load_predictor``,
    ``TrajectoryScorer.from_checkpoint``; models built in code and ``cv`` have none), a
    ``TrajprefWarning`` when its training data's units or step differ from this data's
    (``check_trained_on``: e.g. 10 Hz tracks, 0.1 s, given to a 0.4 s model, or centimetres
    to a metre one), or when this data is a split it trained on or chose its epoch on (e.g.
    ``zara1/generator`` on zara1's train split); one when this data's observed pace is far
    from its training (``warn_observed_pace``), and one when it reads agent types that this
    data do not flag (``warn_untyped_data``). Each text ends with which model or scorer it is
    about (``model_identity``: ``[the model: a generator trained on zara1]``), so that a loop
    over several models is warned of each. Returns what a result records as ``overlap``
    (``model trained on these windows (train split of zara1)``), None when nothing overlaps.

    The record (``models.timing.model_timing``) says where the model chose its epoch
    (``val_dataset``) and which scene it held out (``holdout_scene``), so that a validation
    split is named (``robo/generator`` on Robo's val split); a hand-made record without
    ``val_dataset`` names training splits alone. The other runs of its ``lineage`` (a
    fine-tune's start, a generator's denoiser) are checked too (``check_trained_on``)."""
    checked = _checked(model, scorer)
    labels = [f"{name}: {model_identity(obj, record)}" for name, obj, record in checked]
    notes = []
    for (name, obj, record), label in zip(checked, labels, strict=True):
        data = {"dataset": record["trained_on"], "val_dataset": record.get("val_dataset"),
                "holdout_scene": record.get("holdout_scene")}  # fmt: skip
        note = check_trained_on(name, record, data, dataset.info, words=PYTHON_WORDS,
                                val_known="val_dataset" in obj.timing,
                                tail=f" [{label}]", dataset=dataset)  # fmt: skip
        if note:
            notes.append(role_notes(name.removeprefix("the "), note))
    # one warning each at most, for the first that has the problem (as the functions do)
    for warn in (warn_observed_pace, warn_untyped_data):
        for (name, obj, _), label in zip(checked, labels, strict=True):
            if warn([(name, obj)], dataset, tail=f" [{label}]"):
                break
    return "; ".join(notes) or None


@torch.no_grad()
def sampled_batches(
    model: Predictor, dataset: TrajectoryDataset, num_samples: int = 20, seed: int = 0,
    device: torch.device | str | None = None, max_agents: int = 1024, progress: bool = True,
    desc: str = "sample",
) -> Iterator[tuple[Batch, torch.Tensor]]:  # fmt: skip
    """The one pass over a split: ``(batch, pred [K, N, T_f, 2])`` for every batch of whole
    scenes, in dataset order, with one seeded CPU generator for the whole pass. ``device`` as
    ``trajpref.device.resolve_device`` takes it (``auto``: CUDA when available, else the CPU;
    a device this machine lacks is a ``ConfigError``); None: the model's own (``pass_device``:
    the CPU for a model without one; a model on another device than the one given is a
    ``ConfigError``). ``num_samples`` and ``seed``: integers (numpy's too; ``ConfigError``
    otherwise, ``check_num_samples``, ``check_seed``). Each batch's prediction is checked
    (``check_prediction``: K = ``num_samples`` samples of every agent, finite, ...)."""
    check_inputs(model, dataset)
    num_samples, seed = check_num_samples(num_samples), check_seed(seed)
    device = pass_device(model, device, call="sampled_batches")
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
        radius = float(radius)
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
    device: torch.device | str | None = None, max_agents: int = 1024, progress: bool = True,
    scorer: TrajectoryScorer | None = None,
    collision_radius: float | None | Literal["auto"] = "auto",
    bins: tuple[int, ...] | None = None,
    allow_overlap: bool = False,
    agents: Literal["all", "persons", "primary"] = "all",
    slots: int | None = None,
    check_data: bool = True,
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
    this machine lacks is a ``ConfigError`` before any work); None (the default): the
    model's own device (``model.device``: where ``load_predictor(..., device=...)`` put it;
    the CPU for a model without one, such as ``cv``). A model or scorer whose weights are on
    another device than the one given is a ``ConfigError`` before any work
    (``pass_device``). The other arguments are checked before any work too: ``scorer`` a
    ``TrajectoryScorer`` (a checkpoint's name is a ``NotAPredictor`` saying to build it with
    ``TrajectoryScorer.from_checkpoint``), ``num_samples`` an integer >= 1 and ``seed`` an
    integer (numpy's too), ``collision_radius`` a number > 0, ``bins`` strictly increasing
    integers, ``slots`` an integer >= 1; a ``ConfigError`` otherwise.

    ``check_data`` (default True): before any work, the data are checked against what the
    model and the scorer were trained on, as the CLI checks them (``check_against_training``:
    a ``TrajprefWarning`` for another time step or other units than the model's training data,
    an observed pace far from it, or a split it trained or chose its epoch on), and the result
    holds ``overlap``: what this data shares with the model's (or scorer's) training or
    validation data (``model trained on these windows (train split of zara1)``; with
    ``allow_overlap=True`` also ``zara2 model on zara1``), None when nothing; the CLI's
    ``evaluate --json`` records it the same way. ``check_data=False`` (the CLI, which has made
    its own checks) skips them, and the result has no ``overlap`` key.

    A model (or ``scorer``) whose checkpoint says it was trained on one ETH/UCY fold
    (``model.timing["trained_on"]``), evaluated on another fold's data (a fold's name, or a
    folder holding another fold's Social-GAN test files), is a ConfigError before any work
    (``check_fold_overlap``: its leave-one-out training files hold most of that fold's
    windows); ``allow_overlap=True`` evaluates it anyway, as the CLI's ``--allow-overlap``.
    """
    check_inputs(model, dataset)
    num_samples, seed = check_num_samples(num_samples), check_seed(seed)
    device = pass_device(model, device, scorer)  # before any work
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
    radius = resolve_collision_radius(collision_radius, dataset.info.units)
    if bins is not None:
        try:
            bins = check_bin_edges(bins)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
    try:
        slot_acc = SlotMetrics(slots, radius) if slots is not None else None
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    if not allow_overlap:
        check_fold_overlap(model, dataset, scorer)
    check_scorer(scorer)  # (a record of its fold is read first, whatever it is)
    if scorer is not None:
        check_windows(scorer, dataset, "scorer")
    overlap = None
    if check_data:  # warnings, as the CLI's; the folds' overlap allowed is recorded first
        folds = fold_overlap_note(model, dataset, scorer) if allow_overlap else None
        overlap = "; ".join(n for n in (folds, check_against_training(model, dataset, scorer))
                            if n) or None  # fmt: skip
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
    if check_data:
        out["overlap"] = overlap
    return out


@torch.no_grad()
def predict_dataset(
    model: Predictor, dataset: TrajectoryDataset, num_samples: int = 20, seed: int = 0,
    device: torch.device | str | None = None, max_agents: int = 1024, progress: bool = True,
    scorer: TrajectoryScorer | None = None, check_data: bool = True,
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

    The arguments are checked before any work as ``evaluate`` checks them (``device`` None:
    the model's own); with ``check_data`` (default True) the data too, against what the model
    and the scorer were trained on (``check_against_training``: ``TrajprefWarning``s, as the CLI's
    ``predict`` gives); the CLI, which has made its own, passes False.
    """
    check_inputs(model, dataset)
    check_scorer(scorer, "scene_residual")
    if scorer is not None:
        check_windows(scorer, dataset, "scorer")
    num_samples, seed = check_num_samples(num_samples), check_seed(seed)
    device = pass_device(model, device, scorer, "predict_dataset")  # before any work
    if check_data:
        check_against_training(model, dataset, scorer)
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


def _sync(device: torch.device) -> None:
    """Wait until ``device`` has finished the work queued on it: a CUDA call returns before
    its kernels have run, so a clock read without this charges them to whatever comes next.
    Nothing to wait for elsewhere."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


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
    come first and are not counted. Each predictor runs on its own device (``pass_device``:
    a ``ConfigError`` before any work for one it cannot run on), its batches moved there
    before the clock starts; on a GPU the clock is read once the GPU has finished
    (``_sync``). Returns ``{name: ms}`` plus ``"scenes"``."""
    if not predictors:
        raise ConfigError("time_predictors needs at least one predictor")
    if scenes < 1 or len(dataset) == 0:
        raise ConfigError("time_predictors needs at least one scene")
    devices = {name: pass_device(model, None, call="time_predictors")
               for name, model in predictors.items()}  # fmt: skip
    cpu_batches = [collate([scene]) for scene in dataset.evenly_spaced(scenes)]
    batches = {d: [b.to(d) for b in cpu_batches] for d in set(devices.values())}
    for name, model in predictors.items():
        for b in batches[devices[name]][:warmup]:
            model.predict(b, num_samples, torch.Generator().manual_seed(0))
    total = dict.fromkeys(predictors, 0.0)
    for i in range(len(cpu_batches)):
        for name, model in predictors.items():
            device = devices[name]
            gen = torch.Generator().manual_seed(i)
            _sync(device)
            start = time.perf_counter()
            model.predict(batches[device][i], num_samples, gen)
            _sync(device)
            total[name] += time.perf_counter() - start
    scenes_timed = len(cpu_batches)
    return {name: 1000 * t / scenes_timed for name, t in total.items()} | {"scenes": scenes_timed}
