"""Two bugs a static type sweep found (walkthrough 67-G): a score selection given no scorer
raised AttributeError from deep inside instead of the module's one-line ConfigError, and a
scorer's ``with_steps`` copy lost the file name the data checks' warnings give."""

import numpy as np
import pytest
import torch
from synthetic import make_scene

from trajpref.errors import ConfigError
from trajpref.score.scorer import TrajectoryScorer
from trajpref.score.selection import SelectionConfig, select_with_scorer
from trajpref.types import collate


def test_a_score_selection_without_a_scorer_is_a_config_error():
    batch = collate([make_scene(3)])
    pred = torch.from_numpy(np.random.default_rng(0).normal(size=(20, 3, 12, 2))).float()
    with pytest.raises(ConfigError, match="needs the diffusion score"):
        select_with_scorer(pred, SelectionConfig(keep=5, method="score-facility"), batch, None)


def test_with_steps_keeps_the_scorers_file_name(scorer):
    assert scorer.checkpoint is not None and scorer.checkpoint.endswith("denoiser")
    assert scorer.with_steps([0]).checkpoint == scorer.checkpoint
    fresh = TrajectoryScorer(scorer.denoiser, scorer.schedule, scorer.scale, [0])
    assert fresh.checkpoint is None  # built in code
