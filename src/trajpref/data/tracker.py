"""A tracker's output (timestamped positions per agent) -> the models' input at "now".

``tracks_to_history`` is meant for a planner's loop: each cycle, pass the tracker's recent rows
(any order, any rate, short or gappy tracks) and the present time; it returns the history
[P, T_h, 2] of the agents seen over the whole window, at the model's step and ending at now,
and the partly seen agents as ``context`` [C, T_h, 2] (NaN where unseen), ready for
``score.scorer.predict_scene(model, res.history, 20, context=res.context,
frame_interval=step)``. Pure numpy.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Hashable, Sequence
from typing import Any, NamedTuple

import numpy as np

from trajpref.errors import ConfigError, DataError, LeftOutWarning

EPS_STEPS = 1e-3
"""Times within this share of ``step`` of each other count as equal (float rounding of frame
times such as ``now - 3 * 0.4``): 0.4 ms at a 0.4 s step."""
CLOCKS_APART = 86_400.0
"""Seconds after every observation beyond which ``now`` is refused as on another clock than the
rows (a tracker on simulation time from 0, ``now`` in Unix seconds, 1.7e9): a day. Closer than
that, rows that are all too old give an empty scene, a view that has been empty for a while."""
CYCLE_SLACK = 1.5
"""With ``hold=``, an agent whose last observation at or before ``now`` is at most this many of
its own observation intervals old (the median gap between its times: seen in the tracker's
latest cycle, its stamp a little late or jittered) is extrapolated to ``now`` at its last
velocity; one unseen for longer (missed detections, occlusion) is held where it was last seen,
its motion since being unknown."""


class TrackHistory(NamedTuple):
    """What ``tracks_to_history`` returns (agents in ascending id order in every list)."""

    history: np.ndarray
    """[P, T_h, 2] float64: the agents with a position at every frame, oldest frame first."""
    context: np.ndarray
    """[C, T_h, 2] float64: the agents with a position at ``now`` but not at every frame; NaN at
    the frames they have none (before their first observation, inside a gap longer than
    ``max_gap``). A model reads a row only if it is finite in the last
    ``model.context_frames`` frames (all 8 for the published generators)."""
    ids: list
    """[P]: the input agent id of each ``history`` row."""
    context_ids: list
    """[C]: the input agent id of each ``context`` row."""
    left_out_ids: list
    """Agents observed at or before ``now`` that have no position at ``now`` (last seen more than
    ``hold`` seconds before it, and not within ``hold`` after it): gone from view, or occluded;
    in no array (a ``LeftOutWarning`` where some were seen in the tracker's current cycle:
    ``tracks_to_history``)."""
    frame_times: np.ndarray
    """[T_h] float64: the time of each frame, ``now - (T_h - 1 - i) * step``."""


def tracks_to_history(times: Any, ids: Sequence[Hashable] | np.ndarray, xy: Any, now: float,
                      step: float, t_hist: int = 8, max_gap: float | None = None,
                      hold: float = 0.0) -> TrackHistory:  # fmt: skip
    """Resample a tracker's rows to the models' history at ``step`` seconds, ending at ``now``.

    ``times`` [R] seconds (any origin, e.g. Unix time; float64: float32 cannot hold Unix
    seconds), ``ids`` [R] agent ids (ints, strings or other ids that sort among themselves),
    ``xy`` [R, 2] positions in the model's units; rows in any order. ``now``: the present time,
    in the same clock. ``step``: ``model.frame_interval`` (0.4 s for the ETH/UCY and sdd
    models, 0.5 robo, 0.12 nba); ``t_hist``: ``model.t_hist`` (8 for the published models).

    Rules:

    - Frame i (i = 0 .. T_h - 1) is at ``now - (T_h - 1 - i) * step`` (``frame_times``).
    - An agent's position at a frame is linearly interpolated between its own two observations
      around it (an observation at the frame's time is used as it is). Frames before the
      agent's first observation are NaN; past its last one, only ``hold`` (below) fills any.
    - Observations more than ``max_gap`` seconds apart (default ``2 * step``) are not bridged:
      the frames between them are NaN.
    - Rows after ``now`` are not read (a log can be replayed by moving ``now``), but for the
      tolerance ``hold`` below: with ``hold > 0`` a replay reads up to ``hold`` seconds past
      ``now`` (rule 1), as a live tracker whose stamps run a little late would have them.
    - The frame at ``now`` takes the agent's observation at ``now``. ``hold`` (seconds,
      default 0: none) is a tolerance on the time stamps around ``now``, for a tracker whose
      agents carry their own stamps a few ms apart within one cycle, or a ``now`` set to the
      cycle's nominal time; the frames after the agent's last observation at or before
      ``now`` (the frame at ``now``, and any other such frame) are then, first rule that
      applies:

      1. interpolated linearly toward its first observation after ``now``, when that is at
         most ``hold`` seconds after ``now`` and at most ``max_gap`` after the last one (the
         only use of a row after ``now``);
      2. when its last observation is at most ``hold`` seconds before ``now`` and at most
         ``CYCLE_SLACK`` (1.5) of its own observation intervals old (seen in the tracker's
         latest cycle), extrapolated linearly at its velocity between that observation and
         the latest one at least as much earlier (within ``max_gap``);
      3. when its last observation is at most ``hold`` seconds before ``now``, that position,
         held (an agent missing from the tracker's latest cycles, or seen once: its motion
         since is unknown; a moving agent's held frames lag it by its speed times their
         distance from that observation, and read as it slowing down).

      A stamp of the tracker's latest cycle is never placed at ``now`` as if observed then,
      so a 10 Hz tracker's stamps some ms off the frame grid give no velocity bias (a stale
      position held at ``now`` reads as the agent slowing down). With ``hold=0`` (or every
      agent observed at ``now``) none of this applies. An agent with no position at ``now``
      is left out of both arrays: ``left_out_ids`` lists it (no model reads a neighbour that
      is unseen at the last frame). Where some of them have an observation within half their
      own observation interval of ``now`` (before or after it: seen in the tracker's current
      cycle, not gone), one ``LeftOutWarning`` per call names them with the age at ``now`` of
      their latest observation at or before it, and suggests a ``hold=`` above the oldest
      (1.25 times it, rounded up to 10 ms); an agent that left the view a cycle or more ago
      is left out without a word, and so is every agent of input on one time grid with
      ``now`` on it.
    - An agent with a position at every frame is a ``history`` row; one with a position at
      ``now`` but NaN at some earlier frame (a track that started inside the window, or a gap)
      is a ``context`` row.
    - Rows, ``ids`` and ``context_ids`` are in ascending id order, so an agent keeps its place
      from one cycle to the next whatever order the tracker lists it in (the score's ranking
      depends on the agent order, docs/score.md).
    - The same (id, time) twice with the same position counts once; with different positions
      it is a ``DataError``.

    No rows (an empty view) give empty arrays ([0, T_h, 2]); so do rows whose agents are all
    left out (a view that has been empty for a while, its old rows still passed). Wrong shapes,
    non-finite times or positions, conflicting duplicate rows, ids that do not sort, a ``now``
    before every observation, a ``now`` after every observation by more than
    ``CLOCKS_APART`` (a day: two clocks, not an empty view), or float32 /
    float16 ``times`` or ``now`` too large for that type to resolve ``step`` (Unix seconds in
    float32 are 128 s apart) raise ``DataError``; ``step``, ``t_hist``, ``max_gap`` or
    ``hold`` out of range raise ``ConfigError``.
    """
    step, max_gap, hold = _check_settings(step, t_hist, max_gap, hold)
    _check_resolution("times", times, step)
    _check_resolution("now", now, step)
    t, agent, pos = _check_rows(times, ids, xy)
    now = _finite_number("now", now, DataError)
    if len(t) and now < t.min() - EPS_STEPS * step:
        raise DataError(f"now ({now!r}) is before every observation (the first is at "
                        f"{float(t.min())!r}): pass the present time in the tracker's "
                        "clock")  # fmt: skip
    frames = now - (t_hist - 1 - np.arange(t_hist)) * step  # [T_h], oldest first
    eps = EPS_STEPS * step
    if len(t) and now - t.max() > CLOCKS_APART:
        raise DataError(f"now ({now!r}) is after every observation by more than a day (the "
                        f"newest is at {float(t.max())!r}, {now - float(t.max()):.6g} s before "
                        "now): the times and now are likely on two clocks (e.g. a tracker on "
                        "simulation time, now on wall-clock time); pass the present time in "
                        "the tracker's clock")  # fmt: skip
    groups: dict[Hashable, list[int]] = {}
    for row, key in enumerate(agent):
        groups.setdefault(key, []).append(row)
    try:
        order = sorted(groups)
    except TypeError:
        kinds = sorted({type(k).__name__ for k in groups})
        raise DataError(f"ids: agent ids must sort among themselves (ints, strings), got "
                        f"{', '.join(kinds)}: map them to ints first") from None  # fmt: skip
    full, part, full_ids, part_ids, left_out = [], [], [], [], []
    current = []  # (id, age at now) of the left-out agents seen in the tracker's current cycle
    for key in order:
        every = np.asarray(groups[key])
        rows = every[t[every] <= now + hold + eps]  # rows after now + hold are not read
        if not (t[rows] <= now + eps).any():
            continue  # first seen after now: not there yet
        track, age = _agent_track(key, t[rows], pos[rows], frames, now, max_gap, hold, eps)
        seen = np.isfinite(track).all(-1)  # [T_h]
        if not seen[-1]:
            left_out.append(key)
            if _seen_this_cycle(t[every], now, step, eps):
                current.append((key, age))
        elif seen.all():
            full.append(track)
            full_ids.append(key)
        else:
            part.append(track)
            part_ids.append(key)
    if current:
        warnings.warn(_left_out_warning(current, hold), stacklevel=2)
    return TrackHistory(history=_stack(full, t_hist), context=_stack(part, t_hist), ids=full_ids,
                        context_ids=part_ids, left_out_ids=left_out,
                        frame_times=frames)  # fmt: skip


def _left_out_warning(current: list[tuple[Hashable, float]], hold: float) -> LeftOutWarning:
    """The ``LeftOutWarning`` for the left-out agents ``current`` ((id, age at now of its latest
    observation at or before now), in id order) seen in the tracker's current cycle, under the
    ``hold`` given: a text that names no agent and no age (the same at every call of a loop
    but for the suggested hold, a few values), with ``ages`` and ``suggested_hold`` on it."""
    oldest = max(age for _, age in current)
    suggest = math.ceil(round(oldest * 1.25 * 100, 6)) / 100  # above the oldest: 0.111 -> 0.14
    warning = LeftOutWarning(
        "tracks_to_history: agents seen in the tracker's current cycle (within half their "
        "observation interval of now) have no position at now and are left out "
        f"(left_out_ids): their latest stamp at or before now is older than hold={hold:g} s, "
        "their detections being stamped a little before now, or after it. Pass "
        f"hold={suggest:g} (above the oldest age) to place them at now, interpolated toward a "
        "stamp within hold after now, else extrapolated at their last velocity or held "
        "(tracks_to_history's rules); this warning's .ages gives each one's age at now"
    )
    warning.ages = dict(current)
    warning.suggested_hold = suggest
    return warning


def _seen_this_cycle(t: np.ndarray, now: float, step: float, eps: float) -> bool:
    """Whether an agent observed at times ``t`` [n] (all its rows, after ``now`` too) has an
    observation within half its own observation interval of ``now`` (the median gap between
    its distinct times; ``step`` for an agent seen once): seen in the tracker's current
    cycle, not gone from view a cycle or more ago."""
    gaps = np.diff(np.unique(t))  # [m] > 0
    interval = float(np.median(gaps)) if len(gaps) else step
    return bool((np.abs(t - now) <= interval / 2 + eps).any())


def _agent_track(key, t: np.ndarray, p: np.ndarray, frames: np.ndarray, now: float,
                 max_gap: float, hold: float, eps: float) -> tuple[np.ndarray, float]:  # fmt: skip
    """One agent's positions [T_h, 2] at ``frames`` from its rows (times t [n], positions
    p [n, 2], at or before ``now`` but for those within ``hold`` after it), NaN where the rules
    of ``tracks_to_history`` give none, and the age at ``now`` of its last observation at or
    before it."""
    t, p = _distinct_rows(key, t, p)
    n = int(np.count_nonzero(t <= now + eps))  # rows at or before now: the first n
    t_in, p_in = t[:n], p[:n]
    at = np.clip(frames, t_in[0], t_in[-1])  # [T_h] inside the observed span (after it: last)
    track = np.stack([np.interp(at, t_in, p_in[:, 0]), np.interp(at, t_in, p_in[:, 1])], -1)
    inside = (frames >= t_in[0] - eps) & (frames <= t_in[-1] + eps)  # [T_h]
    if n > 1:
        right = np.clip(np.searchsorted(t_in, at, side="left"), 1, n - 1)  # [T_h] obs >= at
        on_obs = (np.abs(t_in[right] - at) <= eps) | (np.abs(t_in[right - 1] - at) <= eps)
        bridged = on_obs | (t_in[right] - t_in[right - 1] <= max_gap + eps)  # [T_h]
        inside &= bridged
    track[~inside] = np.nan
    last, age = t_in[-1], now - float(t_in[-1])
    past = frames > last + eps  # [T_h] frames after the last observation at or before now
    if hold > 0 and past.any():
        since = (frames[past] - last)[:, None]  # [k, 1] seconds after that observation
        if n < len(t) and t[n] - last <= max_gap + eps:  # rule 1: a stamp within hold after now
            track[past] = p_in[-1] + since / (t[n] - last) * (p[n] - p_in[-1])
        elif age <= hold + eps:  # rules 2 and 3: extrapolated, or held
            track[past] = p_in[-1] + since * _velocity(t_in, p_in, age, max_gap, eps)
    return track, age


def _distinct_rows(key, t: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One agent's rows sorted by time, the same (time, position) twice kept once;
    ``DataError`` for two positions at one time."""
    sort = np.argsort(t, kind="stable")
    t, p = t[sort], p[sort]
    same = np.flatnonzero(np.diff(t) == 0)  # duplicate times: row j equals row j + 1
    if len(same):
        clash = same[(p[same] != p[same + 1]).any(-1)]
        if len(clash):
            j = int(clash[0])
            raise DataError(f"ids/times: agent {key!r} has two rows at time {float(t[j])!r} "
                            f"with different positions {p[j].tolist()} and "
                            f"{p[j + 1].tolist()}")  # fmt: skip
        keep = np.ones(len(t), dtype=bool)
        keep[same + 1] = False
        t, p = t[keep], p[keep]
    return t, p


def _velocity(t: np.ndarray, p: np.ndarray, age: float, max_gap: float,
              eps: float) -> np.ndarray:  # fmt: skip
    """[2] the velocity at which an agent observed at distinct times ``t`` [n] (ascending)
    at positions ``p`` [n, 2] is extrapolated ``age`` seconds past its last observation
    (``tracks_to_history``'s rule 2): between that observation and the latest one at least
    ``age`` earlier (the earliest within ``max_gap`` when none is), so that the noise of two
    close stamps is not magnified. Zero (held, rule 3) for an agent seen once, one whose
    last observation is more than ``CYCLE_SLACK`` of its observation intervals (the median gap
    between its times) old, or one with no other observation within ``max_gap``."""
    if len(t) < 2 or age > CYCLE_SLACK * float(np.median(np.diff(t))) + eps:
        return np.zeros(2)
    base = t[-1] - t[:-1]  # [n - 1] > 0, descending
    near = base <= max_gap + eps
    if not near.any():
        return np.zeros(2)
    long = near & (base >= age - eps)
    j = int(np.flatnonzero(long)[-1]) if long.any() else int(np.flatnonzero(near)[0])
    return (p[-1] - p[j]) / base[j]


def _stack(tracks: list[np.ndarray], t_hist: int) -> np.ndarray:
    """[n, T_h, 2] from n tracks [T_h, 2]; [0, T_h, 2] when there are none."""
    return np.stack(tracks) if tracks else np.zeros((0, t_hist, 2))


def _finite_number(name: str, value, error: type[Exception]) -> float:
    """``value`` as a finite float, else ``error`` naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise error(f"{name} must be finite, got {value!r}")
    return number


def _check_settings(step, t_hist, max_gap, hold) -> tuple[float, float, float]:
    """The checked ``step``, ``max_gap`` (its default filled in) and ``hold``."""
    step = _finite_number("step", step, ConfigError)
    if step <= 0:
        raise ConfigError(f"step must be > 0 seconds (model.frame_interval), got {step!r}")
    if isinstance(t_hist, bool) or not isinstance(t_hist, (int, np.integer)) or t_hist < 2:
        raise ConfigError(f"t_hist must be an integer >= 2 (model.t_hist: a model reads each "
                          f"agent's velocity), got {t_hist!r}")  # fmt: skip
    max_gap = 2.0 * step if max_gap is None else _finite_number("max_gap", max_gap, ConfigError)
    if max_gap <= 0:
        raise ConfigError(f"max_gap must be > 0 seconds (or None: 2 * step), got {max_gap!r}")
    hold = _finite_number("hold", hold, ConfigError)
    if hold < 0:
        raise ConfigError(f"hold must be >= 0 seconds, got {hold!r}")
    return step, max_gap, hold


def _check_resolution(name: str, value, step: float) -> None:
    """``DataError`` when ``value`` (``times`` or ``now``) is a float type narrower than float64
    (float32, float16) whose resolution at its largest magnitude is coarser than ``step``: its
    times are rounded to a coarser grid than the frames (Unix seconds in float32: 128 s)."""
    try:
        arr = np.asarray(value)  # an array, a list of numpy floats, a CPU tensor, a scalar
    except (TypeError, ValueError):
        return  # not numbers: _check_rows or _finite_number says so
    dtype = arr.dtype
    if dtype.kind != "f" or dtype.itemsize >= 8:
        return
    finite = np.abs(arr[np.isfinite(arr)])  # the non-finite ones get their own error
    if not finite.size:
        return
    top = finite.max()
    spacing = float(np.spacing(top))  # in value's own type: the gap to the next number
    if spacing > step:
        raise DataError(f"{name}: {dtype.name} holds times as large as {float(top):.6g} s "
                        f"only to the nearest {spacing:g} s, coarser than step={step:g} s, so "
                        "stamps a step apart collapse into one: pass float64 times (and now), "
                        f"or subtract a start time in float64 before converting to "
                        f"{dtype.name}")  # fmt: skip


def _check_rows(times, ids, xy) -> tuple[np.ndarray, list, np.ndarray]:
    """times [R] float64, ids as a list of R plain Python values, xy [R, 2] float64."""
    try:
        t = np.asarray(times, dtype=np.float64)
        pos = np.asarray(xy, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(f"times and xy must be numbers ({exc})") from None
    if t.ndim != 1:
        raise DataError(f"times: expected [R] (one time per row), got {list(t.shape)}")
    if pos.shape != (len(t), 2):
        raise DataError(f"xy: expected [R, 2] with R = {len(t)} (the rows of times), got "
                        f"{list(pos.shape)}")  # fmt: skip
    agent = ids.tolist() if isinstance(ids, np.ndarray) else list(ids)  # numpy -> Python ids
    if len(agent) != len(t):
        raise DataError(f"ids: expected one id per row ({len(t)}), got {len(agent)}")
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise DataError(f"times: row {int(bad[0])} is not finite ({t[bad[0]]!r}); "
                        f"{len(bad)} such row(s)")  # fmt: skip
    bad = np.flatnonzero(~np.isfinite(pos).all(-1))
    if len(bad):
        raise DataError(f"xy: row {int(bad[0])} is not finite ({pos[bad[0]].tolist()}); "
                        f"{len(bad)} such row(s): leave an unseen agent's rows out")  # fmt: skip
    try:
        for key in agent:
            hash(key)
    except TypeError:
        raise DataError(f"ids: agent ids must be hashable, got {type(key).__name__}") from None
    return t, agent, pos
