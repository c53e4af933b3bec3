"""Tests of the side-by-side timing helper (trajpref.evaluation.time_predictors); the
evaluation pass itself is tested through its callers (train, CLI, reproduce)."""

import pytest
import torch
from synthetic import make_scene

from trajpref.errors import ConfigError
from trajpref.evaluation import time_predictors
from trajpref.types import TrajectoryDataset


class Recorder:
    """A predictor that records the scenes it is called on, in order, with the call log."""

    def __init__(self, name: str, log: list) -> None:
        self.name, self.log = name, log

    def predict(self, batch, num_samples, generator=None):
        self.log.append((self.name, batch.scene_ids[0]))
        return torch.zeros(num_samples, batch.num_agents, 12, 2)


def _dataset(n: int) -> TrajectoryDataset:
    return TrajectoryDataset([make_scene(2, seed=i) for i in range(n)], None)


def test_predictors_are_interleaved_on_the_same_evenly_spaced_scenes():
    log: list = []
    out = time_predictors({"a": Recorder("a", log), "b": Recorder("b", log)}, _dataset(10),
                          num_samples=3, scenes=4, warmup=1)  # fmt: skip
    assert out["scenes"] == 4 and set(out) == {"a", "b", "scenes"}
    assert all(out[k] >= 0 for k in "ab")
    timed = log[2:]  # after one warm-up call each
    assert [name for name, _ in timed] == ["a", "b"] * 4
    picked = [sid for name, sid in timed if name == "a"]
    assert picked == [sid for name, sid in timed if name == "b"]
    assert picked == [f"synthetic#{i}" for i in (0, 3, 6, 9)]  # evenly spaced, ends included


def test_fewer_scenes_than_asked_times_them_all():
    log: list = []
    out = time_predictors({"a": Recorder("a", log)}, _dataset(3), 1, scenes=50, warmup=0)
    assert out["scenes"] == 3 and len(log) == 3


def test_nothing_to_time_is_a_clear_error():
    with pytest.raises(ConfigError, match="at least one predictor"):
        time_predictors({}, _dataset(2), 1)
    with pytest.raises(ConfigError, match="at least one scene"):
        time_predictors({"a": Recorder("a", [])}, _dataset(0), 1)


def test_a_models_name_is_refused_before_any_work_with_how_to_load_it(capsys):
    """evaluate('hotel/generator', ds) drew a progress bar, then raised a bare AttributeError."""
    from trajpref.errors import TrajprefError
    from trajpref.evaluation import evaluate, predict_dataset
    from trajpref.models.baseline import ConstantVelocity

    data = _dataset(3)
    for call in (evaluate, predict_dataset):
        with pytest.raises(TypeError, match=r"model must be a predictor .*got str: load it "
                           r"first, trajpref\.models\.registry\.load_predictor\('hotel/generator'"
                           r"\)") as err:  # fmt: skip
            call("hotel/generator", data, progress=True)
        assert isinstance(err.value, TrajprefError)  # the CLI's one-line kind
        with pytest.raises(TypeError, match=r"got str: load it first, trajpref\.data\."
                           r"load_dataset\('hotel', split\)"):  # fmt: skip
            call(ConstantVelocity(), "hotel", progress=True)
    assert capsys.readouterr().err == ""  # no progress bar was drawn
