"""Summarise a generator sweep trained on a borrowed GPU (benchmarks/gpu_sweep/).

The sweep's runs come back as ``meta.tgz`` (each run's config, metrics and log); unpack it
into a folder and point this script at it. For each run it reads the job line (fold, epochs,
seed, ``--set`` overrides) and the validation history, and writes one measurement file with
the validation minADE20 / minFDE20 at the evaluation with the lowest minFDE20 (``best``), at
the one whose checkpoint the run keeps (``kept``: the lowest minADE20 + minFDE20, as the
training loop chooses), and at the last one, and the training seconds as run on the GPU.
Validation only: a sweep chooses; the test split is read later, once, by
``benchmarks/pretrain.py`` for what is published. Runs unpacked from several calls of one
lease go into one folder, their ``jobs*.txt`` concatenated into ``jobs.txt``.

    tar xzf meta.tgz -C runs/sweep
    python benchmarks/sweep_summary.py runs/sweep --gpu "one NVIDIA H100 80GB (borrowed)" \\
        --out benchmarks/results/meta/gpu_sweep_2026-11-25.json
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from trajpref.results import write_meta
from trajpref.train import read_metrics


def parse_job(line: str) -> dict[str, Any]:
    """One line of a jobs file, ``NAME FOLD EPOCHS EVAL_EVERY SEED [KEY=VALUE ...]``."""
    name, fold, epochs, every, seed, *sets = line.split()
    return {"name": name, "fold": fold, "epochs": int(epochs), "eval_every": int(every),
            "seed": int(seed), "overrides": sets}  # fmt: skip


def summarise(run_dir: Path) -> dict[str, Any] | None:
    """Best and last validation of one run folder (None when it has no validation yet)."""
    log = read_metrics(run_dir, "generator")
    evals = [r for r in log if "val_min_fde" in r]
    if not evals:
        return None
    best = min(evals, key=lambda r: r["val_min_fde"])
    kept = min(evals, key=lambda r: r["val_score"])  # the score the loop kept its checkpoint by

    def pick(r: dict[str, Any]) -> dict[str, Any]:
        return {"epoch": r["epoch"], "min_ade": r["val_min_ade"], "min_fde": r["val_min_fde"]}

    return {"epochs_done": log[-1]["epoch"], "best": pick(best), "kept": pick(kept),
            "last": pick(evals[-1]), "train_seconds": log[-1]["train_seconds"]}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, help="folder of the unpacked meta.tgz")
    parser.add_argument("--gpu", required=True, help="the machine the sweep trained on")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    jobs_file = args.runs / "jobs.txt"
    if not jobs_file.is_file():
        parser.error(f"{jobs_file} not found: unpack the sweep's meta.tgz into {args.runs}")
    jobs = [parse_job(line) for line in jobs_file.read_text().splitlines()
            if line.strip() and not line.startswith("#")]  # fmt: skip
    runs = []
    for job in jobs:
        got = summarise(args.runs / job["name"])
        runs.append({**job, **(got or {"skipped": True})})
        if got:
            k, last = got["kept"], got["last"]
            sets = " ".join(job["overrides"]) or "-"
            print(f"{job['name']:<18} {job['fold']:<8} {sets:<34} kept {k['min_ade']:.4f} / "
                  f"{k['min_fde']:.4f} (ep {k['epoch']})  last {last['min_ade']:.4f} / "
                  f"{last['min_fde']:.4f}  {got['train_seconds']:.0f} s")  # fmt: skip
    write_meta(args.out, train_machine=args.gpu, split="val", runs=runs)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
