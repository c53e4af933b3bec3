"""Readers for datasets shipped as arrays (``.npz``): SDD and the official Robo splits."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from trajpref.data.text import DEFAULT_MAX_COORD
from trajpref.errors import DataError, DataNotFound
from trajpref.types import Scene


def load_npz(path: str | Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Load ``keys`` from an ``.npz`` file without executing code (``allow_pickle=False``)."""
    path = Path(path)
    if not path.is_file():
        raise DataNotFound("no such file", path)
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in keys if k not in data]
            if missing:
                raise DataError(f"missing arrays {missing} (has {sorted(data.files)})", path)
            return {k: np.asarray(data[k]) for k in keys}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise DataError(f"not a readable .npz file ({exc})", path) from None


def scenes_from_arrays(
    history: np.ndarray,
    future: np.ndarray,
    seq_start_end: np.ndarray,
    path: str | Path,
    scale: float = 1.0,
    max_coord: float = DEFAULT_MAX_COORD,
    units: str = "unknown",
) -> list[Scene]:
    """Split agent-packed arrays [N, T_h, 2] / [N, T_f, 2] into scenes by ``seq_start_end``.

    Coordinates (after ``scale``) must be finite in float32 and within ``max_coord`` (in
    ``units``)."""
    if history.ndim != 3 or history.shape[-1] != 2 or future.ndim != 3 or future.shape[-1] != 2:
        raise DataError(
            f"expected [N, T, 2] trajectories, got {history.shape} and {future.shape}", path
        )
    if history.shape[0] != future.shape[0]:
        raise DataError("history and future disagree on the number of agents", path)
    if not (np.isfinite(history).all() and np.isfinite(future).all()):
        raise DataError("NaN or infinite coordinates", path)
    with np.errstate(over="ignore"):
        history = (history * scale).astype(np.float32)  # [N, T_h, 2]
        future = (future * scale).astype(np.float32)  # [N, T_f, 2]
    if not (np.isfinite(history).all() and np.isfinite(future).all()):
        raise DataError("coordinates beyond the float32 range (|value| > 3.4e38)", path)
    biggest = float(max(np.abs(history).max(initial=0), np.abs(future).max(initial=0)))
    if biggest > max_coord:
        raise DataError(
            f"coordinate of magnitude {biggest:g} {units} is beyond the sane bound of "
            f"{max_coord:g} {units} (raise it with --max-coord if the data really spans that far)",
            path,
        )
    sse = np.asarray(seq_start_end, dtype=np.int64)  # [S, 2]
    if sse.ndim != 2 or sse.shape[1] != 2:
        raise DataError(f"seq_start_end must be [S, 2], got {sse.shape}", path)
    n = history.shape[0]
    if len(sse) == 0 or (sse[:, 0] >= sse[:, 1]).any() or sse.min() < 0 or sse.max() > n:
        raise DataError("seq_start_end holds empty or out-of-range scenes", path)
    name = Path(path).name
    scenes = []
    for i, (a, b) in enumerate(sse):
        scenes.append(
            Scene(
                history=history[a:b],
                future=future[a:b],
                agent_type=np.zeros(b - a, np.int64),
                scene_id=f"{name}#{i}",
            )
        )
    return scenes
