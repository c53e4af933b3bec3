"""Sampler speed of every published generator, measured side by side in one run.

    python benchmarks/speed.py --data-root ../shared/data

For each published ``DATASET/generator*`` this times, on the same test scenes of its dataset
(evenly spaced over the split, one scene per call, K = 20), the leapfrog sampler (the
generator plus tau denoising steps) against the full sampler of its own denoiser (100
ancestral steps), interleaved scene by scene (``evaluation.time_predictors``). All models are
timed in this one process, one after the other, so their latencies compare with each other;
the ratio full / leapfrog depends less on the machine's load than the latencies (not entirely:
two runs of one day on the same kind of host moved it by up to 45 %).

Writes benchmarks/results/meta/speed.json (machine, threads, date, command, one entry per
model with the ``model_hash`` of the file it timed); ``python benchmarks/update_readme.py``
puts it in the README's cost table, marking the latencies of a file that has changed since. A subset
(``--datasets``) must go elsewhere (``--out``), so that the file never mixes runs.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm.auto import tqdm

from trajpref.data import load_dataset
from trajpref.evaluation import time_predictors
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.results import write_meta

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "speed.json"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--datasets", nargs="+", default=None, help="default: every dataset")
    parser.add_argument("--scenes", type=int, default=100, help="test scenes per model")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args()
    if args.datasets and Path(args.out).resolve() == OUT.resolve():
        parser.error(
            f"{OUT.name} holds every published model timed in one run (the README compares "
            "them); time a subset with --out somewhere else"
        )

    models = zoo.generators(args.datasets)
    if not models:
        parser.error("no published generator matches --datasets")
    entries = {}
    splits: dict[str, object] = {}
    for name, path in tqdm(models.items(), desc="models", unit="model"):
        dataset = name.split("/")[0]
        if dataset not in splits:
            splits[dataset] = load_dataset(dataset, "test", args.data_root)
        test = splits[dataset]
        predictors = {
            "leapfrog": ckpt.load_predictor(path, sampler="leapfrog", device=args.device),
            "full": ckpt.load_predictor(path, sampler="full", device=args.device),
        }
        ms = time_predictors(predictors, test, args.samples, args.scenes)
        picks = ms["scenes"]
        entries[name] = {
            "dataset": dataset,
            # what was timed (weights, denoiser, scale, settings): update_readme.py marks the
            # latencies of a file that has changed since
            "model_hash": ckpt.model_hash(path),
            "scenes": picks,
            "mean_agents_per_scene": test.num_agents / len(test),
            "leapfrog_ms_per_scene": round(ms["leapfrog"], 2),
            "full_ms_per_scene": round(ms["full"], 2),
            "full_over_leapfrog": round(ms["full"] / ms["leapfrog"], 2),
        }
        tqdm.write(f"{name:<26} leapfrog {ms['leapfrog']:7.1f} ms  full {ms['full']:8.1f} ms  "
                   f"ratio {ms['full'] / ms['leapfrog']:.1f}x  ({picks} scenes)")  # fmt: skip
    write_meta(args.out, samples=args.samples, models=entries)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
