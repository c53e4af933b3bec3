"""Axis titles for data of unknown units: ``x`` and ``y`` alone, never ``x [unknown]``; image
coordinates (pixels) drawn y down."""

import matplotlib.figure
import numpy as np
import pytest

from trajpref.viz import plot_panel, plot_scene, plot_scene_scored


@pytest.fixture
def downward(monkeypatch):
    """Whether each saved figure's axes draw y downwards (``yaxis_inverted``)."""
    seen: list[bool] = []
    original = matplotlib.figure.Figure.savefig

    def savefig(fig, *args, **kwargs):
        seen.extend(ax.yaxis_inverted() for ax in fig.axes)
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    return seen


@pytest.fixture
def labels(monkeypatch):
    """The (x, y) axis titles of every figure saved."""
    seen: list[tuple[str, str]] = []
    original = matplotlib.figure.Figure.savefig

    def savefig(fig, *args, **kwargs):
        seen.extend((ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes)
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    return seen


def _scene(p=2, k=3):
    rng = np.random.default_rng(0)
    hist = rng.normal(size=(p, 8, 2)).cumsum(1)  # [P, 8, 2]
    fut = hist[:, -1:] + rng.normal(size=(p, 12, 2)).cumsum(1)  # [P, 12, 2]
    return hist, fut, fut[None] + rng.normal(size=(k, p, 12, 2))  # pred [K, P, 12, 2]


@pytest.mark.parametrize("units", [None, "", "unknown"])
def test_a_panel_of_unknown_units_titles_its_axes_without_a_unit(tmp_path, labels, units):
    hist, fut, pred = _scene()
    plot_panel(hist, pred, np.ones(pred.shape[:2]), tmp_path / "a.png", (-9, 9, -9, 9), units)
    assert labels == [("x", "y")]  # was "x [unknown]" (units None: "x [None]")


def test_a_panel_in_metres_or_pixels_names_its_unit(tmp_path, labels):
    hist, fut, pred = _scene()
    for units in ("m", "px"):
        plot_panel(hist, pred, np.ones(pred.shape[:2]), tmp_path / f"{units}.png",
                   (-9, 9, -9, 9), units)  # fmt: skip
    assert labels == [("x [m]", "y [m]"), ("x [px]", "y [px, down]")]


def test_scene_figures_of_unknown_units_say_no_unit_either(tmp_path, labels):
    hist, fut, pred = _scene()
    plot_scene(hist, fut, pred, tmp_path / "s.png", "unknown")
    plot_scene_scored(hist, fut, pred, np.zeros(pred.shape[:2]), tmp_path / "r.png", None)
    assert {label for pair in labels for label in pair} == {"x", "y", ""}  # "": a shared y
    plot_scene(hist, fut, pred, tmp_path / "m.png", "m")
    assert labels[-1] == ("x [m]", "y [m]")


def test_image_coordinates_are_drawn_y_down_as_the_video_shows_them(tmp_path, downward):
    """sdd's pixels are image coordinates (y down the frame): drawn y up, a scene was the
    frame's mirror image. Metres keep y up."""
    hist, fut, pred = _scene()
    plot_scene(hist, fut, pred, tmp_path / "px.png", "px")
    plot_panel(hist, pred, np.ones(pred.shape[:2]), tmp_path / "p.png", (-9, 9, -9, 9), "px")
    assert downward and all(downward)
    downward.clear()
    plot_scene(hist, fut, pred, tmp_path / "m.png", "m")
    assert downward and not any(downward)
