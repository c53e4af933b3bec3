"""The DDPM noise schedule, separate from any network."""

from trajpref.diffusion.schedule import DDPMSchedule, StepOutput

__all__ = ["DDPMSchedule", "StepOutput"]
