import dataclasses
import os
import re
from pathlib import Path

import numpy as np
import pytest
from synthetic import make_scene, straight_rows, write_dataset, write_tracks

from trajpref.config import DataConfig
from trajpref.data import (
    ReadOptions,
    hold_out_scene,
    load_dataset,
    mean_speed,
    registry,
    resolve_data_root,
    run_splits,
    split_validation_in_time,
    text,
    with_paced_copy,
)
from trajpref.data.registry import (
    ETH_UCY,
    FEET_TO_METRES,
    SPECS,
    apply_protocol,
    robo_episodes,
)
from trajpref.errors import ConfigError, DataError, TrajprefError
from trajpref.types import DatasetInfo, Scene, TrajectoryDataset

FOLD_TEST_AGENTS = {"eth": 364, "hotel": 1197, "univ": 24334, "zara1": 2356, "zara2": 5910}
SGAN_TEST = {  # (scenes, agents) under --protocol sgan; eth and hotel as the issue states them
    "eth": (70, 181), "hotel": (301, 1053), "univ": (947, 24334), "zara1": (602, 2253),
    "zara2": (921, 5833),
}  # fmt: skip


def test_user_folder_with_split_subfolders(tmp_path):
    for split, n in (("train", 25), ("test", 21)):
        write_tracks(tmp_path / split / "a.txt", straight_rows(n))
    train = load_dataset(str(tmp_path), "train", frame_interval=0.5, units="m")
    test = load_dataset(str(tmp_path), "test")
    assert len(train) == 6 and train.num_agents == 12
    assert len(test) == 2
    assert train.info.frame_interval == 0.5 and train.info.units == "m"
    with pytest.raises(DataError, match="no val/ sub-folder"):
        load_dataset(str(tmp_path), "val")


def test_user_folder_without_subfolders_is_one_split(tmp_path):
    write_tracks(tmp_path / "a.txt", straight_rows(20))
    assert load_dataset(str(tmp_path), "test").num_agents == 2


def test_unknown_names_and_roots(tmp_path, monkeypatch):
    with pytest.raises(TrajprefError, match="unknown dataset 'zara9'"):
        load_dataset("zara9", "test", tmp_path)
    with pytest.raises(TrajprefError, match="unknown split"):
        load_dataset("zara1", "dev", tmp_path)
    monkeypatch.delenv("TRAJPREF_DATA", raising=False)
    with pytest.raises(TrajprefError, match=r"--data-root, or root= in Python.* TRAJPREF_DATA"):
        resolve_data_root(None)
    with pytest.raises(DataError, match="no such folder"):
        load_dataset("zara1", "test", tmp_path)  # root exists, eth_ucy/ does not


def test_bad_npz_is_a_clear_error(tmp_path):
    (tmp_path / "robo").mkdir()
    (tmp_path / "robo" / "test.npz").write_bytes(b"not a zip")
    with pytest.raises(DataError, match="not a readable .npz"):
        load_dataset("robo", "test", tmp_path)
    np.savez(tmp_path / "robo" / "test.npz", obs_traj=np.zeros((3, 8, 2)))
    with pytest.raises(DataError, match="missing arrays"):
        load_dataset("robo", "test", tmp_path)
    obs = np.zeros((3, 8, 2))
    obs[1, 2, 0] = np.nan
    np.savez(
        tmp_path / "robo" / "test.npz",
        obs_traj=obs,
        pred_traj=np.zeros((3, 12, 2)),
        seq_start_end=np.array([[0, 3]]),
    )
    with pytest.raises(DataError, match="NaN"):
        load_dataset("robo", "test", tmp_path)


# ---- real data -------------------------------------------------------------------------


@pytest.mark.realdata
@pytest.mark.parametrize("fold", ETH_UCY)
def test_eth_ucy_test_fold_counts(data_root, fold):
    ds = load_dataset(fold, "test", data_root)
    assert ds.num_agents == FOLD_TEST_AGENTS[fold]
    assert ds.info.units == "m" and ds.info.frame_interval == 0.4
    scene = ds[0]
    assert scene.history.shape[1:] == (8, 2) and scene.future.shape[1:] == (12, 2)


@pytest.mark.realdata
@pytest.mark.parametrize("fold", ETH_UCY)
def test_sgan_protocol_counts(data_root, fold):
    ds = load_dataset(fold, "test", data_root, protocol="sgan")
    assert (len(ds), ds.num_agents) == SGAN_TEST[fold]
    assert ds.info.protocol == "sgan" and min(s.num_agents for s in ds.scenes) >= 2


def test_sgan_protocol_keeps_scenes_with_two_or_more_agents():
    info = DatasetInfo("toy", "test", "m", 0.4, source="toy")
    sizes = (1, 2, 1, 5)
    ds = TrajectoryDataset([make_scene(p, seed=i) for i, p in enumerate(sizes)], info)
    kept = apply_protocol(ds, "sgan")
    assert [s.scene_id for s in kept.scenes] == ["synthetic#1", "synthetic#3"]
    assert kept.num_agents == 7 and kept.info.protocol == "sgan"
    same = apply_protocol(ds, "all")
    assert len(same) == 4 and same.info.protocol == "all" and ds.info.protocol == "all"
    lonely = TrajectoryDataset([make_scene(1)], info)
    with pytest.raises(DataError, match="leaves nothing"):
        apply_protocol(lonely, "sgan")
    with pytest.raises(TrajprefError, match="unknown protocol 'trajnet'; choose one of all, sgan"):
        apply_protocol(ds, "trajnet")


def test_load_dataset_applies_the_protocol(tmp_path):
    rows = straight_rows(20)  # two agents over 20 frames
    rows += [(10 * f, 9, 0.0, 0.5 * f) for f in range(20, 40)]  # a lone agent afterwards
    write_tracks(tmp_path / "a.txt", rows)
    every = load_dataset(str(tmp_path), "test")
    sgan = load_dataset(str(tmp_path), "test", protocol="sgan")
    assert (len(every), every.num_agents) == (2, 3)
    assert (len(sgan), sgan.num_agents) == (1, 2)


@pytest.mark.realdata
def test_univ_has_crowded_scenes(data_root):
    sizes = [s.num_agents for s in load_dataset("univ", "test", data_root).scenes]
    assert max(sizes) >= 50


NBA_CLOCK = re.compile(r"_(\d+\.\d+)_(\d+\.\d+)\.txt$")
"""The end of an NBA rebound file's name: the game clock (seconds left in the quarter) at its
first and last row, e.g. ``LAL_ATL_0021500286_1_365.53_363.05.txt``."""


@pytest.mark.realdata
def test_nba_frame_interval_is_the_files_own_game_clock(data_root):
    # each file's name gives the game clock at its first and last row: the clock time per row
    # step is the data's step (0.12 s: the frame column counts hundredths of a second, rows
    # every 3rd SportVU moment at 25 Hz), not 12 frames at 25 Hz (0.48 s)
    step = SPECS["nba"].frame_interval
    for split in ("train", "test"):
        files = sorted((data_root / "nba" / "rebound" / split).glob("*.txt"))[::97]  # [~39, ~10]
        assert len(files) >= 9, split
        for path in files:
            start, end = map(float, NBA_CLOCK.search(path.name).groups())
            frames = np.unique(np.loadtxt(path, usecols=0))  # [rows]
            assert set(np.diff(frames)) == {12.0}, path.name
            per_step = (start - end) / (len(frames) - 1)  # game-clock seconds per row step
            assert per_step == pytest.approx(step, rel=0.05), path.name
            assert (frames[-1] - frames[0]) / 100 == pytest.approx(start - end, rel=0.05)
    nba = load_dataset("nba", "test", data_root)
    assert nba.info.frame_interval == step
    assert 1.5 < mean_speed(nba) < 2.5  # m/s, players and ball (about 1.81; 0.45 at 0.48 s)


@pytest.mark.realdata
def test_sdd_nba_robo(data_root):
    sdd = load_dataset("sdd", "test", data_root)
    assert sdd.num_agents == 2829 and sdd.info.units == "px"
    train, val = load_dataset("sdd", "train", data_root), load_dataset("sdd", "val", data_root)
    assert set(train.info.source) and len(train) + len(val) == 6097
    assert not {s.scene_id for s in train.scenes} & {s.scene_id for s in val.scenes}

    nba = load_dataset("nba", "val", data_root)
    assert all(s.num_agents == 11 for s in nba.scenes)
    assert all((s.agent_type == 1).sum() == 1 for s in nba.scenes)
    assert nba.info.units == "m" and nba.info.frame_interval == pytest.approx(0.12)
    # court is 94 x 50 feet; after conversion every position lies within ~ 29 x 15 m
    xy = np.concatenate([s.history for s in nba.scenes[:200]])
    assert xy[..., 0].max() < 110 * FEET_TO_METRES

    robo = load_dataset("robo", "test", data_root)
    assert robo.num_agents == 1734 and len(robo) == 578
    with pytest.raises(TrajprefError, match="robo-sim"):
        load_dataset("robo", "train", data_root)


def _sliding_windows(track: np.ndarray, name: str) -> list[Scene]:
    """Every 20-frame window of ``track`` [P, F, 2], one frame apart."""
    kinds = np.zeros(track.shape[0], np.int64)
    return [Scene(track[:, f : f + 8], track[:, f + 8 : f + 20], kinds, f"{name}{f}")
            for f in range(track.shape[1] - 19)]  # fmt: skip


def test_robo_episodes_split_where_windows_stop_overlapping():
    rng = np.random.default_rng(0)
    a = np.cumsum(rng.normal(size=(3, 24, 2)), axis=1)  # 5 windows
    b = np.cumsum(rng.normal(size=(3, 22, 2)), axis=1)  # 3 windows
    c = np.cumsum(rng.normal(size=(2, 21, 2)), axis=1)  # 2 windows, fewer agents
    scenes = _sliding_windows(a, "a") + _sliding_windows(b, "b") + _sliding_windows(c, "c")
    assert robo_episodes(scenes).tolist() == [0] * 5 + [1] * 3 + [2] * 2


@pytest.mark.realdata
def test_robo_mix_holds_out_whole_real_episodes(data_root):
    real = load_dataset("robo", "val", data_root)
    assert robo_episodes(real.scenes).max() + 1 == 19
    train = load_dataset("robo-mix", "train", data_root)
    val = load_dataset("robo-mix", "val", data_root)
    test = load_dataset("robo-mix", "test", data_root)
    assert len(test) == 578  # the official test split, untouched
    # 4 of 19 real episodes validate; the other 15 train, beside robo-sim's 10,000 episodes
    real_ids = {s.scene_id for s in real.scenes}
    val_ids = {s.scene_id for s in val.scenes}
    train_real = [s for s in train.scenes if s.scene_id in real_ids]
    assert val_ids <= real_ids and not val_ids & {s.scene_id for s in train_real}
    assert len(val) + len({s.scene_id for s in train_real}) == len(real)
    assert len(train) - len(train_real) == 10_000
    assert 0.25 < len(train_real) / len(train) < 0.4  # real repeated to about a third
    ids = [s.scene_id for s in real.scenes]
    episode = dict(zip(ids, robo_episodes(real.scenes).tolist(), strict=True))
    held = {episode[i] for i in val_ids}
    assert len(held) == 4 and not held & {episode[s.scene_id] for s in train_real}


def test_robo_sim_splits_are_seeded_and_distinct():
    a = load_dataset("robo-sim", "val")
    b = load_dataset("robo-sim", "val")
    test = load_dataset("robo-sim", "test")
    assert len(a) == 1000 and all(s.num_agents == 3 for s in a.scenes)
    assert a.info.frame_interval == 0.5 and a.info.units == "m"
    np.testing.assert_array_equal(a[0].history, b[0].history)
    assert not np.array_equal(a[0].history, test[0].history)


def test_npz_coordinates_beyond_the_bound_name_the_units(tmp_path):
    (tmp_path / "robo").mkdir()
    obs = np.zeros((3, 8, 2))
    obs[2, 7, 1] = -5e7
    np.savez(tmp_path / "robo" / "test.npz", obs_traj=obs, pred_traj=np.zeros((3, 12, 2)),
             seq_start_end=np.array([[0, 3]]))  # fmt: skip
    with pytest.raises(DataError, match=r"magnitude 5e\+07 m is beyond the sane bound of 1e\+06 m"):
        load_dataset("robo", "test", tmp_path)
    ok = load_dataset("robo", "test", tmp_path, options=ReadOptions(max_coord=1e8))
    assert ok.num_agents == 3
    obs[2, 7, 1] = 1e39
    np.savez(tmp_path / "robo" / "test.npz", obs_traj=obs, pred_traj=np.zeros((3, 12, 2)),
             seq_start_end=np.array([[0, 3]]))  # fmt: skip
    with pytest.raises(DataError, match="float32"):
        load_dataset("robo", "test", tmp_path)


def test_user_folder_options_reach_the_reader(tmp_path):
    rows = straight_rows(20)
    (tmp_path / "a.txt").write_text("".join("|".join(map(str, r)) + "\n" for r in rows))
    with pytest.raises(DataError, match="the line holds '|'"):
        load_dataset(str(tmp_path), "test")
    ds = load_dataset(str(tmp_path), "test", units="m", options=ReadOptions(delimiter="|"))
    assert ds.num_agents == 2
    with pytest.raises(DataError, match="beyond the sane bound of 1 m"):
        load_dataset(str(tmp_path), "test", units="m",
                     options=ReadOptions(delimiter="|", max_coord=1))  # fmt: skip


def test_user_folders_read_csv_files_too(tmp_path):
    rows = straight_rows(20)
    (tmp_path / "a.csv").write_text(
        "frame,agent,x,y\n" + "".join(",".join(map(str, r)) + "\n" for r in rows)
    )
    write_tracks(tmp_path / "b.txt", rows)
    ds = load_dataset(str(tmp_path), "test")
    assert [s.scene_id for s in ds.scenes] == ["a.csv@frame=0", "b.txt@frame=0"]
    np.testing.assert_array_equal(ds[0].future, ds[1].future)


def test_upper_case_suffixes_and_split_folders_are_read(tmp_path):
    # a.TXT, b.CSV and Train/ Val/ Test/ were passed over: "no *.txt or *.csv files"
    for split, n in (("Train", 25), ("Val", 21), ("Test", 22)):
        write_tracks(tmp_path / "d" / split / "a.TXT", straight_rows(n))
        write_tracks(tmp_path / "d" / split / "b.CSV", straight_rows(n))
    for split, windows in (("train", 12), ("val", 4), ("test", 6)):
        ds = load_dataset(str(tmp_path / "d"), split)
        assert len(ds) == windows and ds.info.source.endswith(split.capitalize())
        assert {s.scene_id.split("@")[0] for s in ds.scenes} == {"a.TXT", "b.CSV"}
    write_tracks(tmp_path / "two" / "train" / "a.txt", straight_rows(20))
    write_tracks(tmp_path / "two" / "Train" / "a.txt", straight_rows(20))
    with pytest.raises(DataError, match=r"both Train/ and train/ are there, and split folders "
                       "are matched ignoring case: keep one"):  # fmt: skip
        load_dataset(str(tmp_path / "two"), "train")


def test_a_folder_that_cannot_be_read_says_so(tmp_path, monkeypatch):
    from trajpref.data.text import folder_error

    # an unreadable folder was "no *.txt or *.csv files in folder": Path.glob hides the error
    message = str(folder_error(tmp_path, PermissionError(13, "Permission denied")))
    assert message == f"{tmp_path}: cannot read folder (Permission denied): check its permissions"
    write_tracks(tmp_path / "d" / "test" / "a.txt", straight_rows(20))
    locked = tmp_path / "d" / "test"
    listing = Path.iterdir

    def denied(self):
        if self == locked:
            raise PermissionError(13, "Permission denied", str(self))
        return listing(self)

    monkeypatch.setattr(Path, "iterdir", denied)  # as root, chmod does not deny reading
    with pytest.raises(DataError, match=r"test: cannot read folder \(Permission denied\)"):
        load_dataset(str(tmp_path / "d"), "test")


def test_a_folder_without_read_permission_says_so(tmp_path):
    write_tracks(tmp_path / "d" / "test" / "a.txt", straight_rows(20))
    locked = tmp_path / "d" / "test"
    locked.chmod(0)
    try:
        if os.access(locked, os.R_OK):  # root (os.geteuid() == 0) with its usual rights
            pytest.skip("this user reads a folder whatever its mode")
        with pytest.raises(DataError, match=r"test: cannot read folder \(Permission denied\)"):
            load_dataset(str(tmp_path / "d"), "test")
    finally:
        locked.chmod(0o755)


def test_a_looping_dataset_path_says_so(tmp_path):
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(DataError, match="symlink loop"):
        load_dataset(str(tmp_path / "loop"), "test")
    (tmp_path / "x.ndjson").symlink_to(tmp_path / "x.ndjson")
    with pytest.raises(DataError, match="symlink loop"):
        load_dataset(str(tmp_path / "x.ndjson"), "test")


def test_mean_speed_is_hand_computable():
    # agent 0 moves 1 unit per frame along x, agent 1 stands still: mean step 0.5 per 0.5 s
    track = np.stack([np.stack([np.arange(20.0), np.zeros(20)], 1), np.ones((20, 2))])
    track = track.astype(np.float32)  # [2, 20, 2]
    scene = Scene(track[:, :8], track[:, 8:], np.zeros(2, np.int64), "s")
    ds = TrajectoryDataset([scene, scene], DatasetInfo("x", "test", "m", 0.5))
    assert mean_speed(ds) == pytest.approx(1.0)


def _from(file: str, seed: int) -> Scene:
    s = make_scene(2, seed=seed)
    return Scene(s.history, s.future, s.agent_type, f"{file}@frame={10 * seed}")


def test_a_held_out_scene_leaves_training_and_is_the_whole_validation_split():
    info = DatasetInfo("fold", "train", "m", 0.4, source="fold/train")
    files = ("biwi_hotel", "students001", "students003", "crowds_zara02")
    train = TrajectoryDataset([_from(f"{f}_train.txt", i) for i, f in enumerate(files)], info)
    val = TrajectoryDataset([_from("biwi_hotel_val.txt", 4), _from("students001_val.txt", 5)],
                            dataclasses.replace(info, split="val", source="fold/val"))  # fmt: skip
    kept, held = hold_out_scene(train, val, "students")
    assert [s.scene_id for s in kept.scenes] == [
        "biwi_hotel_train.txt@frame=0", "crowds_zara02_train.txt@frame=30"]  # fmt: skip
    # the scene's training windows and its validation windows; the other scenes' val is dropped
    assert [s.scene_id for s in held.scenes] == [
        "students001_train.txt@frame=10", "students003_train.txt@frame=20",
        "students001_val.txt@frame=50"]  # fmt: skip
    assert held.info.split == "val" and "held-out scene students" in held.info.source
    with pytest.raises(ConfigError, match="no training file of fold starts with 'eth'.*biwi_hotel"):
        hold_out_scene(train, val, "eth")
    with pytest.raises(ConfigError, match="leaves fold no training file"):
        hold_out_scene(TrajectoryDataset(train.scenes[1:3], info), val, "students")
    with pytest.raises(ConfigError, match="holdout_scene and val_dataset exclude each other"):
        DataConfig(holdout_scene="students", val_dataset="robo")


def _window(file: str, frame: int) -> Scene:
    s = make_scene(1, seed=frame)  # T_h + T_f = 20 steps
    return Scene(s.history, s.future, s.agent_type, f"{file}@frame={frame}")


def test_validation_cut_in_time_keeps_no_shared_frame():
    info = DatasetInfo("fold", "val", "m", 0.4, source="fold/val")
    # file a: 50 windows every 10 frames; file b: 4 windows, listed out of order
    val = TrajectoryDataset([_window("a_val.txt", 10 * i) for i in range(50)]
                            + [_window("b_val.txt", f) for f in (30, 0, 20, 10)], info)  # fmt: skip
    train = TrajectoryDataset([_window("a_train.txt", 0)], dataclasses.replace(info, split="train"))
    more, late = split_validation_in_time(train, val, 0.5, to_train=True)
    # a: the first 25 windows (frames 0..240) train; the last of them ends at frame 240 + 19 * 10
    # = 430, so validation starts at 440; b: 0 and 10 train, 20 and 30 overlap them: dropped
    assert [s.scene_id for s in more.scenes[1:]] == (
        [f"a_val.txt@frame={10 * i}" for i in range(25)]
        + ["b_val.txt@frame=0", "b_val.txt@frame=10"]
    )
    assert [s.scene_id for s in late.scenes] == [
        f"a_val.txt@frame={f}" for f in range(440, 500, 10)
    ]
    assert "after its first 50% in time" in late.info.source
    same, late2 = split_validation_in_time(train, val, 0.5, to_train=False)
    assert same.scenes == train.scenes and late2.scenes == late.scenes  # the control's own split
    with pytest.raises(ConfigError, match="leaves none to validate on"):
        split_validation_in_time(train, TrajectoryDataset(val.scenes[50:], info), 0.5, True)
    with pytest.raises(ConfigError, match="must be in"):
        split_validation_in_time(train, val, 1.0, True)
    robo = TrajectoryDataset([Scene(s.history, s.future, s.agent_type, "robo-sim#0:1")
                              for s in val.scenes[:2]], info)  # fmt: skip
    with pytest.raises(ConfigError, match="text track files"):
        split_validation_in_time(train, robo, 0.5, True)
    with pytest.raises(ConfigError, match="val_cut_to_train needs val_cut"):
        DataConfig(val_cut_to_train=True)
    with pytest.raises(ConfigError, match="val_cut and holdout_scene exclude each other"):
        DataConfig(val_cut=0.5, holdout_scene="students")


@pytest.mark.realdata
def test_holding_out_hotel_in_the_zara1_fold(data_root):
    train = load_dataset("zara1", "train", data_root)
    val = load_dataset("zara1", "val", data_root)
    kept, held = hold_out_scene(train, val, "biwi_hotel")
    files = {s.scene_id.split("@")[0] for s in held.scenes}
    assert files == {"biwi_hotel_train.txt", "biwi_hotel_val.txt"}
    assert len(kept) + sum(f.startswith("biwi_hotel_train") for f in
                           (s.scene_id for s in held.scenes)) == len(train)  # fmt: skip
    assert not any(s.scene_id.startswith("biwi_hotel") for s in kept.scenes)


def test_time_step_scales_the_frame_interval_and_refuses_cut_windows(tmp_path, data_root):
    write_tracks(tmp_path / "a.txt", [(f * 10, 1, f * 0.3, 0) for f in range(80)])
    ds = load_dataset(str(tmp_path), "test", frame_interval=0.1,
                      options=ReadOptions(time_step=4))  # fmt: skip
    assert ds.info.frame_interval == pytest.approx(0.4)
    for name in ("sdd", "robo-sim"):
        with pytest.raises(ConfigError, match="time_step"):
            load_dataset(name, "val", data_root, options=ReadOptions(time_step=2))
    # eth's validation read as if annotated every 5/3 steps: fewer, longer-lived windows
    plain = load_dataset("eth", "val", data_root)
    slow = load_dataset("eth", "val", data_root, options=ReadOptions(time_step=5 / 3))
    assert 0 < slow.num_agents < plain.num_agents
    assert slow.info.frame_interval == pytest.approx(0.4 * 5 / 3)


def test_a_paced_copy_joins_training_without_the_held_out_scene():
    info = DatasetInfo("fold", "train", "m", 0.4, source="fold/train")
    train = TrajectoryDataset([_from("biwi_hotel_train.txt", 0), _from("students001_train.txt", 1)],
                              info)  # fmt: skip
    slow = dataclasses.replace(info, frame_interval=0.4 * 5 / 3)
    paced = TrajectoryDataset([_from("biwi_hotel_train.txt", 2), _from("students001_train.txt", 3)],
                              slow)  # fmt: skip
    both = with_paced_copy(train, paced)
    assert [s.scene_id for s in both.scenes] == [s.scene_id for s in train.scenes + paced.scenes]
    assert both.info.frame_interval == 0.4 and "1.66667x its step (2 windows)" in both.info.source
    kept = with_paced_copy(train, paced, exclude="students")
    assert [s.scene_id for s in kept.scenes[2:]] == ["biwi_hotel_train.txt@frame=20"]
    with pytest.raises(ConfigError, match="no window at the extra time step"):
        with_paced_copy(train, TrajectoryDataset([], slow))
    with pytest.raises(ConfigError, match="cannot come from fold/val"):
        with_paced_copy(
            train, TrajectoryDataset(paced.scenes, dataclasses.replace(slow, split="val"))
        )
    with pytest.raises(ConfigError, match="extra_time_step must be 0 .off. or a positive step"):
        DataConfig(extra_time_step=1.0)
    with pytest.raises(ConfigError, match="extra_time_step"):
        DataConfig(extra_time_step=-0.5)


def test_run_splits_hold_out_then_add_the_paced_copy_without_the_held_out_scene(tmp_path):
    from synthetic import write_dataset

    root = str(write_dataset(tmp_path / "long", frames=44))  # windows at step 2 too
    plain_train, plain_val = run_splits(DataConfig(dataset=root))
    assert [s.scene_id for s in plain_train.scenes] == [
        s.scene_id for s in load_dataset(root, "train").scenes]  # fmt: skip
    assert plain_val.num_agents == load_dataset(root, "val").num_agents
    train, val = run_splits(DataConfig(dataset=root, holdout_scene="walk2", extra_time_step=2.0))
    held, held_val = hold_out_scene(load_dataset(root, "train"), load_dataset(root, "val"), "walk2")
    paced = load_dataset(root, "train", options=ReadOptions(time_step=2.0))
    extra = [s for s in paced.scenes if not s.scene_id.startswith("walk2")]
    assert 0 < len(extra) < len(paced.scenes)
    assert [s.scene_id for s in train.scenes] == [s.scene_id for s in held.scenes + extra]
    assert [s.scene_id for s in val.scenes] == [s.scene_id for s in held_val.scenes]


def test_partial_future_applies_to_the_training_split_alone(tmp_path, data_root):
    from synthetic import write_dataset

    root = str(write_dataset(tmp_path / "pf", frames=44))
    plain_train, plain_val = run_splits(DataConfig(dataset=root))
    train, val = run_splits(DataConfig(dataset=root, partial_future=4))
    assert [s.scene_id for s in val.scenes] == [s.scene_id for s in plain_val.scenes]
    assert train.num_agents >= plain_train.num_agents
    # zara1's training files: agents that leave the view after at least 4 future frames
    # join the targets (counted 2026-12-04), its validation split is untouched
    z_plain, z_val_plain = run_splits(DataConfig(dataset="zara1"), data_root)
    z_train, z_val = run_splits(DataConfig(dataset="zara1", partial_future=4), data_root)
    assert (z_plain.num_agents, z_train.num_agents) == (28577, 38146)
    assert z_val.num_agents == z_val_plain.num_agents == 5184
    for name in ("sdd", "robo-sim"):
        with pytest.raises(ConfigError, match="partial_future cuts windows from text track"):
            load_dataset(name, "train", data_root, options=ReadOptions(partial_future=4))
    with pytest.raises(ConfigError, match="partial_future and reverse exclude each other"):
        DataConfig(partial_future=4, reverse=True)
    for bad in (-1, True):
        with pytest.raises(ConfigError, match="partial_future must be an integer"):
            DataConfig(partial_future=bad)


def test_reversed_context_is_read_for_the_training_split_of_a_run_that_trains_with_it(tmp_path):
    from synthetic import write_tracks

    # agent 1 the target over frames 0..19; agent 3 (2..19) and 5 (12..15) only context
    rows = [(f * 10, 1, f, 0) for f in range(20)]
    rows += [(f * 10, 3, f, 2) for f in range(2, 20)] + [(f * 10, 5, f, 5) for f in range(12, 16)]
    for split in ("train", "val"):
        write_tracks(tmp_path / "d" / split / "a.txt", rows)
    root = str(tmp_path / "d")
    train, val = run_splits(DataConfig(dataset=root, reverse=True))
    assert train.scenes[0].context_reverse is None  # off: no memory spent on them
    train, val = run_splits(DataConfig(dataset=root, reverse=True, reverse_context=True))
    assert len(train.scenes[0].context_reverse) == 2 and val.scenes[0].context_reverse is None


def _timed(folder: Path, step: float, count: int = 40, header: str = "timestamp,id,x,y",
           name: str = "log.csv") -> None:  # fmt: skip
    folder.mkdir(parents=True, exist_ok=True)
    rows = "".join(f"{round(100 + k * step, 6)},{a},{0.1 * k:.3f},{a}\n"
                   for k in range(count) for a in (1, 2))  # fmt: skip
    (folder / name).write_text(f"{header}\n{rows}")


def test_a_time_column_in_seconds_gives_the_frame_interval_unless_one_is_given(tmp_path):
    # 10 Hz files whose frame column is headed timestamp: 0.1 s between frames, not the 0.4 s
    # default, so data stats, a model's step check and TrajNet++ output read the right pace
    _timed(tmp_path / "ts", 0.1, count=100)
    info = load_dataset(str(tmp_path / "ts"), "test").info
    assert (info.frame_interval, info.interval_from, info.time_step) == (0.1, "timestamps", 1.0)
    info = load_dataset(str(tmp_path / "ts"), "test", options=ReadOptions(time_step=4)).info
    assert info.frame_interval == pytest.approx(0.4) and info.time_step == 4
    info = load_dataset(str(tmp_path / "ts"), "test", frame_interval=0.2).info
    assert (info.frame_interval, info.interval_from) == (0.2, "given")
    # frame numbers (a frame header, or none) keep the assumed default, and say so
    _timed(tmp_path / "fr", 1, header="frame,agent,x,y")
    info = load_dataset(str(tmp_path / "fr"), "test").info
    assert (info.frame_interval, info.interval_from, info.text_tracks) == (0.4, "default", True)


@pytest.mark.parametrize("case, match", [
    ("ms", r"steps 100, which is no plausible number of seconds between frames "
           r"\(milliseconds\? nanoseconds\? as milliseconds that is 0\.1 s, "
           r"--frame-interval 0\.1\)"),
    # 30 fps in milliseconds: 33 is no number of seconds between frames either
    ("ms30", r"steps 33, which is no plausible number of seconds between frames "
             r"\(milliseconds\? nanoseconds\? as milliseconds that is 0\.033 s, "
             r"--frame-interval 0\.033\)"),
    ("ns", r"steps 1e\+08, which is no plausible number of seconds between frames "
           r"\(milliseconds\? nanoseconds\?\)"),
    ("mixed", r"the files' time columns step differently \(0\.1 in a\.csv, 0\.4 in b\.csv\)"),
    ("untimed", r"a\.csv's frame column is a time in seconds, b\.csv's is not"),
])  # fmt: skip
def test_time_columns_that_give_no_one_interval_keep_the_default_and_say_so(tmp_path, case,
                                                                           match):  # fmt: skip
    from trajpref.data import FrameRateWarning

    folder = tmp_path / case
    if case in ("ms", "ms30", "ns"):
        _timed(folder, {"ms": 100, "ms30": 33, "ns": 1e8}[case], header="time,id,x,y")
    else:
        _timed(folder, 0.1, name="a.csv")
        _timed(folder, 0.4, name="b.csv", header="timestamp,id,x,y" if case == "mixed"
               else "frame,id,x,y")  # fmt: skip
    with pytest.warns(FrameRateWarning, match=match + r": 0\.4 s between frames is assumed; "
                      r"pass the files' own with --frame-interval"):  # fmt: skip
        info = load_dataset(str(folder), "test").info
    assert (info.frame_interval, info.interval_from) == (0.4, "default")


def test_run_splits_read_a_folder_at_the_data_configs_interval_and_units(tmp_path):
    for split in ("train", "val"):
        _timed(tmp_path / "d" / split, 1, header="frame,agent,x,y")
    data = DataConfig(dataset=str(tmp_path / "d"), frame_interval=0.1, units="m", time_step=2)
    train, val = run_splits(data)
    for info in (train.info, val.info):
        assert (info.frame_interval, info.interval_from, info.units) == (0.2, "given", "m")
    # a built-in dataset knows its own: describing it is refused
    with pytest.raises(ConfigError, match=r"DataConfig\.frame_interval describes a folder "
                       r"dataset; zara1 is a built-in one and knows its own units and frame "
                       r"interval: leave it unset"):  # fmt: skip
        DataConfig(dataset="zara1", frame_interval=0.1)
    with pytest.raises(ConfigError, match=r"DataConfig\.frame_interval must be a number of "
                       r"seconds > 0 or null"):  # fmt: skip
        DataConfig(dataset=str(tmp_path / "d"), frame_interval=0)
    with pytest.raises(ConfigError, match=r"DataConfig\.units must be a unit name"):
        DataConfig(dataset=str(tmp_path / "d"), units="")


def test_holding_out_a_scene_of_a_folder_without_splits_validates_each_window_once(tmp_path):
    from synthetic import write_dataset

    root = write_dataset(tmp_path / "d", frames=30)
    flat = tmp_path / "flat"
    flat.mkdir()
    for f in (root / "train").iterdir():  # one folder, read as every split
        (flat / f.name).write_bytes(f.read_bytes())
    train, val = run_splits(DataConfig(dataset=str(flat), holdout_scene="walk1"))
    whole = load_dataset(str(flat), "train")
    held = [s.scene_id for s in whole.scenes if s.scene_id.startswith("walk1")]
    assert [s.scene_id for s in val.scenes] == held  # once, not twice
    assert len(train) + len(val) == len(whole)
    # with split folders the held-out scene's validation windows join its training ones
    _, val = run_splits(DataConfig(dataset=str(root), holdout_scene="walk0"))
    own = load_dataset(str(root), "train").scenes + load_dataset(str(root), "val").scenes
    assert len(val) == sum(s.scene_id.startswith("walk0") for s in own) > len(held)


def test_sgan_is_refused_for_built_in_datasets_other_than_the_eth_ucy_folds():
    """--protocol sgan on SDD silently evaluated 1,478 of its 2,829 test agents."""
    from trajpref.data.registry import NAMES, check_protocol_for

    for name in NAMES:
        check_protocol_for(name, "all")
        if name in ETH_UCY:
            check_protocol_for(name, "sgan")
        else:
            with pytest.raises(ConfigError, match=r"^--protocol sgan is Social-GAN's ETH/UCY "
                               r"counting .* the SDD and NBA peers count every agent .*"
                               rf"use --protocol all \(the default\) for {name} "):  # fmt: skip
                check_protocol_for(name, "sgan")
    check_protocol_for("/some/own/folder", "sgan")  # one's own data: either protocol
    with pytest.raises(TrajprefError, match="unknown protocol"):
        check_protocol_for("eth", "SGAN")


# walkthrough 62 (a contributor), items 3 and 4: a built-in name without its SPECS entry or its
# branch is an error, never another dataset's data


def test_names_specs_and_the_branches_agree():
    from trajpref.data import registry

    assert set(registry.NAMES) == set(registry.SPECS) == set(registry.BRANCHES)
    assert set(registry.SGAN_TEST_FILES) == set(ETH_UCY)
    listed = registry.__doc__.split("BUILTIN_DATASETS``: ``", 1)[1].split("``")[0].split()
    assert listed == list(registry.NAMES)


def test_every_built_in_name_reaches_its_own_branch(tmp_path, monkeypatch):
    from trajpref.data import registry

    seen = []
    empty = ([], tmp_path)

    def reader(tag):
        def read(*args, **_):
            seen.append(tag(args))
            return empty

        return read

    monkeypatch.setattr(registry, "_sdd", reader(lambda a: "sdd"))
    monkeypatch.setattr(registry, "_nba", reader(lambda a: "nba"))
    monkeypatch.setattr(registry, "_robo", reader(lambda a: "robo"))
    monkeypatch.setattr(registry, "_robo_sim", lambda split: seen.append("robo-sim") or "sim")
    monkeypatch.setattr(registry, "_robo_mix", lambda *a: seen.append("robo-mix") or "mix")
    monkeypatch.setattr(registry.text, "read_folder",
                        lambda folder, *a, **k: seen.append(folder.parent.name) or [])  # fmt: skip
    for name in registry.NAMES:
        registry._built_in(name, "test", tmp_path, ReadOptions())
        assert seen.pop() == name


def test_a_built_in_name_without_specs_or_branch_is_a_clear_error(tmp_path, monkeypatch):
    from trajpref.data import registry

    monkeypatch.setattr(registry, "NAMES", (*registry.NAMES, "zara1b"))  # BUILTIN_DATASETS only
    no_specs = (r"^built-in dataset 'zara1b' \(config\.BUILTIN_DATASETS\) has no entry in "
                r"data\.registry\.SPECS \(its units and frame interval\); the datasets with "
                r"one: eth, hotel, univ, ")  # fmt: skip
    with pytest.raises(TrajprefError, match=no_specs):
        load_dataset("zara1b", "test", tmp_path)
    monkeypatch.setitem(registry.SPECS, "zara1b", registry.SPECS["zara1"])  # no branch yet
    (tmp_path / "robo").mkdir()  # what the robo branch would have read
    no_branch = (r"^built-in dataset 'zara1b' has no branch in data\.registry\._built_in "
                 r"that reads it; the datasets it reads: eth, ")  # fmt: skip
    with pytest.raises(TrajprefError, match=no_branch):
        load_dataset("zara1b", "test", tmp_path)


def test_sgan_folds_finds_a_folds_test_files_by_name(tmp_path):
    from trajpref.data.registry import sgan_folds

    rows = straight_rows(24)
    write_tracks(tmp_path / "a" / "test" / "crowds_zara01.txt", rows)
    write_tracks(tmp_path / "a" / "train" / "crowds_zara02_train.txt", rows)  # not a test file
    write_tracks(tmp_path / "b" / "Students001.TXT", rows)  # no split folders, any case
    write_tracks(tmp_path / "c" / "uni_examples.txt", rows)  # every fold trains on it
    write_tracks(tmp_path / "d" / "biwi_eth.txt", rows)
    write_tracks(tmp_path / "d" / "biwi_hotel.txt", rows)
    assert sgan_folds(tmp_path / "a") == ("zara1",)
    assert sgan_folds(tmp_path / "b") == ("univ",)
    assert sgan_folds(tmp_path / "c") == ()
    assert sgan_folds(tmp_path / "d") == ("eth", "hotel")
    assert sgan_folds(tmp_path / "missing") == () and sgan_folds("zara1") == ()


# A built-in dataset of text tracks takes what a folder of its files takes (the library
# extension walkthrough: a contributor's ``mall``, built in, lost ``data.partial_future`` and
# ``--protocol sgan``, which were keyed on ETH/UCY membership), while every built-in dataset
# of today refuses what it refused before.


NEW = "mall"


@pytest.fixture
def mall_root(tmp_path, monkeypatch) -> Path:
    """A data root with ``mall/<split>/*.csv`` and ``mall`` registered as docs/data.md's
    "Adding a built-in dataset" says: its name, its SPECS entry of text tracks, its branch
    (reading CSV files as a user folder does, ``pattern=USER_TEXT``)."""
    root = tmp_path / "root"
    write_dataset(root / NEW, frames=44)
    for path in sorted((root / NEW).rglob("*.txt")):
        path.rename(path.with_suffix(".csv"))
    monkeypatch.setattr(registry, "NAMES", (*registry.NAMES, NEW))
    monkeypatch.setattr(registry, "BRANCHES", (*registry.BRANCHES, NEW))
    monkeypatch.setitem(registry.SPECS, NEW, registry.SourceSpec("m", 0.4, text_tracks=True))
    built_in = registry._built_in

    def branch(name, split, root_, options):
        if name != NEW:
            return built_in(name, split, root_, options)
        spec = registry.SPECS[name]
        folder = registry.resolve_data_root(root_) / NEW / split
        scenes = text.read_folder(folder, pattern=registry.USER_TEXT, options=options,
                                  units=spec.units)  # fmt: skip
        info = DatasetInfo(name, split, spec.units, spec.frame_interval, options.t_hist,
                           options.t_fut, str(folder))  # fmt: skip
        return TrajectoryDataset(scenes, info)

    monkeypatch.setattr(registry, "_built_in", branch)
    return root


def test_a_built_in_text_track_dataset_takes_its_folders_options(mall_root):
    plain = load_dataset(NEW, "train", mall_root)
    assert plain.info.text_tracks  # from its SPECS entry, not a tuple of names in _load
    partial = load_dataset(NEW, "train", mall_root, options=ReadOptions(partial_future=4))
    assert partial.num_agents >= plain.num_agents
    registry.check_protocol_for(NEW, "sgan")
    assert load_dataset(NEW, "test", mall_root, protocol="sgan").info.protocol == "sgan"
    paced = load_dataset(NEW, "train", mall_root, options=ReadOptions(time_step=2))
    assert paced.info.frame_interval == pytest.approx(0.8)


def test_sgans_refusal_names_the_datasets_that_take_it(mall_root):
    with pytest.raises(ConfigError, match=rf"ETH/UCY folds \({', '.join(ETH_UCY)}\) and "
                       rf"{NEW} only"):  # fmt: skip
        registry.check_protocol_for("sdd", "sgan")


def test_a_text_track_dataset_can_keep_the_folder_options_out(monkeypatch):
    """NBA's case: text tracks (``text_tracks``), its own benchmark's counting."""
    monkeypatch.setattr(registry, "NAMES", (*registry.NAMES, NEW))
    spec = registry.SourceSpec("m", 0.4, text_tracks=True, folder_options=False)
    monkeypatch.setitem(registry.SPECS, NEW, spec)
    with pytest.raises(ConfigError, match=r"for the ETH/UCY folds .* only"):
        registry.check_protocol_for(NEW, "sgan")
    with pytest.raises(ConfigError, match=r"partial_future cuts windows .* SPECS entry"):
        load_dataset(NEW, "train", "/nowhere", options=ReadOptions(partial_future=4))


def test_todays_built_ins_refuse_what_they_refused():
    specs = registry.SPECS
    assert {n for n in registry.NAMES if specs[n].text_tracks} == {*ETH_UCY, "nba"}
    assert {n for n in registry.NAMES if specs[n].takes_folder_options} == set(ETH_UCY)
    for name in ("sdd", "nba", "robo", "robo-sim", "robo-mix"):
        with pytest.raises(ConfigError, match="partial_future cuts windows from text track"):
            load_dataset(name, "train", "/nowhere", options=ReadOptions(partial_future=4))
        with pytest.raises(ConfigError, match=r"--protocol sgan is Social-GAN's ETH/UCY"):
            registry.check_protocol_for(name, "sgan")
    for name in ("sdd", "robo", "robo-sim", "robo-mix"):
        with pytest.raises(ConfigError, match="time_step resamples text track files"):
            load_dataset(name, "train", "/nowhere", options=ReadOptions(time_step=2))


# The installed user's walkthrough (67): a shipped config written out as a YAML file to edit
# (``config show --yaml``), where a built-in dataset lies under an empty data root, the
# fine-tuning presets offered by the CLI, and the question on milliseconds in the CLI's advice
# on a frame interval above 10 s.


README = Path(__file__).resolve().parents[2] / "README.md"


DATA_SECTION = "Data: where each dataset comes from"


ROOT_DATASETS = ["eth", "hotel", "univ", "zara1", "zara2", "sdd", "nba", "robo", "robo-mix"]


LAYOUT = {"sdd": "sdd/{train,test}.npz", "nba": "nba/rebound/{train,test}/*.txt",
          "robo": "robo/{val,test}.npz", "robo-mix": "robo/{val,test}.npz"}  # fmt: skip


@pytest.mark.parametrize("name", ROOT_DATASETS)
def test_a_built_in_dataset_missing_under_the_root_says_where_it_lies(name, tmp_path):
    layout = LAYOUT.get(name, f"eth_ucy/{name}/{{train,val,test}}/*.txt")
    with pytest.raises(DataError) as caught:
        load_dataset(name, "test", tmp_path)
    message = str(caught.value)
    assert re.search(r": no such (folder|file); ", message), message
    assert f"{name} is read from {layout} under the data root ({tmp_path};" in message
    assert f'"{DATA_SECTION}"' in message
    assert "\n" not in message


def test_the_readme_has_the_section_the_error_names():
    assert f"## {DATA_SECTION}\n" in README.read_text()


def test_a_users_missing_folder_keeps_its_message(tmp_path, capsys):
    missing = tmp_path / "nope"
    with pytest.raises(DataError) as caught:
        load_dataset(str(missing), "test")
    assert str(caught.value) == f"{missing}: no such folder"
