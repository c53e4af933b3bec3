"""Scene-size bins and collision rates (Col-I, Col-II) of several models on the test splits.

    OMP_NUM_THREADS=1 python benchmarks/social.py --datasets zara2 zara1 \\
        --models pretrained={dataset}/generator cv=cv

For each dataset, every model is evaluated on the test split (K = 20, seed 0) with the
scene-size bins (<= 5, 6-10, 11-20, > 20 agents), the collision rates (TrajNet++'s test, 0.1 m
radius) and, scored by the dataset's published denoiser, maxATS / maxFTS. Writes
benchmarks/results/meta/social_<D>.json, prints the markdown tables of docs/social.md, and
draws minFDE per bin of the --chart dataset (zara2) into docs/social-bins-<D>.png.
``{dataset}`` in a model or scorer spec stands for the dataset's name.
"""

from __future__ import annotations

import argparse
import datetime
import shlex
import sys
import time
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure

from trajpref.data import load_dataset
from trajpref.data.registry import ETH_UCY
from trajpref.evaluation import evaluate
from trajpref.io import atomic_path, write_json
from trajpref.metrics import SCENE_SIZE_EDGES, bin_labels
from trajpref.models.registry import load_predictor
from trajpref.score import TrajectoryScorer

HERE = Path(__file__).resolve().parent
DOCS = HERE.parent / "docs"

REFERENCE_COLLISIONS_PCT = {"LED": 2.62, "SingularTrajectory": 2.96, "MART": 2.23, "MoRE": 2.11}
"""Published collision rates (%) on ETH/UCY: MoRE preprint Table 2, under its own protocol (its
Col-I/Col-II variant and averaging are not stated there; benchmarks/peers.json)."""

OVERALL = (("min_ade", "minADE"), ("min_fde", "minFDE"), ("joint_min_ade", "joint minADE"),
           ("joint_min_fde", "joint minFDE"), ("col_i_pct", "Col-I %"),
           ("col_ii_pct", "Col-II %"), ("col_gt_pct", "GT %"), ("max_ats", "maxATS"))  # fmt: skip
PER_BIN = (("min_ade", "minADE"), ("min_fde", "minFDE"), ("joint_min_fde", "joint minFDE"),
           ("col_i_pct", "Col-I %"), ("col_ii_pct", "Col-II %"), ("max_ats", "maxATS"))  # fmt: skip


def parse_models(specs: list[str]) -> dict[str, str]:
    """``name=spec`` pairs -> {name: spec}, in order."""
    models: dict[str, str] = {}
    for item in specs:
        name, sep, spec = item.partition("=")
        if not sep or not name or not spec:
            sys.exit(f"social.py: error: --models takes NAME=SPEC, got {item!r}")
        if name in models:
            sys.exit(f"social.py: error: the model name {name!r} is given twice")
        models[name] = spec
    return models


def _cell(value, key: str) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return f"{value:.2f}" if key.endswith("_pct") else f"{value:.3f}"


def markdown(result: dict) -> str:
    """The dataset's two tables: whole split, then per scene-size bin."""
    name = result["dataset"]
    lines = [f"**{name}** (test, K = {result['samples']}, seed {result['seed']})", "",
             "| model | " + " | ".join(t for _, t in OVERALL) + " |",
             "|---|" + "---:|" * len(OVERALL)]  # fmt: skip
    for model, res in result["models"].items():
        lines.append(f"| {model} | " + " | ".join(_cell(res.get(k), k) for k, _ in OVERALL) + " |")
    lines += ["", "| agents in scene | model | scenes | agent-windows | "
              + " | ".join(t for _, t in PER_BIN) + " |",
              "|---|---|---:|---:|" + "---:|" * len(PER_BIN)]  # fmt: skip
    for label in result["bin_labels"]:
        for model, res in result["models"].items():
            row = res["bins"][label]
            lines.append(f"| {label} | {model} | {row['scenes']} | {row['agents']} | "
                         + " | ".join(_cell(row.get(k), k) for k, _ in PER_BIN) + " |")  # fmt: skip
    return "\n".join(lines)


def chart(result: dict, path: Path) -> None:
    """Grouped bars: minFDE per scene-size bin, one bar per model."""
    labels = result["bin_labels"]
    models = list(result["models"])
    width = 0.8 / len(models)
    x = np.arange(len(labels))
    fig = Figure(figsize=(6.4, 3.8))  # no pyplot: no global figure state, no backend
    ax = fig.subplots()
    for i, model in enumerate(models):
        bins = result["models"][model]["bins"]
        values = [bins[b].get("min_fde", np.nan) for b in labels]
        bars = ax.bar(x + (i - (len(models) - 1) / 2) * width, values, width, label=model)
        ax.bar_label(bars, fmt="%.2f", fontsize=7)
    scenes = [result["models"][models[0]]["bins"][b]["scenes"] for b in labels]
    ax.set_xticks(x, [f"{b}\n({n} scenes)" for b, n in zip(labels, scenes, strict=True)])
    ax.set_xlabel("agents in the scene")
    ax.set_ylabel(f"minFDE{result['samples']} (m)")
    ax.set_title(f"{result['dataset']} test: minFDE per scene size")
    ax.set_ylim(0, 1.25 * ax.get_ylim()[1])  # room for the legend and the bar labels
    ax.legend(ncols=len(models), loc="upper left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--datasets", nargs="+", default=list(ETH_UCY), choices=list(ETH_UCY))
    parser.add_argument("--models", nargs="+", default=["pretrained={dataset}/generator", "cv=cv"],
                        metavar="NAME=SPEC", help="models to compare: cv, DATASET/NAME or a "
                        "checkpoint path; {dataset} stands for each dataset's name")  # fmt: skip
    parser.add_argument("--scorer", default="{dataset}/denoiser",
                        help="denoiser for maxATS per bin ('none': skip the score)")  # fmt: skip
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--chart", default="zara2", help="dataset whose bar chart is drawn")
    parser.add_argument("--out-dir", default=str(HERE / "results" / "meta"))
    args = parser.parse_args()
    models = parse_models(args.models)
    command = shlex.join(["python", "benchmarks/social.py", *sys.argv[1:]])

    for name in args.datasets:
        ds = load_dataset(name, "test", args.data_root)
        scorer = None
        if args.scorer != "none":
            scorer = TrajectoryScorer.from_checkpoint(args.scorer.format(dataset=name), args.device)
        result = {
            "dataset": name, "split": "test", "samples": args.samples, "seed": args.seed,
            "bin_edges": list(SCENE_SIZE_EDGES), "bin_labels": bin_labels(SCENE_SIZE_EDGES),
            "scorer": None if scorer is None else args.scorer.format(dataset=name),
            "command": command, "date": datetime.date.today().isoformat(),
            "torch_threads": torch.get_num_threads(),
            "reference_collision_pct": REFERENCE_COLLISIONS_PCT, "models": {},
        }  # fmt: skip
        for label, spec in models.items():
            spec = spec.format(dataset=name)
            model = load_predictor(spec, device=args.device)
            start = time.perf_counter()
            res = evaluate(model, ds, args.samples, args.seed, args.device, progress=False,
                           scorer=scorer, bins=SCENE_SIZE_EDGES)  # fmt: skip
            res["seconds"] = round(time.perf_counter() - start, 2)
            result["models"][label] = {"model": spec, **res}
            print(f"{name:>6} {label:>12}: minADE {res['min_ade']:.3f} minFDE {res['min_fde']:.3f}"
                  f"  Col-I {res['col_i_pct']:.2f} %  Col-II {res['col_ii_pct']:.2f} %"
                  f"  ({res['seconds']:.0f} s)", flush=True)  # fmt: skip
        out = Path(args.out_dir) / f"social_{name}.json"
        write_json(out, result)
        print(f"wrote {out}\n\n{markdown(result)}\n", flush=True)
        if name == args.chart:
            png = DOCS / f"social-bins-{name}.png"
            chart(result, png)
            print(f"wrote {png}")


if __name__ == "__main__":
    main()
