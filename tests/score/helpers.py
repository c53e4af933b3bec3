"""Plain helpers shared by the score tests."""

from __future__ import annotations

import numpy as np


def _scene(fast: float = 1.4) -> np.ndarray:
    """[3, 8, 2] three walkers in a map frame (50, 20) m from its origin; agent 2 at ``fast``
    m/s."""
    t = np.arange(8) * 0.4
    walkers = [np.stack([t * 1.2, 0 * t], -1), np.stack([5 - t, 3 + 0 * t], -1),
               np.stack([2 + 0 * t, -2 + fast * t], -1)]  # fmt: skip
    return (np.stack(walkers) + np.array([50.0, 20.0])).astype(np.float32)
