"""Figures from numpy arrays (matplotlib, headless), in the format a file's suffix names."""

from trajpref.viz.plot import (
    FORMATS,
    figure_format,
    plot_curves,
    plot_panel,
    plot_scene,
    plot_scene_scored,
    plot_survey_summary,
    scene_limits,
)

__all__ = [
    "FORMATS",
    "figure_format",
    "plot_curves",
    "plot_panel",
    "plot_scene",
    "plot_scene_scored",
    "plot_survey_summary",
    "scene_limits",
]
