"""``make demo``: the pipeline so far, end to end on the CPU.

Simulates the Robo scenario (robo-sim), evaluates the constant-velocity baseline on the
official Robo test set (or on robo-sim's test split when the data is not on this machine),
prints a table and writes a figure.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from trajpref.errors import TrajprefError


def run(out: Path, data_root: str | None, samples: int, seed: int) -> None:
    from trajpref.data import load_dataset
    from trajpref.models.baseline import ConstantVelocity
    from trajpref.train.evaluate import evaluate
    from trajpref.types import collate
    from trajpref.viz.plot import plot_scene

    start = time.perf_counter()
    train = load_dataset("robo-sim", "train")
    print(
        f"[1/3] simulated robo-sim train: {len(train)} episodes, {train.num_agents} agents "
        f"in {time.perf_counter() - start:.1f} s"
    )
    try:
        test = load_dataset("robo", "test", data_root)
        where = "official Robo test set"
    except TrajprefError as exc:
        print(f"      ({exc}; using robo-sim's test split instead)")
        test = load_dataset("robo-sim", "test")
        where = "robo-sim test split"

    rows = []
    for k in (1, samples):
        res = evaluate(ConstantVelocity(), test, num_samples=k, seed=seed)
        rows.append((f"constant velocity (K={k})", res))
    print(
        f"[2/3] evaluated on the {where} ({rows[0][1]['agents']} agents, "
        f"{rows[0][1]['scenes']} scenes), metres:"
    )
    print(f"  {'method':<28} {'minADE':>8} {'minFDE':>8} {'jADE':>8} {'jFDE':>8}")
    for name, r in rows:
        print(
            f"  {name:<28} {r['min_ade']:8.3f} {r['min_fde']:8.3f} "
            f"{r['joint_min_ade']:8.3f} {r['joint_min_fde']:8.3f}"
        )

    scene = test[0]
    gen = torch.Generator()
    gen.manual_seed(seed)
    pred = ConstantVelocity().predict(collate([scene]), samples, gen).numpy()  # [K, P, T_f, 2]
    fig = plot_scene(
        scene.history,
        scene.future,
        pred,
        out / "robo_scene0_cv.png",
        "m",
        f"{where}, scene 0, constant velocity K={samples}",
    )
    print(f"[3/3] wrote {fig}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out/demo", help="output folder")
    parser.add_argument("--data-root", default=None, help="data folder (default $TRAJPREF_DATA)")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        run(Path(args.out), args.data_root, args.samples, args.seed)
    except TrajprefError as exc:
        print(f"trajpref demo: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
