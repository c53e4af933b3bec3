"""Figures from numpy arrays (matplotlib, headless)."""

from trajpref.viz.plot import plot_scene, plot_scene_scored

__all__ = ["plot_scene", "plot_scene_scored"]
