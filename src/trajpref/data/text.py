"""Readers for whitespace-separated track files (``frame agent x y [type]``) and the
windowing rule that turns tracks into scenes.

Windowing (the standard of Social-GAN, Trajectron++, AgentFormer and LED): per file, take the
sorted unique frame numbers; a window is ``T_h + T_f`` consecutive entries of that list,
starting at every ``stride``-th entry; an agent belongs to a window when it has a row in all
of its frames; every window with at least one such agent is a scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trajpref.errors import DataError
from trajpref.types import AGENT_BALL, AGENT_PERSON, Scene


@dataclass
class Tracks:
    """The rows of one track file, validated."""

    path: Path
    frame: np.ndarray
    """[R] float64 frame numbers."""
    agent: np.ndarray
    """[R] float64 agent ids."""
    xy: np.ndarray
    """[R, 2] float64 positions."""
    agent_type: np.ndarray
    """[R] int64 agent-type flags."""


_TYPE_NAMES = {"PLAYER": AGENT_PERSON, "PERSON": AGENT_PERSON, "BALL": AGENT_BALL}


def read_tracks(path: str | Path, with_type: bool = False) -> Tracks:
    """Read ``frame agent x y`` rows (plus a ``BALL|PLAYER`` column when ``with_type``).

    Raises ``DataError`` naming the file and line for: a wrong number of columns, a value that
    is not a number, NaN or infinity, a duplicated (frame, agent) pair, or an empty file.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError("no such file", path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read file ({exc.__class__.__name__})", path) from None
    n_cols = 5 if with_type else 4
    expect = "frame agent x y BALL|PLAYER" if with_type else "frame agent x y"
    rows: list[tuple[float, float, float, float]] = []
    types: list[int] = []
    line_of: list[int] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        if len(parts) != n_cols:
            raise DataError(
                f"expected {n_cols} columns ({expect}), found {len(parts)}", path, lineno
            )
        try:
            values = tuple(float(v) for v in parts[:4])
        except ValueError:
            bad = next(v for v in parts[:4] if not _is_float(v))
            raise DataError(f"not a number: {bad!r}", path, lineno) from None
        if not all(math.isfinite(v) for v in values):
            raise DataError("NaN or infinite value", path, lineno)
        if with_type:
            kind = _TYPE_NAMES.get(parts[4].upper())
            if kind is None:
                raise DataError(f"unknown agent type {parts[4]!r} (BALL or PLAYER)", path, lineno)
            types.append(kind)
        rows.append(values)  # type: ignore[arg-type]
        line_of.append(lineno)
    if not rows:
        raise DataError("empty file: no data rows", path)
    arr = np.asarray(rows, dtype=np.float64)  # [R, 4]
    _check_duplicates(arr[:, 0], arr[:, 1], np.asarray(line_of), path)
    agent_type = np.asarray(types, np.int64) if with_type else np.zeros(len(arr), np.int64)
    return Tracks(path, arr[:, 0], arr[:, 1], arr[:, 2:4], agent_type)


def _is_float(v: str) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True


def _check_duplicates(frame: np.ndarray, agent: np.ndarray, lines: np.ndarray, path: Path):
    keys = np.stack([frame, agent], 1)  # [R, 2]
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        dup_keys = keys[first[counts > 1]]  # [U, 2]
        is_dup = (keys[:, None, :] == dup_keys[None, :1, :]).all(-1).any(-1)  # [R]
        dup_lines = lines[is_dup]
        f, a = dup_keys[0]
        raise DataError(
            f"duplicate row for frame {f:g}, agent {a:g} (also on line {dup_lines[0]})",
            path,
            int(dup_lines[1]),
        )


def window_scenes(
    tracks: Tracks,
    t_hist: int,
    t_fut: int,
    stride: int = 1,
    scale: float = 1.0,
) -> list[Scene]:
    """Cut one file's tracks into scenes by the windowing rule in the module docstring.

    ``scale`` multiplies coordinates (e.g. feet to metres). Raises ``DataError`` when the file
    has fewer unique frames than one window needs.
    """
    t_total = t_hist + t_fut
    frames, f_idx = np.unique(tracks.frame, return_inverse=True)  # [F], [R]
    if len(frames) < t_total:
        raise DataError(
            f"too few frames: {len(frames)} unique frames, a window needs {t_total}", tracks.path
        )
    agents, a_idx = np.unique(tracks.agent, return_inverse=True)  # [A], [R]
    n_f, n_a = len(frames), len(agents)
    pos = np.full((n_f, n_a, 2), np.nan)  # [F, A, 2]
    pos[f_idx, a_idx] = tracks.xy * scale
    present = np.zeros((n_f, n_a), np.int64)  # [F, A]
    present[f_idx, a_idx] = 1
    kind = np.zeros(n_a, np.int64)  # [A]
    kind[a_idx] = tracks.agent_type
    counts = np.concatenate([np.zeros((1, n_a), np.int64), np.cumsum(present, 0)])  # [F+1, A]
    starts = np.arange(0, n_f - t_total + 1, stride)  # [W]
    full = (counts[starts + t_total] - counts[starts]) == t_total  # [W, A]
    scenes = []
    for w in np.flatnonzero(full.any(1)):
        s = starts[w]
        members = np.flatnonzero(full[w])  # [P]
        window = pos[s : s + t_total, members].transpose(1, 0, 2)  # [P, T, 2]
        scenes.append(
            Scene(
                history=window[:, :t_hist].astype(np.float32),
                future=window[:, t_hist:].astype(np.float32),
                agent_type=kind[members],
                scene_id=f"{tracks.path.name}@frame={frames[s]:g}",
            )
        )
    return scenes


def read_folder(
    folder: str | Path,
    t_hist: int,
    t_fut: int,
    stride: int = 1,
    scale: float = 1.0,
    with_type: bool = False,
    pattern: str = "*.txt",
) -> list[Scene]:
    """Read every track file in ``folder`` (sorted by name) into scenes."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError("no such folder", folder)
    files = sorted(p for p in folder.glob(pattern) if p.is_file())
    if not files:
        raise DataError(f"no {pattern} files in folder", folder)
    scenes: list[Scene] = []
    for path in files:
        scenes.extend(window_scenes(read_tracks(path, with_type), t_hist, t_fut, stride, scale))
    if not scenes:
        raise DataError(
            f"no agent is observed in {t_hist + t_fut} consecutive frames in any file", folder
        )
    return scenes
