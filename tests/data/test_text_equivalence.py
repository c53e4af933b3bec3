"""The streaming per-track reader returns exactly what the dense frames x agents reader that it
replaced returned (kept below as the reference): same scenes, same order, same agents, same
float32 values, same ids."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from trajpref.data.registry import FEET_TO_METRES
from trajpref.data.text import GapWarning, read_tracks, window_scenes
from trajpref.errors import DataError
from trajpref.types import Scene


def dense_reference(path: Path, t_hist: int, t_fut: int, stride: int = 1, scale: float = 1.0,
                    with_type: bool = False) -> list[Scene]:  # fmt: skip
    """The reader before issue 16 (valid input only): a dense [frames, agents] array."""
    rows, kinds = [], []
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        rows.append([float(v) for v in parts[:4]])
        kinds.append(1 if with_type and parts[4].upper() == "BALL" else 0)
    arr = np.asarray(rows, dtype=np.float64)  # [R, 4]
    t_total = t_hist + t_fut
    frames, f_idx = np.unique(arr[:, 0], return_inverse=True)  # [F], [R]
    agents, a_idx = np.unique(arr[:, 1], return_inverse=True)  # [A], [R]
    pos = np.full((len(frames), len(agents), 2), np.nan)  # [F, A, 2]
    pos[f_idx, a_idx] = arr[:, 2:4] * scale
    present = np.zeros((len(frames), len(agents)), np.int64)  # [F, A]
    present[f_idx, a_idx] = 1
    kind = np.zeros(len(agents), np.int64)  # [A]
    kind[a_idx] = np.asarray(kinds, np.int64)
    counts = np.concatenate([np.zeros((1, len(agents)), np.int64), np.cumsum(present, 0)])
    starts = np.arange(0, len(frames) - t_total + 1, stride)  # [W]
    full = (counts[starts + t_total] - counts[starts]) == t_total  # [W, A]
    scenes = []
    for w in np.flatnonzero(full.any(1)):
        s = starts[w]
        members = np.flatnonzero(full[w])  # [P]
        window = pos[s : s + t_total, members].transpose(1, 0, 2)  # [P, T, 2]
        scenes.append(
            Scene(
                window[:, :t_hist].astype(np.float32),
                window[:, t_hist:].astype(np.float32),
                kind[members],
                f"{path.name}@frame={frames[s]:g}",
            )  # fmt: skip
        )
    return scenes


def assert_same(new: list[Scene], ref: list[Scene]) -> None:
    assert [s.scene_id for s in new] == [s.scene_id for s in ref]
    for a, b in zip(new, ref, strict=True):
        assert a.history.dtype == b.history.dtype == np.float32
        np.testing.assert_array_equal(a.history, b.history, strict=True)
        np.testing.assert_array_equal(a.future, b.future, strict=True)
        np.testing.assert_array_equal(a.agent_type, b.agent_type, strict=True)


def random_tracks(path: Path, seed: int) -> Path:
    """Agents entering and leaving at random, some rows dropped, frames 10 apart with a few
    frames missing for everyone, rows in shuffled order, agent ids not contiguous."""
    rng = np.random.default_rng(seed)
    n_frames = int(rng.integers(20, 80))
    frames = np.arange(n_frames) * 10
    frames = frames[rng.random(n_frames) > 0.05]  # global gaps
    rows = []
    for agent in rng.choice(1000, size=int(rng.integers(1, 25)), replace=False):
        a, b = np.sort(rng.integers(0, len(frames), 2))
        for f in frames[a : b + 1]:
            if rng.random() > 0.03:  # a few missing rows inside tracks
                rows.append((f, agent, *np.round(rng.normal(0, 5, 2), 4)))
    rows.append((frames[0], 1001, 0.0, 0.0))
    rows = [rows[i] for i in rng.permutation(len(rows))]
    path.write_text("".join(f"{f}\t{a}\t{x}\t{y}\n" for f, a, x, y in rows))
    return path


@pytest.mark.parametrize("seed", range(40))
def test_synthetic_files_match_the_dense_reference(tmp_path, seed):
    path = random_tracks(tmp_path / f"r{seed}.txt", seed)
    stride = 1 + seed % 3
    t_hist, t_fut = (8, 12) if seed % 2 else (3, 4)
    tracks = read_tracks(path, scale=0.3)
    if len(tracks.frames) < t_hist + t_fut:
        with pytest.raises(DataError, match="too few frames"):
            window_scenes(tracks, t_hist, t_fut, stride)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GapWarning)  # these files have global gaps
        new = window_scenes(tracks, t_hist, t_fut, stride)
    ref = dense_reference(path, t_hist, t_fut, stride, scale=0.3)
    assert len(ref) > 0 or seed % 2
    assert_same(new, ref)


# ---- real data -------------------------------------------------------------------------


@pytest.mark.realdata
def test_every_eth_ucy_file_matches_the_dense_reference(data_root):
    files = sorted((data_root / "eth_ucy").glob("*/*/*.txt"))
    assert len(files) > 50
    unique = {path.read_bytes(): path for path in reversed(files)}  # folds share files
    assert len(unique) >= 20
    for path in unique.values():
        assert_same(window_scenes(read_tracks(path), 8, 12), dense_reference(path, 8, 12))


@pytest.mark.realdata
def test_nba_files_match_the_dense_reference(data_root):
    files = sorted((data_root / "nba" / "rebound" / "test").glob("*.txt"))[:150]
    assert len(files) == 150
    for path in files:
        new = window_scenes(read_tracks(path, True, scale=FEET_TO_METRES), 8, 12)
        assert_same(new, dense_reference(path, 8, 12, scale=FEET_TO_METRES, with_type=True))


@pytest.mark.parametrize("time_step", [1.0, 2.0, 1.5])
def test_read_files_is_the_per_file_reader(tmp_path, time_step):
    # read_files works out each file's frame step once, for the steps it reports and for the
    # resampling: the same scenes as reading, resampling and windowing each file on its own
    from trajpref.data.text import ReadOptions, frame_step, read_files, resample_tracks

    files = [random_tracks(tmp_path / f"r{seed}.txt", seed) for seed in (1, 3, 5)]
    steps = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GapWarning)
        got = read_files(files, options=ReadOptions(time_step=time_step, t_hist=3, t_fut=4),
                         steps=steps)  # fmt: skip
        want = []
        for path in files:
            tracks = read_tracks(path)
            assert steps[path] == (None, frame_step(tracks.frames)) and steps[path][1] == 10
            want += window_scenes(resample_tracks(tracks, time_step), 3, 4)
    assert len(want) > 20
    assert_same(got, want)
