"""In-context adaptation (the paper's Sec. 8.4), before vs after, on a validation split.

    OMP_NUM_THREADS=1 python benchmarks/in_context.py --dataset zara1 --split val \\
        --max-windows 100 --params heads all --steps 5

For each --params setting, every chosen window (those with context; at most --max-windows,
evenly spaced over the split) is predicted by the published generator unadapted ("before")
and after adapting a copy on its context windows ("after"), K = --samples, same per-window
seeds (trajpref.adapt, docs/in_context.md). Prints minADE/minFDE before and after, the window
count and seconds per window; writes benchmarks/results/meta/in_context_<D>_<split>.json (a row
per setting, replacing an earlier row of the same setting). Choose the protocol on val splits
only; test is for the final report.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import sys
from pathlib import Path

import numpy as np

from trajpref.adapt import (
    ADAPT_OBJECTIVES,
    ADAPT_PARAMS,
    AdaptConfig,
    context_windows,
    evaluate_in_context,
)
from trajpref.data import load_dataset
from trajpref.io import write_json
from trajpref.models.registry import load_predictor
from trajpref.results import machine

HERE = Path(__file__).resolve().parent
METRICS = ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde")


def chosen_windows(ctx: list[list[int]], max_windows: int | None) -> list[int]:
    """The windows with context, at most ``max_windows`` of them evenly spaced."""
    have = [i for i, c in enumerate(ctx) if c]
    if max_windows is None or len(have) <= max_windows:
        return have
    picks = np.linspace(0, len(have) - 1, max_windows).round().astype(int)  # [M]
    return [have[p] for p in sorted(set(picks.tolist()))]


def report(split: str) -> str:
    """Markdown table of every row in meta/in_context_*_<split>.json: before -> after on the
    windows with context, per dataset and setting."""
    lines = ["| dataset | setting | windows (with context / in split) | minADE before -> after "
             "| minFDE before -> after | s / window |", "|---|---|---|---|---|---|"]  # fmt: skip
    for path in sorted((HERE / "results" / "meta").glob(f"in_context_*_{split}.json")):
        dataset = path.stem.removeprefix("in_context_").removesuffix(f"_{split}")
        for key, r in json.loads(path.read_text())["rows"].items():
            if not (r["before"] and r["after"]):
                continue
            cells = []
            for m in ("min_ade", "min_fde"):
                b, a = r["before"][m], r["after"][m]
                cells.append(f"{b:.4f} -> {a:.4f} ({100 * (a / b - 1):+.1f} %)")
            have, total = r["windows_with_context_in_split"], r["windows_in_split"]
            secs = r["seconds_per_window"]
            lines.append(f"| {dataset} | `{key}` | {r['windows']} ({have} / {total}) "
                         f"| {cells[0]} | {cells[1]} | {secs:.1f} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dataset", default="zara1")
    ap.add_argument("--split", default="val", choices=["val", "test"])
    ap.add_argument("--model", default="{dataset}/generator", help="({dataset}: the name)")
    ap.add_argument("--data-root", default=None)
    ap.add_argument("--max-windows", type=int, default=None)
    ap.add_argument("--ctx-frames", type=int, default=40)
    ap.add_argument("--params", nargs="+", default=["heads"], choices=list(ADAPT_PARAMS))
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--lr", type=float, default=1e-4)
    ap.add_argument("--trust", type=float, default=0.0)
    ap.add_argument("--objective", nargs="+", default=["supervised"], choices=ADAPT_OBJECTIVES)
    ap.add_argument("--score-weight", type=float, default=1.0, help="objective both's")
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="default results/meta/in_context_<D>_<split>.json")
    ap.add_argument("--report", action="store_true", help="print the table of every stored row")
    args = ap.parse_args()
    if args.report:
        print(report(args.split))
        return
    spec = args.model.format(dataset=args.dataset)
    model = load_predictor(spec, device="cpu")
    ds = load_dataset(args.dataset, args.split, args.data_root)
    out = Path(
        args.out or HERE / "results" / "meta" / f"in_context_{args.dataset}_{args.split}.json"
    )
    result = json.loads(out.read_text()) if out.exists() else {"rows": {}}
    command = shlex.join(["python", "benchmarks/in_context.py", *sys.argv[1:]])
    settings = [(p, o) for p in args.params for o in args.objective]
    for params, objective in settings:
        cfg = AdaptConfig(ctx_frames=args.ctx_frames, steps=args.steps, lr=args.lr,
                          params=params, trust=args.trust, objective=objective,
                          score_weight=args.score_weight)  # fmt: skip
        ctx = context_windows(ds, cfg)
        idx = chosen_windows(ctx, args.max_windows)
        res = evaluate_in_context(model, ds, cfg, args.samples, args.seed, indices=idx)
        before, after = res["before"], res["after"]
        key = f"{params}_s{cfg.steps}_lr{cfg.lr:g}_trust{cfg.trust:g}_ctx{cfg.ctx_frames}"
        if objective != "supervised":  # the supervised rows keep their earlier keys
            key += f"_{objective}" + (f"{cfg.score_weight:g}" if objective == "both" else "")
        result["rows"][key] = {
            "model": spec, "params": params, "steps": cfg.steps, "lr": cfg.lr,
            "trust": cfg.trust, "ctx_frames": cfg.ctx_frames, "samples": args.samples,
            "objective": objective, "score_weight": cfg.score_weight, "machine": machine(),
            "stochastic_steps": model.stochastic,  # ancestral tau steps (before 2026-11-24)
            "seed": args.seed, "windows": len(idx), "windows_in_split": len(ds),
            "windows_with_context_in_split": sum(1 for c in ctx if c),
            "seconds_per_window": res["seconds_per_window"],
            "before": {k: before[k] for k in METRICS} if before else None,
            "after": {k: after[k] for k in METRICS} if after else None,
            "command": command, "date": datetime.date.today().isoformat(),
        }  # fmt: skip
        have = sum(1 for c in ctx if c)
        print(f"{args.dataset}/{args.split} {key}: {have} of {len(ds)} windows have context "
              f"(evaluated {len(idx)}), {res['seconds_per_window']:.2f} s/window")  # fmt: skip
        if before and after:
            for k in METRICS:
                change = 100 * (after[k] / before[k] - 1)
                print(f"  {k:>14}: {before[k]:.4f} -> {after[k]:.4f} ({change:+.1f} %)")
        write_json(out, result)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
