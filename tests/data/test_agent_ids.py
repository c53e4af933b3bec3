"""Each window keeps its agents' ids from the source file (``Scene.agent_id``), exact and in
the order of its agents, through the readers and everything that keeps or drops whole scenes."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from synthetic import write_tracks

from trajpref.data import load_dataset
from trajpref.data.registry import split_validation_in_time
from trajpref.data.text import GapWarning, ReadOptions, read_folder, read_tracks, window_scenes
from trajpref.data.trajnet import read_trajnet


def _tracker_rows(frames: int = 25) -> list[tuple]:
    """A tracker's rows, agents listed 17, 42, 9 (unsorted) at every frame; 42 leaves after
    frame 21. Each agent walks at y = its id, so a window's rows say whose they are."""
    rows = []
    for f in range(frames):
        for a in (17, 42, 9):
            if a == 42 and f > 21:
                continue
            rows.append((f * 10, a, 0.3 * f, float(a)))
    return rows


def _whose(scene) -> list[int]:
    """The agent each row of ``scene`` holds (its y)."""
    return scene.history[:, 0, 1].astype(int).tolist()


def test_windows_carry_each_agents_source_id_in_agent_order(tmp_path):
    path = write_tracks(tmp_path / "cam.txt", _tracker_rows())
    scenes = window_scenes(read_tracks(path), 8, 12)
    assert [s.agent_id.tolist() for s in scenes] == [[9, 17, 42]] * 3 + [[9, 17]] * 3
    assert all(s.agent_id.dtype == np.int64 and s.agent_id.tolist() == _whose(s) for s in scenes)
    folder = read_folder(tmp_path, 8, 12)  # the folder reader: the same windows, the same ids
    assert [s.agent_id.tolist() for s in folder] == [s.agent_id.tolist() for s in scenes]


@pytest.mark.parametrize(
    "options",
    [
        ReadOptions(time_step=2),
        ReadOptions(time_step=0.5),
        ReadOptions(partial_future=4),
        ReadOptions(reverse_context=True),
        ReadOptions(max_gap=0),
    ],  # fmt: skip
)
def test_ids_follow_the_agents_through_every_way_of_reading(tmp_path, options):
    rows = _tracker_rows(100)
    rows += [(f * 10, 5, 0.3 * f, 5.0) for f in range(3, 40) if f != 20]  # agent 5: a gap
    write_tracks(tmp_path / "d" / "test" / "cam.txt", rows)
    write_tracks(tmp_path / "d" / "train" / "cam.txt", rows)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GapWarning)
        for protocol in ("sgan", "all"):
            ds = load_dataset(str(tmp_path / "d"), "test", options=options, protocol=protocol)
            assert len(ds) and all(s.agent_id.tolist() == _whose(s) for s in ds.scenes)
        train = load_dataset(str(tmp_path / "d"), "train", options=options)
    train, val = split_validation_in_time(train, ds, 0.3, to_train=True)
    kept = [*ds.evenly_spaced(3).scenes, *train.scenes, *val.scenes]
    assert len(val) and all(s.agent_id.tolist() == _whose(s) for s in kept)
    if options.partial_future:  # 42 leaves after frame 21: a target of partial windows too
        assert any(42 in s.agent_id.tolist() and np.isnan(s.future).any() for s in ds.scenes)


@pytest.mark.parametrize(
    ("ids", "want", "whose"),
    [
        ((2**53 + 3, 2**53 + 1), [2**53 + 1, 2**53 + 3], [1, 0]),  # beyond float64: int64
        ((7, 2.5), [2.5, 7.0], [1, 0]),  # not whole numbers: float64
        ((5, 2**64 + 1), ["5", str(2**64 + 1)], [0, 1]),  # beyond int64: exact text
        ((1, "9007199254740993.5"), ["1", "9007199254740993.5"], [0, 1]),  # float64 rounds it
    ],
)
def test_ids_stay_exact_where_float64_or_int64_cannot_hold_them(tmp_path, ids, want, whose):
    # agent k of ``ids`` walks at y = k: ``whose`` says which agent each row holds
    rows = [(f * 10, a, 0.3 * f, float(k)) for f in range(20) for k, a in enumerate(ids)]
    (scene,) = window_scenes(read_tracks(write_tracks(tmp_path / "a.txt", rows)), 8, 12)
    assert scene.agent_id.tolist() == want and _whose(scene) == whose
    assert scene.agent_id.dtype.kind == {int: "i", float: "f", str: "U"}[type(want[0])]


def test_trajnet_scenes_carry_their_agents_p_ids(tmp_path):
    frames = range(0, 200, 10)
    tracks = [(f, p, f / 10, float(y)) for f in frames for y, p in enumerate((40, 12, 3))]
    lines = [json.dumps({"scene": {"id": 1, "p": 12, "s": 0, "e": 190}})]
    lines += [json.dumps({"track": {"f": f, "p": p, "x": x, "y": y}}) for f, p, x, y in tracks]
    (tmp_path / "a.ndjson").write_text("\n".join(lines) + "\n")
    (scene,) = read_trajnet(tmp_path / "a.ndjson").scenes
    assert scene.agent_id.tolist() == [12, 3, 40]  # the primary first, then by id
    assert scene.agent_id.dtype == np.int64 and _whose(scene) == [1, 2, 0]
