"""Scene figures: histories, ground truth and sampled futures, in the dataset's units."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from trajpref.io import atomic_path  # noqa: E402


def plot_scene(
    history: np.ndarray,
    future: np.ndarray,
    pred: np.ndarray | None,
    out: str | Path,
    units: str = "m",
    title: str = "",
    agent_type: np.ndarray | None = None,
) -> Path:
    """Write a PNG of one scene.

    history [P, T_h, 2], future [P, T_f, 2], pred [K, P, T_f, 2] or None; absolute coordinates.
    Each agent has its own colour: history solid with dots, ground truth dashed, samples thin.
    """
    p = history.shape[0]
    colours = plt.get_cmap("tab10" if p <= 10 else "tab20")
    fig, ax = plt.subplots(figsize=(6.4, 6.0), dpi=120)
    for i in range(p):
        c = colours(i % colours.N)
        label_gt = "ground truth" if i == 0 else None
        label_hist = "history" if i == 0 else None
        if pred is not None:
            for k in range(pred.shape[0]):
                path = np.concatenate([history[i, -1:], pred[k, i]], 0)  # [T_f+1, 2]
                ax.plot(
                    path[:, 0],
                    path[:, 1],
                    color=c,
                    lw=0.8,
                    alpha=0.35,
                    label="samples" if i == 0 and k == 0 else None,
                )
        gt = np.concatenate([history[i, -1:], future[i]], 0)  # [T_f+1, 2]
        ax.plot(gt[:, 0], gt[:, 1], color=c, lw=1.8, ls="--", label=label_gt)
        ax.plot(
            history[i, :, 0], history[i, :, 1], color=c, lw=2.2, marker="o", ms=3, label=label_hist
        )
        marker = "*" if agent_type is not None and agent_type[i] == 1 else "o"
        ax.plot(*history[i, -1], marker=marker, color=c, ms=8, mec="black", mew=0.6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"x [{units}]")
    ax.set_ylabel(f"y [{units}]")
    if title:
        ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _save(fig, out)


def plot_scene_scored(
    history: np.ndarray,
    future: np.ndarray,
    pred: np.ndarray,
    scores: np.ndarray,
    out: str | Path,
    units: str = "m",
    title: str = "",
    top: int = 2,
) -> Path:
    """Two panels, as the paper's Fig. 2: the ground truth alone, then each agent's ``top``
    samples by score, shaded by their score (darker = higher).

    history [P, T_h, 2], future [P, T_f, 2], pred [K, P, T_f, 2], scores [K, P] (higher is
    better, e.g. each agent's ATS).
    """
    p = history.shape[0]
    colours = plt.get_cmap("tab10" if p <= 10 else "tab20")
    shown = [pred[np.argsort(-scores[:, i])[:top], i] for i in range(p)]  # P x [top, T_f, 2]
    pts = np.concatenate([history.reshape(-1, 2), future.reshape(-1, 2),
                          *(s.reshape(-1, 2) for s in shown)])  # fmt: skip  # [M, 2]
    lo, hi = pts.min(0), pts.max(0)  # [2]
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * 1.05 + 1e-6  # [2], [2] with a margin
    # the shown box is widened (or heightened) to an aspect in [0.35, 1.3], so that a scene
    # much taller or wider than the other way keeps readable panels and titles
    aspect = float(np.clip(half[1] / half[0], 0.35, 1.3))
    half = np.maximum(half, [half[1] / aspect, half[0] * aspect])  # [2]
    # "compressed": the two equal-aspect panels keep no empty band around them
    fig, axes = plt.subplots(1, 2, figsize=(11, 1.2 + 5 * aspect), dpi=120, sharex=True,
                             sharey=True, layout="compressed")  # fmt: skip
    for i in range(p):
        c = colours(i % colours.N)
        for ax in axes:
            ax.plot(history[i, :, 0], history[i, :, 1], color=c, lw=2.2, marker="o", ms=3)
            ax.plot(*history[i, -1], marker="o", color=c, ms=7, mec="black", mew=0.6)
        gt = np.concatenate([history[i, -1:], future[i]], 0)  # [T_f+1, 2]
        axes[0].plot(gt[:, 0], gt[:, 1], color=c, lw=2.0, ls="--")
        axes[0].annotate(str(i), history[i, 0], fontsize=7, color=c)
        s = scores[:, i]  # [K]
        lo, hi = float(s.min()), float(s.max())
        for rank, k in enumerate(np.argsort(-s)[:top]):
            weight = 1.0 if hi == lo else (float(s[k]) - lo) / (hi - lo)
            path = np.concatenate([history[i, -1:], pred[k, i]], 0)  # [T_f+1, 2]
            axes[1].plot(path[:, 0], path[:, 1], color=c, lw=2.0 - 0.6 * rank,
                         alpha=0.3 + 0.7 * weight)  # fmt: skip
    axes[0].set_title("ground truth", fontsize=9)
    # a tall scene makes narrow panels: the long title then takes two lines, not its neighbour's
    sep = "\n" if aspect > 0.8 else " "
    axes[1].set_title(f"top-{top} samples per agent{sep}by diffusion score (darker = higher)",
                      fontsize=9)  # fmt: skip
    for ax in axes:
        ax.set_xlim(centre[0] - half[0], centre[0] + half[0])
        ax.set_ylim(centre[1] - half[1], centre[1] + half[1])
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel(f"x [{units}]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(f"y [{units}]")
    if title:
        fig.suptitle(title, fontsize=9)
    return _save(fig, out)


def plot_panel(
    history: np.ndarray,
    paths: np.ndarray,
    weights: np.ndarray,
    out: str | Path,
    limits: tuple[float, float, float, float],
    units: str = "m",
    dashed: bool = False,
) -> Path:
    """One panel of a blinded study, drawn as the predictions column of the paper's Fig. 2:
    every agent's history, then its ``R`` shown futures shaded by ``weights`` (darker =
    higher score). No title and no legend, so that nothing names the method.

    history [P, T_h, 2], paths [R, P, T_f, 2] (best first), weights [R, P] in [0, 1];
    ``limits`` (x0, x1, y0, y1) are the same for every panel of a scene; ``dashed`` draws
    the paths as the ground truth is drawn in Fig. 2 (the study's reference image).
    """
    p = history.shape[0]
    colours = plt.get_cmap("tab10" if p <= 10 else "tab20")
    aspect = (limits[3] - limits[2]) / max(limits[1] - limits[0], 1e-9)
    fig, ax = plt.subplots(figsize=(5.6, 0.9 + 4.4 * float(np.clip(aspect, 0.35, 1.2))), dpi=100)
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
    ax.set_ylim(limits[2], limits[3])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel(f"x [{units}]")
    ax.set_ylabel(f"y [{units}]")
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
    m = len(names)
    fig, axes = plt.subplots(1, len(columns), figsize=(3.6 * len(columns), 0.9 + 0.55 * m),
                             dpi=120, sharey=True, squeeze=False)  # fmt: skip
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
    n = len(panels)
    cols = min(columns, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.8 * rows), dpi=120,
                             squeeze=False)  # fmt: skip
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


def _save(fig, out: str | Path) -> Path:
    """Lay out, write as PNG through a temporary file, close. The saved canvas grows to hold
    every title and label (``bbox_inches="tight"``), so nothing is clipped however long the
    title or however tall the axes' aspect."""
    if fig.get_layout_engine() is None:  # a figure with its own layout engine keeps it
        fig.tight_layout()
    out = Path(out)
    try:
        with atomic_path(out) as tmp:
            fig.savefig(tmp, format="png", bbox_inches="tight", pad_inches=0.1)
    finally:
        plt.close(fig)
    return out
