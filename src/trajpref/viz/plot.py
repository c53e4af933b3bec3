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
    fig.tight_layout()
    out = Path(out)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return out
