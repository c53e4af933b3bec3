"""The trajectory diffusion score (the paper's Sec. 4): residuals, r, ATS/FTS, ranking; and the
one-scene planning calls (``predict_scene``, ``predict_scenes``, ``rank_samples``)."""

from trajpref.score.scorer import (
    ScoreResult,
    TrajectoryScorer,
    predict_scene,
    predict_scenes,
    rank_samples,
    score_timesteps,
)

__all__ = [
    "ScoreResult",
    "TrajectoryScorer",
    "predict_scene",
    "predict_scenes",
    "rank_samples",
    "score_timesteps",
]
