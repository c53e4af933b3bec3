import re

import numpy as np
import pytest
from matplotlib.colors import to_hex, to_rgba
from PIL import Image
from synthetic import plot_arrays

from trajpref.errors import ConfigError
from trajpref.viz import (
    plot_curves,
    plot_panel,
    plot_scene,
    plot_scene_scored,
    plot_survey_summary,
)
from trajpref.viz.plot import PALETTE

PNG = b"\x89PNG\r\n\x1a\n"


def test_plot_scene_writes_a_png(tmp_path):
    hist, fut, pred = plot_arrays()
    out = plot_scene(hist, fut, pred, tmp_path / "a" / "s.png", "px", "t", np.array([0, 0, 1]))
    assert out.read_bytes()[:8] == PNG
    assert plot_scene(hist, fut, None, tmp_path / "n.png").read_bytes()[:8] == PNG


def test_plot_scene_scored_writes_a_png(tmp_path):
    hist, fut, pred = plot_arrays()
    scores = np.linspace(-1, 1, 15).reshape(5, 3)
    out = plot_scene_scored(hist, fut, pred, scores, tmp_path / "s.png", "m", "title")
    assert out.read_bytes()[:8] == PNG and out.stat().st_size > 5000
    # equal scores (no spread) must not divide by zero
    plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "z.png")


def test_plot_panel_gives_every_panel_of_a_scene_the_same_frame(tmp_path):
    hist, fut, pred = plot_arrays()
    limits = (-10.0, 10.0, -5.0, 5.0)
    a = plot_panel(hist, pred[:2], np.ones((2, 3)), tmp_path / "a.png", limits)
    b = plot_panel(hist, fut[None], np.zeros((1, 3)), tmp_path / "b.png", limits, dashed=True)
    assert a.read_bytes()[:8] == PNG and b.read_bytes()[:8] == PNG
    assert Image.open(a).size == Image.open(b).size  # wide limits: a wide picture
    assert Image.open(a).size[0] > Image.open(a).size[1]


def _bars(ax) -> dict[float, float]:
    """The horizontal bars an axis of ``plot_survey_summary`` draws: row (y) -> length."""
    return {round(b.get_y() + b.get_height() / 2, 6): b.get_width() for b in ax.patches}


def test_plot_survey_summary_skips_missing_values(tmp_path, drawn):
    mean, sd = np.array([3.5, 2.0, np.nan]), np.array([0.5, np.nan, np.nan])
    out = plot_survey_summary(["a", "b", "c"], {"human": (mean, sd), "ATS": (mean - 3, sd)},
                              {"human": ["", "**", "ns"]}, tmp_path / "s.png", "t",
                              xlims={"human": (0, 5)})  # fmt: skip
    assert out.read_bytes()[:8] == PNG
    (fig,) = drawn
    human, ats = fig.axes
    # row c (NaN) draws no bar on either axis, and its mark "ns" is not placed
    assert _bars(human) == {0: 3.5, 1: 2.0} and _bars(ats) == {0: 0.5, 1: -1.0}
    assert [(t.get_text(), t.xy) for t in human.texts] == [("**", (2.0, 1))]  # sd NaN: 0
    assert len(ats.texts) == 0 and human.get_xlim() == (0, 5)


def test_the_ground_truth_draws_no_ats_fts_or_ade_bar(tmp_path, drawn):
    from trajpref.survey.analyze import Analysis, MethodRow, figure_data
    from trajpref.survey.manifest import GROUND_TRUTH

    def row(method, human, score, ade):
        return MethodRow(method, 12, human, 0.5, human, 0.5, human, 0.5, score, 0.1, score - 1,
                         0.2, ade=ade, ade_sd=0.3, marks={"human": "*"})  # fmt: skip

    rows = [row("A", 4.0, 0.4, 1.5), row(GROUND_TRUTH, 4.5, 0.0, 0.0)]
    result = Analysis("t", {}, "human", False, 2, 2, 2, 4, "A", rows, [], {}, units="m")
    names, columns, marks, xlims = figure_data(result)
    assert names == ["A", GROUND_TRUTH]
    human, ats, fts, ade = columns.values()
    assert human[0].tolist() == [4.0, 4.5]  # the ground truth is rated like any method
    for (mean, _), value in zip((ats, fts, ade), (0.4, 0.4 - 1, 1.5), strict=True):
        assert mean[0] == pytest.approx(value) and np.isnan(mean[1])
    plot_survey_summary(names, columns, marks, tmp_path / "s.png", xlims=xlims)
    bars = [_bars(ax) for ax in drawn[0].axes]
    assert bars[0] == {0: 4.0, 1: 4.5}
    assert [list(b) for b in bars[1:]] == [[0], [0], [0]]  # no bar in the ground truth's row


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

    def keep(fig, out, *args):
        seen["axes"] = [(ax.get_xlim(), ax.get_ylim()) for ax in fig.axes]
        return original(fig, out, *args)

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


# --- a paper author's figures (review of 2026-12: formats, limits, ranks, colours) ---


def _lines(fig, prefix):
    return {line.get_gid(): line for ax in fig.axes for line in ax.get_lines()
            if (line.get_gid() or "").startswith(prefix)}  # fmt: skip


def _all_figures(hist, fut, pred, out):
    def name(what):
        return out.with_name(what + out.suffix)

    x, box = np.arange(3.0), (-10.0, 10.0, -5.0, 5.0)
    bars = {"h": (np.ones(1), np.ones(1))}
    return [
        plot_scene(hist, fut, pred, name("scene")),
        plot_scene_scored(hist, fut, pred, np.zeros(pred.shape[:2]), name("scored")),
        plot_panel(hist, pred[:2], np.ones((2, 3)), name("panel"), box),
        plot_survey_summary(["a"], bars, {}, name("summary")),
        plot_curves({"a": [(x, x, {"label": "a"})]}, name("curves"), "x", "y"),
    ]


def test_every_figure_is_written_in_the_format_its_suffix_names(tmp_path):
    """A PNG was written into a .pdf or .svg name (LaTeX then failed on it)."""
    hist, fut, pred = plot_arrays()
    for suffix, magic in ((".pdf", b"%PDF"), (".svg", b"<svg"), (".PNG", PNG)):
        for out in _all_figures(hist, fut, pred, tmp_path / f"f{suffix}"):
            head = out.read_bytes()[:400]
            assert magic in head, (out, head[:20])
    # a suffix that names no format it writes: refused before anything is written
    for name in ("f.jpg", "f.eps", "f"):
        with pytest.raises(ConfigError, match=r"format its suffix names \(\.png, \.pdf, \.svg\)"):
            plot_scene(hist, fut, pred, tmp_path / name)
        assert not (tmp_path / name).exists()


def test_dpi_sets_a_pngs_pixels_and_width_its_printed_size(tmp_path):
    hist, fut, pred = plot_arrays()
    w1 = Image.open(plot_scene(hist, fut, pred, tmp_path / "a.png", dpi=100)).size[0]
    w2 = Image.open(plot_scene(hist, fut, pred, tmp_path / "b.png", dpi=200)).size[0]
    assert 1.9 < w2 / w1 < 2.1
    # a paper's column: 3.3 inches at 100 dpi, legend and labels included (the scored figure
    # stacks its panels; it was 11 inches wide, its text then 2.7 pt in print)
    for out in (plot_scene(hist, fut, pred, tmp_path / "c.png", width=3.3, dpi=100),
                plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "d.png",
                                  width=3.3, dpi=100)):  # fmt: skip
        assert 300 <= Image.open(out).size[0] <= 350
    with pytest.raises(ConfigError, match="width"):
        plot_scene(hist, fut, pred, tmp_path / "e.png", width=0)


def test_a_far_out_sample_does_not_set_the_axes(tmp_path, drawn):
    """One sample 100 m out made the scene a small blob in the middle of the axes."""
    hist, fut, pred = plot_arrays(p=3, k=20)
    pred[4, 1] += np.linspace(0, 100, 12)[:, None]  # [T_f, 2] one sample runs away
    plot_scene(hist, fut, pred, tmp_path / "a.png")
    plot_scene_scored(hist, fut, pred, np.eye(20, 3)[::-1] + (np.arange(20) == 4)[:, None],
                      tmp_path / "b.png")  # fmt: skip  # the far-out sample ranked best
    truth_max = max(hist[..., 0].max(), fut[..., 0].max())
    scene_max = max(truth_max, np.delete(pred, 4, 0)[..., 0].max())  # the other samples
    for fig, shown_max in zip(drawn, (scene_max, truth_max), strict=True):
        x1 = fig.axes[0].get_xlim()[1]
        assert shown_max <= x1 < 30, x1  # the rest of the scene fills the axes
    drawn.clear()
    plot_scene(hist, fut, pred, tmp_path / "c.png", limits="all")
    assert drawn[0].axes[0].get_xlim()[1] >= pred[..., 0].max()
    plot_scene(hist, fut, pred, tmp_path / "d.png", limits=(-1, 2, -3, 4))
    assert drawn[1].axes[0].get_xlim() == (-1, 2) and drawn[1].axes[0].get_ylim() == (-3, 4)
    with pytest.raises(ConfigError, match="x0 < x1"):
        plot_scene(hist, fut, pred, tmp_path / "e.png", limits=(2, 1, 0, 1))


def test_max_samples_caps_the_samples_drawn_per_agent(tmp_path, drawn):
    hist, fut, pred = plot_arrays(p=3, k=20)
    plot_scene(hist, fut, pred, tmp_path / "a.png", max_samples=4)
    for line in _lines(drawn[0], "samples-").values():
        xy = line.get_xydata()
        starts = np.isfinite(xy[:, 0]) & ~np.isfinite(np.r_[np.nan, xy[:-1, 0]])
        assert starts.sum() == 4
    assert len(_lines(drawn[0], "samples-")) == 3


def test_the_ground_truth_is_drawn_over_the_samples_and_the_position_marker(tmp_path, drawn):
    """Twenty samples buried the dashed ground truth, and a walker standing still hid its
    ground truth under its position marker; its end is marked on top now."""
    hist, fut, pred = plot_arrays()
    hist[0], fut[0] = hist[0, -1], hist[0, -1]  # standing still
    plot_scene(hist, fut, pred, tmp_path / "a.png")
    truth, ends = _lines(drawn[0], "truth-"), _lines(drawn[0], "truth-end-")
    samples, marks = _lines(drawn[0], "samples-"), _lines(drawn[0], "position-")
    for i in range(3):
        assert truth[f"truth-{i}"].get_zorder() > samples[f"samples-{i}"].get_zorder()
        assert ends[f"truth-end-{i}"].get_zorder() > marks[f"position-{i}"].get_zorder()
    np.testing.assert_allclose(ends["truth-end-0"].get_xydata()[0], hist[0, -1])


def test_agents_get_colour_blind_safe_colours_and_markers_beyond_the_palette(tmp_path, drawn):
    from matplotlib.colors import to_hex

    from trajpref.viz.plot import PALETTE

    hist, fut, pred = plot_arrays(p=14, k=2)
    plot_scene(hist, fut, pred, tmp_path / "a.png")
    marks = _lines(drawn[0], "position-")
    styles = {(to_hex(m.get_color()), m.get_marker()) for m in marks.values()}
    assert len(styles) == 14  # no two agents alike
    assert {c for c, _ in styles} <= {c.lower() for c in PALETTE}


def test_the_legend_is_neutral_and_explains_every_marker(tmp_path, drawn):
    """The legend's lines were agent 0's colour, and the ball's star had no entry."""
    from matplotlib.colors import to_hex

    hist, fut, pred = plot_arrays()
    ball = np.array([0, 0, 1])
    plot_scene(hist, fut, pred, tmp_path / "a.png", agent_type=ball)
    plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "b.png", agent_type=ball)
    for fig in drawn:
        legend = fig.legends[0]
        texts = [t.get_text() for t in legend.get_texts()]
        assert "the ball" in texts and "last observed position" in texts
        assert any(t.startswith("ground truth") for t in texts)
        colours = {to_hex(h.get_color()) for h in legend.legend_handles}
        assert colours == {to_hex("0.15")}
    star = _lines(drawn[1], "position-2")
    assert {m.get_marker() for m in star.values()} == {"*"}  # in both panels of Fig. 2


def test_the_ranked_panel_shades_by_rank_and_says_what_it_shows(tmp_path, drawn):
    """The second-ranked sample was 0.97-1.0 opaque (shaded min-max over all K) and the
    title said top-2 whatever K was."""
    hist, fut, pred = plot_arrays(k=5)
    scores = np.array([1.0, 0.99, -5, -6, -7])[:, None].repeat(3, 1)  # [K, P] two close
    plot_scene_scored(hist, fut, pred, scores, tmp_path / "a.png", score_name="S's ATS")
    ranked = drawn[0].axes[1]
    assert ranked.get_title() == "each agent's 2 best of K = 5 samples\nby S's ATS"
    lines = _lines(drawn[0], "rank")
    for i in range(3):
        best, second = lines[f"rank0-{i}"], lines[f"rank1-{i}"]
        assert best.get_alpha() == 1.0 and second.get_alpha() <= 0.5
        assert best.get_linewidth() > second.get_linewidth()
    texts = [t.get_text() for t in drawn[0].legends[0].get_texts()]
    assert "best by score" in texts and "2nd by score" in texts
    # K = 1: nothing is ranked, and the title does not say top-2
    plot_scene_scored(hist, fut, pred[:1], scores[:1], tmp_path / "b.png")
    title = drawn[1].axes[1].get_title()
    assert "K = 1" in title and "2" not in title
    assert len(_lines(drawn[1], "rank")) == 3


def test_a_box_far_from_square_and_a_huge_figure_are_refused_before_drawing(tmp_path):
    """--limits=0,1,0,1000 drew a 781 x 683,619 px PNG (4.5 GB); width 40 at dpi 2400 too."""
    from trajpref.viz.plot import plot_scene

    history = np.zeros((1, 8, 2)) + np.linspace(0, 1, 8)[None, :, None]  # [P, T_h, 2]
    future = np.zeros((1, 12, 2)) + np.linspace(1, 2, 12)[None, :, None]  # [P, T_f, 2]
    out = tmp_path / "f.png"
    with pytest.raises(ConfigError, match=r"1000 high and 1 wide; .* 1000x as tall as it is "
                       r"wide \(at most 20\)"):  # fmt: skip
        plot_scene(history, future, None, out, limits=(0, 1, 0, 1000))
    with pytest.raises(ConfigError, match=r"at most 20000 a side"):
        plot_scene(history, future, None, out, width=40, dpi=2400)
    assert not out.exists()
    plot_scene(history, future, None, out, limits=(0, 2, 0, 2))  # a square box draws
    assert out.stat().st_size > 1000


# A paper author's review of `trajpref plot` (walkthrough 67): the ball hidden under its own
# ground truth and coloured as a player, no --keep, a ranked legend of twenty entries that
# did not say which way the score ranks, a standing agent's samples under its marker, agents
# numbered in one figure and not the other (their numbers on their paths), and SVG text drawn
# as outlines.


def _ax_lines(ax, prefix):
    return {line.get_gid(): line for line in ax.get_lines()
            if (line.get_gid() or "").startswith(prefix)}  # fmt: skip


def _numbers(ax) -> dict[str, object]:
    """The agents' number labels of ``ax``, by their text."""
    return {t.get_text(): t for t in ax.texts if t.get_text().isdigit()}


def test_the_ball_is_black_on_top_of_its_ground_truth_and_takes_no_players_colour(
        tmp_path, drawn):  # fmt: skip
    """NBA: the ball's star lay under its own dashed ground truth (zorder 4 < 5), and the ball
    (agent 0) took PALETTE[0], the blue of player 6; its history looked like a player's."""
    hist, fut, pred = plot_arrays(p=8)
    ball = (np.arange(8) == 0).astype(int)
    plot_scene(hist, fut, pred, tmp_path / "a.png", agent_type=ball)
    plot_scene_scored(hist, fut, pred, np.zeros((5, 8)), tmp_path / "b.png", agent_type=ball)
    for fig in drawn:
        ax = fig.axes[0]
        star = _ax_lines(ax, "position-0")["position-0"]
        truth, end = (
            _ax_lines(ax, "truth-0")["truth-0"],
            _ax_lines(ax, "truth-end-0")["truth-end-0"],
        )
        assert star.get_marker() == "*"
        assert star.get_zorder() > max(truth.get_zorder(), end.get_zorder())  # on top
        assert to_hex(star.get_markerfacecolor()) == "#000000"
        assert to_hex(star.get_markeredgecolor()) == "#ffffff"  # its halo
        player = _ax_lines(ax, "position-1")["position-1"]
        assert star.get_markersize() > 1.5 * player.get_markersize()
        # the players take the palette in turn, the ball skipped: 1..7 -> PALETTE[0..5], [0]
        colours = [to_hex(_ax_lines(ax, f"position-{i}")[f"position-{i}"].get_color())
                   for i in range(8)]  # fmt: skip
        assert colours[0] == "#000000"
        assert colours[1:] == [c.lower() for c in (*PALETTE, PALETTE[0])]
        history = _ax_lines(ax, "history-0")["history-0"]
        assert history.get_linestyle() not in ("-", "solid")  # dotted, not a player's
        assert to_hex(history.get_color()) == "#000000"
    # the samples are the ball's colour too
    samples = _ax_lines(drawn[0].axes[0], "samples-0")["samples-0"]
    assert to_hex(samples.get_color()) == "#000000"
    handle = next(h for h in drawn[0].legends[0].legend_handles if h.get_label() == "the ball")
    assert handle.get_marker() == "*" and handle.get_linestyle() not in ("-", "None", "none")


def test_the_ranked_legend_has_three_rank_entries_and_says_which_way_the_score_ranks(
        tmp_path, drawn):  # fmt: skip
    """--draw-samples 20 listed 20 entries (best ... 20th by score), a third of the figure,
    and nothing said that a higher ATS ranks first."""
    hist, fut, pred = plot_arrays(k=20)
    scores = np.random.default_rng(2).normal(size=(20, 3))  # [K, P]
    plot_scene_scored(hist, fut, pred, scores, tmp_path / "a.png", top=20)
    legend = drawn[0].legends[0]
    texts = [t.get_text().replace("\n", " ") for t in legend.get_texts()]
    ranked = [t for t in texts if "by score" in t]
    assert ranked[:2] == ["best by score", "2nd by score"] and len(ranked) == 3
    assert ranked[2].startswith("3rd\u201320th by score")
    title = legend.get_title().get_text().replace("\n", " ")
    assert "rank by diffusion score (ATS), higher = more human-like" in title
    # three ranks: each named; two: as before
    for top, want in ((3, ["best by score", "2nd by score", "3rd by score"]),
                      (2, ["best by score", "2nd by score"])):  # fmt: skip
        plot_scene_scored(hist, fut, pred, scores, tmp_path / "b.png", top=top)
        texts = [t.get_text() for t in drawn[-1].legends[0].get_texts()]
        assert [t for t in texts if "by score" in t] == want


def test_the_ranked_panel_shows_a_standing_agents_samples_through_its_marker(tmp_path, drawn):
    """An almost standing agent's best samples were drawn under its filled position marker
    (samples zorder <= 2, marker 4)."""
    hist, fut, pred = plot_arrays(k=4)
    hist[0] = hist[0, -1] + 0.001 * np.arange(8)[:, None]  # [T_h, 2] almost still
    pred[:, 0] = hist[0, -1] + 0.02 * np.random.default_rng(3).normal(size=(4, 12, 2))
    plot_scene_scored(hist, fut, pred, np.zeros((4, 3)), tmp_path / "a.png")
    truth_panel, ranked = drawn[0].axes
    best = _ax_lines(ranked, "rank0-0")["rank0-0"]
    for i in range(3):
        mark = _ax_lines(ranked, f"position-{i}")[f"position-{i}"]
        shown = mark.get_zorder() < best.get_zorder() or to_rgba(mark.get_markerfacecolor())[3] == 0
        assert shown, i
        full = _ax_lines(truth_panel, f"position-{i}")[f"position-{i}"]
        assert mark.get_markersize() < full.get_markersize()  # smaller than in the other panel


def test_both_figures_number_the_agents_beside_their_paths(tmp_path, drawn):
    """plot_scene did not number the agents (the scored figure did), and the numbers sat at a
    fixed (5, 4) pt, on the path of an agent walking up and right."""
    t = np.arange(20, dtype=float)[:, None]  # [T, 1]
    walks = [np.hstack([t, t]), np.hstack([-t, 0 * t]), np.hstack([0 * t + 5, -t])]  # [T, 2]
    path = np.stack(walks) * 0.4  # [P, T, 2]: up-right, left, down
    hist, fut = path[:, :8], path[:, 8:]
    pred = fut[None] + np.zeros((2, 3, 12, 2))
    plot_scene(hist, fut, pred, tmp_path / "a.png")
    plot_scene_scored(hist, fut, pred, np.zeros((2, 3)), tmp_path / "b.png")
    for ax in (drawn[0].axes[0], drawn[1].axes[0]):
        numbers = _numbers(ax)
        assert set(numbers) == {"0", "1", "2"}
        for i, label in numbers.items():
            motion = hist[int(i), -1] - hist[int(i), -2]
            motion /= np.linalg.norm(motion)
            offset = np.array(label.xyann) / np.linalg.norm(label.xyann)
            assert offset @ motion < 0.1, (i, offset)  # not ahead, onto its future
            assert offset @ motion > -0.9, (i, offset)  # not behind, onto its history
    assert "its number beside it" in drawn[0].legends[0].get_title().get_text()
    plot_scene(hist, fut, pred, tmp_path / "c.png", numbers=False)
    assert not _numbers(drawn[-1].axes[0])
    assert "number" not in drawn[-1].legends[0].get_title().get_text()


def test_image_coordinates_turn_the_numbers_offset_with_the_page(tmp_path, drawn):
    """In pixels the y axis points down the page: an agent walking down the image (y growing)
    moves down the page, and its number must not sit on its history above it."""
    t = np.arange(20, dtype=float)[:, None]
    path = np.hstack([0 * t + 50, 10 * t])[None]  # [1, T, 2] y grows: down the page
    hist, fut = path[:, :8], path[:, 8:]
    plot_scene(hist, fut, None, tmp_path / "a.png", units="px")
    label = _numbers(drawn[0].axes[0])["0"]
    assert label.xyann[1] > 0  # up the page (offset points are the page's), behind its move


def test_svg_text_stays_text(tmp_path):
    """The SVG's text was drawn as outlines (no <text> element), so it could not be edited."""
    hist, fut, pred = plot_arrays()
    svg = plot_scene(hist, fut, pred, tmp_path / "a.svg", title="Scene one").read_text()
    assert "<text" in svg and "Scene one" in svg
    svg = plot_scene_scored(hist, fut, pred, np.zeros((5, 3)), tmp_path / "b.svg").read_text()
    assert re.search(r"<text[^>]*>ground truth", svg)
