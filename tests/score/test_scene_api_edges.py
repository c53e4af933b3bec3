"""The one-scene Python calls at a planner's edges: fewer samples than a generator's fixed set
(a warning, as the CLI's), a view without agents (empty results, not an error; one empty
scene of a batch leaves the others), and context rows the model does not read (a warning
that counts them)."""

import warnings

import numpy as np
import pytest
import torch

from trajpref.errors import ConfigError, DataError
from trajpref.score import predict_scene, predict_scenes, rank_samples


def _walk(p: int, seed: int = 0) -> np.ndarray:
    """[P, 8, 2] straight walkers about 3 m apart at 1.3 m/s."""
    rng = np.random.default_rng(seed)
    start = np.stack([np.zeros(p), 3.0 * np.arange(p)], 1)  # [P, 2]
    step = np.array([0.52, 0.0]) + rng.normal(0, 0.02, (p, 2))  # [P, 2]
    return (start[:, None] + np.arange(8)[None, :, None] * step[:, None]).astype(np.float32)


def test_fewer_samples_than_the_fixed_set_warn_as_the_cli_does(zara1):
    history = _walk(2)
    with pytest.warns(UserWarning, match=r"K = 20 samples .* num_samples=5 takes its first 5, "
                      r"an arbitrary subset: .*select_for_scene"):  # fmt: skip
        five = predict_scene(zara1, history, 5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        all20 = predict_scene(zara1, history, 20)  # the whole set: nothing to say
        predict_scene(zara1, history)  # the default is the set
    np.testing.assert_array_equal(five, all20[:5])  # still what it was: the first 5
    with pytest.warns(UserWarning, match=r"num_samples=3 takes its first 3"):
        predict_scenes(zara1, [history, history[:1]], 3)
    # independent draws (the full sampler, the baseline) take any number: nothing to say
    from trajpref.models.baseline import ConstantVelocity
    from trajpref.models.registry import load_predictor

    full = load_predictor("zara1/generator", sampler="full")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert predict_scene(ConstantVelocity(), history, 5).shape[0] == 5
        assert predict_scene(full, history, 2).shape[0] == 2


def test_a_view_without_agents_gives_empty_futures(zara1):
    empty = np.zeros((0, 8, 2), np.float32)
    out = predict_scene(zara1, empty)
    assert isinstance(out, np.ndarray) and out.shape == (20, 0, 12, 2)
    as_tensor = predict_scene(zara1, torch.zeros(0, 8, 2))
    assert isinstance(as_tensor, torch.Tensor) and as_tensor.shape == (20, 0, 12, 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the fixed-set warning
        assert predict_scene(zara1, empty, 3).shape == (3, 0, 12, 2)
    # what a wrong call is stays an error
    with pytest.raises(DataError, match=r"expected \[P, 8, 2\] .* got \[0, 7, 2\]"):
        predict_scene(zara1, np.zeros((0, 7, 2)))
    with pytest.raises(DataError, match=r"expected \[P, 8, 2\] .* got \[0\]"):
        predict_scene(zara1, np.zeros(0))
    with pytest.raises(ConfigError, match="emits K = 20 samples; asked for 25"):
        predict_scene(zara1, empty, 25)


def test_one_empty_scene_of_a_batch_leaves_the_others_as_they_are(zara1):
    a, b = _walk(2), _walk(3, seed=1) + 30.0
    empty = np.zeros((0, 8, 2), np.float32)
    ref = predict_scenes(zara1, [a, b])
    out = predict_scenes(zara1, [a, empty, b, empty])
    assert [o.shape[1] for o in out] == [2, 0, 3, 0]
    np.testing.assert_array_equal(out[0], ref[0])  # the same batch of agents, bit for bit
    np.testing.assert_array_equal(out[2], ref[1])
    assert out[1].shape == (20, 0, 12, 2)
    with pytest.raises(DataError, match=r"histories\[1\]: 1 value\(s\) not finite"):
        predict_scenes(zara1, [a, np.where(np.arange(16).reshape(1, 8, 2) == 3, np.nan, a[:1])])
    only_empty = predict_scenes(zara1, [empty, torch.zeros(0, 8, 2)])
    assert only_empty[0].shape == (20, 0, 12, 2) and isinstance(only_empty[1], torch.Tensor)


def test_ranking_an_empty_view_gives_every_sample_alike(scorer):
    order, residual = rank_samples(scorer, np.zeros((0, 8, 2)), np.zeros((20, 0, 12, 2)))
    assert order.tolist() == list(range(20)) and residual.tolist() == [0.0] * 20
    order, residual = rank_samples(scorer, torch.zeros(0, 8, 2), torch.zeros(4, 0, 12, 2))
    assert isinstance(order, torch.Tensor) and order.tolist() == [0, 1, 2, 3]
    with pytest.raises(DataError, match=r"samples: expected \[K, 0, 12, 2\]"):
        rank_samples(scorer, np.zeros((0, 8, 2)), np.zeros((20, 1, 12, 2)))
    with pytest.raises(DataError, match=r"samples: no samples \(K = 0\)"):
        rank_samples(scorer, np.zeros((0, 8, 2)), np.zeros((0, 0, 12, 2)))


def test_context_rows_the_model_ignores_are_named_in_a_warning(zara1):
    history = _walk(1)
    seen = np.stack([history[0] + [0.0, 1.0], history[0] + [0.0, -1.5]])  # [2, 8, 2] all frames
    partly = seen.copy()
    partly[0, :3] = np.nan  # seen in the last 5 frames only
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read = predict_scene(zara1, history, context=seen)  # both read: nothing to say
    with pytest.warns(UserWarning, match=r"context rows ignored: .* seen in each "
                      r"of the last 8 frames \(model.context_frames\)"):  # fmt: skip
        out = predict_scene(zara1, history, context=partly)
    assert not np.array_equal(out, read)  # row 0 was dropped, as the warning says
    with pytest.warns(UserWarning, match=r"context rows ignored") as caught:
        predict_scenes(zara1, [history, history + 20.0], contexts=[partly, partly[:1] + 20.0])
    assert len({str(w.message) for w in caught}) == 1  # one text, whatever the counts
