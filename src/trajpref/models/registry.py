"""Build a predictor from a ``--model`` value: ``cv`` or a checkpoint path."""

from __future__ import annotations

import torch

from trajpref.errors import TrajprefError
from trajpref.models import checkpoint
from trajpref.models.baseline import ConstantVelocity
from trajpref.models.predictor import Sampler

BUILTIN = {"cv": ConstantVelocity}
"""Models that need no checkpoint."""


def load_predictor(spec: str, device: torch.device | str = "cpu", sampler: Sampler | None = None):
    """``cv`` gives the constant-velocity baseline; a path loads a checkpoint.

    ``sampler`` (``leapfrog`` or ``full``) applies to diffusion checkpoints; None picks the
    checkpoint's natural one (leapfrog for a generator, full for a bare denoiser).
    """
    if spec in BUILTIN:
        return BUILTIN[spec]()
    try:
        path = checkpoint.resolve_path(spec)
    except TrajprefError:
        raise TrajprefError(f"{spec}: no such model (use 'cv' or a checkpoint file)") from None
    return checkpoint.load_predictor(path, sampler, device)
