"""A paper author's review of `trajpref plot` (walkthrough 67): the ball hidden under its own
ground truth and coloured as a player, no --keep, a ranked legend of twenty entries that
did not say which way the score ranks, a standing agent's samples under its marker, agents
numbered in one figure and not the other (their numbers on their paths), and SVG text drawn
as outlines."""

from __future__ import annotations

import re

import numpy as np
import pytest
from matplotlib.colors import to_hex, to_rgba
from synthetic import plot_arrays

from trajpref.cli import main
from trajpref.models import zoo
from trajpref.viz import plot_scene, plot_scene_scored
from trajpref.viz.plot import PALETTE


def _lines(ax, prefix):
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
        star = _lines(ax, "position-0")["position-0"]
        truth, end = _lines(ax, "truth-0")["truth-0"], _lines(ax, "truth-end-0")["truth-end-0"]
        assert star.get_marker() == "*"
        assert star.get_zorder() > max(truth.get_zorder(), end.get_zorder())  # on top
        assert to_hex(star.get_markerfacecolor()) == "#000000"
        assert to_hex(star.get_markeredgecolor()) == "#ffffff"  # its halo
        player = _lines(ax, "position-1")["position-1"]
        assert star.get_markersize() > 1.5 * player.get_markersize()
        # the players take the palette in turn, the ball skipped: 1..7 -> PALETTE[0..5], [0]
        colours = [to_hex(_lines(ax, f"position-{i}")[f"position-{i}"].get_color())
                   for i in range(8)]  # fmt: skip
        assert colours[0] == "#000000"
        assert colours[1:] == [c.lower() for c in (*PALETTE, PALETTE[0])]
        history = _lines(ax, "history-0")["history-0"]
        assert history.get_linestyle() not in ("-", "solid")  # dotted, not a player's
        assert to_hex(history.get_color()) == "#000000"
    # the samples are the ball's colour too
    samples = _lines(drawn[0].axes[0], "samples-0")["samples-0"]
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
    best = _lines(ranked, "rank0-0")["rank0-0"]
    for i in range(3):
        mark = _lines(ranked, f"position-{i}")[f"position-{i}"]
        shown = mark.get_zorder() < best.get_zorder() or to_rgba(mark.get_markerfacecolor())[3] == 0
        assert shown, i
        full = _lines(truth_panel, f"position-{i}")[f"position-{i}"]
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


# --- the command line: plot --keep, as predict takes it ---


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _predicted(capsys, walks, tmp_path, flags, scene=0):
    """predict's samples of ``scene`` with ``flags`` [K', P, T_f, 2]."""
    npz = tmp_path / "p.npz"
    code, _, err = _run(capsys, "predict", "--dataset", walks, "--device", "cpu", "--no-progress",
                        *flags, "--out", npz)  # fmt: skip
    assert code == 0, err
    z = np.load(npz)
    return z["pred"][:, z["scene"] == scene]


def test_plot_keeps_k_prime_as_predict_keeps_them_and_says_so(capsys, walks, tmp_path, plot_calls):
    """plot had no --keep: a figure of the samples a selection keeps could not be made."""
    flags = ["--samples", "4", "--keep", "2", "--select", "facility", "--seed", "3"]
    want = _predicted(capsys, walks, tmp_path, flags)  # [2, P, T_f, 2]
    code, out, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--no-progress",
                          *flags, "--out", tmp_path / "f.png")  # fmt: skip
    assert (code, err) == (0, ""), err
    name, args, kwargs = plot_calls[-1]
    assert name == "plot_scene"
    np.testing.assert_allclose(args[2], want, atol=1e-6)
    assert "kept 2 of 4 by facility" in args[5]  # the title
    assert kwargs["selection"] == "kept 2 of 4 by facility"  # the legend's samples entry
    assert "minADE_2" in out
    # with --scorer: the kept samples ranked, at most K' of them
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--no-progress",
                        *flags, "--scorer", "zara1/denoiser", "--draw-samples", "5",
                        "--out", tmp_path / "g.png")  # fmt: skip
    assert code == 0, err
    name, args, kwargs = plot_calls[-1]
    assert name == "plot_scene_scored" and args[2].shape[0] == 2 and args[7] == 2
    assert kwargs["selection"] == "kept 2 of 4 by facility"
    # the selection's checks are predict's
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--samples", "4",
                        "--keep", "5", "--out", tmp_path / "h.png")  # fmt: skip
    assert code == 2 and "--keep must lie in 1..--samples (4)" in err
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--samples", "4",
                        "--drop", "0.5", "--no-progress", "--out", tmp_path / "h.png")  # fmt: skip
    assert code == 0 and "--drop only applies with --keep" in err


@pytest.mark.skipif("zara1/generator" not in zoo.published(),
                    reason="the package was built without its models")  # fmt: skip
def test_plot_keep_chosen_draws_predicts_chosen_samples(capsys, walks, tmp_path, plot_calls):
    flags = ["--model", "zara1/generator", "--keep", "3", "--chosen"]
    want = _predicted(capsys, walks, tmp_path, [*flags, "--max-scenes", "2"])
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--no-progress",
                        *flags, "--out", tmp_path / "f.png")  # fmt: skip
    assert code == 0, err  # (a warning: the synthetic data has no units)
    _, args, kwargs = plot_calls[-1]
    np.testing.assert_allclose(args[2], want, atol=1e-5)
    assert kwargs["selection"] == "kept 3 of 20 by score-facility (chosen)"
    assert "kept 3 of 20 by score-facility (chosen)" in args[5]


def test_plot_no_numbers(capsys, walks, tmp_path, plot_calls):
    code, _, err = _run(capsys, "plot", "--dataset", walks, "--device", "cpu", "--samples", "2",
                        "--no-progress", "--no-numbers", "--out", tmp_path / "f.png")  # fmt: skip
    assert code == 0, err
    assert plot_calls[-1][2]["numbers"] is False
