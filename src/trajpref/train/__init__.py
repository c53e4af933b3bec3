"""Training: the three stages (denoiser, generator, fine-tuning), the one training loop, runs
and DDP."""

from trajpref.train.loop import read_metrics
from trajpref.train.run import finetune, train_stage

__all__ = ["finetune", "read_metrics", "train_stage"]
