"""benchmarks/future_span.py: the distance of a future from the smooth output span."""

import numpy as np
from bench import load_benchmark

from trajpref.models.generator import time_projection


def test_a_smooth_future_costs_nothing_and_a_jump_costs_its_distance_from_the_span():
    span = load_benchmark("future_span")
    t = np.arange(1, 13, dtype=float)  # [T_f]
    smooth = np.stack([0.4 * t, 0.01 * t**2], -1)[None]  # [1, T_f, 2], degree 2
    pi = time_projection(12, 3).double().numpy()  # [T_f, T_f]
    ade, fde = span.projection_error(smooth, pi)
    assert ade < 1e-6 and fde < 1e-6  # the projection is stored in float32
    jump = np.zeros((1, 12, 2))
    jump[0, :, 0] = 1.0  # a constant offset: no path through the last position does this
    ade, fde = span.projection_error(jump, pi)
    residual = np.ones(12) - pi @ np.ones(12)  # [T_f], what the span cannot hold
    assert np.isclose(ade, np.abs(residual).mean()) and np.isclose(fde, abs(residual[-1]))
    assert ade > 0.05
