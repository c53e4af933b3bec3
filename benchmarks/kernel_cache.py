"""How much oneDNN's kernel cache matters to training steps, measured side by side.

    python benchmarks/kernel_cache.py --data-root ../shared/data

PyTorch's bfloat16 products on the CPU go through oneDNN, which builds a kernel for each new
matrix shape and keeps the last ``ONEDNN_PRIMITIVE_CACHE_CAPACITY`` of them (1,024 by default).
trajpref raises that to ``trajpref.ONEDNN_CACHE_CAPACITY`` on import. This script trains a few
short epochs of each named stage once per capacity, in a fresh process each time (the variable
is read before the process's first product), alternating the capacities ``--repeats`` times, and
reports the seconds of every epoch. The first epoch meets most shapes for the first time under
either setting; the later ones show the steady state, so the ratio is taken over epochs 2 and
later. Writes benchmarks/results/meta/kernel_cache.json.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "kernel_cache.json"
DEFAULT_RUNS = ("hotel:generator", "zara1:generator", "eth:generator", "hotel:diffusion")

# run in the child process: train_cost's short run of one stage; prints its epochs' seconds
_CHILD = """
import json, sys
from pathlib import Path
root, dataset, stage, epochs, steps, data_root = sys.argv[1:7]
sys.path.insert(0, str(Path(root) / "benchmarks"))
from train_cost import epoch_seconds, short_run
from trajpref.config import load_config
cfg = load_config(Path(root) / "configs" / f"{dataset}.yaml")
denoiser = Path(root) / "models" / dataset / "denoiser.safetensors"
_, records = short_run(cfg, stage, data_root or None, int(steps), int(epochs),
                       denoiser if stage == "generator" else None)
print(json.dumps(epoch_seconds(records)))
"""


def run_once(dataset: str, stage: str, epochs: int, steps: int, data_root: str | None,
             capacity: int | None) -> list[float]:  # fmt: skip
    """Seconds of each training epoch in a fresh process; ``capacity`` None: oneDNN's default."""
    env = dict(os.environ)
    env["ONEDNN_PRIMITIVE_CACHE_CAPACITY"] = str(capacity if capacity is not None else 1024)
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(ROOT), dataset, stage, str(epochs), str(steps),
         data_root or ""],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    from trajpref import ONEDNN_CACHE_CAPACITY
    from trajpref.results import write_meta

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--runs", nargs="+", default=list(DEFAULT_RUNS),
                        metavar="DATASET:STAGE", help="stage: diffusion or generator")  # fmt: skip
    parser.add_argument("--epochs", type=int, default=3, help="short epochs per training")
    parser.add_argument("--steps", type=int, default=50, help="training steps per epoch")
    parser.add_argument("--repeats", type=int, default=2, help="alternations per run")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args()
    if args.epochs < 2:
        raise SystemExit("--epochs must be at least 2: the ratio is taken over epochs 2 and later")

    settings = {"default": 1024, "trajpref": ONEDNN_CACHE_CAPACITY}
    results = {}
    for spec in args.runs:
        dataset, _, stage = spec.partition(":")
        if stage not in ("diffusion", "generator"):
            raise SystemExit(f"{spec}: write DATASET:diffusion or DATASET:generator")
        epochs = {name: [] for name in settings}
        for r in range(args.repeats):
            order = list(settings) if r % 2 == 0 else list(settings)[::-1]
            for name in order:
                epochs[name].append(run_once(dataset, stage, args.epochs, args.steps,
                                             args.data_root, settings[name]))  # fmt: skip
                print(f"{spec:<17} {name:<8} epoch seconds "
                      + " ".join(f"{s:.1f}" for s in epochs[name][-1]), flush=True)  # fmt: skip
        later = {name: statistics.fmean(s for run in runs for s in run[1:])
                 for name, runs in epochs.items()}  # fmt: skip
        speedup = round(later["default"] / later["trajpref"], 2)
        print(f"{spec:<17} steady-state epochs: default {later['default']:.1f} s, "
              f"capacity {ONEDNN_CACHE_CAPACITY} {later['trajpref']:.1f} s: {speedup}x",
              flush=True)  # fmt: skip
        results[spec] = {"epoch_seconds": epochs, "steady_seconds": later,
                         "speedup": speedup}  # fmt: skip
    write_meta(args.out, capacities=settings, epochs=args.epochs, steps=args.steps,
               repeats=args.repeats, runs=results)  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
