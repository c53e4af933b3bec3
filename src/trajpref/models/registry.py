"""Build a predictor from a ``--model`` value: ``cv`` or a checkpoint path."""

from __future__ import annotations

from pathlib import Path

import torch

from trajpref.errors import TrajprefError
from trajpref.models.baseline import ConstantVelocity

BUILTIN = {"cv": ConstantVelocity}
"""Models that need no checkpoint."""


def load_predictor(spec: str, device: torch.device | str = "cpu", sampler: str | None = None):
    """``cv`` gives the constant-velocity baseline; a path loads a checkpoint.

    ``sampler`` (``leapfrog`` or ``full``) applies to diffusion checkpoints; None picks the
    checkpoint's natural one (leapfrog for a generator, full for a bare denoiser).
    """
    if spec in BUILTIN:
        return BUILTIN[spec]()
    path = Path(spec)
    if not path.is_file():
        raise TrajprefError(f"{spec}: no such model (use 'cv' or a checkpoint file)")
    from trajpref.train.checkpoint import load_predictor as load_checkpoint

    return load_checkpoint(path, sampler, device)
