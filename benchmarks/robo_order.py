"""What a Robo generator with roles (``model.agent_roles``) does when a scene lists its robots
in another order than the leader, follower, approacher of its training data: minADE20 /
minFDE20 on Robo's official validation split (``--split test`` for the test split) for each of
the six orders, the published order first.

    python benchmarks/robo_order.py --data-root ../shared/data

Writes benchmarks/results/meta/robo_order[_test].json and prints a markdown table. A probe, not a
choice: nothing is selected from it (docs/pretraining.md, "Robo: robots listed in another
order").
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import itertools
import json
from pathlib import Path

from trajpref.data import load_dataset
from trajpref.evaluation import evaluate
from trajpref.models.registry import load_predictor
from trajpref.results import command_line, machine
from trajpref.types import Scene, TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent


def reordered(scene: Scene, order: tuple[int, ...]) -> Scene:
    """The scene with its agents listed in ``order`` (a permutation of its slots)."""
    idx = list(order)
    return dataclasses.replace(scene, history=scene.history[idx], future=scene.future[idx],
                               agent_type=scene.agent_type[idx])  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["robo/generator", "robo-mix/generator"])
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--split", choices=["val", "test"], default="val")
    args = parser.parse_args()
    ds = load_dataset("robo", args.split, args.data_root)
    rows = []
    print("| model | order of the listed robots | minADE20 | minFDE20 |\n|---|---|---|---|")
    for spec in args.models:
        model = load_predictor(spec)
        for order in itertools.permutations(range(3)):
            scenes = [reordered(s, order) for s in ds.scenes]
            out = evaluate(model, TrajectoryDataset(scenes, ds.info), seed=args.seed,
                           progress=False)  # fmt: skip
            rows.append({"model": spec, "order": list(order), "min_ade": out["min_ade"],
                         "min_fde": out["min_fde"]})  # fmt: skip
            print(f"| {spec} | {order} | {out['min_ade']:.3f} | {out['min_fde']:.3f} |", flush=True)
    record = {"date": datetime.date.today().isoformat(), "machine": machine(),
              "command": command_line(), "split": args.split, "samples": 20,
              "rows": rows}  # fmt: skip
    name = "robo_order.json" if args.split == "val" else "robo_order_test.json"
    out_path = ROOT / "benchmarks" / "results" / "meta" / name
    out_path.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {out_path}")


if __name__ == "__main__":
    main()
