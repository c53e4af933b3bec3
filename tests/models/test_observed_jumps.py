"""A tracker id switch (one agent's position jumping metres in one observed step) fans that
agent's futures out without an error: prediction and ranking warn once, with a fixed text,
when a single observed step exceeds ``models.timing.JUMP_LIMIT`` model units (walkthrough 65,
robot finding 3). No scene of the published test splits is warned."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import UNITS

from trajpref.models.timing import JUMP_LIMIT, jump_problem, observed_jumps
from trajpref.types import AGENT_BALL, AGENT_PERSON

JUMP = "jumps more than"


class _Scaled:
    scale = 1.47  # zara1's data scale, about


def _walkers() -> np.ndarray:
    """[2, 8, 2] two walkers at 1.2 m/s (0.48 m per 0.4 s step), 3 m apart."""
    t = np.arange(8) * 0.4
    return np.stack([np.stack([1.2 * t, 0 * t + dy], -1) for dy in (0.0, 3.0)])


def _jumped(jump: float) -> np.ndarray:
    """``_walkers`` with agent 0 jumping ``jump`` m along x between frames 3 and 4."""
    history = _walkers()
    history[0, 4:, 0] += jump
    return history


def _messages(record, text: str) -> list[str]:
    return [str(w.message) for w in record if text in str(w.message)]


def test_observed_jumps_boundary_and_balls():
    limit = JUMP_LIMIT * _Scaled.scale  # 7.35 m in one step
    below = _walkers()
    below[0, 4:, 0] += limit * 0.99 - 0.48  # the step 3 -> 4 is 0.99 of the limit
    above = _walkers()
    above[0, 4:, 0] += limit * 1.01 - 0.48
    assert observed_jumps(below, _Scaled.scale).tolist() == [False, False]
    assert observed_jumps(above, _Scaled.scale).tolist() == [True, False]
    assert jump_problem(_Scaled(), below) is None and jump_problem(_Scaled(), above) is not None
    balls = np.array([AGENT_BALL, AGENT_PERSON])
    assert observed_jumps(above, _Scaled.scale, balls).tolist() == [False, False]
    assert jump_problem(_Scaled(), above, agent_type=balls) is None
    holed = above.copy()
    holed[1, 2] = np.nan  # an unseen frame is no step
    assert observed_jumps(holed, _Scaled.scale).tolist() == [True, False]
    assert jump_problem(object(), above) is None  # no scale: the constant-velocity baseline
    # the same text whatever the jump, so that a planner's loop is warned once
    assert jump_problem(_Scaled(), _jumped(10.0)) == jump_problem(_Scaled(), _jumped(30.0))


@pytest.fixture(scope="module")
def scorer():
    from trajpref.score import TrajectoryScorer

    return TrajectoryScorer.from_checkpoint("zara1/denoiser")


def test_a_10m_jump_warns_once_per_call_and_a_normal_scene_does_not(zara1, scorer):
    from trajpref.score import predict_scene, rank_samples

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        samples = predict_scene(zara1, _walkers(), 20)
        rank_samples(scorer, _walkers(), samples)
        predict_scene(zara1, _walkers() + 100.0, 20)  # a map frame's offset is no jump
    assert not _messages(caught, JUMP) and not _messages(caught, UNITS)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        predict_scene(zara1, _jumped(10.0), 20)
    (text,) = _messages(caught, JUMP)
    assert "id switch" in text and "scale 1.47192" in text and "observed_jumps" in text
    assert caught[-1].filename == __file__  # the user's line
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        order, _ = rank_samples(scorer, _jumped(10.0), samples)
    (text,) = _messages(caught, JUMP)
    assert text.startswith("this scorer is given an agent") and caught[-1].filename == __file__


def test_data_in_other_units_is_warned_of_once_not_as_a_jump(zara1):
    from trajpref.score import predict_scene

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        predict_scene(zara1, _walkers() * 100.0, 20)  # centimetres: every step 48 units
    assert len(_messages(caught, UNITS)) == 1 and not _messages(caught, JUMP)


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["zara1", "eth", "sdd"])
def test_no_scene_of_the_published_test_splits_is_warned(name, data_root, monkeypatch):
    from trajpref.data import load_dataset
    from trajpref.models.registry import load_predictor

    monkeypatch.setenv("TRAJPREF_DATA", str(data_root))
    model = load_predictor(f"{name}/generator", device="cpu")
    scenes = load_dataset(name, "test").scenes
    largest = (
        max(float(np.linalg.norm(np.diff(s.history, axis=1), axis=-1).max()) for s in scenes)
        / model.scale
    )
    assert largest < JUMP_LIMIT / 2  # zara1 0.68, eth 1.02, sdd 2.46 (JUMP_LIMIT's docstring)
    assert not any(jump_problem(model, s.history, agent_type=s.agent_type) for s in scenes)
