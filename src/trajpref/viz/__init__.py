"""Figures from numpy arrays (matplotlib, headless)."""

from trajpref.viz.plot import plot_scene

__all__ = ["plot_scene"]
