"""Can a shift simulated on a validation split foresee how generators rank on a test file?

    python benchmarks/shift_validators.py --dataset eth --models A.safetensors B.safetensors ... \
        --stretch 1.6 --time-step 1.6667 --data-root ../shared/data

eth's test file differs from its training and validation scenes in two known ways (docs/data.md):
its walkers are faster, and each of its steps spans about 5/3 of the 0.4 s its label says. This
script builds, from the *validation* split only, four versions of it: as recorded; every
coordinate multiplied by ``--stretch`` (faster walkers, same paths); read every ``--time-step``
frame steps (``ReadOptions.time_step``: each step spans more time, so paths turn more per step;
only agents seen long enough remain); and both. It evaluates each checkpoint on each (whole
split, K = 20, seed 0) and writes ``benchmarks/results/meta/shift_validators_<dataset>.json``.
Which ordering the test file gives is not read here: the test rows of the checkpoints compared
are published already, and docs/pretraining.md sets the two side by side. Nothing is chosen
from these numbers.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from selection import stretched

from trajpref.data import ReadOptions, load_dataset
from trajpref.evaluation import evaluate
from trajpref.models.registry import load_predictor
from trajpref.results import write_meta
from trajpref.types import TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent


def shifted_splits(dataset: str, data_root: str | None, stretch: float,
                   time_step: float) -> dict[str, TrajectoryDataset]:  # fmt: skip
    """The validation split as recorded and under the three simulated shifts, by name."""
    val = load_dataset(dataset, "val", data_root)
    slow = load_dataset(dataset, "val", data_root, options=ReadOptions(time_step=time_step))
    return {
        "recorded": val,
        f"x{stretch:g}": stretched(val, stretch),
        f"time_step {time_step:g}": slow,
        f"time_step {time_step:g}, x{stretch:g}": stretched(slow, stretch),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default="eth")
    parser.add_argument("--models", nargs="+", required=True,
                        help="generator checkpoints or published names")  # fmt: skip
    parser.add_argument("--stretch", type=float, default=1.6,
                        help="coordinate factor (eth's test: ~1.6x)")  # fmt: skip
    parser.add_argument("--time-step", type=float, default=5 / 3,
                        help="frame steps per read step (eth's file: ~5/3)")  # fmt: skip
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()

    splits = shifted_splits(args.dataset, args.data_root, args.stretch, args.time_step)
    for name, data in splits.items():
        print(f"{name}: {len(data)} scenes, {data.num_agents} agents", flush=True)
    rows = []
    for spec in args.models:
        pred = load_predictor(spec)
        row = {"model": spec, "splits": {}}
        for name, data in splits.items():
            with torch.no_grad():
                r = evaluate(pred, data, 20, 0, progress=False, collision_radius=None)
            row["splits"][name] = {"min_ade": r["min_ade"], "min_fde": r["min_fde"]}
        rows.append(row)
        print(spec, " | ".join(f"{k} {v['min_ade']:.4f} / {v['min_fde']:.4f}"
                               for k, v in row["splits"].items()), flush=True)  # fmt: skip
    out = Path(args.out or ROOT / "benchmarks" / "results" / "meta" /
               f"shift_validators_{args.dataset}.json")  # fmt: skip
    write_meta(out, dataset=args.dataset, split="val", samples=20, seed=0,
               stretch=args.stretch, time_step=args.time_step,
               agents={k: v.num_agents for k, v in splits.items()}, rows=rows)  # fmt: skip
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
