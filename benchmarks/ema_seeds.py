"""Does the weight average's gain replicate over seeds? Paired raw-vs-averaged validation of
generator runs trained with ``generator.ema_epochs > 0``; validation only.

Each such run validates its raw weights (``val_raw_*`` in its metrics log) and its averaged
weights (``val_*``) at every evaluation, so one run is its own control: same seed, same
batches, same budget. For each run this keeps the epoch the training loop keeps for each set
of weights (lowest minADE20 + minFDE20) and reports the change of minFDE20 (and minADE20) from
the raw to the averaged one; per fold, the mean and standard deviation over its seeds.

    # seed 0 trained on the CPU (runs/ema/<D>), seeds 1 and 2 on a borrowed GPU
    # (benchmarks/gpu_sweep/jobs_2026-11-26.txt, unpacked into runs/gpu1126)
    python benchmarks/ema_seeds.py runs/ema/* runs/gpu1126/R-* \\
        --machine "runs/ema=2-core CPU" --machine "runs/gpu1126=one NVIDIA H100 80GB (borrowed)" \\
        --out benchmarks/results/meta/ema_seeds_val.json

The check it serves (docs/pretraining.md, "Does the average's gain replicate over seeds?"),
fixed before its runs: an adopted fold keeps the average when the mean paired change of
minFDE20 over its seeds is at most -0.5 %.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from trajpref.results import write_meta
from trajpref.train import read_metrics
from trajpref.viz import plot_curves

KEEP_BAR = -0.5
"""Percent: an adopted fold keeps the average when its mean paired change is at most this."""


def paired(run_dir: Path) -> dict[str, Any]:
    """The kept raw and averaged validation of one run, and the change between them."""
    cfg_path = run_dir / "config.yaml"
    if not cfg_path.is_file():
        raise SystemExit(f"{run_dir}: no config.yaml (not a training run folder)")
    cfg = yaml.safe_load(cfg_path.read_text())
    evals = [r for r in read_metrics(run_dir, "generator") if "val_raw_min_fde" in r]
    if not evals:
        raise SystemExit(
            f"{run_dir}: no validation of raw weights in generator_metrics.jsonl "
            "(was it trained with generator.ema_epochs > 0?)"
        )
    raw = min(evals, key=lambda r: r["val_raw_min_ade"] + r["val_raw_min_fde"])
    avg = min(evals, key=lambda r: r["val_min_ade"] + r["val_min_fde"])
    return {
        "run": str(run_dir),
        "dataset": cfg["data"]["dataset"],
        "seed": int(cfg["seed"]),
        "epochs_done": evals[-1]["epoch"],
        "raw": {"epoch": raw["epoch"], "min_ade": raw["val_raw_min_ade"],
                "min_fde": raw["val_raw_min_fde"]},
        "averaged": {"epoch": avg["epoch"], "min_ade": avg["val_min_ade"],
                     "min_fde": avg["val_min_fde"]},
        "change_fde_pct": 100 * (avg["val_min_fde"] / raw["val_raw_min_fde"] - 1),
        "change_ade_pct": 100 * (avg["val_min_ade"] / raw["val_raw_min_ade"] - 1),
    }  # fmt: skip


def by_fold(runs: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per dataset: the seeds, each seed's paired change, their mean and standard deviation
    (population, ``ddof=0``; a single seed has spread 0)."""
    folds: dict[str, dict[str, Any]] = {}
    for name in sorted({r["dataset"] for r in runs}):
        own = sorted((r for r in runs if r["dataset"] == name), key=lambda r: r["seed"])
        seeds = [r["seed"] for r in own]
        if len(set(seeds)) != len(seeds):
            raise SystemExit(f"{name}: seed given twice ({seeds}); pass each run once")
        fde = np.array([r["change_fde_pct"] for r in own])
        ade = np.array([r["change_ade_pct"] for r in own])
        folds[name] = {"seeds": seeds, "change_fde_pct": fde.tolist(),
                       "mean_fde_pct": float(fde.mean()), "std_fde_pct": float(fde.std()),
                       "mean_ade_pct": float(ade.mean()), "std_ade_pct": float(ade.std()),
                       "replicates": bool(fde.mean() <= KEEP_BAR)}  # fmt: skip
    return folds


def curves(run_dir: Path) -> dict[str, np.ndarray]:
    """A run's validation minFDE20 per evaluated epoch, raw and averaged: [E] each."""
    evals = [r for r in read_metrics(run_dir, "generator") if "val_raw_min_fde" in r]
    return {"epoch": np.array([r["epoch"] for r in evals]),
            "raw": np.array([r["val_raw_min_fde"] for r in evals]),
            "averaged": np.array([r["val_min_fde"] for r in evals])}  # fmt: skip


def plot(runs: list[dict[str, Any]], out: Path) -> None:
    """One panel per dataset: each seed's raw (dashed) and averaged (solid) validation curve,
    one colour per seed."""
    panels: dict[str, list] = {}
    for r in sorted(runs, key=lambda r: (r["dataset"], r["seed"])):
        c = curves(Path(r["run"]))
        color = f"C{r['seed'] % 10}"
        panels.setdefault(r["dataset"], []).extend([
            (c["epoch"], c["raw"], {"color": color, "linestyle": "--",
                                    "label": f"seed {r['seed']} raw"}),
            (c["epoch"], c["averaged"], {"color": color, "label": f"seed {r['seed']} averaged"}),
        ])  # fmt: skip
    title = "Generator weights, raw (dashed) and moving average (solid), per seed"
    plot_curves(panels, out, "epoch", "validation minFDE20", title=title)


def parse_machine(text: str) -> tuple[str, str]:
    prefix, sep, what = text.partition("=")
    if not sep or not prefix or not what:
        raise argparse.ArgumentTypeError(f"expected PATH_PREFIX=DESCRIPTION, got {text!r}")
    return prefix, what


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, nargs="+", help="run folders (config.yaml + metrics)")
    parser.add_argument(
        "--machine", type=parse_machine, action="append", default=[],
        help="PATH_PREFIX=DESCRIPTION: where the runs under a prefix trained",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument(
        "--plot", type=Path, default=None,
        help="also draw every run's raw and averaged validation curves (PNG)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    runs = [paired(d) for d in args.runs if d.is_dir()]
    if not runs:
        parser.error("no run folders among the arguments")
    for r in runs:
        r["train_machine"] = next(
            (what for prefix, what in args.machine if r["run"].startswith(prefix)), "not stated"
        )
    folds = by_fold(runs)
    print("| fold | seed: paired change of validation minFDE20 (raw -> averaged) | mean ± std "
          "minFDE20 | mean ± std minADE20 | mean <= -0.5 % |")  # fmt: skip
    print("|---|---|---|---|---|")
    for name, f in folds.items():
        each = ", ".join(
            f"{s}: {c:+.2f} %" for s, c in zip(f["seeds"], f["change_fde_pct"], strict=True)
        )
        print(f"| {name} | {each} | {f['mean_fde_pct']:+.2f} ± {f['std_fde_pct']:.2f} % | "
              f"{f['mean_ade_pct']:+.2f} ± {f['std_ade_pct']:.2f} % | "
              f"{'yes' if f['replicates'] else 'no'} |")  # fmt: skip
    write_meta(args.out, split="val", keep_bar_pct=KEEP_BAR, folds=folds, runs=runs)
    if args.plot is not None:
        plot(runs, args.plot)
        print(f"wrote {args.plot}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
