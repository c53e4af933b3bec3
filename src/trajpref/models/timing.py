"""The pace and units a checkpoint's model was trained at, and the comparison of them with the
data handed to it (the CLI's warning on a dataset, ``predict_scene``'s on a planner's arrays).

A model trained on 0.5 s steps reads 0.4 s tracks as slower walkers, and its 12 future steps
span 6 s, not 4.8 s; a model trained in pixels reads metres as a near standstill. Nothing in
the numbers shows it, so both entry points compare what they are told of the data with what
the checkpoint recorded of its training data.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import numbers
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from trajpref.data.registry import PIXEL_NAMES, SECONDS_STEPS, SPECS, check_frame_interval
from trajpref.data.stats import METRES_PER_UNIT
from trajpref.data.transforms import observed_pace, seen_run
from trajpref.errors import ConfigError, OutOfRangeWarning
from trajpref.metrics import METRE_UNITS
from trajpref.types import AGENT_BALL, TrajectoryDataset

UNKNOWN_UNITS = ("", "unknown")
"""Unit names that say nothing (a folder read without ``--units``)."""
PIXEL_UNITS = PIXEL_NAMES
"""The names of pixels (a model trained with ``--units px`` reads ``--units pixels`` data):
``data.registry.PIXEL_NAMES`` itself, one definition."""


def same_units(a: str, b: str) -> bool:
    """Whether two unit names mean the same (``m``, ``metres``, ``Meters``; ``px``,
    ``pixels``; else literally)."""
    a, b = a.strip().lower(), b.strip().lower()
    return a == b or any(a in names and b in names for names in (METRE_UNITS, PIXEL_UNITS))


LINEAGE_STAGES = ("denoiser", "generator", "finetune")
"""The runs a checkpoint's training lineage names (``training_lineage``), in training order."""
LINEAGE_KEYS = ("dataset", "val_dataset", "holdout_scene")
"""What a lineage entry records of a run's data config: the data it trained on (its
``dataset``'s training split), chose its epoch on (``val_dataset``'s validation split, None:
``dataset``'s) and held out of training (``holdout_scene``, None: no scene)."""
VIA = {"denoiser": "its denoiser", "generator": "the generator it was fine-tuned from",
       "finetune": "the fine-tune it started from"}  # fmt: skip
"""How a warning names a lineage entry other than the checkpoint's own run, by its stage."""


DIGEST_CHARS = 10
"""Hex digits of a file's content digest kept in a checkpoint (``files_record``): 40 bits, so
that a split of NBA's 938 test files compared with its 3,379 training files has about one
chance in 300,000 of a false match."""
NAMED_FILES = 64
"""A split of at most this many files records each file's name beside its digest
(``files_record``), for the warning to name it; a larger one (NBA's thousands of files)
records the digests alone, 10 characters a file."""


def window_digests(dataset: TrajectoryDataset) -> dict[str, str]:
    """``{file: digest}``: per source file of ``dataset`` (a window's ``scene_id`` before
    ``@`` or ``#``), a 16-digit BLAKE2 digest of its windows' values (positions, agent types,
    context agents) and of their ids after the file's name (``@frame=0.4``, ``#12``). The
    file's name and folder are left out, so that a file copied to another folder or under
    another name, or touched, gives the same digest when read the same way, while changed
    lines or another reading (time step) do not. One pass over arrays in memory."""
    digests: dict[str, Any] = {}
    for scene in dataset.scenes:
        source = scene.scene_id.split("@", 1)[0].split("#", 1)[0]
        h = digests.setdefault(source, hashlib.blake2b(digest_size=8))
        h.update(scene.scene_id[len(source) :].encode())
        for values in (scene.history, scene.future, scene.agent_type, scene.context,
                       scene.context_reverse):  # fmt: skip
            if values is not None:
                h.update(str(values.shape).encode())
                h.update(np.ascontiguousarray(values).tobytes())
    return {f: digests[f].hexdigest() for f in sorted(digests)}


def files_record(digests: dict[str, str]) -> dict[str, str] | str:
    """What a checkpoint records of one split's ``window_digests``: ``{file: digest}`` with
    ``DIGEST_CHARS`` digits, or for more than ``NAMED_FILES`` files the sorted digests alone
    run together in one string (unnamed)."""
    short = {f: d[:DIGEST_CHARS] for f, d in digests.items()}
    if len(short) <= NAMED_FILES:
        return short
    return "".join(sorted(set(short.values())))


def record_files(record: Any) -> dict[str, str | None]:
    """``{digest: file name or None}`` of one split's ``files_record`` (empty for anything
    else: a checkpoint written before the record, a damaged one)."""
    if isinstance(record, dict):
        return {d: f for f, d in record.items() if isinstance(d, str) and isinstance(f, str)}
    if isinstance(record, str) and len(record) % DIGEST_CHARS == 0:
        return {record[i : i + DIGEST_CHARS]: None for i in range(0, len(record), DIGEST_CHARS)}
    return {}


def split_files(train: TrajectoryDataset, val: TrajectoryDataset) -> dict[str, Any]:
    """What a lineage entry records of the files a run trained and chose its epoch on
    (``lineage_entry``'s ``files``): ``{"train": files_record, "val": files_record}``."""
    return {"train": files_record(window_digests(train)),
            "val": files_record(window_digests(val))}  # fmt: skip


def shared_files(a: dict[str, str], b: Any) -> list[tuple[str, str | None]]:
    """``(file of a, file of b)`` for each file of ``a`` (``window_digests``) whose windows
    are those of a file of ``b`` (``window_digests`` or a checkpoint's ``files_record``; the
    file's name None where the record keeps none), in ``a``'s order: the same content under
    any name or folder (compared on ``DIGEST_CHARS`` digits). Empty when none."""
    known = {d[:DIGEST_CHARS]: f for d, f in record_files(b).items()}
    return [(name, known[d[:DIGEST_CHARS]]) for name, d in a.items() if d[:DIGEST_CHARS] in known]


def same_content_note(train: TrajectoryDataset, val: TrajectoryDataset) -> str | None:
    """The note for a run whose validation split holds files with the windows of its
    training files (``shared_files``: a file copied into both ``train/`` and ``val/``, under
    any name): the epoch it keeps is then chosen on windows it trained on. None when none."""
    same = shared_files(window_digests(val), window_digests(train))
    if not same:
        return None
    shown = ", ".join(f"{val.info.split}/{v} = {train.info.split}/{t}" for v, t in same[:3])
    more = f" and {len(same) - 3} more" if len(same) > 3 else ""
    return (f"the validation data holds files with the windows of training files: {shown}"
            f"{more}; the epoch kept is chosen on windows the model trains on, and its "
            "validation numbers are training numbers (give val/ other files)")  # fmt: skip


def lineage_entry(data: Any, stage: str, files: dict[str, Any] | None = None) -> dict[str, Any]:
    """One run of a checkpoint's training lineage (``training_lineage``): its ``stage``
    (``LINEAGE_STAGES``) and what its data config (``data``: a ``config.DataConfig`` or its
    dict) says of the windows it trained and chose its epoch on (``LINEAGE_KEYS``; an empty
    ``val_dataset`` or ``holdout_scene`` is None); with ``files`` (``split_files``: the
    content digests of its training and validation files, recorded since 2026-12), those as
    ``files``."""
    get = data.get if isinstance(data, dict) else lambda key: getattr(data, key, None)
    out = {"stage": stage, "dataset": get("dataset"), "val_dataset": get("val_dataset") or None,
           "holdout_scene": get("holdout_scene") or None}  # fmt: skip
    if isinstance(files, dict):
        out["files"] = files
    return out


def _valid_entry(entry: Any) -> bool:
    return (isinstance(entry, dict) and entry.get("stage") in LINEAGE_STAGES
            and isinstance(entry.get("dataset"), str)
            and all(entry.get(k) is None or isinstance(entry.get(k), str)
                    for k in ("val_dataset", "holdout_scene"))
            and (entry.get("files") is None or isinstance(entry.get("files"), dict)))  # fmt: skip


def training_lineage(header: dict) -> list[dict[str, Any]]:
    """Every run whose training data went into a checkpoint (its header or payload), in
    training order, the checkpoint's own run last: ``lineage_entry`` dicts. A generator's
    denoiser trained on its own data and the generator learns through it (a fine-tune's reward
    is that denoiser's score), and a fine-tune starts from a generator trained on other data
    than ``data.dataset`` may say (``finetune --set data.dataset=eth`` of a zara1 generator):
    what the meta's ``trained_on`` list records, written at training time (``train.stages``),
    its last entry the checkpoint's own run (read from its ``config.data``, what the other
    checks read, should the two differ: a header edited after training). A
    checkpoint written before the record: its own ``config.data`` after, for a generator, its
    embedded denoiser's (a published one's, kept beside it, is its own dataset's); a fine-tune
    of then has lost its start's."""
    meta = header.get("meta") or {}
    recorded = meta.get("trained_on") if isinstance(meta, dict) else None
    if isinstance(recorded, list) and recorded and all(_valid_entry(e) for e in recorded):
        out = [lineage_entry(e, e["stage"], e.get("files")) for e in recorded]
        own = lineage_entry(header["config"]["data"], out[-1]["stage"], out[-1].get("files"))
        return [*out[:-1], own] if isinstance(own["dataset"], str) else out
    out = []
    denoiser = header.get("denoiser")
    if header.get("kind") == "generator" and isinstance(denoiser, dict):
        with contextlib.suppress(KeyError, TypeError, AttributeError):
            out = [e for e in training_lineage(denoiser) if e["stage"] == "denoiser"]
    finetuned = isinstance(meta, dict) and meta.get("method") is not None
    stage = "finetune" if finetuned else header.get("kind")
    own = lineage_entry(header["config"]["data"], stage if stage in LINEAGE_STAGES else "generator")
    return [*out, own] if isinstance(own["dataset"], str) else out


def lineage_data(entry: dict[str, Any]) -> tuple[Any, ...]:
    """What two lineage entries must share to see the same windows (``LINEAGE_KEYS``)."""
    return tuple(entry.get(k) or None for k in LINEAGE_KEYS)


def lineage_others(record: dict, own: dict | None = None) -> list[tuple[dict[str, Any], str]]:
    """The runs of a ``model_timing`` record's ``lineage`` whose data differ from its own run's
    (``own``: a data config dict, by default the lineage's last entry), latest first, each once,
    with how a warning names it (``VIA``: ``its denoiser``, ``the generator it was fine-tuned
    from``); empty for a record without a lineage."""
    lineage = record.get("lineage") if isinstance(record, dict) else None
    if not isinstance(lineage, list) or not lineage:
        return []
    seen = {lineage_data(own if own is not None else lineage[-1])}
    out = []
    for entry in reversed(lineage):
        key = lineage_data(entry)
        if key in seen:
            continue
        seen.add(key)
        out.append((entry, VIA.get(entry.get("stage"), "its training lineage")))
    return out


def model_timing(header: dict) -> dict:
    """The pace and units a checkpoint's model was trained at, from its header (what
    ``train.run.data_timing`` recorded in its meta, else a built-in dataset's own): the keys
    ``trained_on`` (its ``data.dataset``), ``step`` (seconds per window step; None for a model
    trained on a folder before the record, 2026-12-06), ``known`` (whether that step's frame
    interval was given, declared or read from time stamps rather than assumed),
    ``interval_from`` (where that interval came from, ``DatasetInfo.interval_from``'s names;
    None when nothing was recorded; a built-in dataset's step is the registry's, whatever the
    record says), ``time_step`` (its ``data.time_step``), ``units`` and ``agent_types`` (the
    agent-type flags its training windows held, None where not recorded: before 2026-12-06),
    ``val_dataset`` and ``holdout_scene`` (where it chose its epoch: its ``data.val_dataset``,
    None for its own dataset's val split, and its ``data.holdout_scene``, None for none), and
    ``lineage`` (``training_lineage``: every run whose data went into it, a fine-tune's start
    and a generator's denoiser among them)."""
    data = header["config"]["data"]
    read_every = float(data.get("time_step", 1.0))
    out = {"trained_on": data["dataset"], "step": None, "known": False, "interval_from": None,
           "time_step": read_every, "units": "unknown", "agent_types": None,
           "val_dataset": data.get("val_dataset") or None,
           "holdout_scene": data.get("holdout_scene") or None,
           "lineage": training_lineage(header)}  # fmt: skip
    timing = (header.get("meta") or {}).get("data_timing")
    source = SPECS.get(data["dataset"])
    if isinstance(timing, dict):
        origin = timing.get("interval_from")
        out.update(step=float(timing["frame_interval"]), known=origin != "default",
                   interval_from=None if origin is None else str(origin),
                   units=str(timing.get("units") or "unknown"),
                   agent_types=timing.get("agent_types"))  # fmt: skip
        if origin == "dataset" and source is not None:  # a built-in dataset's step is the
            # registry's fact, not the record's copy of it (nba's 0.48 s, recorded until its
            # correction to 0.12 s on 2026-12-06, docs/data.md)
            out["step"] = source.frame_interval * read_every
    elif source is not None:
        out.update(step=source.frame_interval * read_every, known=True, interval_from="dataset",
                   units=source.units)  # fmt: skip
    return out


ATTACHED = ("timing", "frame_interval", "units", "training_width", "training_width_from")
"""The attributes ``attach_timing`` gives a loaded predictor or scorer (``copy_attached``
copies them to a copy of it)."""


def copy_attached(source: Any, target: Any) -> Any:
    """``target`` given ``source``'s ``ATTACHED`` attributes (None where ``source`` has none):
    a scorer at other steps (``TrajectoryScorer.with_steps``) keeps its checkpoint's record,
    and with it its data checks and its wide-scene limit. Returns ``target``."""
    for name in ATTACHED:
        setattr(target, name, getattr(source, name, None))
    return target


def attach_timing(obj: Any, header: dict, width_from: dict | None = None) -> Any:
    """Give a loaded predictor or scorer what its checkpoint says of its training data:
    ``timing`` (``model_timing``'s record, None when the header has none that it reads),
    ``frame_interval`` (seconds per step, None unless known), ``units`` (None unless
    known), ``training_width`` (``training_width``'s width, in model units, of ``width_from``,
    by default ``header``: a scorer's is its denoiser's payload; None where not known, and
    ``wide_limit`` falls back to ``WIDE_LIMIT``) and ``training_width_from`` (where that width
    comes from: ``checkpoint`` or a built-in dataset's name; None). ``timing`` stays
    ``model_timing``'s record alone (``evaluate`` compares the records of a model and its
    scorer to check a shared one once). Returns ``obj``."""
    try:
        timing = model_timing(header)
    except (KeyError, TypeError, ValueError, AttributeError):
        timing = None  # a header without the data section: nothing is known
    obj.timing = timing
    width = training_width(header if width_from is None else width_from)
    obj.training_width, obj.training_width_from = width or (None, None)
    obj.frame_interval = timing["step"] if timing and timing["known"] else None
    units = timing["units"] if timing else "unknown"
    obj.units = None if units in UNKNOWN_UNITS else units
    return obj


def timing_problems(model: dict, step: float | None, units: str | None,
                    hint: Callable[[dict], str]) -> list[str]:  # fmt: skip
    """How data stepping ``step`` seconds (None: not known) in ``units`` (None or
    ``UNKNOWN_UNITS``: not known) differs from what the model (``model_timing``'s record) was
    trained on: a list of phrases, empty when nothing known differs. The step is compared
    within 1 % only where the model's is recorded; ``hint(model)`` says how to read the data
    at the model's step (the CLI names its options, Python the resampling)."""
    problems = []
    known = [u for u in (units, model["units"]) if u is not None and u not in UNKNOWN_UNITS]
    if len(known) == 2 and not same_units(*known):
        problems.append(f"this data is in {units}, the model's in {model['units']}"
                        + _conversion_hint(units, model["units"]))  # fmt: skip
    if (step is not None and step > 0 and model["step"] is not None
            and not math.isclose(step, model["step"], rel_tol=0.01)):  # fmt: skip
        problems.append(f"this data steps {step:g} s, the model's {model['step']:g} s "
                        f"({hint(model)})")  # fmt: skip
    return problems


def _conversion_hint(units: str, model_units: str) -> str:
    """How to give data in ``units`` to a model in ``model_units`` where both are lengths that
    ``METRES_PER_UNIT`` knows (ft and m, cm and m): the factor, since a unit name (``--units``,
    ``units=``) is only compared, never applied. Empty otherwise (pixels: no fixed factor)."""
    data = METRES_PER_UNIT.get(units.strip().lower())
    own = METRES_PER_UNIT.get(model_units.strip().lower())
    if data is None or own is None:
        return ""
    return (
        f" (units are named, not converted: multiply x and y by {data / own:.4g} to give "
        f"{model_units} before reading them, and the futures, in {model_units}, by "
        f"{own / data:.4g} for {units})"
    )


def unstated_timing(model: dict, step_assumed: bool, units: str | None) -> list[str]:
    """What the data leaves unsaid that the model (``model_timing``'s record) recorded, the
    case ``timing_problems`` cannot see (an assumed 0.4 s equals a 0.4 s model's step; unknown
    units are never compared): ``"interval"`` when the data's frame interval is only assumed
    (``step_assumed``: ``DatasetInfo.interval_from == "default"``) while the model's step is
    known (given, declared, time stamps or a built-in dataset's), and ``"units"`` when the
    data's ``units`` are unknown (None or ``UNKNOWN_UNITS``) while the model's are known."""
    out = []
    if step_assumed and model["known"] and model["step"] is not None:
        out.append("interval")
    if (units is None or units in UNKNOWN_UNITS) and model["units"] not in UNKNOWN_UNITS:
        out.append("units")
    return out


def trained_otherwise(name: str, model: dict, problems: list[str]) -> str:
    """The one warning line for ``timing_problems``' findings."""
    return f"{name} was trained on {model['trained_on']}: {'; '.join(problems)}"


RESAMPLER = "trajpref.data.tracks_to_history"
"""The public call that resamples a tracker's rows to a model's step, named by ``check_pace``."""


def _resample_hint(model: dict, step: float | None = None) -> str:
    """How to give the model (``model_timing``'s record) its own step, for data stepping
    ``step`` seconds: a step above ``SECONDS_STEPS``' ceiling (10 s) is first asked whether it
    is in milliseconds (``frame_interval=400`` for 0.4 s)."""
    want = model["step"]
    prefix = ""
    if step is not None and step > SECONDS_STEPS[1]:
        prefix = f"milliseconds? pass seconds, frame_interval={step / 1000:g}; else "
    return (f"{prefix}resample the history to one position every {want:g} s, e.g. with "
            f"{RESAMPLER}(times, ids, xy, now, step={want:g}); the futures step {want:g} s "
            "too")  # fmt: skip


def check_pace(
    obj: Any,
    frame_interval: float | None,
    units: str | None,
    name: str = "this model",
    stacklevel: int = 3,
) -> None:
    """Warn (``OutOfRangeWarning``, a ``UserWarning``) when ``frame_interval`` (seconds
    between the positions handed to ``obj``) or ``units`` differ from what ``obj`` (a
    predictor or scorer carrying ``attach_timing``'s record) was trained on: the Python side
    of the CLI's warning. Only what both sides know is compared: ``frame_interval`` against a
    recorded, known step; units against recorded units. ConfigError for a ``frame_interval``
    that is not a number > 0."""
    frame_interval = check_frame_interval(frame_interval, "seconds between the history's positions")
    if units is not None and not isinstance(units, str):
        raise ConfigError(f"units: a unit name such as 'm' or 'px', got {units!r}")
    timing = getattr(obj, "timing", None)
    if timing is None or (frame_interval is None and units is None):
        return
    known = dict(timing, step=getattr(obj, "frame_interval", None))  # compare known steps only
    problems = timing_problems(known, frame_interval, units,
                               lambda m: _resample_hint(m, frame_interval))  # fmt: skip
    if problems:
        warnings.warn(trained_otherwise(name, timing, problems), OutOfRangeWarning,
                      stacklevel=stacklevel)  # fmt: skip


PACE_REFERENCE = 0.582
"""The fastest of the training splits' 99th percentiles of the observed step (model units per
step, first to last observed position, ``data.transforms.observed_pace``): NBA's 0.582; the
others 0.28 (robo-sim) to 0.529 (SDD) (docs/pretraining.md, "An input speed clamp")."""
PACE_LIMIT = 5.0
"""``pace_problem`` (``check_observed_steps``) warns when the ``PACE_QUANTILE`` of the observed
steps of the agents handed over at once exceeds this many model units per step: about 8.6 times
``PACE_REFERENCE`` (zara1, data scale 1.47 m: 7.4 m per 0.4 s step, 18 m/s). Positions in
centimetres given to a metre model move 100 times their metre pace (a walker 15-50 model
units per step). No scene of the published ETH/UCY and SDD training and test splits nor of
robo's and nba's test splits reaches 2.4 (SDD's fastest training scene; 0.73 on the ETH/UCY
ones, 0.58 on nba's), each read with its own model's scale (2026-12-06)."""
PACE_QUANTILE = 0.9
"""The quantile over agents that ``pace_problem`` compares with ``PACE_LIMIT``: the
90th percentile, not the median, as most agents of many scenes stand (the median of hotel's
test split in centimetres stays below the limit; its 90th percentile is above it in 60 % of
its scenes), and not the largest, so that one mistracked agent
among many is not taken for the data's units."""


def _cpu_float64(history: Any) -> torch.Tensor:
    """``history`` (numpy or torch) as a float64 CPU tensor, for the checks' arithmetic."""
    if isinstance(history, torch.Tensor):
        return history.detach().to("cpu", torch.float64)
    return torch.as_tensor(history, dtype=torch.float64)


def pace_quantile(history: Any, scale: float, q: float = PACE_QUANTILE) -> tuple[float, int] | None:
    """The ``q`` quantile over agents (linear interpolation) of the observed step
    (``data.transforms.observed_pace``: first to last observed position per step, divided by
    ``scale``) of ``history`` [N, T_h, 2] (numpy or torch; agents with a non-finite position
    are left out), and the number of agents it was taken over; None when no agent has two
    finite observed steps."""
    hist = _cpu_float64(history)  # [N, T_h, 2]
    if hist.ndim != 3 or hist.shape[1] < 2 or hist.shape[0] == 0:
        return None
    pace = observed_pace(hist, scale)  # [N] model units per step
    pace = pace[pace.isfinite()]  # [N'] agents seen at every step
    if not len(pace):
        return None
    return float(pace.quantile(q)), len(pace)


def pace_problem(obj: Any, history: Any, name: str = "this model") -> str | None:
    """The warning text when the ``PACE_QUANTILE`` of the observed steps of ``history``
    [N, T_h, 2] (positions in the data's units: every agent that one call or one run hands to
    ``obj``) exceeds ``PACE_LIMIT`` model units per step, the units of ``obj`` (a predictor or
    scorer: positions divided by its data scale ``obj.scale``; one without a scale, the
    constant-velocity baseline, reads any units); None otherwise. The model's units are
    ``obj.units`` where known."""
    scale = getattr(obj, "scale", None)
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not scale > 0:
        return None
    found = pace_quantile(history, float(scale))
    if found is None or not found[0] > PACE_LIMIT:
        return None
    units = getattr(obj, "units", None) or "unknown"
    # the same text at every call (no per-scene numbers), so a planner's loop is warned once
    return (f"{name} is given agents much faster than it was trained on: the "
            f"{PACE_QUANTILE:.0%} quantile of their observed step is above {PACE_LIMIT:g} "
            f"model units (positions / the model's data scale {scale:g}), where the 99th "
            f"percentile of any published model's training data is at most {PACE_REFERENCE}. "
            f"The data looks like it is in other units than the model's ({units}; centimetres "
            "given to a metre model move 100 times as far) or at another pace: its "
            "predictions, and the score's ranking of them, would mean nothing. Convert the "
            "positions to the model's units and step (trajpref.models.timing.pace_quantile "
            "gives the number)")  # fmt: skip


JUMP_LIMIT = PACE_LIMIT
"""``jump_problem`` (``check_observed_steps``) warns when one agent's single observed step (between
two consecutive history positions) exceeds this many model units (positions / the model's data
scale): 7.4 m in one 0.4 s step at zara1's scale of 1.47 m, where a tracker id switch (two
people under one id) or a long gap bridged as one step jumps the position, and the model fans
its futures out over tens of metres (a 10 m jump, 6.8 model units, spread zara1's generator's
final positions of that agent over 35 m, against 5 m without it). The largest single step of any
target agent of the published test splits, each read with its own model's scale (2026-12,
walkthrough 65): zara1 0.68 (1.0 m), eth 1.02 (1.55 m), sdd 2.46 (145 px), hotel 0.52, univ
0.50, zara2 0.60, robo 0.58, nba's players 0.62; nba's ball steps up to 8.5 and is not checked
(``AGENT_BALL``). The training splits of zara1's and eth's folds stay below 1.06; sdd's holds
one 14.9 (881 px, ``train.npz#3491``): a mistracked window of the kind this warns of."""


def observed_jumps(history: Any, scale: float, agent_type: Any = None) -> torch.Tensor:
    """[N] bool: the agents of ``history`` [N, T_h, 2] (numpy or torch, the data's units)
    with a single observed step (between consecutive finite positions) above ``JUMP_LIMIT``
    model units (divided by ``scale``); an agent typed ``AGENT_BALL`` in ``agent_type`` [N]
    (None: all people) never counts, a ball being that fast."""
    hist = _cpu_float64(history)  # [N, T_h, 2]
    if hist.ndim != 3 or hist.shape[1] < 2:
        return torch.zeros(hist.shape[0] if hist.ndim else 0, dtype=torch.bool)
    steps = (hist[:, 1:] - hist[:, :-1]).norm(dim=-1) / scale  # [N, T_h - 1], NaN where unseen
    jumps = (steps > JUMP_LIMIT).any(dim=1)  # [N] (NaN compares False)
    if agent_type is not None:
        kinds = torch.as_tensor(
            agent_type.detach().cpu() if isinstance(agent_type, torch.Tensor) else agent_type
        ).reshape(-1)  # [N]
        if len(kinds) == len(jumps):
            jumps &= kinds != AGENT_BALL
    return jumps


def jump_problem(obj: Any, history: Any, name: str = "this model",
                 agent_type: Any = None) -> str | None:  # fmt: skip
    """The warning text when an agent of ``history`` [N, T_h, 2] takes a single observed step
    above ``JUMP_LIMIT`` model units of ``obj`` (a predictor or scorer: positions divided by
    ``obj.scale``; one without a scale, the constant-velocity baseline, is never warned);
    balls in ``agent_type`` [N] are not checked (``observed_jumps``). None otherwise. The text
    is the same at every call (no count), so that a planner's loop is warned once."""
    scale = getattr(obj, "scale", None)
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not scale > 0:
        return None
    if not bool(observed_jumps(history, float(scale), agent_type).any()):
        return None
    return (f"{name} is given an agent whose position jumps more than {JUMP_LIMIT:g} model "
            f"units (positions / the model's data scale {scale:g}) in one observed step, "
            "where no agent of the published test splits steps more than 2.5: a tracker id "
            "switch (two people under one id) or a gap bridged as one step. The model reads "
            "it as a sprint and fans that agent's futures out many times wider than a "
            "walker's. Check the tracker's ids and gaps, and split such a track at its jump; "
            "trajpref.models.timing.observed_jumps(history, model.scale) says which agents, "
            "and how many")  # fmt: skip


FAST_LIMIT = 1.0
"""``fast_problem`` (``check_observed_steps``) warns when the ``PACE_QUANTILE`` of the observed
steps of the agents handed over at once (balls left out) exceeds this many model units per step
and the model has no input speed clamp (``speed_clamp``): its futures, or a scorer's scores, then
extrapolate past its training (robo's generator gave walkers at 10 times robo's median pace
steps of up to 39 m). 1.0 model unit is 1.47 m per 0.4 s step at zara1's scale, 1.73 m per
0.5 s at robo's, 59 px at SDD's; the training splits' 99th percentile is at most
``PACE_REFERENCE``. Chosen as the lowest of the candidates 1.0, 1.5, 2.0 and 2.5 at which no
published model's test split warns on more than 1 % of its scenes: the share of scenes (windows)
whose ``PACE_QUANTILE`` of its agents' pace, in that model's units, exceeds each candidate
(2026-12-06, walkthrough 68; eth's generator-pace reads eth's split as eth's generator; the
training splits' largest scene: 0.54-0.66 on ETH/UCY's, 0.63 nba, 0.32 robo-sim, 0.37
robo-mix, 2.39 SDD, 6 of whose 5,487 scenes exceed 1.0)::

    test split (scenes)   scene max   > 1.0       > 1.5       > 2.0   > 2.5
    eth (253)             0.734       0           0           0       0
    hotel (445)           0.449       0           0           0       0
    univ (947)            0.322       0           0           0       0
    zara1 (705)           0.463       0           0           0       0
    zara2 (998)           0.514       0           0           0       0
    nba (5,126)           0.578       0           0           0       0
    robo (578)            0.427       0           0           0       0
    robo-mix (578)        0.422       0           0           0       0
    sdd (1,951)           1.689       0.05 % (1)  0.05 % (1)  0       0
"""
WIDE_LIMIT = 25.0
"""The wide-scene limit of a model whose training width is not known (``wide_limit``): one built in
code, or loaded from a checkpoint that records none (written before the record, 2026-12-06) and
trained on data other than a built-in dataset (``TRAINING_WIDTHS``). ``wide_problem``
(``check_observed_steps``) warns when two agents of one scene lie more than its model's limit
apart at the scene's last observed frame (in model units: positions / the model's data scale)
and the model has no neighbour radius (``model.neighbour_radius``, ``scorer.neighbour_radius``):
every agent then attends to every other, however far, and one far agent moves the others'
futures and scores. Each model's own limit is the lowest multiple of ``WIDTH_STEP`` above its
training width (``wide_limit``: the farthest two agents of its training scenes were apart); this
one is that of the widest, NBA's court (21.39 -> 25: 36.8 m at zara1's scale, 1,475 px at
SDD's). The largest distance between two agents (targets; the context-only neighbours seen at
the last frame in brackets) at the last observed frame of any scene, per split, in each model's
units (2026-12-06, walkthrough 68), and each published model's own limit: no scene of any
published test split lies above it (recounted 2026-12-06 as ``check_observed_steps`` measures a
split's windows, their targets: 0 scenes of every split for each of the 19 published models)::

    model (train / test data)   train max     test max      above 10 / 15 / 20 / 25  limit
    eth                         10.74 (13.07)  7.43 (12.96)  0 / 0 / 0 / 0 of 253    15
    hotel                       10.72 (13.04)  7.73 (9.45)   0 / 0 / 0 / 0 of 445    15
    univ                         7.25 (10.47)  8.68 (10.56)  0 / 0 / 0 / 0 of 947    15
    zara1                       11.09 (13.50)  7.92 (11.33)  0 / 0 / 0 / 0 of 705    15
    zara2                       10.85 (13.21)  9.02 (11.38)  0 / 0 / 0 / 0 of 998    15
    nba                         21.39          18.16         44.2 % / 0.57 % / 0 / 0   25
                                                             of 5,126
    robo (robo-sim / robo)       7.93           6.50         0 / 0 / 0 / 0 of 578    10
    robo-mix                     7.83           6.42         0 / 0 / 0 / 0 of 578    10
    sdd                          9.25           6.51         0 / 0 / 0 / 0 of 1,951  10
"""
WIDTH_STEP = 5.0
"""A model's wide-scene limit (``wide_limit``) is the lowest multiple of this, in model units,
above its training width (``dataset_width``): 21.39 on NBA's court -> 25, 13.39 on zara1's ->
15, 9.25 on SDD's -> 10; a width of exactly 15 -> 20. Round numbers a planner can remember,
that leave every published test split unwarned (0 scenes: ``WIDE_LIMIT``'s table)."""
TRAINING_WIDTHS = {"eth": 12.96, "hotel": 10.72, "univ": 10.47, "zara1": 13.39, "zara2": 13.10,
                   "nba": 21.39, "robo-sim": 7.93, "robo-mix": 7.83, "sdd": 9.25}  # fmt: skip
"""The training width (``dataset_width``, in the published model's units) of each built-in
dataset's training split, for a checkpoint that records none (the published files, any file
written before the record, 2026-12-06) and whose ``data.dataset`` names the dataset: what its
published generator reads, the targets and, for the context-reading ones (eth, univ, zara1, zara2:
``model.context_agents``, their context-only agents seen over the whole history), those
(measured 2026-12-06 on each published config's own training split; ``WIDE_LIMIT``'s table
counts every context-only agent at the last frame, 0.1 more). The published denoisers read no
context (targets 10.74 eth, 7.25 univ, 11.09 zara1, 10.85 zara2): univ's denoiser is then given
univ's generator's 15, not its own 10, a limit no test scene of univ reaches either way.
``robo`` has no training split (``robo-sim`` trains the published robo models)."""
TRAINING_WIDTH_KEY = "training_width"
"""The key of a checkpoint's meta that records its training width (``dataset_width``, model
units), written by every training stage since 2026-12-06 (``train.stages``)."""


def _width_number(value: Any) -> float | None:
    """``value`` as a float where it is a finite number >= 0 (a training width), else None."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    value = float(value)
    return value if math.isfinite(value) and value >= 0 else None


def training_width(header: Any) -> tuple[float, str] | None:
    """A checkpoint's training width in model units (``dataset_width``) and where it comes
    from, read from its header or payload: its meta's ``TRAINING_WIDTH_KEY`` (``checkpoint``),
    else, where its ``data.dataset`` is a built-in dataset that ``TRAINING_WIDTHS`` holds, that
    entry (the dataset's name); None otherwise (``wide_limit`` then gives ``WIDE_LIMIT``)."""
    meta = header.get("meta") if isinstance(header, dict) else None
    width = _width_number(meta.get(TRAINING_WIDTH_KEY)) if isinstance(meta, dict) else None
    if width is not None:
        return width, "checkpoint"
    try:
        dataset = header["config"]["data"]["dataset"]
    except (KeyError, TypeError, IndexError):
        return None
    if isinstance(dataset, str) and dataset in TRAINING_WIDTHS:
        return TRAINING_WIDTHS[dataset], dataset
    return None


def wide_limit(width: Any) -> float:
    """The wide-scene limit, in model units, of a model whose training width is ``width``
    (model units): the lowest multiple of ``WIDTH_STEP`` above it (21.39 -> 25, 13.39 -> 15,
    15 -> 20, 0 -> 5); ``WIDE_LIMIT`` where ``width`` is None or not a number >= 0."""
    width = _width_number(width)
    if width is None:
        return WIDE_LIMIT
    return WIDTH_STEP * (math.floor(width / WIDTH_STEP) + 1)


def model_width(obj: Any) -> tuple[float, str] | None:
    """The training width of ``obj`` (a predictor or scorer; ``attach_timing``'s
    ``training_width``) and where it comes from (``training_width_from``: ``checkpoint``, a
    built-in dataset's name, or ``set`` for a number set by hand without one); None where it
    has none (built in code, or a checkpoint ``training_width`` finds nothing for)."""
    width = _width_number(getattr(obj, "training_width", None))
    if width is None:
        return None
    source = getattr(obj, "training_width_from", None)
    return width, source if isinstance(source, str) and source else "set"


WIDE_CHUNK = 4096
"""Agents per block of ``scene_widths``' distance matrix (a block of 4,096 x N float64)."""


def _model_scale(obj: Any) -> float | None:
    """``obj.scale`` (data units per model unit) as a float, None where it has none (the
    constant-velocity baseline) or it is not a number > 0."""
    scale = getattr(obj, "scale", None)
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not scale > 0:
        return None
    return float(scale)


def speed_clamp(obj: Any) -> float | None:
    """The input speed clamp ``obj`` applies, in model units per step: a leapfrog predictor's
    ``model.max_speed`` (``obj.generator.cfg.max_speed``, ``ModelConfig.max_speed``) where it
    is > 0; None for none: 0 (off, as robo's, robo-mix's, nba's and SDD's published generators),
    the full sampler (no generator runs), a scorer and the constant-velocity baseline."""
    generator = getattr(obj, "generator", None)
    if generator is None or getattr(obj, "sampler", "leapfrog") != "leapfrog":
        return None
    clamp = getattr(getattr(generator, "cfg", None), "max_speed", None)
    if isinstance(clamp, bool) or not isinstance(clamp, numbers.Real) or not clamp > 0:
        return None
    return float(clamp)


def _people(history: Any, agent_type: Any) -> torch.Tensor:
    """The agents of ``history`` [N, T_h, 2] not typed ``AGENT_BALL`` in ``agent_type`` [N]
    (None, or flags of another length: all of them), as a float64 CPU tensor."""
    hist = _cpu_float64(history)
    if agent_type is None or hist.ndim != 3:
        return hist
    kinds = torch.as_tensor(
        agent_type.detach().cpu() if isinstance(agent_type, torch.Tensor) else agent_type
    ).reshape(-1)  # [N]
    return hist[kinds != AGENT_BALL] if len(kinds) == len(hist) else hist


def fast_problem(obj: Any, history: Any, name: str = "this model",
                 agent_type: Any = None) -> str | None:  # fmt: skip
    """The warning text when the ``PACE_QUANTILE`` of the observed steps of ``history``
    [N, T_h, 2] (balls in ``agent_type`` [N] left out) exceeds ``FAST_LIMIT`` model units of
    ``obj`` (a predictor or scorer; positions divided by ``obj.scale``) and ``obj`` has no
    input speed clamp (``speed_clamp``); None otherwise, and for an object without a scale
    (the constant-velocity baseline). Agents this fast are in the model's units but faster
    than its training data (far faster, above ``PACE_LIMIT``, is ``pace_problem``'s other
    units). The text is the same at every call, so that a planner's loop is warned once."""
    scale = _model_scale(obj)
    if scale is None or speed_clamp(obj) is not None:
        return None
    found = pace_quantile(_people(history, agent_type), scale)
    if found is None or not found[0] > FAST_LIMIT:
        return None
    units = getattr(obj, "units", None) or "data units"
    head = (f"{name} is given agents faster than its training data: the {PACE_QUANTILE:.0%} "
            f"quantile of their observed step is above {FAST_LIMIT:.1f} model units "
            f"({FAST_LIMIT * scale:.4g} {units} at the model's data scale {scale:g}), where "
            f"the 99th percentile of any published model's training data is at most "
            f"{PACE_REFERENCE} and no published test split has 1 % of its scenes above it, "
            "and it has no input speed clamp (model.max_speed; docs/pretraining.md, 'An input "
            "speed clamp for agents faster than training'): ")  # fmt: skip
    if getattr(obj, "generator", None) is not None and getattr(obj, "sampler", None) == "leapfrog":
        return head + (
            "its futures for them extrapolate (robo's generator gave walkers at 10 times "
            "robo's median pace steps of up to 39 m). Set one, in model units per step: in "
            "Python model.generator.cfg.max_speed = its training split's 99th percentile of "
            "the pace (0.280 for robo and robo-mix, 0.529 for SDD, 0.582 for NBA), "
            "--max-speed on the command line; faster agents are then predicted as scaled-up "
            "copies of the fastest it was trained on. If they are not this fast, check the "
            "positions' units and step")  # fmt: skip
    what = "its scores of their samples" if not hasattr(obj, "generator") else "its futures"
    return head + (
        f"{what} extrapolate (the clamp acts on a leapfrog generator's inputs; a scorer's "
        "denoiser and the full sampler have none). If they are not this fast, check the "
        "positions' units and step; for predictions, a leapfrog generator with "
        "model.generator.cfg.max_speed set (--max-speed on the command line) keeps them in "
        "its training range")  # fmt: skip


def scene_widths(history: Any, scenes: Any = None) -> torch.Tensor:
    """[B] float64: per scene, the largest distance between two of its agents at the last
    observed frame of ``history`` [N, T_h, 2] (numpy or torch, the data's units; agents not
    finite there left out; 0 for fewer than two), its N agents split into consecutive scenes
    of ``scenes`` [B] sizes (None: one scene)."""
    hist = _cpu_float64(history)
    if hist.ndim != 3 or not hist.shape[1]:
        return torch.zeros(0, dtype=torch.float64)
    last = hist[:, -1]  # [N, 2]
    sizes = [len(last)] if scenes is None else [int(n) for n in scenes]
    out = []
    for part in last.split(sizes):  # [P_b, 2]
        part = part[part.isfinite().all(dim=-1)]
        widest = 0.0
        for rows in part.split(WIDE_CHUNK) if len(part) > 1 else ():
            widest = max(widest, float(torch.cdist(rows, part).max()))
        out.append(widest)
    return torch.tensor(out, dtype=torch.float64)


def dataset_width(dataset: TrajectoryDataset, scale: float, context: bool = False,
                  context_frames: int = 0) -> float:  # fmt: skip
    """A model's training width: the largest distance between two agents at the last observed
    frame of any scene of ``dataset`` (``scene_widths``), in model units (divided by
    ``scale``), over what the model reads: the targets and, with ``context`` (a generator
    built with ``ModelConfig.context_agents``), the context-only agents it reads, those seen
    in at least the last ``context_frames`` history frames without a break (0: all of them;
    ``data.transforms.observed_context``'s rule). 0.0 for data without a scene of two agents.
    Arithmetic on the arrays alone: nothing is drawn from any random stream."""
    rows, sizes = [], []
    for scene in dataset.scenes:
        last = np.asarray(scene.history[:, -1], dtype=np.float64)  # [P, 2]
        ctx = scene.context if context else None
        if ctx is not None and len(ctx):
            frames = context_frames or ctx.shape[1]
            read = (seen_run(torch.as_tensor(ctx)) >= frames).numpy()  # [C]
            last = np.concatenate([last, np.asarray(ctx[read, -1], dtype=np.float64)])
        rows.append(last)
        sizes.append(len(last))
    if not rows:
        return 0.0
    widths = scene_widths(np.concatenate(rows)[:, None], sizes)  # [B]
    return float(widths.max()) / float(scale) if len(widths) else 0.0


def _width_origin(found: tuple[float, str] | None) -> str:
    """How ``wide_problem``'s text says where a model's limit comes from (``model_width``)."""
    if found is None:
        return ("the limit of a model whose training width is not known (its checkpoint "
                "records none and its data is no built-in dataset), above the widest "
                "training scene of any published model (21.4 model units, NBA's "
                "court)")  # fmt: skip
    width, source = found
    where = {"checkpoint": "recorded in its checkpoint",
             "set": "its training_width as set"}.get(source,
             f"{source}'s training split, timing.TRAINING_WIDTHS")  # fmt: skip
    return (f"its limit: the lowest multiple of {WIDTH_STEP:g} above the width of its widest "
            f"training scene, which is {width:.2f} model units ({where})")  # fmt: skip


def wide_problem(obj: Any, history: Any, name: str = "this model",
                 scenes: Any = None) -> str | None:  # fmt: skip
    """The warning text when two agents of one scene of ``history`` [N, T_h, 2] (split into
    ``scenes`` [B] consecutive sizes; None: one scene) lie more than ``obj``'s own limit
    (``wide_limit`` of its training width, ``model_width``: ``WIDE_LIMIT`` where that is not
    known) in its model units apart at the last observed frame (``scene_widths``, divided by
    ``obj.scale``) and ``obj`` (a predictor or scorer) has no ``neighbour_radius``; None
    otherwise, and for an object without a scale (the constant-velocity baseline). The text
    names the limit and where it comes from, the same at every call, so that a planner's loop
    is warned once."""
    scale = _model_scale(obj)
    if scale is None or getattr(obj, "neighbour_radius", None) is not None:
        return None
    found = model_width(obj)
    limit = wide_limit(None if found is None else found[0])
    widths = scene_widths(history, scenes)
    if not bool((widths > limit * scale).any()):
        return None
    units = getattr(obj, "units", None) or "data units"
    return (f"{name} is given a scene with two agents more than {limit:g} model units "
            f"apart at its last observed frame ({limit * scale:.4g} {units} at the model's "
            f"data scale {scale:g}; {_width_origin(found)}), and it has no neighbour "
            "radius: every agent attends to every other however far, and a far agent moves the "
            "others' futures and scores (one walker 40 m to the side moved zara1's final "
            "positions of a straight walker by 4.3 m). Set model.neighbour_radius (and "
            "scorer.neighbour_radius; --neighbour-radius on the command line), in the "
            "data's units, e.g. 12 for the pedestrian models in metres (README, 'Scenes "
            "wider than the training scenes: set a neighbour radius'); "
            "trajpref.models.timing.scene_widths gives the distances")  # fmt: skip


def observed_problems(obj: Any, history: Any, name: str = "this model",
                      agent_type: Any = None, scenes: Any = None) -> dict[str, str]:  # fmt: skip
    """The warning texts that apply to the agents ``history`` [N, T_h, 2] hands to ``obj`` (a
    predictor or scorer; ``agent_type`` [N]: balls are not checked for jumps or pace;
    ``scenes`` [B]: the sizes of the consecutive scenes it joins, None: one scene), keyed by
    cause, what ``check_observed_steps`` (Python's calls) and ``evaluation.warn_observed_pace``
    (the CLI's and ``evaluate``'s runs over a split) both warn of: ``units``, data in other
    units (``pace_problem``), alone, since it moves and spreads every agent; else ``steps``,
    one agent's jump (``jump_problem``) or, where none, agents faster than training for a
    model without a speed clamp (``fast_problem``), and ``wide``, a scene wider than training
    for a model without a neighbour radius (``wide_problem``). Empty when none applies."""
    units = pace_problem(obj, history, name)
    if units is not None:  # other units: every distance off, it alone
        return {"units": units}
    steps = jump_problem(obj, history, name, agent_type)
    found = {"steps": steps or fast_problem(obj, history, name, agent_type),
             "wide": wide_problem(obj, history, name, scenes)}  # fmt: skip
    return {cause: text for cause, text in found.items() if text is not None}


def check_observed_steps(obj: Any, history: Any, name: str = "this model",
                         stacklevel: int = 3, agent_type: Any = None,
                         scenes: Any = None) -> bool:  # fmt: skip
    """Warn (``OutOfRangeWarning``, a ``UserWarning``) of what is wrong with the agents
    ``history`` [N, T_h, 2] hands to ``obj`` (a predictor or scorer; ``scenes`` [B]: the sizes
    of the consecutive scenes it joins, None: one scene), each cause once
    (``observed_problems``): data in other units (``pace_problem``) alone, since it moves and
    spreads every agent; else one agent's jump (``jump_problem``) or, where none, agents faster
    than training for a model without a speed clamp (``fast_problem``), and beside either a
    scene wider than training for a model without a neighbour radius (``wide_problem``).
    Returns whether it warned. The same texts at every call, so that a planner's loop is
    warned once."""
    found = observed_problems(obj, history, name, agent_type, scenes)
    for text in found.values():
        warnings.warn(text, OutOfRangeWarning, stacklevel=stacklevel)
    return bool(found)
