"""TrajNet++ ``.ndjson`` scene files: read them as a dataset, and write predictions in the
layout that trajnetplusplustools' ``Reader`` and its evaluator's metrics accept.

One JSON object per line (``docs/data_format.md``)::

    {"scene": {"id": 3, "p": 12, "s": 100, "e": 120, "fps": 2.5, "tag": [2, []]}}
    {"track": {"f": 100, "p": 12, "x": 1.23, "y": 4.56}}
    {"track": {"f": 109, "p": 12, "x": 1.9, "y": 4.1, "prediction_number": 0, "scene_id": 3}}

A scene follows its primary agent ``p`` from frame ``s`` to frame ``e``; the agents of the scene
are every agent with rows in those frames. Rows with a ``prediction_number`` are predictions.
"""

from __future__ import annotations

import bisect
import itertools
import json
import math
import warnings
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path

import numpy as np

from trajpref.data.text import (
    DEFAULT_MAX_COORD,
    EXACT_ID_LIMIT,
    check_file,
    file_lines,
    open_data_file,
    source_ids,
)
from trajpref.errors import ConfigError, DataError, GapWarning, ObservedOnlyWarning
from trajpref.errors import FrameRateWarning as FrameRateWarning  # its older place
from trajpref.io import atomic_path
from trajpref.types import WINDOW, Scene


@dataclass
class TrajnetScenes:
    """What one ``.ndjson`` file holds, as windows."""

    scenes: list[Scene]
    """One scene per TrajNet++ scene: the primary agent first, then every agent with a row in
    all of its T_h + T_f frames, by id (``Scene.agent_id``: their ``"p"`` ids); the others
    seen at its last observed frame as ``Scene.context`` (None when there are none); its
    frames and scene row as
    ``Scene.frames`` and ``Scene.source_row``. An observation-only scene (a test file's) has
    its future NaN and its future frames computed (``read_trajnet``)."""
    fps: set[float] = field(default_factory=set)
    """The ``fps`` values the scene rows declare."""
    observed_only: int = 0
    """How many of ``scenes`` are observation-only (``Scene.future`` NaN)."""


def _number(value, what: str, path: Path, line: int, integer: bool = False):
    """A field's number: an exact ``int`` when ``integer`` (ids and frames, of any size), else a
    float. ``value`` is what json read: an int, a float, or a Decimal for a float written beyond
    ``EXACT_ID_LIMIT`` (``_exact_floats``), whose float64 value would be rounded."""
    if isinstance(value, bool) or not isinstance(value, (int, float, Decimal)):
        raise DataError(f"{what} must be a number, got {value!r}", path, line)
    if integer and isinstance(value, int):
        return value  # exact, however large
    if integer and isinstance(value, Decimal):
        if value != value.to_integral_value():
            raise DataError(f"{what} must be an integer, got {value}", path, line)
        return int(value)
    try:
        value = float(value)
    except OverflowError:  # an int beyond float's range (10**400)
        value = math.inf
    if not math.isfinite(value):
        raise DataError(f"{what} is NaN or infinite", path, line)
    if integer:
        if value != int(value):
            raise DataError(f"{what} must be an integer, got {value}", path, line)
        return int(value)
    return value


def _exact_floats(obj: dict, text: str) -> dict:
    """``obj`` (one line's JSON object), read again with its floats as Decimals when one of
    its fields is a float beyond ``EXACT_ID_LIMIT`` (2**53): json reads ``"p":
    9007199254740993.0`` as the float 9007199254740992.0, so two agents (or frames) would
    merge. Lines without such a float, all but a few, are not read twice."""
    inner = next(iter(obj.values()))
    if any(isinstance(v, float) and abs(v) >= EXACT_ID_LIMIT for v in inner.values()):
        return json.loads(text, parse_float=Decimal)
    return obj


def _fields(obj: dict, keys: tuple[str, ...], kind: str, path: Path, line: int) -> list:
    missing = [k for k in keys if k not in obj]
    if missing:
        raise DataError(f"{kind} row without {', '.join(repr(k) for k in missing)}", path, line)
    return [obj[k] for k in keys]


def read_trajnet(
    path: str | Path,
    t_hist: int = 8,
    t_fut: int = 12,
    max_coord: float = DEFAULT_MAX_COORD,
    units: str = "m",
) -> TrajnetScenes:
    """Read one TrajNet++ ``.ndjson`` file into scenes of ``t_hist + t_fut`` frames.

    Each TrajNet++ scene becomes one ``Scene`` over the last ``t_hist + t_fut`` frames of its
    primary agent inside ``[s, e]`` (TrajNet++ scenes have 9 + 12 frames; the default keeps the
    last 8 observed). Raises ``DataError`` naming the file and line for a line that is not a
    JSON object of one ``scene`` or ``track``, a missing or non-numeric field, NaN, a coordinate
    beyond ``max_coord`` (in ``units``), a repeated (frame, agent) row or scene id, and a scene
    whose primary agent has fewer frames than a window needs.

    Observation-only scenes (TrajNet++'s test files: the scene row spans 9 + 12 frames, the
    tracks stop after the 9 observed) are read too: a scene whose primary agent has fewer than
    ``t_hist + t_fut`` frames in ``[s, e]`` but a row at every frame from ``s`` to
    ``e - t_fut * step`` (the file's step), at least ``t_hist`` of them, and none in the
    ``t_fut`` frames after them. Its window is its last ``t_hist`` observed frames and the
    ``t_fut`` future frames, computed (``Scene.frames``, where predictions are written); its
    targets the primary agent and every agent with a row in all ``t_hist`` observed frames,
    its context as a complete scene's, its ``future`` NaN [P, T_f, 2]. A future row at a frame
    that another scene of the file shows as observed is not counted: TrajNet++'s test files
    keep every row at such a frame, so overlapping scenes put rows in each other's hidden
    future (its baselines drop them, ``evaluator/write_utils.preprocess_test``). A scene whose
    primary agent has some of its future frames otherwise is a ``DataError`` naming the frames
    missing. A file with at least one such scene is a test file: every scene of it that is a
    test scene by these rules is read as one, whatever other scenes' rows leaked into its
    hidden future (all of it, or all but a frame, which read otherwise as a complete window or
    one shifted off its frames), its targets the agents of its observed frames; its other
    scenes read as complete windows, and an ``ObservedOnlyWarning`` then says how many scenes
    are observation-only. A file without such a scene reads as before.
    """
    path = Path(path)
    check_file(path)
    t_total = t_hist + t_fut
    # frame -> agent -> (x, y); scene rows as (line, id, primary, start, end, text)
    rows: dict[int, dict[int, tuple[float, float]]] = defaultdict(dict)
    scene_rows: list[tuple[int, int, int, int, int, str]] = []
    seen_ids: set[int] = set()
    fps: set[float] = set()
    with open_data_file(path) as fh:
        for line, raw in enumerate(file_lines(fh), start=1):
            try:
                text = raw.decode("utf-8-sig" if line == 1 else "utf-8")  # a BOM, as in text files
            except UnicodeDecodeError:
                raise DataError("not UTF-8 text", path, line) from None
            if not text.strip():
                continue
            try:
                obj = json.loads(text)
            except (ValueError, RecursionError):
                raise DataError("not a JSON object", path, line) from None
            if (
                not isinstance(obj, dict)
                or len(obj) != 1
                or not (isinstance(obj.get("track"), dict) or isinstance(obj.get("scene"), dict))
            ):
                raise DataError('expected {"scene": {...}} or {"track": {...}}', path, line)
            obj = _exact_floats(obj, text)
            if "track" in obj:
                track = obj["track"]
                if track.get("prediction_number") is not None:
                    continue  # a prediction, not an observation
                f, p, x, y = _fields(track, ("f", "p", "x", "y"), "track", path, line)
                f = _number(f, "frame 'f'", path, line, integer=True)
                p = _number(p, "agent 'p'", path, line, integer=True)
                x, y = _number(x, "'x'", path, line), _number(y, "'y'", path, line)
                with np.errstate(over="ignore"):
                    xy32 = np.array([x, y], np.float32)  # [2]
                if not np.isfinite(xy32).all():
                    raise DataError("coordinate does not fit float32 (|value| > 3.4e38)",
                                    path, line)  # fmt: skip
                if max(abs(x), abs(y)) > max_coord:
                    big = x if abs(x) >= abs(y) else y
                    raise DataError(
                        f"coordinate {big:g} {units} is beyond the sane bound of {max_coord:g} "
                        f"{units} (raise it with --max-coord if the data really spans that far)",
                        path,
                        line,
                    )
                if p in rows[f]:
                    raise DataError(f"duplicate row for frame {f}, agent {p}", path, line)
                rows[f][p] = (float(xy32[0]), float(xy32[1]))
                continue
            scene = obj["scene"]
            sid, p, s, e = _fields(scene, ("id", "p", "s", "e"), "scene", path, line)
            named = zip(("id", "p", "s", "e"), (sid, p, s, e), strict=True)
            sid, p, s, e = (_number(v, f"scene {k!r}", path, line, integer=True)
                            for k, v in named)  # fmt: skip
            if s > e:
                raise DataError(f"scene {sid}: start frame {s} is after end frame {e}", path, line)
            if sid in seen_ids:
                raise DataError(f"scene id {sid} appears twice", path, line)
            seen_ids.add(sid)
            if scene.get("fps") is not None:
                rate = _number(scene["fps"], "scene 'fps'", path, line)
                if rate <= 0:
                    raise DataError(f"scene 'fps' must be > 0, got {rate}", path, line)
                fps.add(float(rate))
            scene_rows.append((line, sid, p, s, e, text.strip()))
    if not scene_rows:
        raise DataError('no {"scene": ...} rows', path)
    frames = sorted(rows)  # [F] every frame of the file
    frames_of: dict[int, list[int]] = defaultdict(list)  # agent -> its frames, sorted
    for f in frames:
        for p in rows[f]:
            frames_of[p].append(f)
    # the file's frame step: the most common jump (the smallest on ties), in Python ints, which
    # hold frames of any size exactly (int64 overflowed beyond 9.2e18)
    jumps = Counter(b - a for a, b in zip(frames, frames[1:], strict=False))
    step = min(jumps, key=lambda j: (-jumps[j], j)) if jumps else 1
    gaps: list[int] = []  # scene ids whose window spans a frame its primary agent misses
    hidden: list[int] = []  # scene ids read as observation-only
    scenes = []
    owns = [[f for f in frames_of.get(p, ()) if s <= f <= e] for _, _, p, s, e, _ in scene_rows]
    test_file = any(len(own) < t_total for own in owns)  # some scene hides its future
    # the frames some scene shows as observed: a test file's rows in other scenes' futures
    shown = _shown_frames(scene_rows, t_fut, step) if test_file else None
    for (line, sid, p, s, e, row), own in zip(scene_rows, owns, strict=True):
        observed = None  # a test scene's observed frames
        if test_file:  # every scene that is a test scene is read as one, whatever leaked
            try:
                observed = _observed_frames(own, sid, p, s, e, t_hist, t_fut, step, shown,
                                            (path, line))  # fmt: skip
            except DataError:
                if len(own) < t_total:
                    raise
        if observed is None:  # a complete window, as always
            window = own[-t_total:]
            if any(b - a != step for a, b in zip(window, window[1:], strict=False)):
                gaps.append(sid)
            present = window  # the frames every target has a row in
        else:
            present = observed[-t_hist:]
            window = present + [present[-1] + step * (i + 1) for i in range(t_fut)]
            hidden.append(sid)
        others = set(rows[present[0]])
        for f in present[1:]:
            others &= rows[f].keys()
        agents = [p, *sorted(others - {p})]
        xy = np.array([[rows[f][a] for f in present] for a in agents], np.float32)  # [P, T', 2]
        if observed is not None:  # observation-only: the future is unknown
            xy = np.concatenate([xy, np.full((len(agents), t_fut, 2), np.nan, np.float32)], 1)
        big = any(not -(2**63) <= f < 2**63 for f in (window[0], window[-1]))
        scenes.append(
            Scene(
                xy[:, :t_hist],
                xy[:, t_hist:],
                np.zeros(len(agents), np.int64),
                f"{path.name}#{sid}",
                context=_context(rows, window[:t_hist], set(agents)),
                agent_id=source_ids(np.array(agents, dtype=object)),  # [P] exact "p" ids
                frames=np.array(window, dtype=object if big else np.int64),  # [T]
                source_row=row,
            )  # fmt: skip
        )
    if hidden and len(hidden) < len(scenes):
        warnings.warn(
            f"{path}: {len(hidden)} of its {len(scenes)} scenes (the first: {hidden[0]}) hold "
            f"their primary agent's observed frames alone and are read as observation-only "
            f"(future unknown: predict writes them, evaluate refuses them); the other "
            f"{len(scenes) - len(hidden)} hold a complete window. A TrajNet++ test file with "
            "overlapping scenes can hold both; a complete file cut short can too",
            ObservedOnlyWarning,
            stacklevel=2,
        )
    if gaps:
        warnings.warn(
            f"{path}: {len(gaps)} scene(s) (the first: {gaps[0]}) have windows whose primary "
            f"agent misses a frame (the file steps {step} frames): their steps span more time "
            "than the others'",
            GapWarning,
            stacklevel=2,
        )
    return TrajnetScenes(scenes, fps, len(hidden))


def _shown_frames(scene_rows: list, t_fut: int, step: int) -> tuple[list[int], list[int]]:
    """Where the file's scenes show observed frames, ``[s, e - t_fut * step]`` each, as sorted
    starts and the running maximum of their ends (``_is_shown`` looks a frame up in them)."""
    spans = sorted((s, e - t_fut * step) for _, _, _, s, e, _ in scene_rows)
    starts, ends, last = [], [], None
    for a, b in spans:
        last = b if last is None else max(last, b)
        starts.append(a)
        ends.append(last)
    return starts, ends


def _is_shown(frame: int, shown: tuple[list[int], list[int]]) -> bool:
    """Whether ``frame`` lies in some scene's observed frames (``_shown_frames``)."""
    starts, ends = shown
    i = bisect.bisect_right(starts, frame) - 1
    return i >= 0 and ends[i] >= frame


def _observed_frames(own: list[int], sid: int, p: int, s: int, e: int, t_hist: int, t_fut: int,
                     step: int, shown, where: tuple[Path, int]) -> list[int]:  # fmt: skip
    """The observed frames ``s .. e - t_fut * step`` of an observation-only scene whose
    primary agent has the rows ``own`` in ``[s, e]`` (fewer than a complete window needs), else
    ``DataError`` saying what is missing (``read_trajnet``). ``where``: the file and line."""
    t_total = t_hist + t_fut
    last = e - t_fut * step  # the last observed frame of a test scene
    # TrajNet++'s test files hide its 12 predicted frames: another T_f misplaces the cut
    hint = ("" if t_fut == WINDOW[1] else f" (TrajNet++ test files hide their last {WINDOW[1]} "
            f"frames, and this read cuts {t_fut} future frames, a model's T_f or --future: "
            f"they are read with {WINDOW[1]})")  # fmt: skip
    if last < s or (last - s) % step or (last - s) // step + 1 < t_hist:
        raise DataError(f"scene {sid}: its primary agent {p} has {len(own)} frames in {s}..{e}; "
                        f"a window needs {t_total}{hint}", *where)  # fmt: skip
    expected = range(s, last + 1, step)  # lazy: a scene's span may be any size (e = 1e20)
    have = set(own)
    n_missing = (last - s) // step + 1 - sum(1 for f in have if f in expected)
    if n_missing:  # the first few found without listing a span that may not fit in memory
        first = list(itertools.islice((f for f in expected if f not in have), 3))
        more = f" and {n_missing - len(first)} more" if n_missing > len(first) else ""
        shown_missing = f"frame{'s' if n_missing > 1 else ''} {', '.join(map(str, first))}{more}"
        raise DataError(f"scene {sid}: its primary agent {p} has {len(own)} frames in {s}..{e}; "
                        f"a window needs {t_total}, and an observation-only scene a row at every "
                        f"frame {s}..{last} (step {step}): {shown_missing} missing{hint}",
                        *where)  # fmt: skip
    after = [f for f in own if f > last]
    unshown = [f for f in after if not _is_shown(f, shown)]
    if unshown:  # some of the future, at frames no scene shows as observed: a file cut short?
        future = range(last + step, e + 1, step)
        lost = [f for f in future if f not in have]
        raise DataError(f"scene {sid}: its primary agent {p} has {len(after)} of its {t_fut} "
                        f"future frames {last + step}..{e} (step {step}; "
                        f"{_frames_text(lost) or 'the others'} missing): a scene needs all "
                        f"{t_total} frames, or its observed frames {s}..{last} alone (a "
                        f"TrajNet++ test file){hint}", *where)  # fmt: skip
    return list(expected)


def _first_few(values: list[int], few: int) -> str:
    """``120, 130, 140 and 2 more``: the first ``few`` values, and how many follow."""
    head = ", ".join(str(v) for v in values[:few])
    return head + (f" and {len(values) - few} more" if len(values) > few else "")


def _frames_text(frames: list[int]) -> str:
    """``frame 120`` or ``frames 120, 130, 140 and 2 more``."""
    if not frames:
        return ""
    return f"frame{'s' if len(frames) > 1 else ''} {_first_few(frames, 3)}"


def observed_only(scenes: list[Scene]) -> list[Scene]:
    """The scenes of ``scenes`` whose future is unknown (NaN anywhere in ``Scene.future``): the
    observation-only scenes of TrajNet++ test files (``read_trajnet``)."""
    return [s for s in scenes if not np.isfinite(s.future).all()]


def require_future(dataset, what: str) -> None:
    """``DataError`` naming the first source file when ``dataset`` (a ``TrajectoryDataset``)
    holds scenes whose future is not known at every frame (``observed_only``), for ``what`` (a
    command, or what it does), which reads each window's future: scoring against it, or its
    speed, would be NaN. Two cases, each with its own message: scenes whose future is NaN
    throughout (hidden, as in TrajNet++'s test files: predict them), and scenes where some
    agent lacks positions at some future frames (a scene built by hand: the library's readers
    keep such an agent as a context-only neighbour, ``Scene.context``, docs/data.md)."""
    unknown = observed_only(dataset.scenes)
    if not unknown:
        return
    hidden = [s for s in unknown if not np.isfinite(s.future).any()]
    partial = [s for s in unknown if np.isfinite(s.future).any()]
    named = hidden or partial
    files = list(dict.fromkeys(source_file_of(s.scene_id) for s in named))
    where = _source_file(getattr(dataset.info, "source", ""), files[0])
    others = f" (and {len(files) - 1} other file(s))" if len(files) > 1 else ""
    total = len(dataset.scenes)
    if hidden:
        also = ""
        if partial:
            also = (f" ({len(partial)} other scene(s) lack part of their future, the first: "
                    f"{partial[0].scene_id})")  # fmt: skip
        raise DataError(f"{what} reads each window's future, and {len(hidden)} of the {total} "
                        f"scenes{others} hold the observed frames alone (the first: "
                        f"{hidden[0].scene_id}): the future is hidden, as in TrajNet++'s test "
                        "files. predict writes predictions for them (--format trajnet, without "
                        "--truth); score those with TrajNet++'s evaluator against the files "
                        f"holding the future (test_private){also}", where)  # fmt: skip
    first = partial[0]
    lacking = ~np.isfinite(first.future).all(-1)  # [P, T_f] True where a position is missing
    agent = int(np.flatnonzero(lacking.any(-1))[0])
    steps = np.flatnonzero(lacking[agent]) + 1  # 1-based future steps
    raise DataError(f"{what} reads each window's future, and {len(partial)} of the {total} "
                    f"scenes{others} have an agent without a position at some future frames "
                    f"(the first: {first.scene_id}, its agent {agent} of {first.num_agents}, "
                    f"NaN at future step{'s' if len(steps) > 1 else ''} {_steps_text(steps)} "
                    f"of {first.future.shape[1]}): an agent is predicted and scored only when "
                    "seen at every frame of its window. The library's readers keep an agent "
                    "unseen for part of a window as a context-only neighbour of its scene "
                    "(Scene.context [C, T_h, 2]: its observed positions, NaN where unseen; "
                    "docs/data.md): move such agents there, or leave them out", where)  # fmt: skip


def source_file_of(scene_id: str) -> str:
    """The source file a scene id names: ``crowds_zara01.txt@frame=120`` (text track files)
    -> ``crowds_zara01.txt``, ``a.ndjson#3`` (TrajNet++ and ``.npz`` files) -> ``a.ndjson``;
    an id of neither form as it is. (``registry.scene_file``, which groups windows for the
    hold-out and the validation cut, reads the ``@`` form alone.)"""
    for sep in ("@frame=", "#"):
        if sep in scene_id:
            return scene_id.rsplit(sep, 1)[0]
    return scene_id


def _source_file(source: str, name: str) -> Path | None:
    """The path of the file ``name`` in a dataset's ``source``: the source itself when it is
    a file, the file in a source folder (at any depth), else the folder; None without a
    source."""
    if not source:
        return None
    folder = Path(source)
    if not folder.is_dir():
        return folder
    if (folder / name).is_file():
        return folder / name
    return next((f for f in sorted(folder.rglob(name)) if f.is_file()), folder)


def _steps_text(steps: np.ndarray) -> str:
    """``9..12`` for consecutive steps, else the first few: ``2, 5, 7 and 3 more``."""
    values = [int(v) for v in steps]
    if len(values) > 1 and values[-1] - values[0] == len(values) - 1:
        return f"{values[0]}..{values[-1]}"
    return _first_few(values, 4)


def _context(
    rows: dict[int, dict[int, tuple[float, float]]], observed: list[int], targets: set[int]
) -> np.ndarray | None:
    """[C, T_h, 2] the window's context-only agents (``Scene.context``, the rule the text
    reader's windows follow): the other agents with a row at its last observed frame
    (``observed[-1]``), not ``targets`` (those in all of its frames), by id, their positions at
    the ``observed`` frames, NaN where they have no row. None when there are none: batches
    read None and an empty array alike (``types.collate``), and a window without context
    keeps the data fingerprint it had before context was read (``train.run.data_fingerprint``:
    a run begun then resumes)."""
    others = sorted(a for a in rows[observed[-1]] if a not in targets)
    if not others:
        return None
    out = np.full((len(others), len(observed), 2), np.nan, np.float32)  # [C, T_h, 2]
    for c, agent in enumerate(others):
        for t, f in enumerate(observed):
            xy = rows[f].get(agent)
            if xy is not None:
                out[c, t] = xy
    return out


def _check_arrays(history, pred, scene, future) -> tuple[np.ndarray, ...]:
    history = np.asarray(history, dtype=np.float32)
    pred = np.asarray(pred, dtype=np.float32)
    scene = np.asarray(scene)
    if history.ndim != 3 or history.shape[-1] != 2:
        raise DataError(f"history must be [N, T_h, 2], got {history.shape}")
    n = history.shape[0]
    if pred.ndim != 4 or pred.shape[1] != n or pred.shape[-1] != 2:
        raise DataError(f"pred must be [K, N={n}, T_f, 2], got {pred.shape}")
    if scene.shape != (n,) or not np.issubdtype(scene.dtype, np.integer):
        raise DataError(f"scene must be [N={n}] integer scene indices, got {scene.shape}")
    if n and (scene.min() != 0 or (np.diff(scene) < 0).any() or (np.diff(scene) > 1).any()):
        raise DataError("scene must number the scenes 0, 1, 2, ... in non-decreasing order")
    if future is not None:
        future = np.asarray(future, dtype=np.float32)
        if future.shape != pred.shape[1:]:
            raise DataError(f"future must be [N, T_f, 2] = {pred.shape[1:]}, got {future.shape}")
    for name, arr in (("history", history), ("pred", pred), ("future", future)):
        if arr is not None and not np.isfinite(arr).all():
            raise DataError(f"{name} holds NaN or infinite values")
    return history, pred, scene.astype(np.int64), future


def _coords(xy: np.ndarray, decimals: int | None) -> np.ndarray:
    """[..., 2] float32 -> strings: the shortest that read back as the same float32, or
    rounded to ``decimals``."""
    if decimals is None:
        return xy.astype(str)
    return np.round(xy.astype(np.float64), decimals).astype(str)


def _track_lines(frames, agents, xy, decimals, k: int | None = None,
                 scenes=None) -> list[str]:  # fmt: skip
    """One ``track`` line per row; predictions (``k``) carry their TrajNet++ scene id
    (``scenes`` [R]: the predicted agent's index)."""
    text = _coords(xy, decimals)  # [R, 2]
    extra = "" if k is None else f', "prediction_number": {k}, "scene_id": '
    ids = agents.tolist() if scenes is None else scenes.tolist()
    out = []
    rows = zip(frames.tolist(), agents.tolist(), text.tolist(), ids, strict=True)
    for f, p, (x, y), i in rows:
        tail = "" if k is None else f"{extra}{i}"
        out.append(f'{{"track": {{"f": {f}, "p": {p}, "x": {x}, "y": {y}{tail}}}}}\n')
    return out


def trajnet_agent_ids(agent_id, scene) -> np.ndarray:
    """[N] TrajNet++ agent ids (``"p"``) from the source data's ids ``agent_id`` [N] (numbers
    as read, the exact text of an integer beyond int64, or None) for agents numbered by
    ``scene`` [N]: the source ids where each is an integer (TrajNet++'s ids are integers) and
    no two agents of one scene share one, int64, or exact Python ints in an object array when
    one does not fit int64 (JSON and TrajNet++'s Reader take integers of any size); else the
    agents' indices 0..N-1 (the ids of an export without source ids)."""
    scene = np.asarray(scene)
    n = len(scene)
    if agent_id is None:
        return np.arange(n)
    ids = np.asarray(agent_id)
    if ids.shape != (n,):
        raise DataError(f"agent_id must be [N={n}], got {ids.shape}")
    values = [_integer_id(v) for v in ids.tolist()]
    if any(v is None for v in values):  # names, fractions, NaN
        return np.arange(n)
    if len(set(zip(scene.tolist(), values, strict=True))) != n:  # an id twice in one scene
        return np.arange(n)
    if all(-(2**63) <= v < 2**63 for v in values):
        return np.array(values, dtype=np.int64)  # [N]
    return np.array(values, dtype=object)  # [N] exact Python ints


def _integer_id(value) -> int | None:
    """An agent id as an exact int: ints, whole floats and the text of an integer
    (``Scene.agent_id`` holds ids beyond int64 as their text); None for anything else."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return int(value) if math.isfinite(value) and value == int(value) else None
    if isinstance(value, str) and value.strip().lstrip("+-").isdigit():
        return int(value)
    return None


def write_trajnet(
    path: str | Path,
    history,
    pred,
    scene,
    frame_interval: float = 0.4,
    decimals: int | None = None,
    agent_id=None,
) -> int:
    """Write sampled futures as a TrajNet++ prediction file; return the number of TrajNet++
    scenes written (one per agent).

    ``history`` [N, T_h, 2], ``pred`` [K, N, T_f, 2] and ``scene`` [N] (scene index per agent:
    0, 1, ... non-decreasing) are the arrays ``trajpref predict`` saves (numpy or torch).
    TrajNet++ scores one primary agent per scene, so every agent gets its own TrajNet++ scene
    (scene id = its index n; agent id the same, or its ``agent_id``) spanning the frames of
    its scene: scene b holds frames
    ``b * (T_h + T_f)`` onwards, one apart, with ``fps = 1 / frame_interval``. The file holds the
    scene rows, the observed rows and, for each agent and sample k, its predicted rows with
    ``"prediction_number": k`` and ``"scene_id"``; ``write_trajnet_truth`` writes the matching
    ground truth. Coordinates are written as the shortest text that reads back as the same
    float32 value, or rounded to ``decimals`` (TrajNet++'s own files use 2).

    TrajNet++'s evaluator reads predictions 0, 1 and 2 for its Top-3 metrics only when there
    are more than two: with K = 1 or 2 it reports Top-1 alone.

    ``agent_id`` [N] (optional): each agent's id in the source data; where they are integers,
    unique within each scene (``trajnet_agent_ids``), they are the rows' agent ids ``"p"``
    (scene ids stay 0..N-1, one per agent), so that predictions map back to the source's
    agents; otherwise, and without them, ``"p"`` is the agent's index n. TrajNet++'s tools
    assume metres (its collision radius is 0.1 m): the coordinates are written as given.
    """
    history, pred, scene, _ = _check_arrays(history, pred, scene, None)
    agents = trajnet_agent_ids(agent_id, scene)  # [N]
    return _write(path, history, scene, frame_interval, decimals, pred=pred, agents=agents)


def write_trajnet_truth(
    path: str | Path,
    history,
    future,
    scene,
    frame_interval: float = 0.4,
    decimals: int | None = None,
    agent_id=None,
) -> int:
    """Write the ground truth that matches ``write_trajnet``'s file (same scene, agent and
    frame numbers; observed and true future rows): the file TrajNet++'s evaluator compares a
    prediction file with. ``future`` is [N, T_f, 2]; the rest as in ``write_trajnet`` (give
    both the same ``agent_id``)."""
    fut = np.asarray(future, dtype=np.float32)
    history, _, scene, future = _check_arrays(history, fut[None], scene, fut)
    agents = trajnet_agent_ids(agent_id, scene)  # [N]
    return _write(path, history, scene, frame_interval, decimals, future=future, agents=agents)


def _write(path, history, scene, frame_interval, decimals, pred=None, future=None,
           agents=None) -> int:  # fmt: skip
    if not (math.isfinite(frame_interval) and frame_interval > 0):
        raise ConfigError(f"frame_interval must be > 0 seconds, got {frame_interval}")
    n, t_hist = history.shape[:2]
    t_fut = pred.shape[2] if pred is not None else future.shape[1]
    t_total = t_hist + t_fut
    if agents is None:
        agents = np.arange(n)  # [N] TrajNet++ agent id = index
    first = scene * t_total  # [N] first frame of each agent's scene
    fps = 1.0 / frame_interval
    lines = [
        f'{{"scene": {{"id": {i}, "p": {a}, "s": {f}, "e": {f + t_total - 1}, '
        f'"fps": {fps:g}, "tag": [0, []]}}}}\n'
        for i, (a, f) in enumerate(zip(agents.tolist(), first.tolist(), strict=True))
    ]
    obs_frames = first[:, None] + np.arange(t_hist)  # [N, T_h]
    fut_frames = (first[:, None] + t_hist + np.arange(t_fut)).ravel()  # [N * T_f]
    lines += _track_lines(obs_frames.ravel(), np.repeat(agents, t_hist),
                          history.reshape(-1, 2), decimals)  # fmt: skip
    per_agent = np.repeat(agents, t_fut)  # [N * T_f]
    per_scene = np.repeat(np.arange(n), t_fut)  # [N * T_f] TrajNet++ scene id = agent index
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.writelines(lines)
        if future is not None:
            fh.writelines(_track_lines(fut_frames, per_agent, future.reshape(-1, 2), decimals))
        else:
            for k in range(pred.shape[0]):
                fh.writelines(
                    _track_lines(
                        fut_frames, per_agent, pred[k].reshape(-1, 2), decimals, k, per_scene
                    )
                )
    return n


def from_trajnet(scenes: list[Scene]) -> bool:
    """Whether every one of ``scenes`` was read from a TrajNet++ file (``read_trajnet``: its
    ``source_row``, ``frames`` and ``agent_id`` are set), so that ``write_trajnet_scenes`` can
    write predictions that match the source files."""
    return bool(scenes) and all(
        s.source_row is not None and s.frames is not None and s.agent_id is not None for s in scenes
    )


def trajnet_output_paths(out: str | Path, names: list[str], folder: bool) -> dict[str, Path]:
    """Where ``write_trajnet_scenes`` writes the predictions (or truth) of each source file of
    ``names`` (file names, ``a.ndjson``): with ``folder`` False, ``out`` itself (one source
    file only); with ``folder`` True, ``<out without its suffix>/<name>`` (``pred.ndjson`` ->
    ``pred/a.ndjson``). Pure: nothing is read or written, so that ``predict`` can check every
    target before any compute."""
    out = Path(out)
    if not folder:
        if len(set(names)) > 1:
            raise DataError(f"scenes from {len(set(names))} source files need one output file "
                            "each: write them as a folder (folder=True)")  # fmt: skip
        return dict.fromkeys(names, out)
    base = trajnet_output_base(out, True)
    return {name: base / name for name in names}


def trajnet_output_base(out: str | Path, folder: bool) -> Path:
    """What ``write_trajnet_scenes`` writes at ``out``: the file ``out``, or with ``folder``
    the folder named as ``out`` without its suffix (``pred.ndjson`` -> ``pred``)."""
    out = Path(out)
    return out.with_suffix("") if folder else out


def write_trajnet_scenes(
    out: str | Path,
    scenes: list[Scene],
    pred,
    scene,
    truth: str | Path | None = None,
    decimals: int | None = None,
    folder: bool = False,
) -> Path:
    """Write predictions for windows read from TrajNet++ files (``from_trajnet``) as the
    official evaluator scores them against those files: per source scene, its scene row
    unchanged (id, primary, start, end, fps, tag), the observed rows of its agents, and for
    each sample k and each agent of the scene (the primary first) the predicted rows at the
    source's own future frames (``Scene.frames``), with ``"prediction_number": k`` and the
    source scene's ``"scene_id"``: a neighbour's predictions are written once per scene it is
    predicted in, each carrying that scene's id, as TrajNet++'s evaluator reads a scene's
    neighbour predictions (its Col-I). Returns what was written: the file ``out`` (the scenes
    must then come from one source file), or with ``folder`` a folder named as ``out`` without
    its suffix holding one file per source file of the scenes, named as it (``pred.ndjson`` ->
    ``pred/a.ndjson``, ``pred/b.ndjson``: ``trajnet_output_paths``), the layout the evaluator
    pairs with its ground-truth folder (TrajNet++ numbers scenes per file, so one file could
    not hold them all). ``predict`` writes a folder when its input was a folder, whatever the
    number of files the scenes come from. Observation-only scenes (``Scene.future`` NaN: a test
    file's) are written the same way, their predictions at their hidden frames; ``truth`` then
    is a ``DataError`` (there is none to write).

    ``pred`` [K, N, T_f, 2] and ``scene`` [N] (each agent's index into ``scenes``,
    non-decreasing) are ``predict_dataset``'s; each scene's rows are all its agents in its
    order, or its primary agent alone. ``truth`` (optional, a path laid out as ``out``): the
    matching ground truth, the same scene rows and every agent's rows over its window (8
    observed frames, not TrajNet++'s 9: the window's first frame is the scene's second).
    ``decimals`` as in ``write_trajnet``. Nothing here checks that the targets are not source
    files: ``predict`` does that before any compute."""
    pred = np.asarray(pred, dtype=np.float32)
    scene = np.asarray(scene)
    if not from_trajnet(scenes):
        raise DataError("write_trajnet_scenes needs scenes read from TrajNet++ files (their "
                        "source_row, frames and agent_id set): use write_trajnet")  # fmt: skip
    if pred.ndim != 4 or pred.shape[-1] != 2 or scene.shape != pred.shape[1:2]:
        raise DataError(f"pred must be [K, N, T_f, 2] with scene [N], got {pred.shape} and "
                        f"{scene.shape}")  # fmt: skip
    if not np.isfinite(pred).all():
        raise DataError("pred holds NaN or infinite values")
    hidden = observed_only(scenes) if truth is not None else []
    if hidden:
        raise DataError(f"truth: {len(hidden)} scene(s) (the first: {hidden[0].scene_id}) hold "
                        "the observed frames alone (the future is hidden): there is no truth to "
                        "write")  # fmt: skip
    starts = np.searchsorted(scene, np.arange(len(scenes) + 1))  # [B + 1] each scene's rows
    if (np.diff(scene) < 0).any() or starts[-1] != len(scene):
        raise DataError(f"scene must index the {len(scenes)} scenes in non-decreasing order")
    rows_of = []
    for b, s in enumerate(scenes):
        count = int(starts[b + 1] - starts[b])
        if count not in (s.num_agents, 1) or s.future.shape[1] != pred.shape[2]:
            raise DataError(f"{s.scene_id}: pred holds {count} agents of {pred.shape[2]} "
                            f"frames for this scene of {s.num_agents} agents of "
                            f"{s.future.shape[1]}: every agent or the primary alone")  # fmt: skip
        rows_of.append(np.arange(starts[b], starts[b + 1]))
    groups: dict[str, list[int]] = defaultdict(list)  # source file -> its scenes, in order
    for b, s in enumerate(scenes):
        groups[s.scene_id.rsplit("#", 1)[0]].append(b)
    targets = trajnet_output_paths(out, list(groups), folder)
    truths = trajnet_output_paths(truth, list(groups), folder) if truth is not None else {}
    for name, members in groups.items():
        chosen = [scenes[b] for b in members]
        rows = [rows_of[b] for b in members]
        _write_source(targets[name], chosen, pred, rows, decimals)
        if truth is not None:
            _write_source(truths[name], chosen, None, rows, decimals)
    return trajnet_output_base(out, folder)


def _write_source(path: Path, scenes: list[Scene], pred: np.ndarray | None,
                  rows_of: list[np.ndarray], decimals: int | None) -> None:  # fmt: skip
    """One file of ``write_trajnet_scenes``: the scenes' rows, their agents' observed rows (and
    true future rows without ``pred``), then the predictions of ``pred`` [K, N, T_f, 2] (agent
    rows ``rows_of[b]`` of scene b), every track row by ``_track_lines``."""
    first: dict[tuple[int, int], np.ndarray] = {}  # (frame, agent) -> [2] position, first wins
    predicted: list[str] = []
    for s, rows in zip(scenes, rows_of, strict=True):
        t_hist = s.history.shape[1]
        frames = s.frames.tolist()  # [T] Python ints, exact
        ids = [int(a) for a in s.agent_id.tolist()]  # [P] "p", exact (text beyond int64)
        xy = np.concatenate([s.history, s.future], axis=1)  # [P, T, 2]
        shown = xy[:, :t_hist] if pred is not None else xy  # [P, T_h or T, 2]
        for a, agent in enumerate(ids):
            for t, f in enumerate(frames[: shown.shape[1]]):
                first.setdefault((f, agent), shown[a, t])
        if pred is None:
            continue
        sid = int(s.scene_id.rsplit("#", 1)[1])
        future = np.array(frames[t_hist:], dtype=object)  # [T_f]
        agents = np.repeat(np.array(ids[: len(rows)], dtype=object), len(future))  # [P' * T_f]
        per_row = np.full(len(agents), sid, dtype=object)  # [P' * T_f] the scene's id
        for k in range(pred.shape[0]):  # P' <= P agents of the scene: the primary first
            xy_k = pred[k, rows].reshape(-1, 2)  # [P' * T_f, 2]
            predicted += _track_lines(np.tile(future, len(rows)), agents, xy_k, decimals, k,
                                      per_row)  # fmt: skip
    keys = sorted(first)
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.writelines(s.source_row + "\n" for s in scenes)
        if keys:
            fh.writelines(_track_lines(np.array([f for f, _ in keys], dtype=object),
                                       np.array([a for _, a in keys], dtype=object),
                                       np.stack([first[k] for k in keys]), decimals))  # fmt: skip
        fh.writelines(predicted)
