"""The one evaluation loop (and, with the diffusion models, the one training loop)."""

from trajpref.train.device import resolve_device
from trajpref.train.evaluate import Predictor, evaluate, predict_dataset

__all__ = ["Predictor", "evaluate", "predict_dataset", "resolve_device"]
