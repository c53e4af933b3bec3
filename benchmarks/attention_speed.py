"""The social attention's two forms, timed side by side inside real training steps.

    python benchmarks/attention_speed.py --data-root ../shared/data

``SocialAttention.forward`` folds the edge read-out W2 into the query and past the attention
weights, so no per-pair edge embedding is formed; ``direct_social_attention`` computes the
same output with them formed. For each named stage this script builds the stage as
``trajpref train`` does (its config's precision included), takes ``--batches`` shuffled
training batches and times full training steps (objective, backward, AdamW step; learning
rate 0, so every pass sees the same weights) over them with one form and then the other,
alternating ``--repeats`` times in one process. The first round is a warm-up and is not
counted. Writes benchmarks/results/meta/attention_speed.json.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from trajpref.config import load_config
from trajpref.data.loader import SceneLoader
from trajpref.data.registry import load_dataset
from trajpref.models import checkpoint as ckpt
from trajpref.models import layers
from trajpref.results import write_meta
from trajpref.train.loop import precision_autocast
from trajpref.train.stages import build_denoiser_stage, build_generator_stage

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "attention_speed.json"
DEFAULT_RUNS = ("hotel:generator", "zara1:generator", "eth:generator", "univ:generator",
                "sdd:generator", "nba:generator", "hotel:diffusion", "zara1:diffusion")  # fmt: skip


def time_stage(dataset: str, stage: str, data_root, batches: int, repeats: int) -> dict:
    """Seconds of ``repeats`` rounds over the same batches with each form (round 0 dropped)."""
    cfg = load_config(ROOT / "configs" / f"{dataset}.yaml")
    # the config names the data it trains on (e.g. robo trains on robo-sim)
    train = load_dataset(cfg.data.dataset, "train", data_root)
    val = load_dataset(cfg.data.val_dataset or cfg.data.dataset, "val", data_root)
    cpu = torch.device("cpu")
    if stage == "diffusion":
        built, optim = build_denoiser_stage(cfg, train, val, cpu)[0], cfg.denoiser
    else:
        denoiser = ckpt.load(ROOT / "models" / dataset / "denoiser.safetensors")
        built, optim = build_generator_stage(cfg, denoiser, val, cpu), cfg.generator
    loader = SceneLoader(train, max_agents=cfg.data.max_agents, shuffle=True)
    chosen = [b for _, b in zip(range(batches), loader, strict=False)]  # the first ones
    params = [p for p in built.trainable.parameters() if p.requires_grad]
    opt = torch.optim.AdamW(params, lr=0.0)
    built.objective.train()
    # a plain function set on the class binds as a method, as forward does
    forms = {"factored": layers.SocialAttention.forward,
             "direct": layers.direct_social_attention}  # fmt: skip
    seconds = {name: 0.0 for name in forms}
    noise = torch.Generator().manual_seed(0)
    try:
        for r in range(repeats + 1):
            for name in list(forms) if r % 2 == 0 else list(forms)[::-1]:
                layers.SocialAttention.forward = forms[name]
                start = time.perf_counter()
                for batch in chosen:
                    with precision_autocast(cpu, optim.precision):  # as the loop's steps
                        loss, _ = built.objective(batch, noise)
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
                if r > 0:  # round 0 builds kernels and caches for both forms
                    seconds[name] += time.perf_counter() - start
    finally:
        layers.SocialAttention.forward = forms["factored"]
    return {"precision": optim.precision, "seconds": {k: round(v, 2) for k, v in seconds.items()},
            "speedup": round(seconds["direct"] / seconds["factored"], 2)}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--runs", nargs="+", default=list(DEFAULT_RUNS),
                        metavar="DATASET:STAGE", help="stage: diffusion or generator")  # fmt: skip
    parser.add_argument("--batches", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=4)
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args()
    results = {}
    for spec in args.runs:
        dataset, _, stage = spec.partition(":")
        if stage not in ("diffusion", "generator"):
            raise SystemExit(f"{spec}: write DATASET:diffusion or DATASET:generator")
        results[spec] = r = time_stage(dataset, stage, args.data_root, args.batches, args.repeats)
        print(f"{spec:<17} {r['precision']}: direct {r['seconds']['direct']:.2f} s, factored "
              f"{r['seconds']['factored']:.2f} s: {r['speedup']}x", flush=True)  # fmt: skip
    write_meta(args.out, batches=args.batches, repeats=args.repeats, runs=results)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
