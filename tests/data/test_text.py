import numpy as np
import pytest
from synthetic import straight_rows, write_tracks

from trajpref.data.text import read_folder, read_tracks, window_scenes
from trajpref.errors import DataError


def test_windowing_rule_counts_agents_present_in_all_frames(tmp_path):
    # agent 1 in frames 0..21 (3 windows), agent 2 only in frames 0..19 (1 window),
    # agent 3 misses frame 5 (never complete)
    rows = [(f * 10, 1, f, 0) for f in range(22)]
    rows += [(f * 10, 2, f, 1) for f in range(20)]
    rows += [(f * 10, 3, f, 2) for f in range(22) if f != 5]
    scenes = window_scenes(read_tracks(write_tracks(tmp_path / "a.txt", rows)), 8, 12)
    assert [s.num_agents for s in scenes] == [2, 1, 1]
    first = scenes[0]
    np.testing.assert_allclose(first.history[0, :, 0], np.arange(8))
    np.testing.assert_allclose(first.future[1, :, 0], np.arange(8, 20))
    assert first.scene_id == "a.txt@frame=0"


def test_windows_follow_unique_frames_even_with_gaps(tmp_path):
    # frame numbers jump (0, 10, 20, 60, ...): windows walk the sorted unique frames
    frames = [0, 10, 20] + [60 + 10 * i for i in range(17)]
    rows = [(f, 1, i, 0) for i, f in enumerate(frames)]
    scenes = window_scenes(read_tracks(write_tracks(tmp_path / "g.txt", rows)), 8, 12)
    assert len(scenes) == 1


def test_scale_converts_units(tmp_path):
    path = write_tracks(tmp_path / "s.txt", straight_rows(20, agents=1))
    scene = window_scenes(read_tracks(path), 8, 12, scale=0.5)[0]
    assert scene.history[0, 1, 0] == pytest.approx(0.15)


@pytest.mark.parametrize(
    ("content", "message", "line"),
    [
        ("0\t1\t1.0\n", "expected 4 columns", 1),
        ("0\t1\t1.0\t2.0\n10\t1\tabc\t2.0\n", "not a number: 'abc'", 2),
        ("0\t1\t1.0\t2.0\n10\t1\tnan\t2.0\n", "NaN or infinite", 2),
        ("0\t1\tinf\t2.0\n", "NaN or infinite", 1),
        (
            "0\t1\t1.0\t2.0\n0\t2\t1.0\t2.0\n0\t1\t3.0\t4.0\n",
            "duplicate row for frame 0, agent 1",
            3,
        ),
    ],
)
def test_malformed_rows_name_file_and_line(tmp_path, content, message, line):
    path = tmp_path / "bad.txt"
    path.write_text(content)
    with pytest.raises(DataError, match=message) as info:
        read_tracks(path)
    assert info.value.line == line
    assert str(info.value).startswith(f"{path}:{line}: ")
    assert "\n" not in str(info.value)


def test_empty_and_missing(tmp_path):
    empty = tmp_path / "empty.txt"
    empty.write_text("\n\n")
    with pytest.raises(DataError, match="empty file") as info:
        read_tracks(empty)
    assert info.value.path == str(empty)
    with pytest.raises(DataError, match="no such folder"):
        read_folder(tmp_path / "nope", 8, 12)
    with pytest.raises(DataError, match="no such file"):
        read_tracks(tmp_path / "nope.txt")
    (tmp_path / "emptydir").mkdir()
    with pytest.raises(DataError, match=r"no \*\.txt files"):
        read_folder(tmp_path / "emptydir", 8, 12)


def test_too_few_frames_names_the_file(tmp_path):
    path = write_tracks(tmp_path / "short.txt", straight_rows(19))
    with pytest.raises(DataError, match="too few frames: 19 unique frames") as info:
        read_folder(tmp_path, 8, 12)
    assert info.value.path == str(path)


def test_typed_rows(tmp_path):
    path = tmp_path / "nba.txt"
    path.write_text("0 -1 1.0 2.0 BALL\n0 7 3.0 4.0 PLAYER\n12 7 1 1 REFEREE\n")
    with pytest.raises(DataError, match="unknown agent type 'REFEREE'"):
        read_tracks(path, with_type=True)
    path.write_text("0 -1 1.0 2.0 BALL\n0 7 3.0 4.0 PLAYER\n")
    tracks = read_tracks(path, with_type=True)
    assert tracks.agent_type.tolist() == [1, 0]
