"""Tests of the side-by-side timing helper (trajpref.evaluation.time_predictors); the
evaluation pass itself is tested through its callers (train, CLI, reproduce)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import _messages
from synthetic import make_scene

from trajpref.data import load_dataset
from trajpref.data.registry import SECONDS_STEPS
from trajpref.errors import ConfigError
from trajpref.evaluation import (
    CLI_WORDS,
    PYTHON_WORDS,
    step_hint,
    time_predictors,
    warn_untyped_data,
)
from trajpref.models.registry import load_predictor
from trajpref.models.timing import model_timing
from trajpref.score import TrajectoryScorer
from trajpref.types import DatasetInfo, TrajectoryDataset


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


# The installed user's walkthrough (67): a shipped config written out as a YAML file to edit
# (``config show --yaml``), where a built-in dataset lies under an empty data root, the
# fine-tuning presets offered by the CLI, and the question on milliseconds in the CLI's advice
# on a frame interval above 10 s.


def _folder_info(frame: float, every: float = 1.0, given: bool = True) -> DatasetInfo:
    return DatasetInfo("/data/mine", "test", "m", frame * every, source="/data/mine/test",
                       interval_from="given" if given else "default", time_step=every,
                       text_tracks=True)  # fmt: skip


ZARA1 = model_timing({"config": {"data": {"dataset": "zara1"}}})


@pytest.mark.parametrize("every", [1.0, 4.0])
def test_the_step_hint_asks_milliseconds_above_ten_seconds(every):
    hint = step_hint(_folder_info(400, every), ZARA1)
    assert hint.startswith("milliseconds? pass seconds, --frame-interval 0.4; else "), hint
    python = step_hint(_folder_info(400, every), ZARA1, PYTHON_WORDS)
    assert python.startswith("milliseconds? pass seconds, frame_interval=0.4; else "), python


def test_the_step_hint_does_not_ask_at_or_below_ten_seconds():
    assert SECONDS_STEPS[1] == 10.0
    for frame in (0.1, 2.0, SECONDS_STEPS[1]):
        assert "milliseconds" not in step_hint(_folder_info(frame), ZARA1, CLI_WORDS)
    assert "milliseconds" not in step_hint(_folder_info(400, given=False), ZARA1)


# A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
# and inputs the models read; feet given to a metre model are told the factor; a scene with no
# ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
# are types.


def _typed(walks: Path, balls: list[int]) -> TrajectoryDataset:
    """The walks' test scenes with ``balls[i]`` of scene i's agents flagged as the ball."""
    data = load_dataset(str(walks), "test")
    scenes = []
    for scene, n in zip(data.scenes, balls, strict=False):
        flags = np.zeros(len(scene.history), np.int64)
        flags[:n] = 1
        scenes.append(dataclasses.replace(scene, agent_type=flags))
    assert len(scenes) == len(balls) and all(len(s.history) >= 2 for s in scenes)
    return TrajectoryDataset(scenes, data.info)


def test_a_split_with_scenes_of_no_ball_or_two_says_how_many(nba, walks):
    checked = [("nba/generator", nba)]
    assert not _messages(lambda: warn_untyped_data(checked, _typed(walks, [1, 1, 1, 1])))
    got = _messages(lambda: warn_untyped_data(checked, _typed(walks, [1, 0, 2, 0])))
    assert got == ["nba/generator was trained with the ball flagged (agent_type 1; one in every "
                   "scene of NBA's splits), and of this data's 4 scenes, 2 flag no ball and 1 "
                   "flags two or more (up to 2): it reads each as flagged, a scene it never saw; "
                   "the ball is one agent, flagged BALL in a 5th column and seen in every frame "
                   "of a window (docs/data_format.md)"]  # fmt: skip
    got = _messages(lambda: warn_untyped_data(checked, _typed(walks, [0, 0, 0, 0])))
    assert len(got) == 1 and "this data flag no ball: every agent is read as a person" in got[0]
    zara1 = load_predictor("zara1/generator", device="cpu")
    assert not _messages(lambda: warn_untyped_data([("z", zara1)], _typed(walks, [1, 0, 2, 0])))


def test_the_published_nba_splits_have_one_ball_a_scene(nba, data_root):
    scorer = TrajectoryScorer.from_checkpoint("nba/denoiser")
    for split in ("test", "val"):
        data = load_dataset("nba", split, data_root)
        assert not _messages(lambda d=data: warn_untyped_data([("g", nba), ("s", scorer)], d))
