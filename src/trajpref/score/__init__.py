"""The trajectory diffusion score (the paper's Sec. 4): residuals, r, ATS/FTS, ranking."""

from trajpref.score.scorer import ScoreResult, TrajectoryScorer, rank_samples, score_timesteps

__all__ = ["ScoreResult", "TrajectoryScorer", "rank_samples", "score_timesteps"]
