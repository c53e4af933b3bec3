"""A built-in dataset of text tracks takes what a folder of its files takes (the library
extension walkthrough: a contributor's ``mall``, built in, lost ``data.partial_future`` and
``--protocol sgan``, which were keyed on ETH/UCY membership), while every built-in dataset
of today refuses what it refused before."""

from __future__ import annotations

from pathlib import Path

import pytest
from synthetic import write_dataset

from trajpref.data import ETH_UCY, ReadOptions, load_dataset, registry, text
from trajpref.errors import ConfigError
from trajpref.types import DatasetInfo, TrajectoryDataset

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
        scenes = text.read_folder(folder, spec.t_hist, spec.t_fut, pattern=registry.USER_TEXT,
                                  options=options, units=spec.units)  # fmt: skip
        info = DatasetInfo(name, split, spec.units, spec.frame_interval, spec.t_hist,
                           spec.t_fut, str(folder))  # fmt: skip
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
