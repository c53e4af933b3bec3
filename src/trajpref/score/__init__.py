"""The trajectory diffusion score (the paper's Sec. 4): residuals, r, ATS/FTS, ranking."""

from trajpref.score.scorer import (
    ScoreResult,
    TrajectoryScorer,
    predict_scene,
    rank_samples,
    score_timesteps,
)

__all__ = ["ScoreResult", "TrajectoryScorer", "predict_scene", "rank_samples", "score_timesteps"]
