"""Fixtures of the score tests: zara1's published generator and its denoiser's scorer."""

import pytest

from trajpref.score.scorer import TrajectoryScorer


@pytest.fixture(scope="module")
def zara1():
    """zara1's published generator on the CPU."""
    from trajpref.models.registry import load_predictor

    return load_predictor("zara1/generator", device="cpu")


@pytest.fixture(scope="module")
def scorer():
    """zara1's published denoiser as a scorer at two score steps (0 and 3): cheap; a module
    that needs another scorer defines its own ``scorer``."""
    return TrajectoryScorer.from_checkpoint("zara1/denoiser").with_steps([0, 3])
