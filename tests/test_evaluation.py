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


class OnDevice(Recorder):
    """A Recorder whose weights are on ``device`` and that records the device of each batch."""

    def __init__(self, name: str, log: list, device: str) -> None:
        super().__init__(name, log)
        self.device = torch.device(device)
        self.seen: list[torch.device] = []

    def predict(self, batch, num_samples, generator=None):
        self.seen.append(batch.history.device)
        return super().predict(batch, num_samples, generator)


def test_each_predictor_is_given_its_batches_on_its_own_device(monkeypatch):
    """The batches were built on the CPU and handed over as they were: on CUDA, a crash."""
    from trajpref import evaluation

    monkeypatch.setattr(evaluation, "pass_device",
                        lambda model, device, call: torch.device("meta"))  # fmt: skip
    model = OnDevice("a", [], "meta")
    time_predictors({"a": model}, _dataset(3), 1, scenes=3, warmup=1)
    assert model.seen == [torch.device("meta")] * 4  # the warm-up call, then 3 timed ones


def test_a_predictor_on_a_device_it_cannot_run_on_is_refused_before_any_work():
    log: list = []
    with pytest.raises(ConfigError, match=r"time_predictors: the model's weights are on meta"):
        time_predictors({"a": Recorder("a", log), "b": OnDevice("b", log, "meta")},
                        _dataset(3), 1)  # fmt: skip
    assert log == []


def test_the_clock_is_read_after_the_gpu_has_finished(monkeypatch):
    """CUDA calls return before the GPU is done: without a synchronize on each side of the
    clock, one predictor's kernels were charged to the next one's time."""
    from trajpref import evaluation

    events: list = []
    monkeypatch.setattr(evaluation, "_sync", lambda device: events.append(("sync", device)))
    clock = evaluation.time.perf_counter
    monkeypatch.setattr(evaluation.time, "perf_counter",
                        lambda: events.append("clock") or clock())  # fmt: skip
    time_predictors({"a": Recorder("a", [])}, _dataset(2), 1, scenes=2, warmup=0)
    cpu = ("sync", torch.device("cpu"))
    assert events == [cpu, "clock", cpu, "clock"] * 2


def test_sync_waits_for_a_cuda_device_only(monkeypatch):
    from trajpref import evaluation

    calls: list = []
    monkeypatch.setattr(torch.cuda, "synchronize", lambda device=None: calls.append(device))
    evaluation._sync(torch.device("cpu"))
    evaluation._sync(torch.device("meta"))
    assert calls == []
    evaluation._sync(torch.device("cuda:1"))
    assert calls == [torch.device("cuda:1")]
