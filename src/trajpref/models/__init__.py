"""Networks (denoiser, generator, critic), their losses, the predictors behind ``predict``
(constant velocity; the diffusion predictor that owns the leapfrog rollout) and checkpoint
files."""

from trajpref.models.baseline import ConstantVelocity

__all__ = ["ConstantVelocity"]
