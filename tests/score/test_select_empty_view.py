"""``select_for_scene`` on a scene without agents (an empty view, as ``rank_samples`` takes
it): K' rows of no agent's indices, not an error."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from trajpref.errors import ConfigError, DataError
from trajpref.score import TrajectoryScorer
from trajpref.score.selection import SelectionConfig, select_for_scene


@pytest.fixture(scope="module")
def scorer() -> TrajectoryScorer:
    return TrajectoryScorer.from_checkpoint("zara1/denoiser").with_steps([0, 50])


@pytest.mark.parametrize("method", ["score-facility", "facility", "top", "random"])
@pytest.mark.parametrize("per", ["agent", "scene"])
def test_an_empty_view_keeps_k_prime_rows_of_no_agent(scorer, method, per):
    history, samples = np.zeros((0, 8, 2)), np.zeros((20, 0, 12, 2))
    cfg = SelectionConfig(keep=5, method=method, per=per)
    idx = select_for_scene(scorer, history, samples, cfg)
    assert isinstance(idx, np.ndarray) and idx.shape == (5, 0) and idx.dtype == np.int64
    assert samples[idx, np.arange(0)].shape == (5, 0, 12, 2)  # the docstring's take
    idx = select_for_scene(scorer, torch.as_tensor(history), samples, cfg)
    assert isinstance(idx, torch.Tensor) and idx.shape == (5, 0) and idx.dtype == torch.int64


def test_an_empty_view_still_checks_keep_and_shapes(scorer):
    with pytest.raises(ConfigError, match="cannot keep 5 of 4 samples"):
        select_for_scene(scorer, np.zeros((0, 8, 2)), np.zeros((4, 0, 12, 2)),
                         SelectionConfig(keep=5))  # fmt: skip
    with pytest.raises(DataError, match=r"samples: expected \[K, 0, 12, 2\]"):
        select_for_scene(scorer, np.zeros((0, 8, 2)), np.zeros((4, 2, 12, 2)),
                         SelectionConfig(keep=2))  # fmt: skip
    with pytest.raises(DataError, match=r"samples: no samples \(K = 0\)"):
        select_for_scene(scorer, np.zeros((0, 8, 2)), np.zeros((0, 0, 12, 2)),
                         SelectionConfig(keep=1))  # fmt: skip
