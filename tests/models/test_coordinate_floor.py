"""The float32 coordinate check of prediction compares the rounding with a step of at least
``data.text.PRECISION_STEP_FLOOR`` model units (walkthrough 65, robot finding 1): a standing
crowd with millimetre tracker jitter in a map frame 2 km from its origin is accepted as the
same scene with walkers is, while UTM-size coordinates are refused whether the crowd stands or
walks. The text reader, which knows no model, keeps the plain median-step rule."""

import numpy as np
import pytest
import torch

from trajpref.data.text import PRECISION_SHARE, PRECISION_STEP_FLOOR, float32_precision_loss
from trajpref.errors import DataError
from trajpref.models.predictor import check_coordinates

HALF_SPACING = 2.0**-24  # float32's rounding of a value v is at most v * 2**-24 (eps / 2)


def _standing(offset: float, jitter: float = 0.002, seed: int = 0) -> np.ndarray:
    """[3, 8, 2] three people standing 3-5 m apart, with ``jitter`` (m) of tracker noise, in a
    map frame whose origin is ``offset`` away along both axes."""
    rng = np.random.default_rng(seed)
    spots = np.array([[0.0, 0.0], [3.0, 1.0], [5.0, 4.0]])[:, None]  # [3, 1, 2]
    return offset + spots + rng.normal(0.0, jitter, (3, 8, 2))


def test_the_floor_is_the_least_step_the_rounding_is_compared_with():
    steps = np.full(10, 0.003)  # jitter: 1 % of it is 3e-5
    floor = 0.147  # 0.1 model units at zara1's scale 1.47: the bar is 1.47e-3
    assert PRECISION_SHARE * floor == pytest.approx(1.47e-3)
    assert float32_precision_loss(2000.0, 1.46e-3, steps, floor=floor) is None
    text = float32_precision_loss(2000.0, 1.48e-3, steps, floor=floor)
    assert text is not None and "1% of a step of 0.147" in text and "median step 0.003" in text
    # a median step above the floor is compared as before
    walkers = np.full(10, 0.5)
    assert float32_precision_loss(5e5, 4.9e-3, walkers, floor=floor) is None
    assert "of a median step (0.5)" in float32_precision_loss(5e5, 5.1e-3, walkers, floor=floor)
    # nothing moving: the floor still applies (a map frame's answer does not depend on it)
    assert float32_precision_loss(1e5, 1.48e-3, np.zeros(10), floor=floor) is not None
    assert float32_precision_loss(1e5, 1.46e-3, np.zeros(10), floor=floor) is None


def test_without_a_floor_the_text_readers_rule_is_unchanged():
    steps = np.full(10, 0.003)
    assert float32_precision_loss(2000.0, 1.2e-4, steps) is not None  # 4 % of a jitter step
    assert float32_precision_loss(1e5, 6e-3, np.zeros(10)) is None  # nothing moves: no rule


def test_check_coordinates_boundary_for_a_standing_crowd_hand_computed():
    # scale 1: the bar is PRECISION_SHARE * PRECISION_STEP_FLOOR = 1e-3 data units, so the
    # largest coordinate a jittering crowd may have is 1e-3 / 2**-24 = 16777.2
    assert PRECISION_SHARE * PRECISION_STEP_FLOOR == pytest.approx(1e-3)
    inside = torch.tensor(_standing(16000.0 - 6.0, jitter=0.0005))  # largest ~16000
    outside = torch.tensor(_standing(17600.0 - 6.0, jitter=0.0005))  # largest ~17600
    rounded = [float(h.abs().max()) * HALF_SPACING for h in (inside, outside)]
    assert rounded[0] < 1e-3 < rounded[1]
    check_coordinates(inside, scale=1.0)
    with pytest.raises(DataError, match="float32 rounding.*subtract an origin"):
        check_coordinates(outside, scale=1.0)
    check_coordinates(outside, scale=2.0)  # a model unit of 2: the bar doubles
    with pytest.raises(DataError, match="float32 rounding"):  # no scale: the plain rule
        check_coordinates(inside)


@pytest.mark.parametrize("jitter", [0.002, 0.005])
def test_a_standing_crowd_2km_out_is_predicted_as_walkers_there_are(zara1, jitter):
    from trajpref.score import predict_scene

    futures = predict_scene(zara1, _standing(2000.0, jitter), 20)
    assert futures.shape == (20, 3, 12, 2) and np.isfinite(futures).all()
    t = np.arange(8) * 0.4
    walkers = 2000.0 + np.stack([np.stack([1.2 * t, 0 * t + dy], -1) for dy in (0, 3)])
    predict_scene(zara1, walkers, 20)


def test_utm_coordinates_are_refused_whether_the_crowd_walks_or_stands(zara1):
    from trajpref.score import predict_scene

    t = np.arange(8) * 0.4
    walkers = np.stack([np.stack([1.2 * t, 0 * t + dy], -1) for dy in (0, 3)])  # [2, 8, 2]
    for history in (walkers + [5e5, 4.5e6], _standing(5e5), np.tile([5e5, 5e5], (2, 8, 1))):
        with pytest.raises(DataError, match="float32 rounding.*subtract an origin"):
            predict_scene(zara1, history, 20)
    # a still crowd 100 km out was accepted before the floor (nothing moved), unlike its
    # walking twin: now both are refused
    with pytest.raises(DataError, match="float32 rounding"):
        predict_scene(zara1, np.tile([1e5, 1e5], (2, 8, 1)), 20)
