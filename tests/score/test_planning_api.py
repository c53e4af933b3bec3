"""The one-scene planning calls on a tiny trained model: several scenes in one batch, the
float32 check shared by prediction and ranking, numpy views and integers, wrong arguments,
and selection from a single sample."""

import warnings

import numpy as np
import pytest
import torch

from trajpref.data import load_dataset
from trajpref.errors import ConfigError, DataError
from trajpref.models.registry import load_predictor
from trajpref.score import TrajectoryScorer, predict_scene, predict_scenes, rank_samples
from trajpref.score.selection import SelectingPredictor, SelectionConfig, select_for_scene


@pytest.fixture(scope="module")
def model(tiny_run):
    return load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")


@pytest.fixture(scope="module")
def scorer(tiny_run):
    return TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors")


@pytest.fixture(scope="module")
def scenes(walks):
    return load_dataset(str(walks), "test").scenes[:4]


def test_predict_scenes_is_the_loop_in_one_batch(model, scenes):
    histories = [s.history[: 1 + i % 3] for i, s in enumerate(scenes)]  # 1, 2, 3, 1 agents
    together = predict_scenes(model, histories, 4, seed=2)
    assert len(together) == len(scenes)
    for history, got in zip(histories, together, strict=True):
        alone = predict_scene(model, history, 4, seed=2)
        assert isinstance(got, np.ndarray) and got.shape == alone.shape
        np.testing.assert_allclose(got, alone, atol=1e-4)
    mixed = predict_scenes(model, [torch.from_numpy(histories[0]), histories[1]], 4, seed=2)
    assert isinstance(mixed[0], torch.Tensor) and isinstance(mixed[1], np.ndarray)
    types = [np.zeros(len(h), np.int64) for h in histories]
    same = predict_scenes(model, histories, 4, agent_types=types, seed=2)
    np.testing.assert_array_equal(same[2], together[2])


def test_predict_scenes_names_the_scene_at_fault(model, scenes):
    histories = [s.history for s in scenes[:2]]
    with pytest.raises(DataError, match=r"histories\[1\]: expected \[P, 8, 2\]"):
        predict_scenes(model, [histories[0], histories[1][:, 1:]])
    with pytest.raises(DataError, match=r"agent_types: expected one entry per scene \(2\)"):
        predict_scenes(model, histories, agent_types=[None])
    with pytest.raises(DataError, match="predict_scene takes one scene"):
        predict_scenes(model, histories[0])
    with pytest.raises(DataError, match="no scenes"):
        predict_scenes(model, [])
    # the constant-velocity baseline takes any T_h, but one batch needs one (a raw RuntimeError)
    from trajpref.models.baseline import ConstantVelocity

    with pytest.raises(DataError, match=r"histories\[1\]: 7 observed steps, but histories\[0\] "
                       r"has 8: the scenes of one call need the same number"):  # fmt: skip
        predict_scenes(ConstantVelocity(), [histories[0], histories[1][:, 1:]])


def test_ranking_and_selection_refuse_map_coordinates_as_prediction_does(model, scorer, scenes):
    history = scenes[0].history
    samples = predict_scene(model, history, 4)
    far = 5e5  # float32 keeps about 0.03 there: a good share of a step
    for call in (lambda: predict_scene(model, history + far),
                 lambda: rank_samples(scorer, history + far, samples + far),
                 lambda: select_for_scene(scorer, history + far, samples + far,
                                          SelectionConfig(keep=2))):  # fmt: skip
        with pytest.raises(DataError, match="float32 rounding.*subtract an origin"):
            call()
    rank_samples(scorer, history + 1e3, samples + 1e3)  # a few km off is fine


def test_numpy_views_and_integers_are_read_as_their_values(model, scorer, scenes):
    history = scenes[0].history.astype(np.float32)
    flipped = history[::-1]  # a view with a negative stride
    assert flipped.strides[0] < 0
    np.testing.assert_array_equal(predict_scene(model, flipped, np.int64(4)),
                                  predict_scene(model, flipped.copy(), 4))  # fmt: skip
    samples = predict_scene(model, history, 4)
    order, _ = rank_samples(scorer, history[::-1], samples[::-1, ::-1])  # both views
    ref, _ = rank_samples(scorer, history[::-1].copy(), samples[::-1, ::-1].copy())
    np.testing.assert_array_equal(order, ref)
    assert rank_samples(scorer, history, samples, agent_type=np.zeros(len(history))[::-1].astype(
        np.int64))[0].tolist() == rank_samples(scorer, history, samples)[0].tolist()  # fmt: skip
    cfg = SelectionConfig(keep=np.int64(2), score_every=np.int64(3), score_from=np.int32(1))
    assert (cfg.keep, cfg.score_every, cfg.score_from) == (2, 3, 1)
    assert type(cfg.keep) is int
    assert select_for_scene(scorer, history, samples, cfg).shape == (2, len(history))
    with pytest.raises(ConfigError, match="num_samples must be an integer >= 1"):
        predict_scene(model, history, np.float64(4))


def test_a_name_or_the_wrong_object_as_model_or_scorer_says_what_to_do(model, scorer, scenes):
    history = scenes[0].history
    samples = predict_scene(model, history, 4)
    with pytest.raises(ConfigError, match=r"load_predictor\('zara1/generator'\)"):
        predict_scene("zara1/generator", history)
    with pytest.raises(ConfigError, match="TrajectoryScorer, which ranks futures"):
        predict_scene(scorer, history)
    with pytest.raises(ConfigError, match=r"TrajectoryScorer.from_checkpoint\('zara1/denoiser'\)"):
        rank_samples("zara1/denoiser", history, samples)
    with pytest.raises(ConfigError, match="got a predictor, which samples futures"):
        rank_samples(model, history, samples)
    with pytest.raises(ConfigError, match="got a predictor"):
        select_for_scene(model, history, samples, SelectionConfig(keep=2))


def test_boolean_agent_types_are_refused(model, scorer, scenes):
    history = scenes[0].history
    flags = np.zeros(len(history), bool)
    with pytest.raises(DataError, match="agent_type: expected integer flags .* got booleans"):
        predict_scene(model, history, 4, agent_type=flags)
    with pytest.raises(DataError, match="got booleans"):
        rank_samples(scorer, history, predict_scene(model, history, 4), agent_type=flags)


def test_selection_from_one_sample_warns_nothing(model, scorer, scenes):
    history = scenes[0].history
    one = predict_scene(model, history, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # torch's std() warning at K = 1 would raise here
        idx = select_for_scene(scorer, history, one, SelectionConfig(keep=1))
    assert idx.tolist() == [[0] * len(history)]


def test_selecting_predictor_documents_predict():
    assert "K' (``cfg.keep``)" in (SelectingPredictor.predict.__doc__ or "")


def test_a_model_trained_on_a_folder_without_a_recorded_interval_knows_no_step(model, scorer):
    # the synthetic folder gives no interval (0.4 s is assumed): nothing is known to compare
    assert model.frame_interval is None and scorer.frame_interval is None
    assert model.timing is not None and model.timing["known"] is False
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predict_scene(model, np.zeros((1, 8, 2)) + np.arange(8)[:, None] * 0.5, 4,
                      frame_interval=0.1)  # fmt: skip
