"""The figures leave the process that draws them as they found it (walkthrough 69): importing
``trajpref.viz`` switched matplotlib's backend to Agg (``matplotlib.use`` at import, closing a
host's pyplot figures); the scene figures set matplotlib's ``rcParams`` for the whole process
while drawing (``plt.rc_context``, which also put back every key on leaving, another thread's
change among them); and finding whether the layout gave up caught every thread's warnings
(``warnings.catch_warnings``, process-wide before Python 3.14): a planner thread's warning
shown once was shown again each time a figure was laid out meanwhile."""

from __future__ import annotations

import subprocess
import sys
import threading
import warnings

import matplotlib
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from synthetic import plot_arrays

import trajpref.viz.plot as plot
from trajpref.viz import plot_scene, plot_scene_scored

RENDERING = {"pdf.fonttype": 42, "svg.fonttype": "none", "text.hinting": "none"}
"""What the scene figures need of matplotlib's rcParams while they are drawn and saved."""
TITLE_SIZE, LABEL_SIZE, TICK_SIZE = 9, 8, 7
"""Their text's sizes in points: titles, axis titles, tick labels and legend."""

PLOTS = """
import numpy as np
import trajpref.viz as viz
rng = np.random.default_rng(0)
hist = rng.normal(size=(2, 8, 2)).cumsum(1)
fut = hist[:, -1:] + rng.normal(size=(2, 12, 2)).cumsum(1)
pred = fut[None] + rng.normal(size=(3, 2, 12, 2))
viz.plot_scene(hist, fut, pred, OUT + "/a.png", "m", "a title")
viz.plot_scene_scored(hist, fut, pred, rng.normal(size=(3, 2)), OUT + "/b.pdf")
viz.plot_panel(hist, pred, np.ones((3, 2)), OUT + "/c.png", (-9, 9, -9, 9))
viz.plot_survey_summary(["a"], {"h": (np.ones(1), np.ones(1))}, {}, OUT + "/d.png")
viz.plot_curves({"v": [(np.arange(3), np.arange(3.0), {"label": "l"})]}, OUT + "/e.svg", "x", "y")
"""


def _python(code: str, tmp_path) -> None:
    proc = subprocess.run([sys.executable, "-c", f"OUT = {str(tmp_path)!r}\n{code}"],
                          capture_output=True, text=True, timeout=300, check=False)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_importing_and_plotting_keep_the_hosts_backend_and_its_figures(tmp_path):
    """A host with its own backend (svg here) and a pyplot figure open: importing
    ``trajpref.viz`` and ``trajpref.demo`` and drawing every figure leave both as they were."""
    code = (
        "import matplotlib\n"
        "matplotlib.use('svg')\n"
        "import matplotlib.pyplot as plt\n"
        "host = plt.figure()\n"
        "import trajpref.viz\n"
        "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
        + PLOTS
        + "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
        "assert plt.get_fignums() == [host.number], plt.get_fignums()\n"
        "import trajpref.demo\n"
        "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
        "assert plt.get_fignums() == [host.number], plt.get_fignums()\n"
    )
    _python(code, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.pdf", "c.png", "d.png",
                                                          "e.svg"]  # fmt: skip


def test_plotting_imports_no_pyplot_and_chooses_no_backend(tmp_path):
    """Drawn headless on their own canvas: pyplot is never imported (no figure of ours in its
    list, nothing for it to show or to keep), and so no backend is chosen."""
    code = "import sys\n" + PLOTS + "assert 'matplotlib.pyplot' not in sys.modules\n"
    _python(code, tmp_path)


def _warn_once(text: str) -> None:
    """A warning from one fixed line, as a planner's ``warnings.warn``: shown once there under
    Python's default filter."""
    warnings.warn(text, UserWarning, stacklevel=1)


def test_plotting_does_not_show_a_warning_shown_once_again(tmp_path):
    """One thread, a warning shown once between figures: each figure's layout reset every
    registry of warnings shown (changing the warning filters does), so it showed each time."""
    hist, fut, pred = plot_arrays()
    text = "walkthrough 69: frame_interval differs from the model's step (one thread)"
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("default")
        for i in range(4):
            _warn_once(text)
            plot_scene(hist, fut, pred, tmp_path / f"{i}.png", "m", "t")
    assert [str(w.message) for w in shown].count(text) == 1


def test_a_figure_drawn_in_one_thread_does_not_repeat_another_threads_warnings(
    tmp_path, monkeypatch
):
    """A planner thread warns (a warning shown once) while this thread lays a figure out, at
    each of the layout's draws in turn (events, not timing): it is shown once. It was caught
    by the layout's ``catch_warnings`` and shown again each time."""
    hist, fut, pred = plot_arrays()
    text = "walkthrough 69: frame_interval differs from the model's step (two threads)"
    rounds = 5  # the first five draws; each figure draws at least once
    drawing, warned, stop = threading.Event(), threading.Event(), threading.Event()
    draws = []
    original = Figure.draw_without_rendering

    def draw(self):  # the layout's draw: the planner warns now, while it is under way
        if len(draws) < rounds:
            draws.append(self)
            drawing.set()
            assert warned.wait(30), "the planner thread did not warn"
            warned.clear()
        return original(self)

    def planner():
        for _ in range(rounds):
            drawing.wait(30)
            if stop.is_set():
                return
            drawing.clear()
            _warn_once(text)
            warned.set()

    monkeypatch.setattr(Figure, "draw_without_rendering", draw)
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("default")
        thread = threading.Thread(target=planner)
        thread.start()
        try:
            for i in range(rounds):
                plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / f"{i}.png")
                if len(draws) == rounds:
                    break
        finally:
            stop.set()
            drawing.set()
            thread.join(30)
    assert not thread.is_alive() and len(draws) == rounds
    assert [str(w.message) for w in shown].count(text) == 1


def test_a_scene_figure_sets_only_what_the_renderers_read(tmp_path, monkeypatch, drawn):
    """While a scene figure is drawn, matplotlib's ``rcParams`` hold ``RENDERING`` and nothing
    else of ours (the text sizes are the texts' own), and a key that another thread sets
    meanwhile is kept (``rc_context`` put every key back on leaving)."""
    hist, fut, pred = plot_arrays()
    seen = []
    original = Figure.draw_without_rendering

    def draw(self):
        seen.append({k: matplotlib.rcParams[k] for k in ("font.size", *RENDERING)})
        matplotlib.rcParams["lines.linewidth"] = 3.25  # another thread's setting, meanwhile
        return original(self)

    monkeypatch.setattr(Figure, "draw_without_rendering", draw)
    with matplotlib.rc_context():  # puts the test's change back
        matplotlib.rcParams["font.size"] = 10.0
        before = {k: matplotlib.rcParams[k] for k in RENDERING}
        plot_scene(hist, fut, pred, tmp_path / "a.png", "m", "a title")
        plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "b.png", "m", "t")
        assert matplotlib.rcParams["lines.linewidth"] == 3.25
        assert {k: matplotlib.rcParams[k] for k in RENDERING} == before
        assert matplotlib.rcParams["font.size"] == 10.0
    assert seen and all(s == {"font.size": 10.0, **RENDERING} for s in seen), seen
    assert len(drawn) == 2
    for fig in drawn:  # the sizes, in points, each text was given
        assert [t.get_fontsize() for t in fig.texts if t.get_gid() == "suptitle"] == [TITLE_SIZE]
        legend = fig.legends[0]
        assert {t.get_fontsize() for t in legend.get_texts()} == {TICK_SIZE}
        assert legend.get_title().get_fontsize() == TICK_SIZE
        for ax in fig.axes:
            if ax.get_title():
                assert ax.title.get_fontsize() == TITLE_SIZE
            assert ax.xaxis.label.get_fontsize() == LABEL_SIZE
            ticks = ax.get_xticklabels() + ax.get_yticklabels()
            assert {t.get_fontsize() for t in ticks} == {TICK_SIZE}
            assert ax.xaxis.get_offset_text().get_fontsize() == TICK_SIZE


def test_laid_out_tells_a_layout_that_gave_up_by_the_axes_positions():
    """A figure too short for its title: the layout gives up (matplotlib warns, as it does)
    and ``_laid_out`` says so; taller, it is laid out."""
    fig = Figure(figsize=(3.0, 1.0), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.set_title("a panel")
    fig.suptitle("\n".join(["a title of many lines"] * 8))
    with pytest.warns(UserWarning, match="constrained_layout not applied"):
        assert not plot._laid_out(fig)
    fig.set_size_inches(3.0, 6.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert plot._laid_out(fig)
        assert plot._laid_out(fig)  # laid out again at the same size: the same, applied
    assert ax.get_in_layout()


@pytest.mark.parametrize("scored", [False, True])
def test_the_least_width_is_fitted_without_the_layout_giving_up(tmp_path, monkeypatch, scored):
    """One inch wide, a long title and 14 agents' legend: the figure is made tall enough for
    its text before each layout (``_text_height``), so that the layout never gives up on the
    way (it gave up up to three times a figure, each warning caught and thrown away)."""
    hist, fut, pred = plot_arrays(p=14)
    results = []
    original = plot._laid_out

    def laid_out(fig):
        results.append(original(fig))
        return results[-1]

    monkeypatch.setattr(plot, "_laid_out", laid_out)
    title = "nba/test scene 0 (ATL_BOS_0021500389_3_314.96_a_long_file_name.txt@frame=0) " * 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        if scored:
            plot_scene_scored(hist, fut, pred, np.zeros((5, 14)), tmp_path / "a.png", "m",
                              title, width=1.0, dpi=100)  # fmt: skip
        else:
            plot_scene(hist, fut, pred, tmp_path / "a.png", "m", title, width=1.0, dpi=100)
    assert results and all(results), results
