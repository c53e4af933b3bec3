"""The planning calls warn when a model (or scorer) trained with the ball flagged (nba) is given
no agent types: every agent is then read as a person, the ball included, with no error. Models
trained without types (zara1, a folder of walks) stay silent."""

import warnings

import numpy as np
import pytest
from helpers import _messages

from trajpref.data import load_dataset
from trajpref.models.registry import load_predictor
from trajpref.score import TrajectoryScorer, predict_scene, predict_scenes, rank_samples
from trajpref.score.scorer import reads_agent_types
from trajpref.score.selection import SelectionConfig, select_for_scene

UNTYPED = "no agent_type given, so every agent is taken as a person"


@pytest.fixture(scope="module")
def model(tiny_run):
    return load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")


@pytest.fixture(scope="module")
def scorer(tiny_run):
    return TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors").with_steps([0])


@pytest.fixture(scope="module")
def scene(walks):
    return load_dataset(str(walks), "test").scenes[0]


def _as_nba(monkeypatch, obj) -> None:
    """``obj`` as if its checkpoint said it trained on nba (the ball flagged)."""
    monkeypatch.setattr(obj, "timing", {**obj.timing, "trained_on": "nba", "agent_types": [0, 1]})


def _calls(model, scorer, history, types=None):
    samples = predict_scene(model, history, 4, types)
    rank_samples(scorer, history, samples, types)
    select_for_scene(scorer, history, samples, SelectionConfig(keep=2), types)
    predict_scenes(model, [history], 4, None if types is None else [types])


def test_a_typed_model_given_no_types_says_so_each_call(monkeypatch, model, scorer, scene):
    _as_nba(monkeypatch, model)
    _as_nba(monkeypatch, scorer)
    got = [m for m in _messages(lambda: _calls(model, scorer, scene.history)) if "person" in m]
    assert len(got) == 4, got
    assert got[0].startswith(f"predict_scene: {UNTYPED}")
    assert "trained on nba with the ball flagged (agent_type 1)" in got[0]
    assert "pass agent_type=[P] integers, 1 for the ball, 0 for a player" in got[0]
    assert got[1].startswith(f"rank_samples: {UNTYPED}") and "its scores change" in got[1]
    assert got[2].startswith(f"select_for_scene: {UNTYPED}")
    assert got[3].startswith("predict_scenes: no agent_types given")
    assert "agent_types=[one [P] integer array per scene]" in got[3]
    free = SelectionConfig(keep=2, method="facility")  # reads no score: the types change nothing
    samples = predict_scene(model, scene.history, 4, np.zeros(len(scene.history), np.int64))
    assert not _messages(lambda: select_for_scene(scorer, scene.history, samples, free))
    types = np.zeros(len(scene.history), np.int64)
    given = _messages(lambda: _calls(model, scorer, scene.history, types))
    assert not [m for m in given if "person" in m], given


def test_the_warning_points_at_the_callers_line_once(monkeypatch, model, scene):
    _as_nba(monkeypatch, model)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")  # Python's own rule: once per place in the code
        for _ in range(3):
            predict_scene(model, scene.history, 4)
    mine = [w for w in caught if UNTYPED in str(w.message)]
    assert len(mine) == 1 and mine[0].filename == __file__


def test_models_without_types_stay_silent(model, scorer, scene):
    assert not reads_agent_types(model) and not reads_agent_types(scorer)
    assert not [m for m in _messages(lambda: _calls(model, scorer, scene.history)) if
                "person" in m]  # fmt: skip


def test_the_published_models_say_whether_they_read_types():
    nba = load_predictor("nba/generator", device="cpu")
    assert reads_agent_types(nba)
    assert reads_agent_types(TrajectoryScorer.from_checkpoint("nba/denoiser"))
    assert not reads_agent_types(load_predictor("zara1/generator", device="cpu"))
    history = np.cumsum(np.full((11, 8, 2), 0.2, np.float32), axis=1)  # [11, 8, 2]
    history += np.arange(11, dtype=np.float32)[:, None, None]  # 11 agents 1 m apart
    msgs = _messages(lambda: predict_scene(nba, history, 20))
    assert any(m.startswith(f"predict_scene: {UNTYPED}") for m in msgs), msgs
    types = np.zeros(11, np.int64)
    types[0] = 1
    assert not [m for m in _messages(lambda: predict_scene(nba, history, 20, types))
                if UNTYPED in m]  # fmt: skip


def test_the_recorded_training_flags_decide_whether_a_model_reads_types():
    """A checkpoint records the flags its training windows held (``agent_types``, since
    2026-12-06): a folder with a BALL column counts, whatever its name; without the record,
    the dataset decides (nba)."""
    from types import SimpleNamespace

    from trajpref.models.timing import attach_timing

    def timing(dataset, types):
        meta = {} if types is None else {"data_timing": {
            "frame_interval": 0.12, "interval_from": "given", "time_step": 1.0, "units": "m",
            "agent_types": types}}  # fmt: skip
        header = {"config": {"data": {"dataset": dataset, "time_step": 1.0}}, "meta": meta}
        return attach_timing(SimpleNamespace(), header)

    assert reads_agent_types(timing("/data/court", [0, 1]))
    assert not reads_agent_types(timing("/data/walks", [0]))
    assert reads_agent_types(timing("nba", None)) and not reads_agent_types(timing("zara1", None))


def test_training_records_the_agent_type_flags_it_saw(walks):
    from trajpref.train.run import data_timing
    from trajpref.types import TrajectoryDataset

    train = load_dataset(str(walks), "train")
    assert data_timing(train)["agent_types"] == [0]
    scenes = [train.scenes[0]]
    scenes[0].agent_type[0] = 1  # a ball in the first scene
    assert data_timing(TrajectoryDataset(scenes, train.info))["agent_types"] == [0, 1]
