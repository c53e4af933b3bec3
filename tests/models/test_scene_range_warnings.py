"""Scenes outside what the models were trained on, in the models' own units, warn where a
planner hands them over (``models.timing.check_observed_steps``: ``predict_scene``,
``predict_scenes``, ``rank_samples``, ``select_for_scene``; walkthrough 68, findings 2-3):
agents faster than training for a model without an input speed clamp (``FAST_LIMIT``: robo's
generator gave walkers at 10 times robo's median pace steps of 39 m, silently), and a scene
wider than training for a model without a neighbour radius (``wide_limit``, each model's own:
a walker 1 km to the side bent zara1's futures of a straight walker by metres). The texts are
fixed, the data in other units (``PACE_LIMIT``) keeps its own warning alone, and no published
test split warns on more than 1 % of its scenes."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import FAST, UNITS, walker_and_far

from trajpref.models.registry import load_predictor
from trajpref.models.timing import (
    FAST_LIMIT,
    PACE_QUANTILE,
    WIDE_LIMIT,
    check_observed_steps,
    pace_quantile,
    scene_widths,
    speed_clamp,
    wide_limit,
)
from trajpref.score import TrajectoryScorer, predict_scene, predict_scenes, rank_samples
from trajpref.score.selection import SelectionConfig, select_for_scene
from trajpref.types import AGENT_BALL

T = np.arange(8)[:, None]
WIDE = "model units apart at its last observed frame"  # each model's own limit before it


def _convoy(pace: float) -> np.ndarray:
    """[3, 8, 2] three agents 2 m apart walking ``pace`` m a step along x (robo's layout)."""
    return np.stack([T * [pace, 0.0] + [0.0, dy] for dy in (0.0, 2.0, 4.0)]).astype(np.float32)


def _record(call) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    assert all(w.filename == __file__ for w in caught), [w.filename for w in caught]
    return [str(w.message) for w in caught]


@pytest.fixture(scope="module")
def robo_scorer():
    return TrajectoryScorer.from_checkpoint("robo/denoiser").with_steps([0])


@pytest.fixture(scope="module")
def zara1_scorer():
    return TrajectoryScorer.from_checkpoint("zara1/denoiser").with_steps([0])


# --- agents faster than training -------------------------------------------------------------


def test_robo_at_ten_times_its_pace_warns_once_with_the_clamp_remedy(robo):
    assert speed_clamp(robo) is None  # published without a clamp
    fast = _convoy(3.8)  # robo's test median pace is about 0.38 m per 0.5 s step
    first = _record(lambda: predict_scene(robo, fast))
    assert len(first) == 1 and FAST in first[0]
    assert "model.max_speed" in first[0] and "model.generator.cfg.max_speed" in first[0]
    assert "--max-speed" in first[0] and "0.280 for robo" in first[0]
    assert _record(lambda: predict_scene(robo, fast * 1.1)) == first  # the same text each call


def test_robo_at_its_own_pace_does_not_warn(robo):
    assert _record(lambda: predict_scene(robo, _convoy(0.38))) == []
    assert _record(lambda: predict_scene(robo, _convoy(0.9 * FAST_LIMIT * robo.scale))) == []


def test_a_clamped_model_is_not_warned(robo, zara1):
    fast = _convoy(3.8)
    assert speed_clamp(zara1) is not None  # zara1's published 90 % clamp
    assert _record(lambda: predict_scene(zara1, fast * zara1.scale / robo.scale)) == []
    saved = robo.generator.cfg.max_speed
    try:
        robo.generator.cfg.max_speed = 0.28  # the remedy the text names
        assert speed_clamp(robo) == pytest.approx(0.28)
        assert _record(lambda: predict_scene(robo, fast)) == []
    finally:
        robo.generator.cfg.max_speed = saved


def test_the_full_sampler_has_no_clamp_and_is_warned():
    full = load_predictor("zara1/generator", device="cpu", sampler="full")
    assert speed_clamp(full) is None
    shown = _record(lambda: predict_scene(full, _convoy(2.2), num_samples=1))
    assert len(shown) == 1 and FAST in shown[0] and "the full sampler have none" in shown[0]


def test_ranking_and_selection_warn_of_fast_agents(robo, robo_scorer):
    fast = _convoy(3.8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        samples = predict_scene(robo, fast)
    for call in (lambda: rank_samples(robo_scorer, fast, samples),
                 lambda: select_for_scene(robo_scorer, fast, samples,
                                          SelectionConfig(keep=5))):  # fmt: skip
        shown = _record(call)
        assert len(shown) == 1 and shown[0].startswith("this scorer is given agents faster")
        assert "its scores of their samples extrapolate" in shown[0]
    calm = predict_scene(robo, _convoy(0.38))
    assert _record(lambda: rank_samples(robo_scorer, _convoy(0.38), calm)) == []


def test_data_in_other_units_gives_only_its_own_warning(robo):
    centimetres = _convoy(0.38) * 100  # fast, and 400 units wide: neither warns beside it
    shown = _record(lambda: predict_scene(robo, centimetres))
    assert len(shown) == 1 and UNITS in shown[0]


def test_balls_are_left_out_of_the_pace():
    class Model:
        scale = 1.0

    history = np.stack([T * [0.3, 0.0], T * [0.3, 0.0] + [0, 1], T * [1.5, 0.0]])  # ball fast
    types = np.array([0, 0, AGENT_BALL])
    assert pace_quantile(history, 1.0)[0] > FAST_LIMIT  # 3 agents: the ball lifts the 90 %
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not check_observed_steps(Model(), history, agent_type=types)
    with pytest.warns(UserWarning, match=FAST):
        check_observed_steps(Model(), history)


# --- scenes wider than training --------------------------------------------------------------


def test_a_walker_one_kilometre_to_the_side_warns_with_the_radius_remedy(zara1):
    shown = _record(lambda: predict_scene(zara1, walker_and_far(1000.0)))
    assert len(shown) == 1 and WIDE in shown[0]
    for remedy in ("model.neighbour_radius", "scorer.neighbour_radius", "--neighbour-radius",
                   "Scenes wider than the training scenes"):  # fmt: skip
        assert remedy in shown[0]
    assert _record(lambda: predict_scene(zara1, walker_and_far(500.0))) == shown


def test_a_scene_as_wide_as_training_does_not_warn(zara1):
    assert _record(lambda: predict_scene(zara1, walker_and_far(3.0))) == []
    below = 0.99 * wide_limit(zara1.training_width) * zara1.scale  # its own: 15, 22.1 m
    assert _record(lambda: predict_scene(zara1, walker_and_far(below))) == []


def test_a_model_with_a_neighbour_radius_is_not_warned(zara1):
    zara1.neighbour_radius = 12.0
    try:
        assert _record(lambda: predict_scene(zara1, walker_and_far(1000.0))) == []
    finally:
        zara1.neighbour_radius = None


def test_scenes_of_one_call_are_measured_apart(zara1):
    near = walker_and_far(3.0)
    assert _record(lambda: predict_scenes(zara1, [near, near + 5000.0])) == []
    shown = _record(lambda: predict_scenes(zara1, [near, walker_and_far(1000.0)]))
    assert len(shown) == 1 and WIDE in shown[0]


def test_ranking_and_selection_warn_of_a_wide_scene(zara1, zara1_scorer):
    wide = walker_and_far(1000.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        samples = predict_scene(zara1, wide)
    for call in (lambda: rank_samples(zara1_scorer, wide, samples),
                 lambda: select_for_scene(zara1_scorer, wide, samples,
                                          SelectionConfig(keep=5))):  # fmt: skip
        shown = _record(call)
        assert len(shown) == 1 and shown[0].startswith("this scorer is given a scene") and (
            WIDE in shown[0])  # fmt: skip
    zara1_scorer.neighbour_radius = 12.0
    try:
        assert _record(lambda: rank_samples(zara1_scorer, wide, samples)) == []
    finally:
        zara1_scorer.neighbour_radius = None


def test_scene_widths_per_scene():
    history = np.zeros((5, 8, 2))
    history[1, -1] = [3.0, 4.0]  # scene 0: 5 apart
    history[3, -1] = [0.0, 2.0]  # scene 1: agents 2 and 3, 2 apart
    history[4, -1] = [np.nan, 0.0]  # scene 2: one finite agent... of none
    np.testing.assert_allclose(scene_widths(history, [2, 2, 1]).numpy(), [5.0, 2.0, 0.0])
    assert scene_widths(history).item() == pytest.approx(5.0)


def test_the_constants_are_the_measured_ones():
    assert FAST_LIMIT == 1.0 and WIDE_LIMIT == 25.0 and PACE_QUANTILE == 0.9


@pytest.mark.parametrize(("model", "dataset"), [("sdd/generator", "sdd"), ("nba/generator", "nba")])
def test_published_test_splits_are_seldom_warned(data_root, model, dataset):
    """The two test splits nearest the limits (SDD's pace, NBA's court): at most 1 % of
    their scenes warn, each read as a planner hands it over."""
    from trajpref.data.registry import load_dataset

    predictor = load_predictor(model, device="cpu")
    data = load_dataset(dataset, "test", root=data_root)
    warned = 0
    for scene in data.scenes:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_observed_steps(predictor, scene.history, agent_type=scene.agent_type)
        warned += any(FAST in str(w.message) or WIDE in str(w.message) for w in caught)
    assert warned <= 0.01 * len(data.scenes), (warned, len(data.scenes))
