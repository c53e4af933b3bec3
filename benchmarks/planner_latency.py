"""What the planning calls of the Python API cost, in ms per scene, measured side by side.

    OMP_NUM_THREADS=1 python benchmarks/planner_latency.py --dataset zara1 --sizes 1 3 7 15 \
        --calls 15 --data-root ../shared/data

For each scene size P (the first P agents of the first validation scene with at least P), times
the calls of the README's planner section on the same histories, interleaved (one call of each
in turn, ``--calls`` rounds after one warm-up round), and keeps each call's median:
``predict_scene`` (K = 20), ``rank_samples`` at the scorer's 34 steps and at one step
(``with_steps([0])``), ``select_for_scene`` at ``SelectionConfig``'s default (12 steps), the
dataset's chosen setting (``chosen_selection``) and its cheap one, and score-free facility
location. Scenes come from the validation split: only the histories are read, no metric.
Writes benchmarks/results/meta/planner_latency_<dataset>.json (with machine, threads, command
and date), which ``benchmarks/update_readme.py`` turns into the README's cost table.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from trajpref.data import load_dataset
from trajpref.models.registry import load_predictor
from trajpref.results import write_meta
from trajpref.score import predict_scene, rank_samples
from trajpref.score.scorer import TrajectoryScorer
from trajpref.score.selection import SelectionConfig, chosen_selection, select_for_scene

ROOT = Path(__file__).resolve().parent.parent
CALLS = ("predict_scene", "rank_34", "rank_1", "select_default", "chosen", "chosen_cheap",
         "facility")  # fmt: skip
"""The timed calls, in the README table's column order: the keys of ``timed_calls`` and of each
record row, and the columns ``update_readme.py`` reads (``PLANNER_COLUMNS``)."""


def scene_histories(dataset, sizes: list[int]) -> dict[int, np.ndarray]:
    """{P: [P, T_h, 2]} the first P agents' histories of the first scene with at least P."""
    out = {}
    for p in sizes:
        scene = next((s for s in dataset.scenes if s.num_agents >= p), None)
        if scene is None:
            raise SystemExit(f"no {dataset.info.name} {dataset.info.split} scene has {p} agents")
        out[p] = np.asarray(scene.history[:p], dtype=np.float32)  # [P, T_h, 2]
    return out


def timed_calls(model, scorer, history: np.ndarray, dataset: str) -> dict:
    """{name: zero-argument call} for one scene's history, in ``CALLS`` order."""
    samples = predict_scene(model, history, 20)  # [K, P, T_f, 2]
    one_step = scorer.with_steps([0])
    default = SelectionConfig(keep=5)
    chosen = chosen_selection(f"{dataset}/generator", keep=5)
    cheap = chosen_selection(f"{dataset}/generator", keep=5, cheap=True)
    facility = SelectionConfig(keep=5, method="facility")
    calls = (  # in CALLS order
        lambda: predict_scene(model, history, 20),
        lambda: rank_samples(scorer, history, samples),  # 34 steps
        lambda: rank_samples(one_step, history, samples),  # 1 step
        lambda: select_for_scene(scorer, history, samples, default),
        lambda: select_for_scene(scorer, history, samples, chosen),
        lambda: select_for_scene(scorer, history, samples, cheap),
        lambda: select_for_scene(scorer, history, samples, facility),
    )
    return dict(zip(CALLS, calls, strict=True))


def median_ms(calls: dict, rounds: int) -> dict[str, float]:
    """Each call's median wall time in ms over ``rounds`` interleaved rounds, after one
    warm-up round (a process's first call costs more)."""
    times: dict[str, list[float]] = {name: [] for name in calls}
    for r in range(rounds + 1):
        for name, call in calls.items():
            t0 = time.perf_counter()
            call()
            if r:  # round 0 warms up
                times[name].append((time.perf_counter() - t0) * 1e3)
    return {name: round(statistics.median(v), 2) for name, v in times.items()}


def latency_args(doc: str, dataset_help: str, argv: list[str] | None) -> argparse.Namespace:
    """The options of the latency scripts (this one and ``export_latency.py``), parsed:
    --dataset, --data-root, --sizes, --calls and --out-dir."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--dataset", default="zara1", help=dataset_help)
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 3, 7, 15])
    parser.add_argument("--calls", type=int, default=15, help="timed rounds per size")
    parser.add_argument("--out-dir", default=str(ROOT / "benchmarks" / "results" / "meta"))
    args = parser.parse_args(argv)
    if args.calls < 1 or min(args.sizes) < 1:
        parser.error("--calls and every --sizes must be >= 1")
    return args


@torch.no_grad()
def main(argv: list[str] | None = None) -> dict:
    args = latency_args(__doc__, "a dataset with a chosen selection", argv)
    model = load_predictor(f"{args.dataset}/generator", device="cpu")
    scorer = TrajectoryScorer.from_checkpoint(f"{args.dataset}/denoiser")
    val = load_dataset(args.dataset, "val", args.data_root)
    rows = []
    for p, history in scene_histories(val, args.sizes).items():
        ms = median_ms(timed_calls(model, scorer, history, args.dataset), args.calls)
        rows.append({"agents": p, **ms})
        print(f"P={p}: " + "  ".join(f"{k} {v:.1f}" for k, v in ms.items()), flush=True)
    out = Path(args.out_dir) / f"planner_latency_{args.dataset}.json"
    record = write_meta(out, dataset=args.dataset, split="val", samples=20, keep=5,
                        calls=args.calls, rows=rows)  # fmt: skip
    print(f"wrote {out}")
    return record


if __name__ == "__main__":
    main()
