import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from trajpref.viz import (
    plot_curves,
    plot_panel,
    plot_scene,
    plot_scene_scored,
    plot_survey_summary,
)

PNG = b"\x89PNG\r\n\x1a\n"


def _scene(p=3, k=5):
    rng = np.random.default_rng(0)
    hist = rng.normal(size=(p, 8, 2)).cumsum(1)
    fut = hist[:, -1:] + rng.normal(size=(p, 12, 2)).cumsum(1)
    pred = fut[None] + rng.normal(size=(k, p, 12, 2))
    return hist, fut, pred


def test_plot_scene_writes_a_png(tmp_path):
    hist, fut, pred = _scene()
    out = plot_scene(hist, fut, pred, tmp_path / "a" / "s.png", "px", "t", np.array([0, 0, 1]))
    assert out.read_bytes()[:8] == PNG
    assert plot_scene(hist, fut, None, tmp_path / "n.png").read_bytes()[:8] == PNG


def test_plot_scene_scored_writes_a_png(tmp_path):
    hist, fut, pred = _scene()
    scores = np.linspace(-1, 1, 15).reshape(5, 3)
    out = plot_scene_scored(hist, fut, pred, scores, tmp_path / "s.png", "m", "title")
    assert out.read_bytes()[:8] == PNG and out.stat().st_size > 5000
    # equal scores (no spread) must not divide by zero
    plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "z.png")


def test_plot_panel_gives_every_panel_of_a_scene_the_same_frame(tmp_path):
    hist, fut, pred = _scene()
    limits = (-10.0, 10.0, -5.0, 5.0)
    a = plot_panel(hist, pred[:2], np.ones((2, 3)), tmp_path / "a.png", limits)
    b = plot_panel(hist, fut[None], np.zeros((1, 3)), tmp_path / "b.png", limits, dashed=True)
    assert a.read_bytes()[:8] == PNG and b.read_bytes()[:8] == PNG
    assert Image.open(a).size == Image.open(b).size  # wide limits: a wide picture
    assert Image.open(a).size[0] > Image.open(a).size[1]


def test_plot_survey_summary_skips_missing_values(tmp_path):
    mean, sd = np.array([3.5, 2.0, np.nan]), np.array([0.5, np.nan, np.nan])
    out = plot_survey_summary(["a", "b", "c"], {"human": (mean, sd), "ATS": (mean - 3, sd)},
                              {"human": ["", "**", "ns"]}, tmp_path / "s.png", "t",
                              xlims={"human": (0, 5)})  # fmt: skip
    assert out.read_bytes()[:8] == PNG


def test_long_titles_and_labels_are_not_clipped(tmp_path):
    """The saved canvas grows to hold the whole title: a title wider than the 6.4-inch figure
    is still in the picture (it was cut at the figure's edge)."""
    hist, fut, pred = _scene()
    title = "zara1/test scene 100, models/zara1/generator-long.safetensors, K=20; " * 3
    fig = Figure(dpi=120)
    text = fig.text(0, 0, title, fontsize=9)
    title_px = text.get_window_extent(FigureCanvasAgg(fig).get_renderer()).width
    assert title_px > 6.4 * 120  # wider than the figure itself
    for out in (plot_scene(hist, fut, pred, tmp_path / "a.png", "m", title),
                plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "b.png", "m",
                                  title)):  # fmt: skip
        assert Image.open(out).size[0] >= title_px


def test_plot_curves_lays_panels_in_a_grid_and_refuses_none(tmp_path):
    x = np.arange(4, 44, 4)
    line = (x, 0.3 + 1 / x, {"label": "raw", "linestyle": "--"})
    gap = (x, np.where(x == 20, np.nan, 0.31 + 1 / x), {"label": "averaged"})
    one = plot_curves({"zara1": [line, gap]}, tmp_path / "one.png", "epoch", "minFDE")
    four = plot_curves({n: [line] for n in "abcd"}, tmp_path / "four.png", "epoch", "minFDE",
                       title="t", columns=3)  # fmt: skip
    assert one.read_bytes()[:8] == PNG and four.read_bytes()[:8] == PNG
    (w1, h1), (w4, h4) = Image.open(one).size, Image.open(four).size
    assert w4 > 2 * w1 and h4 > 1.5 * h1  # three columns, two rows
    with pytest.raises(ValueError, match="at least one panel"):
        plot_curves({}, tmp_path / "none.png", "x", "y")


def test_a_tall_or_flat_scene_is_shown_in_a_readable_box(tmp_path, monkeypatch):
    # one walker going straight down 10 m within 0.2 m of x: the panels would be a sliver;
    # the shown box is widened to an aspect of at most 1.3 (at least 0.35 the other way),
    # and every plotted point stays inside it
    import trajpref.viz.plot as plot

    seen = {}
    original = plot._save

    def keep(fig, out):
        seen["axes"] = [(ax.get_xlim(), ax.get_ylim()) for ax in fig.axes]
        return original(fig, out)

    monkeypatch.setattr(plot, "_save", keep)
    t = np.arange(20, dtype=float)
    path = np.stack([0.01 * np.sin(t), -0.5 * t], -1)  # [20, 2]
    for walk in (path, path[:, ::-1]):  # tall, then flat
        hist, fut = walk[None, :8], walk[None, 8:]
        pred = fut[None] + np.zeros((3, 1, 12, 2))
        plot_scene_scored(hist, fut, pred, np.zeros((3, 1)), tmp_path / "t.png")
        (x0, x1), (y0, y1) = seen["axes"][0]
        assert 0.35 - 1e-6 <= (y1 - y0) / (x1 - x0) <= 1.3 + 1e-6
        assert x0 <= walk[:, 0].min() and walk[:, 0].max() <= x1
        assert y0 <= walk[:, 1].min() and walk[:, 1].max() <= y1
