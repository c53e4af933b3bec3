"""Windows of other lengths than the published models' 8 + 12 frames (``ReadOptions.t_hist``,
``ReadOptions.t_fut``): cut from text track files, refused where the windows come already
cut."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import write_tracks

from trajpref.data import ReadOptions, load_dataset
from trajpref.errors import ConfigError, DataError
from trajpref.types import WINDOW


def _folder(tmp_path, frames: int = 40, agents: int = 2):
    """One test file of ``agents`` agents seen in every one of ``frames`` frames; agent a's
    position at frame f is (f, 100 a + f / 10), so each row says where it came from."""
    rows = [(f * 10, a + 1, float(f), 100.0 * a + f / 10) for f in range(frames)
            for a in range(agents)]  # fmt: skip
    write_tracks(tmp_path / "ds" / "test" / "walk.txt", rows)
    return tmp_path / "ds"


def test_a_folder_is_cut_into_windows_of_the_lengths_asked_for(tmp_path):
    folder = _folder(tmp_path)
    ds = load_dataset(str(folder), "test", options=ReadOptions(t_hist=6, t_fut=16))
    assert (ds.info.t_hist, ds.info.t_fut) == (6, 16)
    assert len(ds) == 40 - 22 + 1  # one window per start frame, stride 1
    first, last = ds.scenes[0], ds.scenes[-1]
    assert first.history.shape == (2, 6, 2) and first.future.shape == (2, 16, 2)
    # agent 1 (the second) over frames 0-5, then 6-21; the last window starts at frame 18
    np.testing.assert_allclose(first.history[1, :, 0], np.arange(6))
    np.testing.assert_allclose(first.future[1, :, 1], 100 + np.arange(6, 22) / 10, rtol=1e-6)
    np.testing.assert_allclose(last.future[0, -1], [39.0, 3.9], rtol=1e-6)


def test_without_options_the_windows_are_the_published_models_lengths(tmp_path):
    ds = load_dataset(str(_folder(tmp_path)), "test")
    assert (ds.info.t_hist, ds.info.t_fut) == WINDOW == (8, 12)
    assert len(ds) == 40 - 20 + 1
    assert ds.scenes[0].future.shape == (2, 12, 2)


def test_windows_longer_than_the_files_are_a_data_error_naming_both(tmp_path):
    folder = _folder(tmp_path, frames=24)
    with pytest.raises(DataError, match=r"24 unique frames, a window needs 30 \(10 observed \+ "
                       r"20 future\)"):  # fmt: skip
        load_dataset(str(folder), "test", options=ReadOptions(t_hist=10, t_fut=20))


@pytest.mark.parametrize("name", ["sdd", "robo", "robo-sim", "robo-mix"])
def test_datasets_whose_windows_come_already_cut_refuse_other_lengths(name, tmp_path):
    # refused before any file is read: the data root may be empty
    with pytest.raises(ConfigError, match=rf"{name} comes as windows already cut .* at 8 "
                       r"observed \+ 12 future frames; windows of 8 \+ 20 \(the lengths asked, "
                       "or a model's own\\) are cut from text track files alone"):  # fmt: skip
        load_dataset(name, "test", tmp_path, options=ReadOptions(t_fut=20))


@pytest.mark.parametrize(("key", "value"), [("t_hist", 1), ("t_hist", 0), ("t_fut", 0),
                                            ("t_fut", 2.5), ("t_hist", True)])  # fmt: skip
def test_bad_lengths_are_a_config_error(key, value):
    with pytest.raises(ConfigError, match=rf"{key} must be an integer >= "):
        ReadOptions(**{key: value})


def test_an_eth_ucy_fold_can_be_read_at_a_longer_horizon(data_root):
    options = ReadOptions(t_fut=20)
    long = load_dataset("zara1", "test", data_root, options=options)
    usual = load_dataset("zara1", "test", data_root)
    assert (long.info.t_hist, long.info.t_fut) == (8, 20)
    assert long.scenes[0].future.shape[1] == 20
    assert 0 < long.num_agents < usual.num_agents  # fewer agents stay 28 frames in view


def test_lengths_given_twice_to_a_reader_must_agree(tmp_path):
    """``read_folder(folder, 8, 12, options=ReadOptions(t_hist=6, ...))`` cut 8 + 12 while a
    caller recorded 6 + 16 (the "Adding a built-in dataset" recipe passed its spec's)."""
    from trajpref.data.text import read_folder

    folder = _folder(tmp_path) / "test"
    with pytest.raises(ConfigError, match=r"windows of 8 \+ 12 frames asked, but the "
                       r"ReadOptions ask 6 \+ 16: give the lengths once"):  # fmt: skip
        read_folder(folder, 8, 12, options=ReadOptions(t_hist=6, t_fut=16))
    scenes = read_folder(folder, options=ReadOptions(t_hist=6, t_fut=16))
    assert scenes[0].future.shape == (2, 16, 2)
    assert read_folder(folder, 6, 16)[0].future.shape == (2, 16, 2)  # no options: as given


def test_a_paced_copy_of_other_lengths_is_refused(tmp_path):
    from trajpref.data.registry import with_paced_copy

    folder = str(_folder(tmp_path))
    train = load_dataset(folder, "test", options=ReadOptions(t_hist=6, t_fut=16))
    usual = load_dataset(folder, "test", options=ReadOptions(time_step=2))  # 8 + 12
    with pytest.raises(ConfigError, match=r"must be cut into its windows of 6 \+ 16 frames, "
                       r"not 8 \+ 12"):  # fmt: skip
        with_paced_copy(train, usual)
    paced = load_dataset(folder, "test", options=ReadOptions(time_step=1.5, t_hist=6, t_fut=16))
    both = with_paced_copy(train, paced)
    assert {s.future.shape[1] for s in both.scenes} == {16}
