"""Constant-velocity baseline on every dataset's test split (K = 1 and K = 20).

    python benchmarks/cv_baseline.py --data-root ../shared/data

Writes benchmarks/results/cv.json and regenerates the README's results table.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from trajpref.data import load_dataset
from trajpref.data.registry import ETH_UCY
from trajpref.evaluation import evaluate
from trajpref.models.baseline import ConstantVelocity
from trajpref.results import make_row, write_rows

HERE = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--datasets", nargs="+", default=[*ETH_UCY, "sdd", "nba", "robo"])
    parser.add_argument("--samples", nargs="+", type=int, default=[1, 20])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=str(HERE / "results" / "cv.json"))
    args = parser.parse_args()

    rows = []
    for name in args.datasets:
        ds = load_dataset(name, "test", args.data_root)
        for k in args.samples:
            start = time.perf_counter()
            res = evaluate(ConstantVelocity(), ds, k, args.seed, progress=False)
            ms = 1000 * (time.perf_counter() - start) / len(ds)
            row = make_row(
                dataset=name, split="test", method="cv", seed=args.seed, samples=k,
                uses_score=False,
                ms_per_scene=round(ms, 4),
                **{key: res[key] for key in ("min_ade", "min_fde", "joint_min_ade",
                                             "joint_min_fde")},
            )  # fmt: skip
            rows.append(row)
            print(f"{name:>6} K={k:<3} minADE {res['min_ade']:.3f} minFDE {res['min_fde']:.3f} "
                  f"[{ds.info.units}]  ({res['agents']} agents)")  # fmt: skip
    write_rows(args.out, rows)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
