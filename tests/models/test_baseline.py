import math

import numpy as np
import pytest
import torch

from trajpref.errors import ConfigError
from trajpref.models.baseline import ConstantVelocity
from trajpref.types import Scene, collate


def _line_scene() -> Scene:
    t = np.arange(20, dtype=np.float32)
    track = np.stack([0.5 * t, -0.25 * t], -1)[None]  # [1, 20, 2]
    return Scene(track[:, :8], track[:, 8:], np.zeros(1, np.int64), "line")


def test_deterministic_cv_is_exact_on_a_straight_line():
    batch = collate([_line_scene()])
    pred = ConstantVelocity().predict(batch, 1)
    assert pred.shape == (1, 1, 12, 2)
    torch.testing.assert_close(pred[0], batch.future)


def test_sampled_cv_keeps_sample_zero_and_is_seeded():
    batch = collate([_line_scene()])
    g1, g2 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    a = ConstantVelocity().predict(batch, 20, g1)
    b = ConstantVelocity().predict(batch, 20, g2)
    assert torch.equal(a, b)
    torch.testing.assert_close(a[0], batch.future)
    assert not torch.allclose(a[1], a[0])


def test_sampled_cv_perturbs_heading_and_speed_as_configured():
    batch = collate([_line_scene()])
    pred = ConstantVelocity(heading_std_deg=0.0, speed_log_std=0.0).predict(batch, 5)
    assert torch.allclose(pred, pred[:1].expand_as(pred))
    pred = ConstantVelocity(heading_std_deg=30.0, speed_log_std=0.0).predict(batch, 50)
    step = pred[:, 0, 1] - pred[:, 0, 0]  # [K, 2] per-step displacement
    speed = torch.linalg.vector_norm(step, dim=-1)
    torch.testing.assert_close(speed, torch.full_like(speed, math.hypot(0.5, 0.25)))


def test_bad_config():
    with pytest.raises(ConfigError):
        ConstantVelocity(heading_std_deg=-1)
    with pytest.raises(ConfigError):
        ConstantVelocity().predict(collate([_line_scene()]), 0)


def test_cv_extrapolates_its_horizon_where_no_future_gives_one():
    """``predict_scene(cv, ...)`` always predicted 12 steps (walkthrough 70): a planner of
    other horizons had no way to ask for another."""
    from trajpref.score.scorer import predict_scene

    history = np.cumsum(np.ones((2, 5, 2)), 1)  # [P, 5, 2], one unit per step along x and y
    futures = predict_scene(ConstantVelocity(horizon=10), history, 1)
    assert futures.shape == (1, 2, 10, 2)
    np.testing.assert_allclose(futures[0, 0, -1], history[0, -1] + 10)
    assert predict_scene(ConstantVelocity(), history, 1).shape == (1, 2, 12, 2)
    with pytest.raises(ConfigError, match="horizon must be an integer >= 1"):
        ConstantVelocity(horizon=0)
