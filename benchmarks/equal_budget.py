"""The equal-budget table: every fine-tuning method from the same start for the same CPU time.

    python benchmarks/equal_budget.py --datasets zara1 eth robo --seeds 0 1 2 --minutes 4 \
        --workers 2 --data-root ../shared/data
    python benchmarks/equal_budget.py --datasets zara1 eth robo --report   # the table only

Each job (dataset, method, seed) is one ``benchmarks/finetune.py`` process on one thread,
starting from ``models/<dataset>/generator.safetensors``, that trains until ``--minutes`` of its
own CPU time are spent on training steps (``finetune.budget_clock=cpu``: validation and the test
evaluation are not counted, and other jobs sharing the machine do not eat into it), keeps the
checkpoint chosen on validation and writes its test row. Methods:

- ``control``: the supervised generator loss alone (no score), the equal-budget control;
- ``rlhf``, ``rlhf-res``: the paper's methods at the fine-tuning defaults;
- ``rlhf-set``: RLHF with the set-aware reward (``finetune.reward=set``);
- ``rlhf-res-smooth``: RLHF-ReS exploring in smooth directions (``finetune.explore=smooth``,
  a velocity and an acceleration offset per sample, RMS 0.1 per step).

Jobs run seed-major (every dataset and method of seed 0 first), so that an interrupted table
is balanced; finished rows are skipped when it is run again, and an interrupted job resumes
from its ``finetune_last.pt``. The table (mean +- std over seeds, the change of minFDE20
against the start and against the control) is printed and written to
``benchmarks/results/meta/equal_budget.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from tqdm import tqdm

from trajpref.results import merge_rows, read_rows

ROOT = Path(__file__).resolve().parent.parent
METHODS = {
    "control": ["--methods", "control"],
    "rlhf": ["--methods", "rlhf"],
    "rlhf-res": ["--methods", "rlhf-res"],
    "rlhf-set": ["--methods", "rlhf", "--tag", "set", "--set", "finetune.reward=set"],
    "rlhf-res-smooth": [
        "--methods",
        "rlhf-res",
        "--tag",
        "smooth",
        "--set",
        "finetune.explore=smooth",
        "--set",
        "finetune.explore_std=0.1",
    ],
}
"""Each table method and the finetune.py arguments that produce its rows."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["zara1", "eth", "robo"])
    parser.add_argument("--methods", nargs="+", default=["control", "rlhf", "rlhf-res", "rlhf-set"],
                        choices=list(METHODS))  # fmt: skip
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--minutes", type=float, default=4.0, help="CPU minutes of training")
    parser.add_argument(
        "--warmup",
        type=int,
        default=4,
        help="learning-rate warm-up steps, the same for every method (the default 20 would "
        "leave the RL methods, which fit ~16 steps in 4 CPU minutes, below the full rate)",
    )
    parser.add_argument("--workers", type=int, default=2, help="jobs at once (one thread each)")
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--report", action="store_true", help="only print the table")
    args = parser.parse_args()
    if not args.report:
        run_jobs(args)
    table = report(args.datasets, args.methods)
    out = ROOT / "benchmarks" / "results" / "meta" / "equal_budget.md"
    out.write_text(table + "\n")
    print(table)


def _done(dataset: str, method: str, seed: int) -> bool:
    tag = METHODS[method][METHODS[method].index("--tag") + 1] if "--tag" in METHODS[method] else ""
    name = f"finetune_{dataset}{'_' + tag if tag else ''}.json"
    path = ROOT / "benchmarks" / "results" / name
    rows = json.loads(path.read_text()) if path.is_file() else []
    return any((r["method"], r["seed"]) == (method, seed) for r in rows)


def run_jobs(args: argparse.Namespace) -> None:
    jobs = [(d, m, s) for s in args.seeds for d in args.datasets for m in args.methods]
    todo = [j for j in jobs if not _done(*j)]
    print(f"{len(jobs) - len(todo)} of {len(jobs)} rows already measured; {len(todo)} to run")
    logs = ROOT / "runs" / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    budget = [
        "--set", f"finetune.max_minutes={args.minutes}", "--set", "finetune.budget_clock=cpu",
        "--set", "finetune.epochs=100000", "--set", "finetune.eval_every=3",
        "--set", f"finetune.warmup_steps={args.warmup}",
    ]  # fmt: skip
    data = ["--data-root", args.data_root] if args.data_root else []

    def one(job: tuple[str, str, int]) -> tuple[tuple[str, str, int], int, float]:
        dataset, method, seed = job
        cmd = [sys.executable, str(ROOT / "benchmarks" / "finetune.py"), "--dataset", dataset,
               *METHODS[method], "--seeds", str(seed), "--skip-done", "--no-start-validation",
               *budget, *data]  # fmt: skip
        t0 = time.perf_counter()
        with open(logs / f"equal_budget-{dataset}-{method}-s{seed}.log", "a") as log:
            code = subprocess.call(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
        return job, code, time.perf_counter() - t0

    failed = []
    with ThreadPoolExecutor(args.workers) as pool:
        bar = tqdm(pool.map(one, todo), total=len(todo), desc="equal-budget jobs", unit="job")
        for (dataset, method, seed), code, seconds in bar:
            status = "ok" if code == 0 else f"FAILED (exit {code})"
            tqdm.write(f"{dataset} {method} seed {seed}: {status} in {seconds / 60:.1f} min")
            if code != 0:
                failed.append((dataset, method, seed))
    if failed:
        sys.exit(f"{len(failed)} jobs failed (logs in runs/logs/): {failed}")


def _fmt(x: float | None) -> str:
    return "–" if x is None else f"{x:.3f}"


def _ms(xs: list[float]) -> str:
    if len(xs) < 2:
        return f"{xs[0]:.3f}" if xs else "–"
    return f"{statistics.mean(xs):.3f} ± {statistics.stdev(xs):.3f}"


def report(datasets: list[str], methods: list[str]) -> str:
    """Mean +- std over seeds of each method's test rows, against the start and the control."""
    rows = merge_rows(read_rows(ROOT / "benchmarks" / "results"))
    lines = [
        "| dataset | method | seeds | minADE20 | minFDE20 | minFDE20 vs start | vs control "
        "| joint minADE / minFDE | maxATS | train wall min |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for dataset in datasets:
        pick = [r for r in rows if r["dataset"] == dataset and r["split"] == "test"]
        pick = [r for r in pick if r["samples"] == 20]
        start = next((r for r in pick if r["method"] == "pretrained"), None)
        control = [r["min_fde"] for r in pick if r["method"] == "control"]
        if start is not None:
            lines.append(
                f"| {dataset} | start (pretrained) | – | {_fmt(start['min_ade'])} "
                f"| {_fmt(start['min_fde'])} | – | – | {_fmt(start['joint_min_ade'])} / "
                f"{_fmt(start['joint_min_fde'])} | {_fmt(start['max_ats'])} | – |"
            )
        for method in methods:
            own = sorted((r for r in pick if r["method"] == method), key=lambda r: r["seed"])
            if not own:
                continue
            fde = [r["min_fde"] for r in own]
            vs_start = (
                f"{100 * (statistics.mean(fde) / start['min_fde'] - 1):+.1f} %" if start else "–"
            )
            vs_control = (
                f"{100 * (statistics.mean(fde) / statistics.mean(control) - 1):+.1f} %"
                if control and method != "control"
                else "–"
            )
            lines.append(
                f"| {dataset} | {method} | {','.join(str(r['seed']) for r in own)} "
                f"| {_ms([r['min_ade'] for r in own])} | {_ms(fde)} | {vs_start} | {vs_control} "
                f"| {_ms([r['joint_min_ade'] for r in own])} / "
                f"{_ms([r['joint_min_fde'] for r in own])} | {_ms([r['max_ats'] for r in own])} "
                f"| {statistics.mean(r['train_seconds'] for r in own) / 60:.1f} |"
            )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
