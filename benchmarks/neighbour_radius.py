"""What a neighbour radius (``model.neighbour_radius``) costs on validation and what it repairs
in scenes wider than the training scenes (docs/pretraining.md, "A neighbour radius for scenes
wider than training's").

    OMP_NUM_THREADS=1 python benchmarks/neighbour_radius.py --data-root ../shared/data

1. Validation minADE20 / minFDE20 (K = 20, seed 0, whole split) of each ``--datasets``
   generator at no radius and at each ``--radii`` value; the rule's choice is the smallest
   radius at which every dataset's two numbers are within ``--tolerance`` of no radius.
2. Synthetic far walkers: agent 0 walks +x at 1.3 m/s; alone, and beside one parallel walker d
   m to the side; agent 0's minFDE20 for each published pedestrian generator, without a radius
   and at the chosen one.
3. Synthetic crowds: P straight walkers at random places and headings in a side x side m
   square, minFDE20 over all of them for the whole scene, for each walker predicted alone, and
   for the whole scene at the chosen radius (zara1/generator).

The synthetic walkers ignore each other, so "alone" is their right answer. Writes
benchmarks/results/meta/neighbour_radius.json (with machine, command and date).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
import torch

from trajpref.data import load_dataset
from trajpref.evaluation import evaluate
from trajpref.models.registry import load_predictor
from trajpref.results import write_meta
from trajpref.score import predict_scene

ROOT = Path(__file__).resolve().parent.parent
PEDESTRIANS = ("zara1", "zara2", "univ", "eth", "hotel")
"""The published pedestrian generators of the far-walker table."""
STEP = 0.4
"""Seconds per step of the synthetic walkers (the ETH/UCY models' step)."""
SPEED = 1.3
"""Their walking speed (m/s)."""


def chosen_radius(table: dict[str, dict], radii: list[float], tolerance: float) -> float | None:
    """The smallest of ``radii`` at which every dataset's minADE20 and minFDE20 are within
    ``tolerance`` (a fraction) of its no-radius numbers; None when none is. ``table``:
    {dataset: {"none": {"min_ade", "min_fde"}, "<radius>": {...}}}."""
    for r in sorted(radii):
        if all(row[str(r)][k] <= row["none"][k] * (1 + tolerance)
               for row in table.values() for k in ("min_ade", "min_fde")):  # fmt: skip
            return r
    return None


def far_walker_row(model, distances: tuple[float, ...]) -> list[float]:
    """Agent 0's minFDE20 alone, then beside a parallel walker at each distance (m)."""
    t = np.arange(8) * STEP
    walker = np.stack([SPEED * t, 0 * t], -1)[None]  # [1, T_h, 2]
    end = np.array([SPEED * STEP * (7 + 12), 0.0])  # its true endpoint
    out = [float(np.linalg.norm(predict_scene(model, walker, 20)[:, 0, -1] - end, axis=-1).min())]
    for d in distances:
        beside = np.stack([SPEED * t, 0 * t + d], -1)[None]  # [1, T_h, 2]
        pred = predict_scene(model, np.concatenate([walker, beside]), 20)  # [K, 2, T_f, 2]
        out.append(float(np.linalg.norm(pred[:, 0, -1] - end, axis=-1).min()))
    return out


def crowd_row(model, count: int, side: float, radius: float | None, seed: int) -> dict:
    """minFDE20 of ``count`` random straight walkers in a side x side m square: the whole
    scene, each alone, and the whole scene at ``radius``."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(0, side, (count, 1, 2))  # [P, 1, 2]
    heading = rng.uniform(0, 2 * np.pi, count)  # [P]
    velocity = SPEED * np.stack([np.cos(heading), np.sin(heading)], -1)[:, None]  # [P, 1, 2]
    path = start + velocity * (np.arange(20) * STEP)[None, :, None]  # [P, 20, 2]
    hist, end = path[:, :8], path[:, -1]  # [P, T_h, 2], [P, 2]

    def min_fde(pred: np.ndarray) -> float:  # [K, P, T_f, 2] -> mean over agents
        return float(np.linalg.norm(pred[:, :, -1] - end[None], axis=-1).min(0).mean())

    before = model.neighbour_radius
    model.neighbour_radius = None
    whole = min_fde(predict_scene(model, hist, 20))
    each = [predict_scene(model, hist[i : i + 1], 20)[:, 0, -1] for i in range(count)]  # [K, 2]
    alone = float(np.mean([np.linalg.norm(e - end[i], axis=-1).min() for i, e in enumerate(each)]))
    model.neighbour_radius = radius
    cut = min_fde(predict_scene(model, hist, 20))
    model.neighbour_radius = before
    return {"agents": count, "side_m": side, "whole": whole, "alone": alone, "radius": cut}


@torch.no_grad()
def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--datasets", nargs="+", default=["zara1", "univ"])
    parser.add_argument("--radii", type=float, nargs="+", default=[4.0, 6.0, 8.0, 12.0])
    parser.add_argument(
        "--tolerance",
        type=float,
        default=0.005,
        help="allowed rise of validation minADE20 / minFDE20, a fraction",
    )
    parser.add_argument("--distances", type=float, nargs="+", default=[2, 5, 10, 20, 40, 100])
    parser.add_argument("--out-dir", default=str(ROOT / "benchmarks" / "results" / "meta"))
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore", UserWarning)  # the synthetic scenes name no step or units
    val: dict[str, dict] = {}
    for name in args.datasets:
        model = load_predictor(f"{name}/generator", device="cpu")
        data = load_dataset(name, "val", args.data_root)
        val[name] = {}
        for radius in (None, *args.radii):
            model.neighbour_radius = radius
            res = evaluate(model, data, 20, 0, "cpu", progress=False, collision_radius=None)
            val[name]["none" if radius is None else str(radius)] = {
                "min_ade": res["min_ade"], "min_fde": res["min_fde"]}  # fmt: skip
            print(f"{name} val radius {radius}: minADE20 {res['min_ade']:.4f} "
                  f"minFDE20 {res['min_fde']:.4f}", flush=True)  # fmt: skip
    chosen = chosen_radius(val, args.radii, args.tolerance)
    print(f"chosen radius (smallest within +{args.tolerance:.1%} on every dataset): {chosen}")
    walkers = {}
    for name in PEDESTRIANS:
        model = load_predictor(f"{name}/generator", device="cpu")
        for radius in dict.fromkeys((None, chosen)):
            model.neighbour_radius = radius
            row = far_walker_row(model, tuple(args.distances))
            walkers[f"{name} {radius}"] = row
            print(f"{name}/generator radius {radius}: alone {row[0]:.2f}, beside a walker at "
                  + " / ".join(f"{d:g}" for d in args.distances)
                  + " m: " + " ".join(f"{v:.2f}" for v in row[1:]), flush=True)  # fmt: skip
    model = load_predictor("zara1/generator", device="cpu")
    crowds = [
        crowd_row(model, p, side, chosen, seed)
        for seed, (p, side) in enumerate([(10, 10), (10, 40), (50, 15), (50, 60)])
    ]
    for c in crowds:
        print(f"P={c['agents']} in {c['side_m']:g} x {c['side_m']:g} m: whole {c['whole']:.2f}, "
              f"alone {c['alone']:.2f}, radius {chosen}: {c['radius']:.2f}")  # fmt: skip
    out = Path(args.out_dir) / "neighbour_radius.json"
    record = write_meta(out, validation=val, radii=args.radii, tolerance=args.tolerance,
                        chosen=chosen, distances=args.distances, far_walkers=walkers,
                        crowds=crowds)  # fmt: skip
    print(f"wrote {out}")
    return record


if __name__ == "__main__":
    main()
