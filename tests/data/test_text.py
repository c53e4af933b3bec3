import warnings

import numpy as np
import pytest
from synthetic import straight_rows, write_tracks

from trajpref.data import load_dataset
from trajpref.data.registry import USER_TEXT, sgan_folds
from trajpref.data.text import GapWarning, ReadOptions, read_folder, read_tracks, window_scenes
from trajpref.errors import ConfigError, DataError


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
    tracks = read_tracks(write_tracks(tmp_path / "g.txt", rows))
    with pytest.warns(GapWarning, match=r"1 windows \(1 agent-windows\) .* \(up to 3 in a row\)"):
        scenes = window_scenes(tracks, 8, 12)
    assert len(scenes) == 1
    assert window_scenes(tracks, 8, 12, max_gap=0) == []
    assert window_scenes(tracks, 8, 12, max_gap=2) == []
    assert len(window_scenes(tracks, 8, 12, max_gap=3)) == 1


def test_scale_converts_units(tmp_path):
    path = write_tracks(tmp_path / "s.txt", straight_rows(20, agents=1))
    scene = window_scenes(read_tracks(path, scale=0.5), 8, 12)[0]
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


# ---- formats: CSV, headers, delimiters ----------------------------------------------------


def _same_scenes(a, b):
    assert [s.scene_id.split("@")[1] for s in a] == [s.scene_id.split("@")[1] for s in b]
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.history, y.history)
        np.testing.assert_array_equal(x.future, y.future)


@pytest.mark.parametrize(
    ("header", "sep"),
    [
        ("", "\t"),
        ("frame agent x y\n", " "),
        ("frame,agent,x,y\n", ","),
        ("frame, agent, x, y\n", ", "),
        ("# exported by a tool\nframe;agent;x;y\n", ";"),
    ],
)
def test_csv_and_header_lines_read_like_the_tab_format(tmp_path, header, sep):
    rows = straight_rows(21, agents=2)
    reference = window_scenes(read_tracks(write_tracks(tmp_path / "ref.txt", rows)), 8, 12)
    path = tmp_path / "data.txt"
    body = "".join(sep.join(str(v) for v in r) + "  # trailing comment\n" for r in rows)
    path.write_text(header + body)
    _same_scenes(window_scenes(read_tracks(path), 8, 12), reference)
    assert len(reference) == 2


def test_explicit_delimiter_and_hints_on_a_wrong_column_count(tmp_path):
    path = tmp_path / "mixed.txt"
    path.write_text("0 1 2.0 3.0\n10,1,2.5,3.5\n")
    with pytest.raises(DataError, match=r"found 1; the line holds ',': pass --delimiter ','"):
        read_tracks(path)
    path.write_text("0|1|2.0|3.0\n10|1|2.5|3.5\n")
    with pytest.raises(DataError, match="separated by whitespace, found 1; the line holds '|'"):
        read_tracks(path)
    assert read_tracks(path, options=ReadOptions(delimiter="|")).num_rows == 2
    path.write_text("0\t1\t2.0\t3.0\n")
    with pytest.raises(
        DataError, match=r"separated by ',', found 1; the line holds a tab: pass --delimiter tab"
    ):
        read_tracks(path, options=ReadOptions(delimiter=","))
    assert read_tracks(path, options=ReadOptions(delimiter="tab")).num_rows == 1
    path.write_text("0\t1\t2.0\t3.0\n10\t1\t2.5\n")  # tabs read as whitespace, a column short
    with pytest.raises(DataError, match=r"mixed\.txt:2: expected 4 columns .* found 3$"):
        read_tracks(path)
    path.write_text("0 1 2.0 3.0 7\n")
    with pytest.raises(DataError, match="found 5; only frame agent x y are read"):
        read_tracks(path)


def test_a_header_is_only_the_first_line_and_only_when_nothing_in_it_is_a_number(tmp_path):
    path = tmp_path / "h.txt"
    path.write_text("frame agent x y\n0 1 2 3\nframe agent x y\n")
    with pytest.raises(DataError, match="not a number: 'frame'") as info:
        read_tracks(path)
    assert info.value.line == 3
    path.write_text("frame agent 2 y\n0 1 2 3\n")
    with pytest.raises(DataError, match="not a number: 'frame'") as info:
        read_tracks(path)
    assert info.value.line == 1
    path.write_text("frame agent x y\n")
    with pytest.raises(DataError, match="empty file"):
        read_tracks(path)


def test_a_byte_order_mark_is_ignored(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf0,1,2,3\n10,1,2.5,3.5\n")
    np.testing.assert_array_equal(read_tracks(path).xy, [[2, 3], [2.5, 3.5]])
    path.write_bytes(b"\xef\xbb\xbf0,1,2,3\n   \n10,1,2.5,3.5\n")  # the line parser too
    np.testing.assert_array_equal(read_tracks(path).xy, [[2, 3], [2.5, 3.5]])


def test_csv_lines_numpy_refuses_are_read_by_the_line_parser(tmp_path):
    # a blank-but-spaces line inside a CSV stops numpy's parser; the line parser skips it
    path = tmp_path / "c.csv"
    path.write_text("0,1,2,3\n   \n10,1,2.5,3.5\n")
    tracks = read_tracks(path)
    np.testing.assert_array_equal(tracks.xy, [[2, 3], [2.5, 3.5]])
    path.write_text("0,1,2,3\n   \n10,1,abc,3.5\n")
    with pytest.raises(DataError, match="not a number: 'abc'") as info:
        read_tracks(path)
    assert info.value.line == 3


def test_read_options_are_checked():
    with pytest.raises(ConfigError, match="delimiter ':'"):
        ReadOptions(delimiter=":")
    with pytest.raises(ConfigError, match="max_gap"):
        ReadOptions(max_gap=-1)
    with pytest.raises(ConfigError, match="max_coord"):
        ReadOptions(max_coord=float("inf"))
    assert ReadOptions(delimiter="comma").delimiter == ","
    assert ReadOptions(delimiter="whitespace").delimiter == "whitespace"


def test_explicit_whitespace_turns_sniffing_off(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("0,1,2,3\n")
    assert read_tracks(path).num_rows == 1
    with pytest.raises(DataError, match="separated by whitespace, found 1; the line holds ','"):
        read_tracks(path, options=ReadOptions(delimiter="whitespace"))


# ---- sanity: float32, bounds, encodings, links ---------------------------------------------


def test_coordinates_beyond_float32_or_the_bound_are_errors_with_units(tmp_path):
    path = tmp_path / "big.txt"
    path.write_text("0 1 2 3\n10 1 1e39 3\n")
    with pytest.raises(DataError, match="1e\\+39 does not fit float32") as info:
        read_tracks(path)
    assert info.value.line == 2
    path.write_text("0 1 2 3\n10 1 5 3\n20 1 3 -2e20\n")
    with pytest.raises(DataError, match=r"-2e\+20 m is beyond the sane bound of 1e\+06 m"):
        read_tracks(path, units="m")
    with pytest.raises(DataError, match=r"5 px is beyond the sane bound of 4 px") as info:
        read_tracks(path, options=ReadOptions(max_coord=4), units="px")
    assert info.value.line == 2
    assert read_tracks(path, options=ReadOptions(max_coord=1e21)).num_rows == 3
    # the bound applies after unit scaling (feet -> metres)
    path.write_text("0 1 10 0\n")
    with pytest.raises(DataError, match="beyond the sane bound of 3 m"):
        read_tracks(path, options=ReadOptions(max_coord=3), scale=0.3048 * 1.0, units="m")


def test_map_coordinates_that_float32_would_round_away_are_refused_with_the_fix(tmp_path):
    # one walker at 0.37 / 0.23 m per frame, as UTM eastings and northings and near the origin
    rows = [(10 * i, 1, 0.37 * i, 0.23 * i) for i in range(20)]
    near = tmp_path / "near.txt"
    near.write_text("".join(f"{f} {a} {x:.2f} {y:.2f}\n" for f, a, x, y in rows))
    assert read_tracks(near).num_rows == 20
    utm = tmp_path / "utm.txt"
    utm.write_text("".join(f"{f} {a} {500000 + x:.2f} {4500000 + y:.2f}\n" for f, a, x, y in rows))
    big = ReadOptions(max_coord=1e7)
    with pytest.raises(
        DataError, match=r"4\.5e\+06 lose up to 0\.\d+ to float32 rounding.*subtract an"
    ):
        read_tracks(utm, options=big)
    # 100 Hz tracks 10 km out: float32 rounds away 4 % of each recorded step, but read every
    # 40 frame steps (a 0.4 s model's) the rounding is 0.1 % of a step
    fast = tmp_path / "fast.txt"
    rows100 = [(i, 1, 10000 + 0.013 * i, 0.0) for i in range(400)]
    fast.write_text("".join(f"{f} {a} {x:.4f} {y:.4f}\n" for f, a, x, y in rows100))
    with pytest.raises(DataError, match="float32 rounding"):
        read_tracks(fast)
    assert read_tracks(fast, options=ReadOptions(time_step=40)).num_rows > 0
    # an offset float32 carries to well within a step reads as before
    shifted = tmp_path / "shifted.txt"
    shifted.write_text("".join(f"{f} {a} {1000 + x:.2f} {2000 + y:.2f}\n" for f, a, x, y in rows))
    assert read_tracks(shifted).num_rows == 20


def test_the_bound_message_leaves_out_unknown_units(tmp_path):
    path = tmp_path / "big.txt"
    path.write_text("0 1 2 3\n10 1 5e6 3\n")
    with pytest.raises(DataError, match=r"coordinate 5e\+06 is beyond the sane bound of 1e\+06 \("):
        read_tracks(path)


def test_a_coordinate_just_beyond_the_bound_reads_differently_from_it(tmp_path):
    # 1,000,000.5 m and the bound of 1e6 m both printed as 1e+06 ("1e+06 m is beyond 1e+06 m")
    path = tmp_path / "big.txt"
    path.write_text("0 1 2 3\n10 1 1000000.5 3\n")
    with pytest.raises(DataError, match=r"coordinate 1000000\.5 m is beyond the sane bound of "
                                        r"1000000 m \("):  # fmt: skip
        read_tracks(path, units="m")
    path.write_text("0 1 2 3\n10 1 3 -1000000.5\n")
    with pytest.raises(DataError, match=r"coordinate -1000000\.5 m is beyond .* of 1000000 m"):
        read_tracks(path, units="m")
    # a bound float32 cannot hold: 0.1 in the file is 0.100000001 in float32, beyond 0.1
    path.write_text("0 1 0 0\n10 1 0.1 0\n")
    with pytest.raises(DataError, match=r"coordinate 0\.100000001 m is beyond .* of 0\.1 m"):
        read_tracks(path, units="m", options=ReadOptions(max_coord=np.float64(0.1)))


def test_text_that_is_not_utf8_names_the_line(tmp_path):
    path = tmp_path / "bin.txt"
    path.write_bytes(b"0 1 2 3\n10 1 \xff\xfe 3\n")
    with pytest.raises(DataError, match="not UTF-8 text") as info:
        read_tracks(path)
    assert info.value.line == 2


def test_symlink_loops_and_broken_links_are_named(tmp_path):
    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "a.txt").symlink_to(folder / "b.txt")
    (folder / "b.txt").symlink_to(folder / "a.txt")
    with pytest.raises(DataError, match="symlink loop") as info:
        read_folder(folder, 8, 12)
    assert info.value.path == str(folder / "a.txt")
    with pytest.raises(DataError, match="symlink loop"):
        read_tracks(folder / "b.txt")
    other = tmp_path / "e"
    other.mkdir()
    (other / "gone.txt").symlink_to(tmp_path / "nowhere.txt")
    with pytest.raises(DataError, match="broken symlink"):
        read_folder(other, 8, 12)
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(DataError, match="symlink loop"):
        read_folder(tmp_path / "loop", 8, 12)


def test_a_folder_warns_once_about_gaps_and_max_gap_drops_those_windows(tmp_path):
    frames = [10 * i for i in range(10)] + [10 * i for i in range(15, 25)]
    for name in ("a.txt", "b.txt"):
        write_tracks(tmp_path / name, [(f, 1, f / 10, 0) for f in frames])
    with pytest.warns(GapWarning, match=r"^" + str(tmp_path) + r": 2 windows") as record:
        scenes = read_folder(tmp_path, 8, 12)
    assert len(record) == 1 and len(scenes) == 2
    with pytest.raises(DataError, match="no agent is observed in 20 consecutive frames"):
        read_folder(tmp_path, 8, 12, options=ReadOptions(max_gap=0))


def _rows(tracks):
    """{(agent id, frame): xy} of every row of ``tracks``."""
    keys = zip(tracks.agents[tracks.agent_index], tracks.frames[tracks.frame_index], strict=True)
    return dict(zip(keys, tracks.xy, strict=True))


def test_resampling_reads_every_f_frame_steps_with_positions_interpolated(tmp_path):
    from trajpref.data.text import resample_tracks

    # agent 1: frames 0..30 every 10, x = frame / 10; agent 2: frames 0, 10, then a gap, 40, 50
    rows = [(f, 1, f / 10, 0) for f in (0, 10, 20, 30)]
    rows += [(f, 2, f / 10, 5) for f in (0, 10, 40, 50)]
    tracks = read_tracks(write_tracks(tmp_path / "r.txt", rows))
    assert resample_tracks(tracks, 1.0) is tracks
    two = resample_tracks(tracks, 2.0)  # frames 0, 20, 40: exact rows, no interpolation
    np.testing.assert_array_equal(two.frames, [0, 20, 40])
    rows_of = _rows(two)
    assert set(rows_of) == {(1, 0), (1, 20), (2, 0), (2, 40)}  # agent 2 never at 20: a gap
    np.testing.assert_allclose(rows_of[(1, 20)], [2, 0])
    half = resample_tracks(tracks, 1.5)  # frames 0, 15, 30, 45
    np.testing.assert_allclose(half.frames, [0, 15, 30, 45])
    got = _rows(half)
    assert set(got) == {(1, 0), (1, 15), (1, 30), (2, 0), (2, 45)}  # 15 and 30 lie in the gap
    np.testing.assert_allclose(got[(1, 15)], [1.5, 0])  # halfway between frames 10 and 20
    np.testing.assert_allclose(got[(2, 45)], [4.5, 5])


def test_time_step_windows_span_more_frames(tmp_path):
    rows = [(f * 10, 1, f * 0.3, 0) for f in range(40)]  # 0.3 per frame step, 40 frames
    path = write_tracks(tmp_path / "w.txt", rows)
    scenes = read_folder(tmp_path, 8, 12, options=ReadOptions(time_step=2))
    assert len(scenes) == 1  # 40 frames read every 2nd: 20 steps, one window
    np.testing.assert_allclose(np.diff(scenes[0].future[0, :, 0]), 0.6, rtol=1e-5)
    assert scenes[0].scene_id == f"{path.name}@frame=0"
    for bad in (0, -1, float("nan"), 1000):
        with pytest.raises(ConfigError, match="time_step"):
            ReadOptions(time_step=bad)


def test_context_agents_are_the_others_seen_at_the_last_observed_frame(tmp_path):
    # agent 1 in frames 0..19 (the target), agent 2 in frames 0..9 (whole history, leaves in
    # the future), agent 3 in frames 2..19 (enters during the history: NaN before), agent 4 in
    # frames 0..6 (gone before the history ends: not context)
    rows = [(f * 10, 1, f, 0) for f in range(20)]
    rows += [(f * 10, 2, f, 1) for f in range(10)]
    rows += [(f * 10, 3, f, 2) for f in range(2, 20)]
    rows += [(f * 10, 4, f, 3) for f in range(7)]
    (scene,) = window_scenes(read_tracks(write_tracks(tmp_path / "c.txt", rows)), 8, 12)
    assert scene.num_agents == 1
    assert scene.context.shape == (2, 8, 2)  # [C, T_h, 2], agents 2 and 3
    np.testing.assert_allclose(scene.context[0, :, 0], np.arange(8))
    np.testing.assert_allclose(scene.context[0, :, 1], 1.0)
    assert np.isnan(scene.context[1, :2]).all()  # agent 3 not yet seen
    np.testing.assert_allclose(scene.context[1, 2:, 0], np.arange(2, 8))


def test_context_agents_per_scene_and_stride(tmp_path):
    # two windows (frames 0.. and 10..): agent 2 (frames 0..7) is context of the first only;
    # agent 3 (frames 1..11) of both, seen from its second frame in the first; with stride 2
    # the second window is not cut at all
    rows = [(f * 10, 1, f, 0) for f in range(21)]
    rows += [(f * 10, 2, f, 1) for f in range(8)]
    rows += [(f * 10, 3, f, 2) for f in range(1, 12)]
    scenes = window_scenes(read_tracks(write_tracks(tmp_path / "d.txt", rows)), 8, 12)
    assert [s.scene_id for s in scenes] == ["d.txt@frame=0", "d.txt@frame=10"]
    assert [len(s.context) for s in scenes] == [2, 1]
    np.testing.assert_allclose(scenes[0].context[0, :, 1], 1.0)
    assert np.isnan(scenes[0].context[1, 0]).all()
    np.testing.assert_allclose(scenes[1].context[0, :, 0], np.arange(1, 9))
    (only,) = window_scenes(read_tracks(write_tracks(tmp_path / "d.txt", rows)), 8, 12, stride=2)
    assert len(only.context) == 2 and only.context[0, 0, 1] == 1.0


def test_real_eth_test_split_context_count(data_root):
    from trajpref.data.registry import load_dataset

    test = load_dataset("eth", "test", data_root)
    assert test.num_agents == 364  # the targets are unchanged
    assert sum(len(s.context) for s in test.scenes) == 1630  # seen at the last observed frame
    whole = sum(int(np.isfinite(s.context).all(axis=(1, 2)).sum()) for s in test.scenes)
    assert whole == 860  # seen over the whole history
    assert all(s.context_reverse is None for s in test.scenes)  # not kept unless asked for
    options = ReadOptions(reverse_context=True)
    test = load_dataset("eth", "test", data_root, options=options)
    assert sum(len(s.context_reverse) for s in test.scenes) == 1746  # the windows backwards


def test_reversed_window_context_is_the_reversed_files_context(tmp_path):
    # agent 1 in frames 0..19 (the target), 2 in 0..9 (not seen at frame 12: none), 3 in
    # 2..19 (seen over the whole of 12..19), 5 in 12..15 (leaves: NaN at the reversed start)
    rows = [(f * 10, 1, f, 0) for f in range(20)]
    rows += [(f * 10, 2, f, 1) for f in range(10)]
    rows += [(f * 10, 3, f, 2) for f in range(2, 20)]
    rows += [(f * 10, 5, f, 5) for f in range(12, 16)]
    tracks = read_tracks(write_tracks(tmp_path / "f.txt", rows))
    assert window_scenes(tracks, 8, 12)[0].context_reverse is None  # kept only when asked for
    (scene,) = window_scenes(tracks, 8, 12, reverse_context=True)
    assert scene.context_reverse.shape == (2, 8, 2)  # [C', T_h, 2], agents 3 and 5
    np.testing.assert_allclose(scene.context_reverse[0, :, 0], np.arange(19, 11, -1))
    assert np.isnan(scene.context_reverse[1, :4]).all()  # frames 19..16: not there
    np.testing.assert_allclose(scene.context_reverse[1, 4:, 0], [15, 14, 13, 12])
    # the same file played backwards (frame f -> 190 - f) reads them as its own context
    back = [(190 - f, a, x, y) for f, a, x, y in rows]
    (rev,) = window_scenes(read_tracks(write_tracks(tmp_path / "b.txt", back)), 8, 12,
                           reverse_context=True)  # fmt: skip
    np.testing.assert_array_equal(rev.context, scene.context_reverse)
    np.testing.assert_array_equal(rev.context_reverse, scene.context)
    window = np.concatenate([scene.history, scene.future], 1)  # [1, T, 2]
    np.testing.assert_array_equal(rev.history, window[:, ::-1][:, :8])


def test_partial_future_makes_agents_that_leave_the_view_targets(tmp_path):
    # agent 1 in frames 0..19 (a complete window); agent 2 in frames 0..12 (the whole history
    # and 5 future frames, then leaves); agent 3 in frames 0..9 (2 future frames)
    rows = [(f * 10, 1, f, 0) for f in range(20)]
    rows += [(f * 10, 2, f, 1) for f in range(13)]
    rows += [(f * 10, 3, f, 2) for f in range(10)]
    write_tracks(tmp_path / "p.txt", rows)
    (plain,) = read_folder(tmp_path, 8, 12)
    assert plain.num_agents == 1 and len(plain.context) == 2  # both leave: context only
    (scene,) = read_folder(tmp_path, 8, 12, options=ReadOptions(partial_future=4))
    assert scene.num_agents == 2  # agent 2 is seen in 5 >= 4 future frames: a target
    np.testing.assert_allclose(scene.history[1, :, 0], np.arange(8))
    np.testing.assert_allclose(scene.future[1, :5, 0], np.arange(8, 13))
    assert np.isnan(scene.future[1, 5:]).all()  # NaN from the first frame it is missing on
    np.testing.assert_array_equal(scene.future[0], plain.future[0])
    assert len(scene.context) == 1  # agent 3 (2 future frames) stays context-only
    np.testing.assert_allclose(scene.context[0, :, 1], 2.0)
    (strict,) = read_folder(tmp_path, 8, 12, options=ReadOptions(partial_future=6))
    assert strict.num_agents == 1 and len(strict.context) == 2


def test_partial_future_windows_need_the_files_frames_and_a_valid_setting(tmp_path):
    # one agent in frames 0..14 of a 15-frame file: no window needs fewer than 20 frames
    write_tracks(tmp_path / "q.txt", [(f * 10, 1, f, 0) for f in range(15)])
    with pytest.raises(DataError, match="too few frames"):
        read_folder(tmp_path, 8, 12, options=ReadOptions(partial_future=4))
    for bad in (-1, True):
        with pytest.raises(ConfigError, match="partial_future"):
            ReadOptions(partial_future=bad)
    write_tracks(tmp_path / "q.txt", [(f * 10, 1, f, 0) for f in range(25)])
    with pytest.raises(ConfigError, match="below the 12 future frames"):
        read_folder(tmp_path, 8, 12, options=ReadOptions(partial_future=12))


def test_partial_future_windows_stop_at_the_files_last_frame(tmp_path):
    # 22 frames: windows start at frame indices 0, 1, 2 (agent 1's complete ones). Agent 2 in
    # frames 10..21 has its history and 4 future frames there, but its window would reach
    # frame index 29, past the file's end, so it is not cut
    rows = [(f * 10, 1, f, 0) for f in range(22)]
    rows += [(f * 10, 2, f, 1) for f in range(10, 22)]
    write_tracks(tmp_path / "e.txt", rows)
    scenes = read_folder(tmp_path, 8, 12, options=ReadOptions(partial_future=4))
    assert [s.scene_id for s in scenes] == ["e.txt@frame=0", "e.txt@frame=10", "e.txt@frame=20"]
    assert [s.num_agents for s in scenes] == [1, 1, 1]


def test_scene_ids_keep_large_frame_numbers_exact(tmp_path):
    # frames from 12,000,000 and Unix-like times: six significant digits made ids collide
    for first, step in ((12_000_000, 10), (1_700_000_000.1, 0.4)):
        rows = [(first + f * step, a, f, a) for f in range(24) for a in (1, 2)]
        scenes = window_scenes(read_tracks(write_tracks(tmp_path / "d.txt", rows)), 8, 12)
        ids = [s.scene_id for s in scenes]
        assert len(set(ids)) == len(ids) == 5
        assert ids[0] == f"d.txt@frame={first}"


@pytest.mark.parametrize(
    "header", ["agent,frame,x,y", "frame,x,y,agent", "frame,agent,y,x", "ped_id;time;pos_x;pos_y"]
)
def test_a_header_naming_the_columns_in_another_order_is_refused(tmp_path, header):
    sep = ";" if ";" in header else ","
    path = tmp_path / "h.csv"
    path.write_text(f"{header}\n" + "".join(f"{f}{sep}1{sep}{f}{sep}0\n" for f in range(3)))
    with pytest.raises(DataError, match="columns are read by position as frame agent x y: "
                       "reorder") as info:  # fmt: skip
        read_tracks(path)
    assert info.value.line == 1


@pytest.mark.parametrize(
    "header", ["frame_id,ped_id,x,y", "t,id,x,y", "a,b,c,d", "Frame,Track,X,Y"]
)
def test_a_header_in_the_read_order_or_of_unknown_names_is_read(tmp_path, header):
    path = tmp_path / "h.csv"
    path.write_text(f"{header}\n" + "".join(f"{f},1,{f},0\n" for f in range(3)))
    assert read_tracks(path).num_rows == 3


def test_reading_at_another_pace_is_the_same_with_millisecond_timestamps(tmp_path, data_root):
    from trajpref.data.text import resample_tracks

    # zara1's test file at 10 Hz, its frames written as Unix milliseconds: read every 4th
    # step, it must give the windows the same rows with small frame numbers give
    (src,) = (data_root / "eth_ucy" / "zara1" / "test").glob("*.txt")
    fast = resample_tracks(read_tracks(src), 0.25)  # rows every 2.5 frames
    f = fast.frames[fast.frame_index].tolist()  # [R] frame number of each row
    a = fast.agents[fast.agent_index].tolist()  # [R]
    xy = fast.xy.tolist()  # [R, 2]
    windows = []
    for name, first, scale in (("ms.txt", 1_700_000_000_000, 40), ("small.txt", 0, 4)):
        body = [(first + round(v * scale), i, x, y) for v, i, (x, y) in zip(f, a, xy, strict=True)]
        tracks = resample_tracks(read_tracks(write_tracks(tmp_path / name, body)), 4)
        windows.append(sum(s.num_agents for s in window_scenes(tracks, 8, 12)))
    assert windows[0] == windows[1] > 2000


def test_error_lines_count_right_after_a_byte_order_mark_and_a_comment(tmp_path):
    rows = "".join(f"{f},1,{f},0\n" for f in range(5)) + "2,1,2,0\n"  # row 3 again, line 9
    path = tmp_path / "z.csv"
    for prefix in (b"", b"\xef\xbb\xbf"):
        path.write_bytes(prefix + b"# exported\nframe,agent,x,y\n" + rows.encode())
        with pytest.raises(DataError, match=r"duplicate row for frame 2, agent 1 \(also on "
                           r"line 5\)") as info:  # fmt: skip
            read_tracks(path)
        assert info.value.line == 8


def _walkers(frame) -> list[tuple]:
    """12 agents, each on 45 consecutive frame steps k (agent 4 misses two of them), starting
    15 steps apart; ``frame(k)`` is the frame column of step k."""
    rows = []
    for a in range(12):
        for k in range(15 * a, 15 * a + 45):
            if a != 3 or k not in (15 * a + 20, 15 * a + 21):
                rows.append((frame(k), a + 1, round(0.3 * k, 3), float(a)))
    return rows


@pytest.mark.parametrize("time_step", [1.0, 0.4, 1.5])
def test_unix_second_timestamps_read_the_windows_of_frame_numbers(tmp_path, time_step):
    from trajpref.data.text import resample_tracks

    # the same rows with frames 0, 1, 2, ... and as Unix seconds 0.4 apart: read at a
    # non-integer step, numpy's arange laid the grid with the step rounded at 1.5e9
    # (0.16000009 for 0.16) and the grid drifted off the rows (1067 windows for 1072)
    counts = []
    for name, frame in (("small.txt", lambda k: k), ("unix.txt", lambda k: 1.5e9 + 0.4 * k)):
        tracks = resample_tracks(read_tracks(write_tracks(tmp_path / name, _walkers(frame))),
                                 time_step)  # fmt: skip
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", GapWarning)  # agent 4's own gap
            counts.append(sum(s.num_agents for s in window_scenes(tracks, 8, 12)))
    assert counts[0] == counts[1] == {1.0: 291, 0.4: 1072, 1.5: 121}[time_step]


def test_a_step_that_float_rounding_splits_is_still_the_most_common(tmp_path):
    # one agent at Unix seconds 0.4 apart for 40 steps, then 0.8 apart for 34: the 0.4 jumps
    # come as 0.39999986 (16) and 0.4000001 (24), the 0.8 ones as 0.79999995 (27) and
    # 0.80000019 (7); counted apart, 0.8 won and no frame was missing
    ks = [*range(41), *range(42, 110, 2)]
    path = write_tracks(tmp_path / "u.txt", [(1.5e9 + 0.4 * k, 1, 0.3 * k, 0) for k in ks])
    tracks = read_tracks(path)
    with pytest.warns(GapWarning, match=r"34 windows \(34 agent-windows\) span missing frames "
                      r"\(up to 1 in a row\)"):  # fmt: skip
        assert len(window_scenes(tracks, 8, 12)) == 75 - 19
    assert len(window_scenes(tracks, 8, 12, max_gap=0)) == 41 - 19


def test_agent_ids_beyond_float64_integers_stay_distinct_and_exact(tmp_path):
    big = 2**53 + 1  # 9007199254740993: float64 reads it as 2**53, the id of another agent
    # two agents one after the other: one track of 40 frames, 21 windows, if the ids merge
    rows = [(f * 10, big, 0.3 * f, 0) for f in range(20)]
    rows += [(f * 10, big - 1, 100 + 0.3 * f, 5) for f in range(20, 40)]
    tracks = read_tracks(write_tracks(tmp_path / "a.txt", rows))
    assert tracks.agents.tolist() == [big - 1, big]
    assert [s.num_agents for s in window_scenes(tracks, 8, 12)] == [1, 1]
    # the brief's pair at the same frames: two agents of one scene, in id order
    rows = [(f * 10, a, 0.3 * f, y) for f in range(20) for a, y in ((big + 2, 1), (big, 0))]
    (scene,) = window_scenes(read_tracks(write_tracks(tmp_path / "b.txt", rows)), 8, 12)
    np.testing.assert_array_equal(scene.history[:, 0, 1], [0, 1])  # big first, then big + 2
    path = write_tracks(tmp_path / "c.txt", [*rows, (0, big, 9.0, 9.0)])
    with pytest.raises(DataError, match=f"duplicate row for frame 0, agent {big} "):
        read_tracks(path)


def write_text(path, text: str):
    """``text`` written as it is (no newline translation)."""
    path.write_bytes(text.encode())
    return path


def test_old_mac_line_ends_read_like_unix_ones(tmp_path):
    # CR-only line ends: the line parser and the header sniffing saw one line, so a file with
    # a header was refused as "found 136 columns" and every error said line 1
    text = "# exported\nframe,agent,x,y\n" + "".join(
        f"{f * 10},{a},{0.3 * f},{a}\n" for f in range(22) for a in (1, 2)
    )
    unix = read_tracks(write_text(tmp_path / "n.csv", text))
    mac = read_tracks(write_text(tmp_path / "r.csv", text.replace("\n", "\r")))
    np.testing.assert_array_equal(mac.xy, unix.xy)
    assert len(window_scenes(mac, 8, 12)) == 3
    bad = text.replace("50,1,", "50,1,abc,", 1)  # row 11: line 13
    with pytest.raises(DataError, match="expected 4 columns") as info:
        read_tracks(write_text(tmp_path / "b.csv", bad.replace("\n", "\r")))
    assert info.value.line == 13
    dup = text + "0,1,5,5\n"  # the first row again, line 47
    with pytest.raises(DataError, match=r"duplicate row for frame 0, agent 1 \(also on line 3\)"
                       ) as info:  # fmt: skip
        read_tracks(write_text(tmp_path / "d.csv", dup.replace("\n", "\r")))
    assert info.value.line == 47


def _timestamped(path, first: str, count: int, step: str = "0.1"):
    """A ``timestamp,id,x,y`` file of two walkers, times ``first + k * step`` written as the
    shortest decimals (as a logger writes seconds)."""
    from decimal import Decimal

    times = [Decimal(first) + k * Decimal(step) for k in range(count)]
    rows = "".join(f"{t},{a},{0.1 * k:.4f},{a}\n" for k, t in enumerate(times) for a in (1, 2))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("timestamp,id,x,y\n" + rows)
    return times


@pytest.mark.parametrize("first", ["227.3", "1700000000.1"])
def test_resampled_seconds_give_scene_ids_without_float_noise(tmp_path, first):
    # 10 Hz seconds read every 4 steps: the grid 227.3 + 0.4 j is a rounded float sum, and the
    # ids read 227.70000000000002; now each is the decimal it stands for, one per window
    from decimal import Decimal

    times = _timestamped(tmp_path / "d" / "log.csv", first, 200)
    scenes = read_folder(tmp_path / "d", 8, 12, pattern="*.csv",
                         options=ReadOptions(time_step=4))  # fmt: skip
    ids = [s.scene_id for s in scenes]
    want = [f"log.csv@frame={times[0] + 4 * j * Decimal('0.1')}" for j in range(len(ids))]
    assert ids == want and len(set(ids)) == len(ids) == 50 - 19
    # read as recorded, an id is the file's own text
    scenes = read_folder(tmp_path / "d", 8, 12, pattern="*.csv")
    assert [s.scene_id for s in scenes[:2]] == [f"log.csv@frame={t}" for t in times[:2]]


def test_frame_labels_stay_distinct_when_frames_round_alike():
    from trajpref.data.text import frame_labels

    assert frame_labels(np.array([227.3, 227.3 + 0.4]), 1e-12) == ["227.3", "227.7"]
    assert frame_labels(np.array([227.3, 227.3 + 0.4])) == ["227.3", "227.70000000000002"]
    # two frames closer than the rounding: every label is its float's exact text
    close = np.array([0.1, 0.1 + 1e-9, 0.5])
    labels = frame_labels(close, 1e-6)
    assert len(set(labels)) == 3 and labels == ["0.1", "0.100000001", "0.5"]


NS = 1_700_000_000_000_000_123  # a Unix time in nanoseconds: beyond 2**53, float64 rounds it


def test_frame_numbers_beyond_float64_integers_stay_exact(tmp_path):
    from trajpref.data.text import frame_step, read_files

    # nanosecond timestamps at 10 Hz: float64 rounded every frame to a multiple of 256, so the
    # scene ids named frames that are not in the file (...000 for ...123)
    rows = [(NS + k * 100_000_000, a, 0.3 * k, a) for k in range(24) for a in (1, 2)]
    path = write_tracks(tmp_path / "ns.txt", rows)
    steps = {}
    scenes = read_files([path], 8, 12, steps=steps)
    assert [s.scene_id for s in scenes] == [f"ns.txt@frame={NS + k * 100_000_000}"
                                            for k in range(5)]  # fmt: skip
    assert steps[path] == (None, 100_000_000.0)
    assert frame_step(read_tracks(path).frames) == 100_000_000.0
    # read every 2 steps, the grid's frames are exact too
    paced = read_files([path], options=ReadOptions(time_step=2, t_hist=3, t_fut=4))
    assert paced[1].scene_id == f"ns.txt@frame={NS + 200_000_000}"
    # frames one apart beyond 2**53: float64 merged neighbours into one frame and called the
    # next row a duplicate
    rows = [(2**53 + 1 + k, 1, 0.3 * k, 0) for k in range(22)]
    scenes = window_scenes(read_tracks(write_tracks(tmp_path / "one.txt", rows)), 8, 12)
    assert [s.scene_id for s in scenes] == [f"one.txt@frame={2**53 + 1 + k}" for k in range(3)]
    # non-integer frames beyond 2**53 are read exactly from their text as well
    rows = [(f"{NS + k}.5", 1, 0.3 * k, 0) for k in range(20)]
    (scene,) = window_scenes(read_tracks(write_tracks(tmp_path / "dec.txt", rows)), 8, 12)
    assert scene.scene_id == f"dec.txt@frame={NS}.5"
    # two agents logged 1 ns apart are at different frames, not one (float64 merged them
    # silently into windows of two agents)
    rows = [(NS + k * 100_000_000 + a, a, 0.3 * k, a) for k in range(24) for a in (0, 1)]
    tracks = read_tracks(write_tracks(tmp_path / "apart.txt", rows))
    assert len(tracks.frames) == 48
    # a repeated row names its exact frame and lines
    dup = write_tracks(tmp_path / "dup.txt", [*rows, (NS + 1, 1, 5.0, 5.0)])
    with pytest.raises(DataError, match=rf"duplicate row for frame {NS + 1}, agent 1 \(also "
                       r"on line 2\)") as info:  # fmt: skip
        read_tracks(dup)
    assert info.value.line == 49


def test_frame_numbers_float64_cannot_keep_apart_ask_to_rescale(tmp_path):
    # frames from 0 to beyond 2**53 in one file: no origin makes float64 hold them all, and
    # 2**53 and 2**53 + 1 (two agents' rows) became one frame without a word
    rows = [(k, 1, 0.3 * k, 0) for k in range(21)]
    rows += [(2**53, 2, 0.0, 0.0), (2**53 + 1, 3, 1.0, 1.0)]
    with pytest.raises(DataError, match=r"frame numbers \(column 1\) 9007199254740992 and "
                       r"9007199254740993 are 1 apart, but the file's frames span "
                       r"9007199254740993 .*rescale the time column"):  # fmt: skip
        read_tracks(write_tracks(tmp_path / "far.txt", rows))
    # far apart yet held apart by float64: read as before
    rows[-1] = (2**53 + 8, 3, 1.0, 1.0)
    tracks = read_tracks(write_tracks(tmp_path / "far.txt", rows))
    assert len(tracks.frames) == 23


def test_numbers_only_in_the_syntax_numpy_reads(tmp_path):
    # Python's float reads "1_12" and "11_2" both as 112 (digit separators), so two
    # camera_track ids became one agent, whose track jumped from one walker to the other;
    # numpy refuses them and the line parser, which took over, accepted them
    rows = "".join(f"{f * 10} 1_12 {f * 0.3} 0\n" for f in range(10))
    rows += "".join(f"{f * 10} 11_2 {f * 0.3} 5\n" for f in range(10, 20))
    with pytest.raises(DataError, match="not a number: '1_12'") as info:
        read_tracks(write_text(tmp_path / "cam.txt", rows))
    assert info.value.line == 1
    # and digits of other scripts (Arabic-Indic, full-width)
    for digits in ("\u0661\u0662", "\uff11\uff12"):
        path = write_text(tmp_path / "u.txt", f"0 1 2 3\n10 {digits} 2 3\n")
        with pytest.raises(DataError, match="not a number") as info:
            read_tracks(path)
        assert info.value.line == 2
    # a first line of such fields is a data line to refuse, not a header to skip
    with pytest.raises(DataError, match="not a number: '1_0'") as info:
        read_tracks(write_text(tmp_path / "h.txt", "1_0 2_0 3_0 4_0\n0 1 2 3\n"))
    assert info.value.line == 1


# Reader messages and formats a researcher with their own files met (walkthrough 63-B,
# findings 3, 11 and 12): a header without an agent column, ``.tsv`` files, millisecond time
# columns, extra columns, and the mean speed's plausibility note.


def _walker_rows(count: int = 30, step: float = 1.0, first: float = 0.0, sep: str = ",") -> str:
    """Rows of two walkers, ``count`` frames ``step`` apart from ``first``, 0.1 units a frame."""
    return "".join(f"{round(first + k * step, 6)}{sep}{a}{sep}{0.1 * k:.3f}{sep}{a}\n"
                   for k in range(count) for a in (1, 2))  # fmt: skip


def test_a_header_without_an_agent_column_says_so_rather_than_asking_to_reorder(tmp_path):
    # "frame,x,y" was told to reorder its columns, which cannot give it a fourth one
    path = tmp_path / "a.csv"
    path.write_text("frame,x,y\n" + "".join(f"{f},{0.1 * f:.2f},0.4\n" for f in range(30)))
    with pytest.raises(DataError) as info:
        read_tracks(path)
    message = str(info.value)
    assert "reorder" not in message and info.value.line == 1
    assert message.endswith(
        "a.csv:1: the header names 3 columns (frame x y), where 4 are needed (frame agent x y, "
        "read by position): no agent column was found; add it as column 2 (a file of one "
        "agent: the same agent id on every row)"
    )
    # a two-column header names both missing columns
    path.write_text("frame,x\n0,1\n")
    with pytest.raises(DataError, match=r"names 2 columns \(frame x\), where 4 are needed .*: "
                       r"no agent or y column was found"):  # fmt: skip
        read_tracks(path)
    # a short header with a name the reader does not know is left to the column count
    path.write_text("frame,pid,xy\n0,1,2,3\n")
    assert read_tracks(path).num_rows == 1


def test_extra_columns_say_how_to_proceed(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("frame,id,x,y,label\n" + "".join(f"{f},5,{f},0,ped\n" for f in range(3)))
    with pytest.raises(DataError) as info:
        read_tracks(path)
    message = str(info.value)
    assert "found 5; only frame agent x y are read" in message  # the start, as docs quote it
    assert ("the first 4 columns, by position, not by header name: drop the other column "
            "(keep frame agent x y, in that order)") in message  # fmt: skip
    path.write_text("0 1 2.0 3.0 7 8\n")
    with pytest.raises(DataError, match="drop the other 2 columns"):
        read_tracks(path)


def test_tsv_files_are_read_like_txt_files(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "a.tsv").write_text("frame\tid\tx\ty\n" + _walker_rows(sep="\t"))
    (tmp_path / "d" / "b.TSV").write_text(_walker_rows(sep="\t"))
    ds = load_dataset(str(tmp_path / "d"), "test")
    assert {s.scene_id.split("@")[0] for s in ds.scenes} == {"a.tsv", "b.TSV"}
    assert "*.tsv" in USER_TEXT
    # a folder of other files names every accepted suffix
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "a.dat").write_text(_walker_rows())
    with pytest.raises(DataError, match=r"no \*\.txt or \*\.csv or \*\.tsv files in folder"):
        load_dataset(str(tmp_path / "e"), "test")
    # a .tsv beside .ndjson files is two formats in one folder, as a .txt is
    (tmp_path / "d" / "s.ndjson").write_text("")
    with pytest.raises(DataError, match=r"holds both text \(\*\.txt, \*\.csv, \*\.tsv\) and "
                       r"\*\.ndjson files"):  # fmt: skip
        load_dataset(str(tmp_path / "d"), "test")
    # a copy of a Social-GAN test file saved as .tsv is still that fold's data
    (tmp_path / "f" / "test").mkdir(parents=True)
    (tmp_path / "f" / "test" / "crowds_zara01.tsv").write_text(_walker_rows(sep="\t"))
    assert sgan_folds(tmp_path / "f") == ("zara1",)


@pytest.mark.parametrize("header", ["timestamp_ms,track,u,v", "time_ms,id,x,y"])
def test_millisecond_time_columns_give_the_interval_in_seconds(tmp_path, header):
    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "log.csv").write_text(f"{header}\n" + _walker_rows(step=100, first=2800))
    info = load_dataset(str(folder), "test").info
    assert (info.frame_interval, info.interval_from) == (0.1, "timestamps")
    assert load_dataset(str(folder), "test", frame_interval=0.2).info.frame_interval == 0.2


def test_a_millisecond_column_of_an_implausible_step_keeps_the_default_and_says_so(tmp_path):
    from trajpref.data import FrameRateWarning

    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "log.csv").write_text(
        "time_ms,id,x,y\n" + _walker_rows(step=0.1)
    )  # seconds, misnamed
    with pytest.warns(FrameRateWarning, match=r"the files' time column, in milliseconds, steps "
                      r"0\.1 ms \(0\.0001 s\), which is no plausible number of seconds between "
                      r"frames: 0\.4 s between frames is assumed"):  # fmt: skip
        info = load_dataset(str(folder), "test").info
    assert info.interval_from == "default"
    # files in seconds and in milliseconds that step alike agree
    (folder / "log.csv").write_text("time_ms,id,x,y\n" + _walker_rows(step=100))
    (folder / "b.csv").write_text("time,id,x,y\n" + _walker_rows(step=0.1))
    assert load_dataset(str(folder), "test").info.frame_interval == 0.1
    (folder / "b.csv").write_text("frame,id,x,y\n" + _walker_rows(step=1))
    with pytest.warns(FrameRateWarning, match=r"log\.csv's frame column is a time in "
                      r"milliseconds, b\.csv's is not"):  # fmt: skip
        load_dataset(str(folder), "test")
