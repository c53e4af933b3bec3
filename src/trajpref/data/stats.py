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
