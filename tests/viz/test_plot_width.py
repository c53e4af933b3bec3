"""The scene figures are exactly ``width`` inches wide (a PDF's or SVG's page, a PNG's
``width * dpi`` pixels), whatever their title, legend, panels and units: their height follows
what they hold, and nothing is drawn outside the page. They were saved with
``bbox_inches="tight"``, which cropped or grew the canvas (3.3 inches gave 3.41 without a
title, 3.75 with the title plot makes)."""

import re
import warnings

import numpy as np
import pytest
from PIL import Image
from synthetic import plot_arrays

import trajpref.viz.plot as plot
from trajpref.viz import plot_scene, plot_scene_scored

FILE_TITLE = ("nba/test scene 0 (ATL_BOS_0021500389_3_314.96_312.36_a_long_file_name.txt@"
              "frame=0)\ncv, K=5, seed 0, sampler full, neighbour-radius 2; ranked by "
              "models/nba/denoiser.safetensors")  # fmt: skip


def page_width(path) -> float:
    """A figure's width in inches: a PDF's page (its MediaBox), an SVG's width, a PNG's
    pixels (at the dpi it was written at, ``dpi``)."""
    data = path.read_bytes()
    if path.suffix == ".pdf":
        box = [float(v) for v in re.search(rb"/MediaBox \[ ?([^\]]+?) ?\]", data)[1].split()]
        return (box[2] - box[0]) / 72
    return float(re.search(rb'<svg[^>]* width="([\d.]+)pt"', data)[1]) / 72


def png_size(path) -> tuple[int, int]:
    with Image.open(path) as im:
        return im.size


@pytest.fixture
def laid_out(monkeypatch):
    """Per figure saved: how far (pixels) its drawn content reaches past each side of the
    page (left, right, bottom, top; <= 0 inside), and its axes."""
    seen = []
    original = plot._save

    def keep(fig, out, *args, **kwargs):
        fig.draw_without_rendering()
        box = fig.get_tightbbox(fig.canvas.get_renderer())  # inches: titles, legend, axes
        w, h = fig.get_size_inches()
        past = np.array([-box.x0, box.x1 - w, -box.y0, box.y1 - h]) * fig.dpi  # pixels
        seen.append({"past": past, "fig": fig})
        return original(fig, out, *args, **kwargs)

    monkeypatch.setattr(plot, "_save", keep)
    return seen


@pytest.mark.parametrize("width", [1.0, 3.3, 4.99, 5.0, 12.0])
def test_a_scene_figure_is_exactly_its_width_and_holds_everything(tmp_path, laid_out, width):
    """Both figures, with a long title (a file name with no space in it), 14 agents and the
    ball in the legend, stacked (below 5 inches) and side by side."""
    hist, fut, pred = plot_arrays(p=14)
    ball = (np.arange(14) == 13).astype(int)
    scores = np.random.default_rng(1).normal(size=pred.shape[:2])  # [K, P]
    for suffix in (".png", ".pdf"):
        a = plot_scene(hist, fut, pred, tmp_path / f"a{suffix}", "m", FILE_TITLE, ball,
                       width=width, dpi=100)  # fmt: skip
        b = plot_scene_scored(hist, fut, pred, scores, tmp_path / f"b{suffix}", "m", FILE_TITLE,
                              agent_type=ball, width=width, dpi=100)  # fmt: skip
        for out in (a, b):
            if suffix == ".png":
                assert png_size(out)[0] == round(width * 100), out
            else:
                assert page_width(out) == pytest.approx(width, abs=1e-3), out
    for seen in laid_out:
        assert max(seen["past"]) <= 0.5, seen["past"]  # nothing cut off (half a pixel)
        assert "\n" in seen["fig"].get_suptitle()  # the title was wrapped to fit


@pytest.mark.parametrize("scored", [False, True])
@pytest.mark.parametrize("units", ["m", "px"])
def test_every_format_is_the_width_asked_for(tmp_path, laid_out, scored, units):
    """PDF, SVG and PNG (at two dpi) of one figure: the width, and the same layout (text
    takes the same width at any dpi, so the height is the same too)."""
    hist, fut, pred = plot_arrays()
    heights = []
    for name, dpi in (("f.pdf", None), ("f.svg", None), ("f100.png", 100), ("f300.png", 300)):
        out = tmp_path / name
        if scored:
            plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), out, units, "a title",
                              width=3.3, dpi=dpi)  # fmt: skip
        else:
            plot_scene(hist, fut, pred, out, units, "", width=3.3, dpi=dpi)
        if out.suffix == ".png":
            size = png_size(out)
            assert size[0] == round(3.3 * dpi)
            heights.append(size[1] / dpi)
        else:
            assert page_width(out) == pytest.approx(3.3, abs=1e-3)
            heights.append(laid_out[-1]["fig"].get_figheight())
    assert max(heights) - min(heights) < 0.02, heights
    for seen in laid_out:
        assert max(seen["past"]) <= 0.5, seen["past"]
    if units == "px":  # image rows run down
        ax = laid_out[-1]["fig"].axes[0]
        assert ax.get_ylim()[0] > ax.get_ylim()[1]


def test_the_panels_fill_the_width_at_one_scale(tmp_path, laid_out):
    """No empty band beside or above the equal-aspect panels: each is as wide as the layout
    lets it be, and as tall as x and y at one scale make it."""
    hist, fut, pred = plot_arrays()
    for limits in ((-20, 20, -1, 1), (-1, 1, -5, 5), "auto"):
        plot_scene(hist, fut, pred, tmp_path / "a.png", limits=limits, width=3.3)
        for width in (3.3, 7.0):
            plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "b.png",
                              limits=limits, width=width)  # fmt: skip
    for seen in laid_out:
        fig = seen["fig"]
        w, h = fig.get_size_inches()
        for ax in fig.axes:
            cell, box = ax.get_position(original=True), ax.get_position()
            assert box.width * w == pytest.approx(cell.width * w, abs=0.01)
            (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
            assert box.height * h == pytest.approx(box.width * w * abs(y1 - y0) / (x1 - x0),
                                                   abs=0.01)  # fmt: skip


def test_a_long_title_is_wrapped_not_cut_off_and_not_widening_the_page(tmp_path, laid_out):
    """(It had widened the saved canvas to the title's width, 2.5 times the figure's.)"""
    hist, fut, pred = plot_arrays()
    title = "zara1/test scene 100, models/zara1/generator-long.safetensors, K=20; " * 3
    plot_scene(hist, fut, pred, tmp_path / "a.png", "m", title)
    plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "b.png", "m", title)
    assert png_size(tmp_path / "a.png")[0] == round(plot.SCENE_WIDTH * plot.DPI)
    assert png_size(tmp_path / "b.png")[0] == round(plot.SCORED_WIDTH * plot.DPI)
    for seen in laid_out:
        shown = seen["fig"].get_suptitle()
        assert shown.count("\n") >= 2 and shown.replace("\n", " ") == title
        assert max(seen["past"]) <= 0.5


def test_wrapping_keeps_words_mathtext_and_dollars(tmp_path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(dpi=100)
    FigureCanvasAgg(fig)
    probe = fig.text(0, 0, "", fontsize=9)

    def widest(text):
        widths = []
        for line in text.split("\n"):
            probe.set_text(line)
            widths.append(probe.get_window_extent(fig.canvas.get_renderer()).width / 100)
        return max(widths)

    name = "ATL_BOS_0021500389_3_314.96_312.36.txt@frame=0"
    wrapped = plot._wrap(fig, f"scene 0 ({name})", 1.5, 9)
    assert widest(wrapped) <= 1.5 and wrapped.replace("\n", "") == f"scene 0 ({name})"
    assert plot._wrap(fig, "a short one", 3.0, 9) == "a short one"
    maths = plot._wrap(fig, r"$\alpha + \beta_{t}$ and " * 6, 0.6, 9)  # one a line
    assert maths.split("\n")[:-1] == [r"$\alpha + \beta_{t}$", "and"] * 5 + [
        r"$\alpha + \beta_{t}$"
    ]
    # an odd number of $ is drawn as it is: its lines must not turn into mathtext
    odd = plot._wrap(fig, "price $5 and $6 or $7 " * 3, 1.0, 9)
    assert "\n" in odd and all(line.count("$") == line.count(r"\$") for line in odd.split("\n"))


def test_a_width_too_small_for_the_text_still_lays_out(tmp_path, laid_out):
    """At the least width, 1 inch, the legend is one column with its labels wrapped, and the
    layout does not give up (matplotlib warns when it does)."""
    hist, fut, pred = plot_arrays()
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "a.png", "m",
                          FILE_TITLE, width=1.0, dpi=100)  # fmt: skip
    assert png_size(tmp_path / "a.png")[0] == 100
    assert max(laid_out[0]["past"]) <= 0.5
    legend = laid_out[0]["fig"].legends[0]
    assert legend._ncols == 1 and any("\n" in t.get_text() for t in legend.get_texts())
