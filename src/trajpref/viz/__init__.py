"""Figures from numpy arrays (matplotlib, headless), in the format a file's suffix names.

Each is drawn on its own canvas: importing this package or drawing leaves matplotlib's
backend and pyplot's figures as they were (``plot.new_figure``)."""

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
