"""Ranking and selection apply prediction's float32 coordinate check with the scorer's data
scale (``models.predictor.check_coordinates``, ``data.text.PRECISION_STEP_FLOOR``): a
standing crowd with tracker jitter 2 km from the map's origin is ranked, UTM-size
coordinates are still refused (walkthrough 65, robot finding 1)."""

import numpy as np
import pytest

from trajpref.errors import DataError
from trajpref.score import TrajectoryScorer, rank_samples
from trajpref.score.selection import SelectionConfig, select_for_scene


@pytest.fixture(scope="module")
def scorer():
    return TrajectoryScorer.from_checkpoint("zara1/denoiser")


def _standing(offset: float, jitter: float) -> np.ndarray:
    """[3, 8, 2] three people standing, ``jitter`` m of tracker noise, ``offset`` from 0."""
    rng = np.random.default_rng(1)
    spots = np.array([[0.0, 0.0], [3.0, 1.0], [5.0, 4.0]])[:, None]  # [3, 1, 2]
    return offset + spots + rng.normal(0.0, jitter, (3, 8, 2))


def _samples(history: np.ndarray, k: int = 4) -> np.ndarray:
    """[K, P, 12, 2] futures drifting away from the last observed positions."""
    drift = np.linspace(0.0, 1.0, 12)[None, None, :, None] * np.arange(k)[:, None, None, None]
    return history[None, :, -1:, :] + 0.1 * drift  # [K, P, 12, 2]


@pytest.mark.parametrize("jitter", [0.002, 0.005])
def test_a_standing_crowd_2km_out_is_ranked_and_selected(scorer, jitter):
    history = _standing(2000.0, jitter)
    samples = _samples(history)
    order, _ = rank_samples(scorer, history, samples)
    assert sorted(np.asarray(order).tolist()) == [0, 1, 2, 3]
    assert select_for_scene(scorer, history, samples, SelectionConfig(keep=2)).shape == (2, 3)


def test_utm_coordinates_are_still_refused_by_ranking(scorer):
    t = np.arange(8) * 0.4
    walkers = np.stack([np.stack([1.2 * t, 0 * t + dy], -1) for dy in (0, 3)]) + 5e5
    for history in (walkers, _standing(5e5, 0.002)):
        with pytest.raises(DataError, match="float32 rounding.*subtract an origin"):
            rank_samples(scorer, history, _samples(history))
