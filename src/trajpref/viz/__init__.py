"""Figures from numpy arrays (matplotlib, headless)."""

from trajpref.viz.plot import (
    plot_curves,
    plot_panel,
    plot_scene,
    plot_scene_scored,
    plot_survey_summary,
)

__all__ = ["plot_curves", "plot_panel", "plot_scene", "plot_scene_scored", "plot_survey_summary"]
