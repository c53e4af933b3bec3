"""Build a predictor from a ``--model`` value: ``cv``, a published name or a checkpoint path."""

from __future__ import annotations

import os
from pathlib import Path

import torch

from trajpref.device import resolve_device
from trajpref.errors import ConfigError, ModelNotFound, TrajprefError
from trajpref.models import checkpoint, zoo
from trajpref.models.baseline import ConstantVelocity
from trajpref.models.predictor import Sampler

BUILTIN = {"cv": ConstantVelocity}
"""Models that need no checkpoint."""


def load_predictor(
    spec: str | os.PathLike, *, device: torch.device | str = "cpu", sampler: Sampler | None = None
):
    """``cv`` gives the constant-velocity baseline; a published name (``zara1/generator``)
    or a path loads a checkpoint.

    ``sampler`` (``leapfrog`` or ``full``) applies to diffusion checkpoints; None picks the
    checkpoint's natural one (leapfrog for a generator, full for a bare denoiser). ``device``:
    ``auto`` (a GPU when there is one), ``cpu`` or ``cuda[:i]``; the baseline computes on its
    inputs' device. ``spec`` of another type (None, a number) is a ``ConfigError``; one that
    names no checkpoint file or published model is a ``ModelNotFound`` (a ``TrajprefError``
    and a ``FileNotFoundError``).
    """
    checkpoint.check_spec(spec, "load_predictor", f"'cv', {checkpoint.MODEL_SPECS}")
    device = resolve_device(device)  # "auto" as the CLI reads it; a missing GPU in one line
    if spec in BUILTIN:
        return BUILTIN[spec]()
    if zoo.is_name(spec):  # DATASET/NAME: a published model, or an error listing them
        return _named(checkpoint.load_predictor(
            checkpoint.resolve_path(spec), sampler=sampler, device=device
        ), spec)  # fmt: skip
    try:
        path = checkpoint.resolve_path(spec)
    except TrajprefError:
        folder = Path(spec)
        if folder.is_dir():  # a run folder: name the checkpoint it holds
            found = [folder / f"{n}{checkpoint.SUFFIX}" for n in ("finetune", "generator")]
            found = [str(p) for p in found if p.is_file()]
            hint = f": pass {' or '.join(found)}" if found else ""
            # there, but not a model: no NotFound, which an "if missing, fetch it" handler takes
            raise ConfigError(f"{spec}: a folder, not a checkpoint file{hint}") from None
        message = zoo.not_here_message(spec)  # models/zara1/generator.safetensors elsewhere
        if message is not None:
            raise ModelNotFound(message) from None
        raise ModelNotFound(
            f"{spec}: no such model (use 'cv', a published name such as zara1/generator "
            "(`trajpref models` lists them) or a checkpoint file)"
        ) from None
    return _named(checkpoint.load_predictor(path, sampler=sampler, device=device), spec)


def _named(model, spec: str | os.PathLike):
    """``model`` with ``checkpoint``: the name or path it was loaded by, which the Python data
    checks' warnings name (``evaluation.model_identity``)."""
    model.checkpoint = str(spec)
    return model
