"""Scene figures: histories, ground truth and sampled futures, in the dataset's units.

Every ``plot_*`` function writes the format that its file name's suffix names (``FORMATS``:
PNG, PDF or SVG); any other suffix is a ``ConfigError`` before anything is drawn (a PNG
written under a ``.pdf`` name broke LaTeX). ``dpi`` sets a PNG's pixels per inch.

The scene figures (``plot_scene``, ``plot_scene_scored``) give each agent a colour of a
colour-blind-safe palette (``PALETTE``) and, beyond its length, another marker (``MARKERS``),
the ball black with a star (``agent_styles``), and number the agents (``label_offset``);
their legend, in a neutral colour, explains the line styles and markers. By default their
axes hold every history and ground truth and the bulk of the samples, not a sample that runs
far out (``scene_limits``). They are exactly ``width`` inches wide (a PDF's or SVG's page, a
PNG's ``width * dpi`` pixels), their height what their panels take at that width: a title or
legend wider than that is wrapped onto more lines, not cut off and not widening the page.

Figures are drawn headless on their own canvas (``new_figure``): this module neither chooses
nor switches matplotlib's backend and leaves pyplot alone (none of its figures is in pyplot's
list), so that importing it and plotting from an application, a notebook or another thread
changes nothing there."""

from __future__ import annotations

import math
import numbers
import operator
import re
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib import patheffects
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from trajpref.errors import ConfigError, DataError
from trajpref.io import atomic_path

FORMATS = {".png": "png", ".pdf": "pdf", ".svg": "svg"}
"""The file suffixes a figure may have, and the format each writes (not EPS: PostScript has
no transparency, and the samples' would be lost)."""
DPI = 120
"""A PNG's pixels per inch unless ``dpi`` says otherwise."""
PALETTE = ("#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9")
"""The agents' colours: Okabe and Ito's colour-blind-safe set (their black is the legend's
neutral colour, their pale yellow does not show as a thin line on white)."""
MARKERS = ("o", "s", "^", "D", "v", "P")
"""The agents' position markers: agent ``i`` has ``MARKERS[i // len(PALETTE)]``, so agents
that share a colour differ in marker."""
BALL = 1
"""``agent_type`` of the ball (``trajpref.types.AGENT_BALL``): drawn with a star."""
BALL_COLOUR = "#000000"
"""The ball's colour (Okabe and Ito's black): no player's, so that it is not taken for one;
the players take the palette's colours in turn, the ball skipped (``agent_styles``)."""
NEUTRAL = "0.15"
"""The legend's colour: it explains line styles and markers, not an agent."""
LIMITS = ("auto", "all")
"""``limits``' names: ``auto`` leaves out samples that run far out; ``all`` holds them."""
FAR_OUT = 3.0
"""A sample runs far out when its reach lies more than this many interquartile ranges above
the upper quartile of its agent's samples' reaches (Tukey's far-out fence; ``far_out``)."""
SCENE_WIDTH = 6.4
"""``plot_scene``'s default width in inches."""
SCORED_WIDTH = 7.0
"""``plot_scene_scored``'s default width in inches (a two-column page's text width)."""
EDGE = 0.1
"""Inches that a scene figure's title and legend keep clear of each side of the page (their
lines are wrapped to the width less twice this)."""
TITLE_SIZE, LABEL_SIZE, TICK_SIZE = 9, 8, 7
"""A scene figure's text in points at the printed size (a scene figure is ``width`` inches
wide: printed at that width, it shows them so): the figure's and the panels' titles, the axes'
titles, and the tick labels, the legend and the agents' numbers. Each is given to the text
it sizes, not set in matplotlib's ``rcParams``, which the whole process shares."""
RENDERING = {"pdf.fonttype": 42, "svg.fonttype": "none", "text.hinting": "none"}
"""What only matplotlib's renderers read, from its ``rcParams`` (no figure or text takes them
itself), so set there while a scene figure is drawn and saved (``rendering``): TrueType fonts
embedded in PDF files (as journals ask), an SVG's text kept as text (editable, not drawn as
outlines), and text not hinted to a PNG's pixels: it takes the same width at every dpi as in a
PDF or SVG, so that the layout (the legend's columns, the title's lines) is the same in each
(hinted text at 120 dpi is up to 5 % wider than at 300)."""
_RENDERING_LOCK = threading.RLock()


@contextmanager
def rendering() -> Iterator[None]:
    """``RENDERING`` in matplotlib's ``rcParams`` within, and those three keys as they were
    after (any other key, which another thread may set meanwhile, is left alone; matplotlib's
    ``rc_context`` would put every key back). One figure at a time holds them: two threads
    drawing scene figures do not put back each other's values."""
    with _RENDERING_LOCK:
        before = {key: matplotlib.rcParams[key] for key in RENDERING}
        matplotlib.rcParams.update(RENDERING)
        try:
            yield
        finally:
            matplotlib.rcParams.update(before)


def new_figure(size: tuple[float, float], dpi: float, layout: str | None = None) -> Figure:
    """A figure of ``size`` inches on its own Agg canvas: drawn and saved headless whatever
    matplotlib's backend, which it neither needs nor changes, and not pyplot's (no figure
    manager, nothing to close; it is freed when no longer used). In a notebook it shows as
    any figure does."""
    fig = Figure(figsize=size, dpi=dpi, layout=layout)
    FigureCanvasAgg(fig)  # the canvas sets itself as fig.canvas
    return fig


def figure_format(out: str | Path) -> str:
    """The format a figure named ``out`` is written in, by its suffix (any case); a
    ``ConfigError`` naming the suffixes there are for any other."""
    suffix = Path(out).suffix.lower()
    if suffix not in FORMATS:
        got = f"{suffix} is none of them" if suffix else "it has none"
        raise ConfigError(f"{out}: a figure is written in the format its suffix names "
                          f"({', '.join(FORMATS)}); {got}")  # fmt: skip
    return FORMATS[suffix]


def agent_style(i: int) -> tuple[str, str]:
    """Player ``i``'s colour and position marker (``i`` counts the agents that are not the
    ball: ``agent_styles``)."""
    return PALETTE[i % len(PALETTE)], MARKERS[(i // len(PALETTE)) % len(MARKERS)]


def agent_styles(agent_type: np.ndarray | None, p: int) -> list[tuple[str, str, bool]]:
    """Each of ``p`` agents' colour, position marker and whether it is the ball: the ball
    (``agent_type == BALL``) ``BALL_COLOUR`` and a star, the others ``agent_style`` in turn,
    counting only them (the ball takes no player's colour)."""
    styles, player = [], 0
    for i in range(p):
        if agent_type is not None and int(agent_type[i]) == BALL:
            styles.append((BALL_COLOUR, "*", True))
        else:
            styles.append((*agent_style(player), False))
            player += 1
    return styles


HISTORY = "[P, T_h, 2] (agents, observed steps, x/y)"
"""The shape of a scene figure's histories, as its errors name it."""


def as_array(name: str, value: Any, shape: str = "") -> np.ndarray:
    """``value`` as a float64 numpy array: a numpy array, anything ``np.asarray`` reads (nested
    lists), or a torch tensor on any device (read through ``.detach().cpu()``; this package
    does not import torch). ``DataError`` naming ``name`` (and the expected ``shape``) for
    None, a single number and anything that is not an array of numbers. NaN stays (an unseen
    position is not drawn)."""
    expected = f" {shape}" if shape else ""
    if value is None or isinstance(value, (numbers.Number, str, bytes)):
        raise DataError(f"{name} must be an array{expected}, got {value!r}")
    if callable(getattr(value, "detach", None)):  # a torch tensor: to the CPU, bf16 to fp32
        value = value.detach().cpu()
        if callable(getattr(value, "is_floating_point", None)) and value.is_floating_point():
            value = value.float()
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise DataError(f"{name}: expected an array of numbers{expected} ({exc})") from None
    if array.ndim == 0:
        raise DataError(f"{name} must be an array{expected}, got a single value ({value})")
    return array


def scene_arrays(
    history: Any, future: Any = None, pred: Any = None
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """A scene figure's inputs as float64 numpy arrays (``as_array``), their shapes checked
    against each other: history [P, T_h, 2], future [P, T_f, 2] or None (no ground truth, as
    ``predict_scene``'s output has none), pred [K, P, T_f, 2] or None. ``DataError`` naming
    the argument, the shape expected and the shape given."""
    hist = as_array("history", history, HISTORY)
    if hist.ndim != 3 or hist.shape[2] != 2 or hist.shape[1] < 1:
        raise DataError(f"history: expected {HISTORY}, got {list(hist.shape)}")
    p = hist.shape[0]
    fut = None
    if future is not None:
        want = (f"[{p}, T_f, 2] (the history's {p} agents, future steps, x/y; None: no ground "
                "truth)")  # fmt: skip
        fut = as_array("future", future, want)
        if fut.ndim != 3 or fut.shape[0] != p or fut.shape[2] != 2 or fut.shape[1] < 1:
            raise DataError(f"future: expected {want}, got {list(fut.shape)}")
    samples = None
    if pred is not None:
        t_f = "T_f" if fut is None else fut.shape[1]
        want = f"[K, {p}, {t_f}, 2] (samples, the history's {p} agents, future steps, x/y)"
        samples = as_array("pred", pred, want)
        right = samples.ndim == 4 and samples.shape[1] == p and samples.shape[3] == 2 and (
            fut is None or samples.shape[2] == fut.shape[1])  # fmt: skip
        if not right:
            hint = ""
            if samples.ndim == 3 and samples.shape[0] == p:
                hint = " (one sample? add a leading axis: pred[None])"
            elif samples.ndim == 4 and samples.shape[0] == p and samples.shape[1] != p:
                hint = (" (agents first? samples lead, as predict_scene returns them: "
                        "pred.transpose(1, 0, 2, 3))")  # fmt: skip
            raise DataError(f"pred: expected {want}, got {list(samples.shape)}{hint}")
    return hist, fut, samples


def _agent_types(agent_type: Any, p: int) -> np.ndarray | None:
    """``agent_type`` [P] as a numpy array (None stays None), its shape checked."""
    if agent_type is None:
        return None
    types = as_array("agent_type", agent_type, f"[{p}] (0 person, {BALL} ball)")
    if types.shape != (p,):
        raise DataError(f"agent_type: expected [{p}] (one flag per agent: 0 person, {BALL} "
                        f"ball), got {list(types.shape)}")  # fmt: skip
    return types


def _count(name: str, value: Any) -> int:
    """``value`` as an int >= 1 (numpy integers count), else ``ConfigError``."""
    try:
        count = None if isinstance(value, bool) else operator.index(value)
    except TypeError:
        count = None
    if count is None or count < 1:
        raise ConfigError(f"{name}: at least 1 sample per agent, an integer, got {value!r}")
    return count


def far_out(history: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """[K, P] True for the samples that run far out: a sample's reach is its farthest point
    from its agent's last observed position, and it is far out when that lies more than
    ``FAR_OUT`` interquartile ranges above the upper quartile of its agent's K reaches, and
    more than a quarter of that quartile above it (so that of samples of almost equal reach
    none is far out).

    history [P, T_h, 2], pred [K, P, T_f, 2]."""
    start = history[:, -1]  # [P, 2]
    reach = np.linalg.norm(pred - start[None, :, None], axis=-1).max(-1)  # [K, P]
    q1, q3 = np.nanpercentile(reach, [25, 75], axis=0)  # [P], [P]
    fence = q3 + np.maximum(FAR_OUT * (q3 - q1), 0.25 * q3)  # [P]
    return reach > fence[None]  # NaN reaches compare False: their points are dropped later


MAX_ASPECT = 20.0
"""How much taller than wide (or wider than tall) an explicit ``limits`` box may be: x and y
share one scale, so the figure takes the box's shape (0-1 by 0-1000 made a 683,619 px tall
PNG and took 4.5 GB)."""

MAX_PIXELS = 20_000
"""The most pixels a figure may have on a side (``width`` or height times ``dpi``)."""


def _check_pixels(size: tuple[float, float], dpi: float) -> None:
    """ConfigError for a figure of ``size`` inches at ``dpi`` beyond ``MAX_PIXELS`` a side."""
    w, h = size[0] * dpi, size[1] * dpi
    if max(w, h) > MAX_PIXELS:
        raise ConfigError(f"the figure would be {w:.0f} x {h:.0f} pixels (at most {MAX_PIXELS} "
                          "a side): a smaller width or dpi")  # fmt: skip


def check_limits(limits) -> str | tuple[float, float, float, float]:
    """``limits`` checked: ``"auto"``, ``"all"`` or ``(x0, x1, y0, y1)``, finite, x0 < x1 and
    y0 < y1 (ConfigError otherwise)."""
    if isinstance(limits, str):
        if limits not in LIMITS:
            raise ConfigError(f"limits: 'auto', 'all' or (x0, x1, y0, y1), got {limits!r}")
        return limits
    try:
        box = tuple(float(v) for v in limits)
    except (TypeError, ValueError):
        box = ()
    if len(box) != 4 or not all(math.isfinite(v) for v in box):
        raise ConfigError(f"limits: 'auto', 'all' or four finite numbers (x0, x1, y0, y1), "
                          f"got {limits!r}")  # fmt: skip
    if not (box[0] < box[1] and box[2] < box[3]):
        raise ConfigError(f"limits (x0, x1, y0, y1) need x0 < x1 and y0 < y1, got {box}")
    ratio = (box[3] - box[2]) / (box[1] - box[0])
    if not 1 / MAX_ASPECT <= ratio <= MAX_ASPECT:  # the axes keep x and y at one scale
        raise ConfigError(f"limits {box}: {box[3] - box[2]:g} high and {box[1] - box[0]:g} "
                          f"wide; x and y are drawn at one scale, so the figure would be "
                          f"{max(ratio, 1 / ratio):.0f}x as {'tall' if ratio > 1 else 'wide'} "
                          f"as it is {'wide' if ratio > 1 else 'tall'} "
                          f"(at most {MAX_ASPECT:g})")  # fmt: skip
    return box


def scene_limits(
    history: np.ndarray,
    future: np.ndarray | None,
    pred: np.ndarray | None = None,
    limits="auto",
    far: np.ndarray | None = None,
) -> tuple[float, float, float, float]:
    """The axes' (x0, x1, y0, y1) of a scene figure. ``auto``: every history and ground truth
    and the samples that do not run far out (``far_out``, or ``far`` [K, P] when given);
    ``all``: every sample too; the box gets a 5 % margin and is widened (or heightened) to an
    aspect between 0.35 and 1.3, so that a scene much taller than wide keeps a readable
    panel. A given (x0, x1, y0, y1) is returned as it is.

    history [P, T_h, 2], future [P, T_f, 2] or None, pred [K, P, T_f, 2] or None."""
    limits = check_limits(limits)
    if not isinstance(limits, str):
        return limits
    history, future, pred = scene_arrays(history, future, pred)
    parts = [history.reshape(-1, 2)] + ([] if future is None else [future.reshape(-1, 2)])
    if pred is not None and pred.size:
        keep = np.ones(pred.shape[:2], bool)  # [K, P]
        if limits == "auto":
            keep = ~(far_out(history, pred) if far is None else far)
        parts.append(pred[keep].reshape(-1, 2))
    pts = np.concatenate(parts)  # [M, 2]
    pts = pts[np.isfinite(pts).all(-1)]
    if not len(pts):
        return -1.0, 1.0, -1.0, 1.0
    lo, hi = pts.min(0), pts.max(0)  # [2]
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.05  # [2], [2]
    if half.max() <= 1e-9 * max(1.0, float(np.abs(centre).max())):  # one point: 1 unit around
        half = np.ones(2)
    aspect = float(np.clip(half[1] / max(half[0], 1e-12), 0.35, 1.3))
    half = np.maximum(half, [half[1] / aspect, half[0] * aspect])  # [2]
    return (float(centre[0] - half[0]), float(centre[0] + half[0]),
            float(centre[1] - half[1]), float(centre[1] + half[1]))  # fmt: skip


WIDTH_RANGE = (1.0, 40.0)
"""A figure's width in inches, least and most (``width``; the CLI's ``--width``)."""

DPI_RANGE = (10.0, 2400.0)
"""A raster figure's pixels per inch, least and most (``dpi``; the CLI's ``--dpi``)."""


def in_range(value: float | None, bounds: tuple[float, float]) -> bool:
    """Whether ``value`` is None (the default) or a finite number within ``bounds``."""
    if value is None:
        return True
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)
    return number and math.isfinite(value) and bounds[0] <= value <= bounds[1]


def _check_size(width: float | None, dpi: float | None) -> None:
    if not in_range(width, WIDTH_RANGE):
        raise ConfigError(f"width: the figure's width in inches, {WIDTH_RANGE[0]:g} to "
                          f"{WIDTH_RANGE[1]:g}, got {width}")  # fmt: skip
    if not in_range(dpi, DPI_RANGE):
        raise ConfigError(f"dpi: pixels per inch of a PNG, {DPI_RANGE[0]:g} to "
                          f"{DPI_RANGE[1]:g}, got {dpi}")  # fmt: skip


def _joined(paths: np.ndarray) -> np.ndarray:
    """[S, T, 2] paths as one [S * (T + 1), 2] polyline broken by NaN rows (one artist)."""
    gap = np.full((paths.shape[0], 1, 2), np.nan)
    return np.concatenate([paths, gap], 1).reshape(-1, 2)


def _halo(width: float) -> list:
    """A white outline under a line or text, so that it shows over the samples."""
    return [patheffects.withStroke(linewidth=width, foreground="white")]


def _legend_handles(samples: str | None, ranks: Sequence[tuple[str, float, float]] = (),
                    ball: bool = False, truth: bool = True) -> list[Line2D]:  # fmt: skip
    """The legend's entries, all in ``NEUTRAL``: what each line style and marker means (the
    ground truth's only where it is drawn, ``truth``); the ball's: its star and its dotted
    history."""
    handles = [Line2D([], [], color=NEUTRAL, lw=2.0, marker="o", ms=3, label="history")]
    if truth:
        handles.append(Line2D([], [], color=NEUTRAL, lw=1.6, ls="--", marker="x", ms=5, mew=1.4,
                              label="ground truth (x: its end)"))  # fmt: skip
    if samples:
        handles.append(Line2D([], [], color=NEUTRAL, lw=0.8, alpha=0.6, label=samples))
    for label, lw, alpha in ranks:
        handles.append(Line2D([], [], color=NEUTRAL, lw=lw, alpha=alpha, label=label))
    handles.append(Line2D([], [], color=NEUTRAL, ls="none", marker="o", ms=6, mfc="white",
                          mec="black", mew=0.6, label="last observed position"))  # fmt: skip
    if ball:
        handles.append(Line2D([], [], color=NEUTRAL, lw=BALL_HISTORY["lw"], ls=BALL_HISTORY["ls"],
                              marker="*", ms=10, mfc=BALL_COLOUR, mec="white", mew=0.8,
                              label="the ball"))  # fmt: skip
    return handles


BALL_HISTORY = {"lw": 1.4, "ls": (0, (1.2, 1.2))}
"""The ball's history: dotted, with no markers (a player's is solid with dots)."""
LABEL_OFFSET = 6.0
"""Points between an agent's last observed position and its number (``label_offset``)."""


def label_offset(history: np.ndarray, down: bool = False,
                 box: tuple[float, float, float, float] | None = None
                 ) -> tuple[tuple[float, float], str, str]:  # fmt: skip
    """Where an agent's number goes: its offset in points from the last observed position,
    and the text's horizontal and vertical alignment. Away from its direction of motion (its
    last move, or the last one it made where it has stopped): beside its path, on the side
    that is up on the page (right for a vertical move), tilted back from the direction it
    goes, so that the number sits neither on its history nor on its future. An agent that
    never moves has it up and right. ``down``: the y axis points down the page (image
    coordinates); ``box`` (x0, x1, y0, y1): the axes, from whose edge the number is turned
    back inwards.

    history [T_h, 2]."""
    pts = history[np.isfinite(history).all(-1)]  # [T', 2]
    motion = np.zeros(2)
    if len(pts) >= 2:
        steps = np.diff(pts, axis=0)  # [T'-1, 2]
        size = np.linalg.norm(steps, axis=-1)  # [T'-1]
        scale = max(1.0, float(np.abs(pts).max()))
        moved = np.flatnonzero(size > 1e-9 * scale)
        if len(moved):
            motion = steps[moved[-1]] / size[moved[-1]]
    if down:
        motion[1] = -motion[1]  # on the page
    if not motion.any():
        way = np.array([0.78, 0.62])  # up and right
    else:
        side = np.array([-motion[1], motion[0]])  # a right angle to the motion
        if side[1] < -1e-9 or (abs(side[1]) <= 1e-9 and side[0] < 0):
            side = -side  # the side up the page (right for a vertical move)
        way = side - 0.5 * motion
        way /= np.linalg.norm(way)
    if box is not None and len(pts):
        x0, x1, y0, y1 = box
        at = pts[-1]
        near = 0.08
        fx, fy = (at[0] - x0) / (x1 - x0), (at[1] - y0) / (y1 - y0)
        if down:
            fy = 1 - fy
        if (fx > 1 - near and way[0] > 0) or (fx < near and way[0] < 0):
            way[0] = -way[0]
        if (fy > 1 - near and way[1] > 0) or (fy < near and way[1] < 0):
            way[1] = -way[1]
    ha = "left" if way[0] > 0.3 else "right" if way[0] < -0.3 else "center"
    va = "bottom" if way[1] > 0.3 else "top" if way[1] < -0.3 else "center"
    return (float(LABEL_OFFSET * way[0]), float(LABEL_OFFSET * way[1])), ha, va


def _draw_agent(ax, i: int, history: np.ndarray, future: np.ndarray | None,
                style: tuple[str, str, bool], label: bool = False, hollow: bool = False,
                down: bool = False, box=None) -> None:  # fmt: skip
    """Agent ``i``'s history, its last observed position and (unless None) its ground truth,
    drawn over the samples: the ground truth last, with a white outline and its end marked,
    so that a walker standing still shows it on top of its position marker. ``style``: its
    colour, marker and whether it is the ball (``agent_styles``): the ball's history is
    dotted, and its star, larger, lies over its ground truth with a white edge. ``label``:
    its number beside it (``label_offset``; ``down`` and ``box`` as that takes them);
    ``hollow``: its position marker smaller and open, so that samples that start there (an
    agent standing still) show through it (the ranked panel).

    history [T_h, 2], future [T_f, 2]."""
    c, m, ball = style
    if ball:
        ax.plot(history[:, 0], history[:, 1], color=c, zorder=3, gid=f"history-{i}",
                **BALL_HISTORY)  # fmt: skip
    else:
        ax.plot(history[:, 0], history[:, 1], color=c, lw=2.0, marker=m, ms=2.5, zorder=3,
                gid=f"history-{i}")  # fmt: skip
    if hollow:
        ax.plot(*history[-1], marker=m, ms=9 if ball else 5, mfc="none", mec=c, mew=1.0,
                ls="none", zorder=4, gid=f"position-{i}")  # fmt: skip
    elif ball:  # over its ground truth (zorder 5, 6): the ball is what the eye looks for
        ax.plot(*history[-1], marker=m, ms=13, color=c, mec="white", mew=1.0, ls="none",
                zorder=6.5, gid=f"position-{i}")  # fmt: skip
    else:
        ax.plot(*history[-1], marker=m, ms=6.5, color=c, mec="black", mew=0.6, ls="none",
                zorder=4, gid=f"position-{i}")  # fmt: skip
    if future is not None:
        gt = np.concatenate([history[-1:], future], 0)  # [T_f+1, 2]
        ax.plot(gt[:, 0], gt[:, 1], color=c, lw=1.6, ls="--", zorder=5, path_effects=_halo(3.2),
                gid=f"truth-{i}")  # fmt: skip
        ax.plot(*gt[-1], marker="x", ms=5, mew=1.4, color=c, ls="none", zorder=6,
                path_effects=_halo(3.0), gid=f"truth-end-{i}")  # fmt: skip
    if label and np.isfinite(history[-1]).all():
        offset, ha, va = label_offset(history, down, box)
        ax.annotate(str(i), history[-1], xytext=offset, textcoords="offset points",
                    fontsize=TICK_SIZE, color=c, fontweight="bold", ha=ha, va=va, zorder=7,
                    clip_on=True, path_effects=_halo(2.0), gid=f"number-{i}")  # fmt: skip


NO_UNITS = (None, "", "unknown")
"""Units that name nothing (a folder read without ``--units``): the axes then say no unit."""


IMAGE_UNITS = ("px", "pixel", "pixels", "pix")
"""Units of image coordinates (sdd): their y axis points down the image, so figures draw it
downwards too (``y_down``), as the video frame shows the scene."""


def y_down(units: str | None) -> bool:
    """Whether ``units`` are image coordinates (``IMAGE_UNITS``, any case), drawn y down."""
    return isinstance(units, str) and units.strip().lower() in IMAGE_UNITS


def axis_label(axis: str, units: str | None) -> str:
    """An axis title: ``x [m]``, or ``x`` alone where the units are unknown (``NO_UNITS``)
    rather than ``x [unknown]``; image coordinates' y says it points down."""
    if units in NO_UNITS:
        return axis
    down = ", down" if axis == "y" and y_down(units) else ""
    return f"{axis} [{units}{down}]"


def _set_axes(ax, box: tuple[float, float, float, float], units: str | None,
              ylabel: bool = True):  # fmt: skip
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(*((box[3], box[2]) if y_down(units) else (box[2], box[3])))  # image rows down
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(axis_label("x", units), fontsize=LABEL_SIZE)
    if ylabel:
        ax.set_ylabel(axis_label("y", units), fontsize=LABEL_SIZE)
    ax.tick_params(labelsize=TICK_SIZE)
    for axis in (ax.xaxis, ax.yaxis):  # an offset or scale beside the tick labels ("1e3")
        axis.get_offset_text().set_fontsize(TICK_SIZE)
    ax.grid(alpha=0.3)


_BREAK_AFTER = re.compile(r"(?<=[_/@.,;:=+-])")
"""Where a word too long for a line (a file name) is broken when it has to be: after these."""


def _dollars(text: str) -> int:
    return text.count("$") - text.count(r"\$")


def _wrap(fig, text: str, width: float, fontsize: float) -> str:
    """``text`` with line breaks added so that no line is wider than ``width`` inches at
    ``fontsize`` points (as ``fig`` draws it): between words, and a word wider than that
    after one of ``_/@.,;:=+-`` (``_BREAK_AFTER``), else between any two characters. Its own
    line breaks are kept, and mathtext (``$...$``) is kept on one line. (Matplotlib reads a
    line with an even number of ``$`` as mathtext: in a line with an odd number, which it
    draws as it is, they are escaped, so that no part of it becomes mathtext.)"""
    renderer = fig.canvas.get_renderer()
    probe = fig.text(0, 0, "", fontsize=fontsize)

    def fits(line: str) -> bool:
        probe.set_text(line)
        return probe.get_window_extent(renderer).width <= width * fig.dpi

    lines = []
    try:
        for paragraph in text.split("\n"):
            if _dollars(paragraph) % 2:  # not mathtext: none of its lines either
                paragraph = re.sub(r"(?<!\\)\$", r"\\$", paragraph)
            words: list[str] = []
            for word in paragraph.split(" "):
                if words and _dollars(words[-1]) % 2:  # within $...$: one word
                    words[-1] += " " + word
                else:
                    words.append(word)
            line = ""
            for word in words:
                parts = [word]
                if not fits(word) and not _dollars(word):  # broken where it can
                    parts = [q for part in _BREAK_AFTER.split(word) if part
                             for q in ([part] if fits(part) else list(part))]  # fmt: skip
                for j, part in enumerate(parts):
                    joined = line + (" " if j == 0 and line else "") + part
                    if not line or fits(joined):
                        line = joined
                    else:
                        lines.append(line)
                        line = part
            lines.append(line)
    finally:
        probe.remove()
    return "\n".join(lines)


def _legend_below(fig, handles: list[Line2D], title: str, width: float) -> None:
    """The legend, centred at the foot of the figure (the constrained layout keeps its room
    under the panels), in as many columns as fit ``width`` inches less ``EDGE`` a side: all
    of them from 8 inches, at most 4 from 6, else at most 2, down to 1; a legend too wide in
    one column has its title and labels wrapped."""
    room = width - 2 * EDGE
    renderer = fig.canvas.get_renderer()
    most = len(handles) if width >= 8 else 4 if width >= 6 else 2
    for ncols in range(min(most, len(handles)), 0, -1):
        legend = fig.legend(handles=handles, loc="outside lower center", ncols=ncols,
                            frameon=False, title=title, fontsize=TICK_SIZE,
                            title_fontsize=TICK_SIZE, columnspacing=1.2,
                            handlelength=2.2)  # fmt: skip
        wide = legend.get_window_extent(renderer).width / fig.dpi
        if wide <= room or ncols == 1:
            break
        legend.remove()
    if wide > room:  # one column: its labels beside their handles, and its title, wrapped
        texts = legend.get_texts()
        label = max(t.get_window_extent(renderer).width for t in texts) / fig.dpi
        for t in texts:
            t.set_text(_wrap(fig, t.get_text(), max(room - (wide - label), 0.1), TICK_SIZE))
        legend.get_title().set_text(_wrap(fig, title, room, TICK_SIZE))


def _title(fig, title: str, width: float) -> None:
    """``title`` centred at the top of the figure, above the panels and their own titles,
    wrapped to ``width`` inches less ``EDGE`` a side (none when empty)."""
    if title:
        fig.suptitle(_wrap(fig, title, width - 2 * EDGE, TITLE_SIZE),
                     fontsize=TITLE_SIZE).set_gid("suptitle")  # fmt: skip


NUDGE = 1e-9
"""How far (a share of its height) ``_laid_out`` moves each axes before a layout: a layout
that is applied moves it elsewhere."""


def _laid_out(fig) -> bool:
    """Lay ``fig`` out (its constrained layout, drawn without rendering); False where the
    layout found no room for the axes (the figure too short for its titles, labels and
    legend) and left them where they were. Told by where the axes are, not by the warning
    that matplotlib gives then: each axes is first made shorter by a hair (``NUDGE``), and
    one that the layout has not moved from there was not laid out. (Catching the warning
    took ``warnings.catch_warnings``, which before Python 3.14 holds for every thread: it
    caught other threads' warnings, to be shown again each time, and made every warning
    shown "once" show again.) ``_fit_height`` keeps the figure tall enough for its text
    (``_text_height``), so that the layout is not expected to give up."""
    nudged = []
    for ax in fig.axes:
        x0, y0, width, height = ax.get_position(original=True).bounds
        ax.set_position((x0, y0, width, height * (1 - NUDGE)))
        ax.set_in_layout(True)  # set_position takes it out of the layout: back in
        nudged.append(ax.get_position(original=True).bounds)
    fig.draw_without_rendering()
    return any(ax.get_position(original=True).bounds != at
               for ax, at in zip(fig.axes, nudged, strict=True))  # fmt: skip


PAD = 0.1
"""Inches that ``_text_height`` adds to each text for the layout's pads (3 points on each
side of it) and to spare."""
ROOM = 0.5
"""Inches of height that ``_fit_height`` leaves each row of panels, at least, before a
layout (the layout then finds the height they take)."""


def _text_height(fig, axes) -> float:
    """Inches of ``fig``'s height that its text takes: its title and legend, and for each row
    of ``axes`` the most that one of them has above and below it (its title, tick labels and
    axis titles), each with ``PAD`` to spare: more than its constrained layout keeps clear
    of the panels, so that a figure taller than this is laid out (the layout gives up, and
    warns, where the text leaves the panels no height)."""
    renderer = fig.canvas.get_renderer()
    texts = [t for t in (*fig.texts, *fig.legends) if t.get_visible() and t.get_in_layout()]
    inches = sum(t.get_window_extent(renderer).height / fig.dpi + PAD for t in texts)
    rows: dict[int, float] = {}
    for ax in axes:
        outer, own = ax.get_tightbbox(renderer), ax.get_window_extent(renderer)  # pixels
        row = ax.get_subplotspec().rowspan.start
        rows[row] = max(rows.get(row, 0.0), (outer.height - own.height) / fig.dpi + 2 * PAD)
    return inches + sum(rows.values())


def _fit_height(fig, axes, dpi: float) -> None:
    """Give ``fig`` (its width fixed, laid out by its constrained layout) the height at which
    its equal-aspect ``axes`` fill the width the layout gives them: no empty band above and
    below them, none beside them. The layout is found with the axes free to take any shape
    (the constrained layout leaves bands it cannot use around an axes of fixed aspect), each
    step making them as tall as their x and y scales then need; a panel's title wider than
    its panel is wrapped to its width (the layout makes no room beside a panel for its
    title). Before the first layout, and after titles are wrapped, the figure is made at
    least as tall as its text and ``ROOM`` a row of panels (``_text_height``), so that the
    layout does not give up (a narrow figure's wrapped title and legend can be taller than
    the height it starts from). ``dpi``: the PNG's, checked against ``MAX_PIXELS``."""
    w = fig.get_figwidth()
    titles = [ax.title.get_text() for ax in axes]
    aspects = [ax.get_aspect() for ax in axes]  # 1.0: x and y at one scale
    renderer = fig.canvas.get_renderer()
    for ax in axes:
        ax.set_aspect("auto")
    n_rows = len({ax.get_subplotspec().rowspan.start for ax in axes})
    check = True  # whether the text may have outgrown the figure since the last layout
    for _ in range(12):
        if check:  # room for the text and the panels, else the layout would give up
            need = _text_height(fig, axes) + ROOM * n_rows
            if fig.get_figheight() < need:
                fig.set_size_inches(w, need)
            check = False
        h = fig.get_figheight()
        if not _laid_out(fig):  # too short for its text all the same: taller, then fitted
            fig.set_size_inches(w, 1.5 * h + 1.0)
            continue
        wrapped = False
        for ax, title in zip(axes, titles, strict=True):
            room, shown = ax.get_position().width * w, ax.title.get_text()  # inches
            ax.title.set_text(title)
            if ax.title.get_window_extent(renderer).width > room * fig.dpi:
                ax.title.set_text(_wrap(fig, title, room, ax.title.get_fontsize()))
            wrapped |= ax.title.get_text() != shown
        if wrapped:  # laid out again with the titles' new lines (room for them first)
            check = True
            continue
        rows: dict[int, float] = {}
        for ax, aspect in zip(axes, aspects, strict=True):
            box, (x0, x1), (y0, y1) = ax.get_position(), ax.get_xlim(), ax.get_ylim()
            tall = box.width * w * aspect * abs((y1 - y0) / (x1 - x0))  # inches it should be
            row = ax.get_subplotspec().rowspan.start
            rows[row] = max(rows.get(row, -math.inf), tall - box.height * h)
        change = sum(rows.values())  # inches the figure is too short (> 0) or too tall
        if abs(change) < 1e-3:
            break
        fig.set_size_inches(w, max(h + change, 0.5))
    for ax, aspect in zip(axes, aspects, strict=True):
        ax.set_aspect(aspect, adjustable="box")
    _check_pixels((w, fig.get_figheight()), dpi)


def plot_scene(
    history: np.ndarray,
    future: np.ndarray | None,
    pred: np.ndarray | None,
    out: str | Path,
    units: str | None = "m",
    title: str = "",
    agent_type: np.ndarray | None = None,
    *,
    limits="auto",
    max_samples: int | None = None,
    width: float | None = None,
    dpi: float | None = None,
    numbers: bool = True,
    selection: str = "",
) -> Path:
    """Write a figure of one scene, in the format ``out``'s suffix names (``FORMATS``).

    history [P, T_h, 2], future [P, T_f, 2] or None (no ground truth: ``predict_scene``'s
    output), pred [K, P, T_f, 2] or None; absolute coordinates; numpy arrays, lists or torch
    tensors (on any device); agent_type [P] (``BALL``: the ball, drawn in black with a star
    and a dotted history; the players take the palette's colours, ``agent_styles``). Shapes
    that do not fit together are a ``DataError`` naming the argument and the shape expected
    (``scene_arrays``). Each agent has its own colour (and,
    beyond ``len(PALETTE)`` agents, marker): history solid with dots, samples thin, the ground
    truth dashed on top with its end marked. ``limits``: ``auto`` (default: the samples that
    run far out do not widen the axes, ``scene_limits``), ``all`` or (x0, x1, y0, y1).
    ``max_samples``: draw only each agent's first so many samples. ``width``: the figure's
    width in inches (default ``SCENE_WIDTH``), exactly (its height follows the scene's
    aspect); text is at its printed size, so 3.3 suits a paper's column; ``dpi``: a PNG's
    pixels per inch (default ``DPI``). A ``title`` is centred at the top, wrapped to the
    width (an empty one draws none). ``units`` None (or ``""``, ``unknown``): the axes are
    titled without a unit (``axis_label``). ``numbers``: each agent's number (its index)
    beside its last observed position, away from its path (``label_offset``), as
    ``plot_scene_scored`` numbers them. ``selection``: how the samples were kept, e.g.
    ``kept 5 of 20 by score-facility``, said in the legend's samples entry.
    """
    figure_format(out)
    _check_size(width, dpi)
    if max_samples is not None:
        max_samples = _count("max_samples", max_samples)
    history, future, pred = scene_arrays(history, future, pred)
    p = history.shape[0]
    agent_type = _agent_types(agent_type, p)
    if pred is not None and max_samples is not None:
        pred = pred[:max_samples]  # [K', P, T_f, 2]
    box = scene_limits(history, future, pred, limits)
    styles = agent_styles(agent_type, p)
    ball = any(s[2] for s in styles)
    aspect = (box[3] - box[2]) / (box[1] - box[0])
    w = SCENE_WIDTH if width is None else width
    with rendering():
        # the width is fixed; the axes' aspect sets the height (_fit_height), laid out with
        # room for the labels, the title and the legend (from a height with room to spare)
        _check_pixels((w, (w - 0.7) * aspect + 0.8), dpi or DPI)
        fig = new_figure((w, (w - 0.7) * aspect + 2.5), dpi or DPI, "constrained")
        ax = fig.subplots()
        for i in range(p):
            if pred is not None:
                start = np.repeat(history[None, i, -1:], len(pred), 0)  # [K', 1, 2]
                line = _joined(np.concatenate([start, pred[:, i]], 1))  # [K'(T_f+2), 2]
                ax.plot(line[:, 0], line[:, 1], color=styles[i][0], lw=0.8, alpha=0.45,
                        zorder=1, gid=f"samples-{i}")  # fmt: skip
            _draw_agent(ax, i, history[i], None if future is None else future[i], styles[i],
                        label=numbers, down=y_down(units), box=box)  # fmt: skip
        _set_axes(ax, box, units)
        _title(fig, title, w)
        samples = None
        if pred is not None:
            samples = (f"samples per agent: {selection}" if selection
                       else f"samples ({len(pred)} per agent)")  # fmt: skip
        _legend_below(fig, _legend_handles(samples, ball=ball, truth=future is not None),
                      _agents_note(numbers), w)  # fmt: skip
        _fit_height(fig, [ax], dpi or DPI)
        return _save(fig, out, dpi, True)


def _agents_note(numbers: bool) -> str:
    """The legend's title: what an agent's colour and marker (and number) say."""
    return "colour and marker: one agent" + (" (its number beside it)" if numbers else "")


def _ordinal(n: int) -> str:
    return {1: "best", 2: "2nd", 3: "3rd"}.get(n, f"{n}th")


def rank_style(rank: int, top: int) -> tuple[float, float]:
    """Line width and opacity of the sample ranked ``rank`` (0: best) of the ``top`` shown:
    from 2.2 and opaque down to 1.0 and 0.4, by rank alone (not by the score's value)."""
    share = rank / max(top - 1, 1)
    return 2.2 - 1.2 * share, 1.0 - 0.6 * share


def rank_entries(top: int, k: int) -> list[tuple[str, float, float]]:
    """The legend's entries for the ranked samples, (label, line width, opacity): the best,
    the 2nd and, for more, one entry for all the lower ranks (``3rd`` or ``3rd-20th``, drawn
    as the last of them), so that 20 ranks take three entries, not twenty; K = 1: its one
    sample."""
    if k == 1:
        return [("its one sample", *rank_style(0, 1))]
    entries = [(f"{_ordinal(r + 1)} by score", *rank_style(r, top)) for r in range(min(top, 2))]
    if top == 3:
        entries.append(("3rd by score", *rank_style(2, top)))
    elif top > 3:
        entries.append((f"3rd\u2013{_ordinal(top)} by score",
                        *rank_style(top - 1, top)))  # fmt: skip
    return entries


def scored_title(k: int, top: int, score_name: str = "diffusion score (ATS)") -> str:
    """The ranked panel's title, on two lines: which samples of how many, ranked by what."""
    if k == 1:
        return "each agent's one sample (K = 1):\nnothing to rank"
    if top >= k:
        return f"each agent's {k} samples,\nranked by {score_name}"
    best = "best" if top == 1 else f"{top} best"
    return f"each agent's {best} of K = {k} samples\nby {score_name}"


def _scores(scores: Any, k: int, p: int) -> np.ndarray:
    """``plot_scene_scored``'s ``scores`` as a [K, P] array (higher is better), else a
    ``DataError`` saying what it takes (a 1-D [K] array: ``rank_samples``' residual)."""
    want = (f"[{k}, {p}] (one number per sample and agent, higher is better, e.g. each "
            "agent's ATS: ScoreResult.agent_ats)")  # fmt: skip
    array = as_array("scores", scores, want)
    if array.ndim == 1:
        raise DataError(f"scores: expected {want}, got a 1-D [{len(array)}]: rank_samples' "
                        "residual is one number per sample, summed over the agents, and lower "
                        "is better; to draw every agent's samples in its order pass "
                        f"-np.repeat(residual[:, None], {p}, 1)")  # fmt: skip
    if array.shape != (k, p):
        hint = " (agents first? pass scores.T)" if array.shape == (p, k) else ""
        raise DataError(f"scores: expected {want}, got {list(array.shape)}{hint}")
    return array


def plot_scene_scored(
    history: np.ndarray,
    future: np.ndarray,
    pred: np.ndarray,
    scores: np.ndarray,
    out: str | Path,
    units: str | None = "m",
    title: str = "",
    top: int = 2,
    *,
    score_name: str = "diffusion score (ATS)",
    direction: str = "higher = more human-like",
    agent_type: np.ndarray | None = None,
    limits="auto",
    width: float | None = None,
    dpi: float | None = None,
    numbers: bool = True,
    selection: str = "",
) -> Path:
    """Two panels, as the paper's Fig. 2: the ground truth alone, then each agent's ``top``
    samples by score (at most K), the best thickest and opaque, each next one thinner and
    lighter (by rank, as the legend says; ``rank_style``). The ranked panel's title says how
    many of how many samples, ranked by ``score_name`` (``scored_title``); the legend names
    the best, the 2nd and the lower ranks in one entry (``rank_entries``), and says what
    ranks them and which way (``direction``: the scores are higher-is-better, and a higher
    ATS is a sample more human-like by the denoiser than its ground truth's level). In the
    ranked panel each agent's position marker is small and open, so that the samples of an
    agent standing still show through it.

    history [P, T_h, 2], future [P, T_f, 2], pred [K, P, T_f, 2], scores [K, P]: one number
    per sample and agent, HIGHER IS BETTER (each agent's ATS, ``ScoreResult.agent_ats``; a
    residual, lower is better, is drawn best-first by its negation). ``rank_samples``'
    ``residual`` [K] (one number per sample, summed over the agents, lower is better) is
    refused with that hint. Numpy arrays, lists or torch tensors (on any device); shapes that
    do not fit together are a ``DataError`` naming the argument and the shape expected.
    agent_type [P] (``BALL``: the ball, black, with a star; ``agent_styles``). ``limits``:
    ``auto`` (default: every history and ground truth and the shown samples that do not run
    far out among their agent's K), ``all`` or (x0, x1, y0, y1). ``width``: the figure's
    width in inches (default ``SCORED_WIDTH``), exactly (its height follows the panels'
    aspect); below 5 the panels are stacked, one above the other, so that 3.3 suits a paper's
    column; ``dpi``: a PNG's pixels per inch (default ``DPI``). A ``title`` is centred at the
    top, wrapped to the width (an empty one draws none). ``numbers``: each agent's number
    beside it in the ground truth panel (``label_offset``). ``selection``: how the K samples
    were kept, e.g. ``kept 5 of 20 by score-facility``, said in the legend's title.
    """
    figure_format(out)
    _check_size(width, dpi)
    top = _count("top", top)
    if future is None:
        raise DataError("future: the first panel draws the ground truth [P, T_f, 2], got None "
                        "(without one, plot_scene draws the samples)")  # fmt: skip
    if pred is None:
        raise DataError("pred: expected [K, P, T_f, 2] samples to rank, got None")
    history, future, pred = scene_arrays(history, future, pred)
    k, p = pred.shape[:2]
    if k == 0:
        raise DataError("pred: no samples (K = 0): nothing to rank")
    scores = _scores(scores, k, p)
    agent_type = _agent_types(agent_type, p)
    top = min(top, k)
    order = np.argsort(-scores, axis=0, kind="stable")[:top]  # [top, P] best first
    shown = np.take_along_axis(pred, order[..., None, None], 0)  # [top, P, T_f, 2]
    far = np.take_along_axis(far_out(history, pred), order, 0)  # [top, P]
    box = scene_limits(history, future, shown, limits, far=far)
    aspect = (box[3] - box[2]) / (box[1] - box[0])
    styles = agent_styles(agent_type, p)
    ball = any(s[2] for s in styles)
    down = y_down(units)
    w = SCORED_WIDTH if width is None else width
    stacked = w < 5
    with rendering():
        # the width is fixed; the panels' aspect sets the height (_fit_height), laid out with
        # room for the labels, the titles and the legend (from a height with room to spare)
        if stacked:
            size = (w, 2 * (w - 0.7) * aspect + 1.2)
        else:
            size = (w, (w - 1.0) / 2 * aspect + 1.0)
        _check_pixels(size, dpi or DPI)
        fig = new_figure((size[0], size[1] + 2.5), dpi or DPI, "constrained")
        axes = fig.subplots(2 if stacked else 1, 1 if stacked else 2, sharex=True, sharey=True)
        for i in range(p):
            c = styles[i][0]
            for rank in range(top):
                lw, alpha = rank_style(rank, top)
                path = np.concatenate([history[i, -1:], shown[rank, i]], 0)  # [T_f+1, 2]
                axes[1].plot(path[:, 0], path[:, 1], color=c, lw=lw, alpha=alpha,
                             zorder=2 - rank / top, gid=f"rank{rank}-{i}")  # fmt: skip
            _draw_agent(axes[0], i, history[i], future[i], styles[i], label=numbers, down=down,
                        box=box)  # fmt: skip
            _draw_agent(axes[1], i, history[i], None, styles[i], hollow=True)
        axes[0].set_title("ground truth", fontsize=TITLE_SIZE)
        axes[1].set_title(scored_title(k, top, score_name), fontsize=TITLE_SIZE)
        for j, ax in enumerate(axes):
            _set_axes(ax, box, units, ylabel=j == 0 or stacked)
            if stacked and j == 0:
                ax.set_xlabel("")
                ax.tick_params(labelbottom=False)
        note = _agents_note(numbers)
        if k > 1:
            note += f"\nline width and shade: rank by {score_name}, {direction}"
        if selection:
            note += f"\nsamples per agent: {selection}"
        _title(fig, title, w)
        _legend_below(fig, _legend_handles(None, rank_entries(top, k), ball), note, w)
        _fit_height(fig, list(axes), dpi or DPI)
        return _save(fig, out, dpi, True)


def plot_panel(
    history: np.ndarray,
    paths: np.ndarray,
    weights: np.ndarray,
    out: str | Path,
    limits: tuple[float, float, float, float],
    units: str | None = "m",
    dashed: bool = False,
    axis_titles: bool = True,
) -> Path:
    """One panel of a blinded study, drawn as the predictions column of the paper's Fig. 2:
    every agent's history, then its ``R`` shown futures shaded by ``weights`` (darker =
    higher score). No title and no legend, so that nothing names the method.

    history [P, T_h, 2], paths [R, P, T_f, 2] (best first), weights [R, P] in [0, 1];
    ``limits`` (x0, x1, y0, y1) are the same for every panel of a scene; ``dashed`` draws
    the paths as the ground truth is drawn in Fig. 2 (the study's reference image); ``units``
    None (or ``""``, ``unknown``): the axes are titled ``x`` and ``y`` without a unit;
    ``axis_titles=False`` leaves the titles' room but draws them in no colour (the study's
    panels of data whose unit is unknown, so that no rater reads "x [unknown]"). (Its look is
    the study's: a study's panels keep it whatever the scene figures change.)
    """
    figure_format(out)
    p = history.shape[0]
    colours = matplotlib.colormaps["tab10" if p <= 10 else "tab20"]
    aspect = (limits[3] - limits[2]) / max(limits[1] - limits[0], 1e-9)
    fig = new_figure((5.6, 0.9 + 4.4 * float(np.clip(aspect, 0.35, 1.2))), 100)
    ax = fig.subplots()
    for i in range(p):
        c = colours(i % colours.N)
        for rank in range(paths.shape[0]):
            path = np.concatenate([history[i, -1:], paths[rank, i]], 0)  # [T_f+1, 2]
            alpha = 0.3 + 0.7 * float(weights[rank, i])
            ax.plot(path[:, 0], path[:, 1], color=c, lw=2.0 - 0.6 * min(rank, 2),
                    ls="--" if dashed else "-", alpha=alpha)  # fmt: skip
        ax.plot(history[i, :, 0], history[i, :, 1], color=c, lw=2.2, marker="o", ms=3)
        ax.plot(*history[i, -1], marker="o", color=c, ms=7, mec="black", mew=0.6)
    ax.set_xlim(limits[0], limits[1])
    ax.set_ylim(*((limits[3], limits[2]) if y_down(units) else (limits[2], limits[3])))
    ax.set_aspect("equal", adjustable="box")
    shown = {} if axis_titles else {"color": "none"}  # their room kept, the tick values shown
    ax.set_xlabel(axis_label("x", units), **shown)
    ax.set_ylabel(axis_label("y", units), **shown)
    ax.grid(alpha=0.3)
    return _save(fig, out)


def plot_survey_summary(
    names: list[str],
    columns: dict[str, tuple[np.ndarray, np.ndarray]],
    marks: dict[str, list[str]],
    out: str | Path,
    title: str = "",
    xlims: dict[str, tuple[float, float]] | None = None,
) -> Path:
    """The study's result as horizontal bars, one axis per column (human score, ATS, FTS):
    mean and standard deviation per method, with the significance marks beside the bars.

    names [M]; columns: label -> (mean [M], sd [M]) (NaN draws no bar); marks: label -> [M]
    strings ("", "ns", "*", ...); xlims: label -> fixed x range (e.g. the rating scale).
    """
    figure_format(out)
    m = len(names)
    fig = new_figure((3.6 * len(columns), 0.9 + 0.55 * m), 120)
    axes = fig.subplots(1, len(columns), sharey=True, squeeze=False)
    y = np.arange(m)
    for ax, (label, (mean, sd)) in zip(axes[0], columns.items(), strict=True):
        mean = np.asarray(mean, dtype=float)  # [M]
        sd = np.nan_to_num(np.asarray(sd, dtype=float))  # [M]
        ok = np.isfinite(mean)
        ax.barh(y[ok], mean[ok], xerr=sd[ok], color="tab:blue", alpha=0.7, capsize=3)
        ax.axvline(0, color="black", lw=0.6)
        for i, mark in enumerate(marks.get(label, [""] * m)):
            if ok[i] and mark:
                ax.annotate(mark, (mean[i] + sd[i], y[i]), xytext=(4, -3),
                            textcoords="offset points", fontsize=8)  # fmt: skip
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3, axis="x")
        if xlims and label in xlims:
            ax.set_xlim(*xlims[label])
    axes[0][0].set_yticks(y, names)
    axes[0][0].invert_yaxis()
    if title:
        fig.suptitle(title, fontsize=9)
    return _save(fig, out)


def plot_curves(
    panels: dict[str, list[tuple[np.ndarray, np.ndarray, dict]]],
    out: str | Path,
    xlabel: str,
    ylabel: str,
    title: str = "",
    columns: int = 3,
) -> Path:
    """Line plots in a grid, one axis per panel (e.g. validation curves per dataset).

    panels: title -> lines, each ``(x [E], y [E], style)`` where ``style`` holds matplotlib
    keywords (``label``, ``color``, ``linestyle``, ...); NaN values leave gaps. Each panel
    has its own y range; the first panel carries the legend."""
    if not panels:
        raise ValueError("plot_curves needs at least one panel")
    figure_format(out)
    n = len(panels)
    cols = min(columns, n)
    rows = -(-n // cols)
    fig = new_figure((3.6 * cols, 2.8 * rows), 120)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, (name, lines) in zip(axes.flat, panels.items(), strict=False):
        for x, y, style in lines:
            ax.plot(np.asarray(x, dtype=float), np.asarray(y, dtype=float), lw=1.2, **style)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    return _save(fig, out)


NO_DATE = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}
"""Vector files carry no creation date, so that the same figure is the same bytes."""


def _save(fig, out: str | Path, dpi: float | None = None, sized: bool = False) -> Path:
    """Lay out, write in the format ``out``'s suffix names (``figure_format``) through a
    temporary file (``fig`` is not pyplot's: there is nothing to close). ``dpi``: a PNG's
    pixels per inch (default: the figure's own). ``sized``: the figure is written at its own
    size (the scene figures: their width is the one asked for, and their layout holds every
    title, label and legend); otherwise the saved canvas grows or shrinks to hold every title
    and label (``bbox_inches="tight"``, the study's and the benchmarks' figures), so nothing
    is clipped however long the title or however tall the axes' aspect."""
    out = Path(out)
    fmt = figure_format(out)
    if fig.get_layout_engine() is None:  # a figure with its own layout engine keeps it
        fig.tight_layout()
    tight = {} if sized else {"bbox_inches": "tight", "pad_inches": 0.1}
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format=fmt, dpi=dpi or fig.dpi, metadata=NO_DATE.get(fmt),
                    **tight)  # fmt: skip
    return out
