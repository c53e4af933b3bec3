"""Build a predictor from a ``--model`` value: ``cv`` or a checkpoint path."""

from __future__ import annotations

from pathlib import Path

import torch

from trajpref.errors import TrajprefError
from trajpref.models.baseline import ConstantVelocity

BUILTIN = {"cv": ConstantVelocity}
"""Models that need no checkpoint."""


def load_predictor(spec: str, device: torch.device | str = "cpu"):
    """``cv`` gives the constant-velocity baseline; a path loads a checkpoint."""
    if spec in BUILTIN:
        return BUILTIN[spec]()
    path = Path(spec)
    if not path.is_file():
        raise TrajprefError(f"{spec}: no such model (use 'cv' or a checkpoint file)")
    raise TrajprefError(
        f"{spec}: trained checkpoints are not supported yet; only 'cv' is available"
    )
