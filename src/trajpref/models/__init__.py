"""Predictors: the constant-velocity baseline, and later the denoiser and the generator."""

from trajpref.models.baseline import ConstantVelocity

__all__ = ["ConstantVelocity"]
