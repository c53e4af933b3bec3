"""Our published ETH/UCY models under the Social-GAN evaluation protocol (``--protocol sgan``).

    python benchmarks/protocols.py --data-root ../shared/data

The default protocol (``all``) keeps every test window with a fully observed agent, as LED's
released windows and MoFlow do; the Social-GAN loader, and every method built on it
(EigenTrajectory, SingularTrajectory, ...), keeps only windows with at least two (docs/data.md,
"Evaluation protocols"). This script evaluates, on each fold's test split under ``sgan``: the
constant-velocity baseline (K = 20) and every published generator of the fold (the default
``generator`` as ``pretrained``, ``generator-NAME`` as ``pretrained-NAME``), with the same seed
and settings as their ``all`` rows. No model is trained or chosen here: the same checkpoints,
read on a subset of the same test windows.

Writes benchmarks/results/protocol_sgan.json (rows with ``protocol: "sgan"``); then
``python benchmarks/update_readme.py`` regenerates the README's tables.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from trajpref.data import load_dataset
from trajpref.data.registry import ETH_UCY
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.models.baseline import ConstantVelocity
from trajpref.results import make_row, upsert_rows

ROOT = Path(__file__).resolve().parent.parent
METRICS = ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde")


def published_generators(fold: str) -> dict[str, Path]:
    """Result-row method name -> checkpoint, for the fold's published generators."""
    return {"pretrained" + name.split("/")[1].removeprefix("generator"): path  # "", "-long"
            for name, path in zoo.generators([fold]).items()}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--folds", nargs="+", default=list(ETH_UCY), choices=ETH_UCY)
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default="cpu")
    default_out = ROOT / "benchmarks" / "results" / "protocol_sgan.json"
    parser.add_argument("--out", default=str(default_out), help="the rows file")
    args = parser.parse_args()

    rows = []
    for fold in args.folds:
        every = load_dataset(fold, "test", args.data_root)
        ds = load_dataset(fold, "test", args.data_root, protocol="sgan")
        print(f"{fold}: sgan keeps {len(ds)} of {len(every)} scenes, "
              f"{ds.num_agents} of {every.num_agents} agents")  # fmt: skip
        models = {"cv": ConstantVelocity()}
        checkpoints = published_generators(fold)
        for method, path in checkpoints.items():
            models[method] = ckpt.load_predictor(path, sampler="leapfrog", device=args.device)
        for method, model in models.items():
            start = time.perf_counter()
            res = evaluate(model, ds, args.samples, args.seed, args.device, progress=False,
                           collision_radius=None)  # fmt: skip
            ms = 1000 * (time.perf_counter() - start) / len(ds)
            path = checkpoints.get(method)
            rows.append(make_row(
                dataset=fold, split="test", protocol="sgan", method=method, seed=args.seed,
                samples=args.samples, uses_score=False, ms_per_scene=round(ms, 3),
                checkpoint=None if path is None else str(path.relative_to(ROOT)),
                model_hash=None if path is None else ckpt.model_hash(path),
                **{k: res[k] for k in METRICS},
            ))  # fmt: skip
            print(f"  {method:<20} minADE {res['min_ade']:.3f}  minFDE {res['min_fde']:.3f}  "
                  f"joint {res['joint_min_ade']:.3f} / {res['joint_min_fde']:.3f}")  # fmt: skip
    upsert_rows(args.out, rows)  # the other folds' rows stay
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
