"""Summary numbers of a dataset split (``trajpref data stats``), computed scene by scene so that
nothing the size of the whole split is allocated on top of the split itself."""

from __future__ import annotations

import numpy as np

from trajpref.types import TrajectoryDataset


def mean_speed(dataset: TrajectoryDataset) -> float:
    """Mean speed over every step of every agent-window (units per second), in float64."""
    total, steps = 0.0, 0
    for scene in dataset.scenes:
        track = np.concatenate([scene.history, scene.future], 1)  # [P, T, 2]
        step = np.linalg.norm(np.diff(track, axis=1), axis=-1)  # [P, T-1]
        total += float(step.sum(dtype=np.float64))
        steps += step.size
    if steps == 0:
        return float("nan")
    return total / steps / dataset.info.frame_interval


METRES_PER_UNIT = {"m": 1.0, "metre": 1.0, "metres": 1.0, "meter": 1.0, "meters": 1.0,
                   "cm": 0.01, "mm": 0.001, "ft": 0.3048, "feet": 0.3048}  # fmt: skip
"""Unit names (``--units``, lower case) that ``speed_note`` can turn into metres; other units
(``px``, ``unknown``) get no note."""
WALKING_SPEEDS = (0.3, 3.0)
"""Mean speeds (m/s) of a pedestrian split that ``speed_note`` takes as plausible: people walk
at about 0.5-2 m/s, and a split's mean over every agent-window is lower where many stand
(hotel's test split: 0.46 m/s; eth and zara1: 0.94-0.97 m/s)."""
TYPICAL_WALK = 1.3
"""A typical walking speed (m/s) that ``speed_note`` names an interval for."""


def speed_text(speed: float, units: str) -> str:
    """``mean_speed`` as ``data stats`` prints it: ``1.25 m/s``, or for unknown units
    ``0.3022 units/s (units unknown: name them with --units)`` rather than ``unknown/s``."""
    if units == "unknown":
        return f"{speed:.4g} units/s (units unknown: name them with --units)"
    return f"{speed:.4g} {units}/s"


def speed_note(speed: float, units: str, frame_interval: float,
               interval_from: str | None = None, time_step: float = 1.0) -> str | None:  # fmt: skip
    """A one-line note when a split's mean speed (``mean_speed``, ``units`` per second) is no
    walking pace: in metres (``METRES_PER_UNIT``), outside ``WALKING_SPEEDS``. It asks whether
    the frame interval is right, says what the interval means, and names the interval a
    ``TYPICAL_WALK`` would give. ``frame_interval`` is the split's seconds per window step
    (``DatasetInfo.frame_interval``, ``time_step`` included), ``interval_from`` where it comes
    from (``DatasetInfo.interval_from``: ``default`` is named as assumed; ``dataset``, a
    built-in dataset's own, gets no note). None when the pace is plausible, the units cannot be
    turned into metres, or the speed is not a positive number (nobody moved: no interval
    would change that)."""
    per = METRES_PER_UNIT.get(units.strip().lower())
    if per is None or interval_from == "dataset" or not np.isfinite(speed) or speed <= 0:
        return None
    metres = speed * per
    if WALKING_SPEEDS[0] <= metres <= WALKING_SPEEDS[1]:
        return None
    shown = f"{speed:.4g} {units}/s" + ("" if per == 1.0 else f" ({metres:.4g} m/s)")
    rows = frame_interval / time_step  # seconds between the files' rows, as given or assumed
    now = f"{rows:g} s" + (", assumed" if interval_from == "default" else "")
    now += "" if time_step == 1.0 else f", read every {time_step:g}"
    return (f"{shown} is not a walking pace (pedestrians: about 0.5-2 m/s): is "
            "--frame-interval (or --units) right? It is the seconds between consecutive rows "
            f"of an agent (now {now}), not per frame number: at {TYPICAL_WALK:g} m/s these rows "
            f"would be {rows * metres / TYPICAL_WALK:.4g} s apart")  # fmt: skip
