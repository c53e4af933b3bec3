"""What keeping K' of K samples with the diffusion score costs beside the prediction itself,
measured side by side (interleaved, one scene per call) on a split's largest scenes.

    python benchmarks/selection_cost.py --dataset univ --scenes 20 --precision fp32 bf16 \
        --data-root ../shared/data
    python benchmarks/selection_cost.py --dataset univ --scorer own \
        runs/sm49/univ/denoiser.safetensors   # a denoiser of another shape beside the own

For each scorer (``own``: the generator's denoiser; or a denoiser checkpoint, path or
DATASET/NAME), score-step spacing and score precision (``--precision fp32 bf16``), prints ms per
scene of: the prediction (K = 20 leapfrog samples, fp32), the score of its samples, the
selection itself, and the ratio (score + selection) / prediction. Writes
benchmarks/results/meta/selection_cost_<dataset>.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from trajpref.data import load_dataset
from trajpref.models import checkpoint as ckpt
from trajpref.results import command_line, machine
from trajpref.score.scorer import PRECISIONS, TrajectoryScorer, score_timesteps
from trajpref.score.selection import SelectionConfig, select_samples
from trajpref.types import collate

ROOT = Path(__file__).resolve().parent.parent


def add_scene_arguments(parser: argparse.ArgumentParser, repeats: int) -> None:
    """The options of a timing run on a test split's largest scenes (this script's and
    ``score_step_profile.py``'s): dataset, data root, how many scenes, K, repeats."""
    parser.add_argument("--dataset", default="univ")
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--scenes", type=int, default=20, help="the largest this many")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=repeats)


def largest_scenes(args: argparse.Namespace):
    """The dataset's published generator (leapfrog) and its test split's ``args.scenes``
    largest scenes, largest first."""
    path = ROOT / "models" / args.dataset / "generator.safetensors"
    model = ckpt.load_predictor(path, sampler="leapfrog")
    test = load_dataset(args.dataset, "test", args.data_root)
    return model, sorted(test.scenes, key=lambda s: -s.num_agents)[: args.scenes]


@torch.no_grad()
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_arguments(parser, repeats=3)
    parser.add_argument("--every", type=int, nargs="+", default=[3, 9, 13, 20, 33])
    parser.add_argument("--precision", nargs="+", default=["fp32"], choices=PRECISIONS,
                        help="score precisions, timed side by side")  # fmt: skip
    parser.add_argument("--scorer", nargs="+", default=["own"],
                        help="scorers timed side by side: own (the generator's denoiser) or "
                        "denoiser checkpoints (path or DATASET/NAME)")  # fmt: skip
    args = parser.parse_args()

    model, largest = largest_scenes(args)
    bases = {name: model if name == "own" else TrajectoryScorer.from_checkpoint(
                 ckpt.resolve_path(name)) for name in args.scorer}  # fmt: skip
    scorers = {(name, p, e): TrajectoryScorer(base.denoiser, base.schedule, base.scale,
                                              score_timesteps(base.schedule.num_steps, e),
                                              precision=p)
               for name, base in bases.items() for p in args.precision
               for e in args.every}  # fmt: skip
    cfg = SelectionConfig(keep=5, method="score-fps", drop=0.4)
    ms = {"predict": 0.0, "select": 0.0} | {key: 0.0 for key in scorers}
    for _ in range(args.repeats):
        for i, scene in enumerate(largest):
            batch = collate([scene])
            t0 = time.perf_counter()
            pred = model.predict(batch, args.samples, torch.Generator().manual_seed(i))
            ms["predict"] += time.perf_counter() - t0
            for key, scorer in scorers.items():
                t0 = time.perf_counter()
                residual = scorer.residual(batch, pred).sum(-1)  # [K, N]
                ms[key] += time.perf_counter() - t0
            t0 = time.perf_counter()
            select_samples(pred, cfg, residual, batch)
            ms["select"] += time.perf_counter() - t0
    calls = args.repeats * len(largest)
    ms = {k: 1000 * v / calls for k, v in ms.items()}
    sizes = [s.num_agents for s in largest]
    print(
        f"{args.dataset} test, the {len(largest)} largest scenes ({min(sizes)}-{max(sizes)} "
        f"agents), K = {args.samples}, {torch.get_num_threads()} threads, {args.repeats} "
        f"repeats: predict {ms['predict']:.1f} ms/scene, select {ms['select']:.2f} ms/scene"
    )
    rows = []
    for key, scorer in scorers.items():
        name, p, e = key
        params = sum(t.numel() for t in scorer.denoiser.parameters())
        steps = len(scorer.steps)
        ratio = (ms[key] + ms["select"]) / ms["predict"]
        rows.append({"scorer": name, "parameters": params, "precision": p, "every": e,
                     "steps": steps, "ms_score": ms[key], "ratio": ratio})  # fmt: skip
        print(f"  {name} ({params / 1e6:.2f} M) {p} score every {e:>3} ({steps:>2} steps): "
              f"{ms[key]:7.1f} ms/scene, (score + select) / predict = {ratio:.2f}x")  # fmt: skip
    out = {"dataset": args.dataset, "scene_sizes": sizes, "ms_predict": ms["predict"],
           "ms_select": ms["select"], "settings": rows, "command": command_line(),
           "machine": machine()}  # fmt: skip
    meta = ROOT / "benchmarks" / "results" / "meta" / f"selection_cost_{args.dataset}.json"
    meta.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
