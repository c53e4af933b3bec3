"""Fixtures of the score tests: zara1's denoiser's scorer (its generator, ``zara1``, is
tests/conftest.py's)."""

import pytest

from trajpref.score.scorer import TrajectoryScorer


@pytest.fixture(scope="module")
def scorer():
    """zara1's published denoiser as a scorer at two score steps (0 and 3): cheap; a module
    that needs another scorer defines its own ``scorer``."""
    return TrajectoryScorer.from_checkpoint("zara1/denoiser").with_steps([0, 3])
