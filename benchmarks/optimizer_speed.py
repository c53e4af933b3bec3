"""How much faster a training step runs with AdamW's fused implementation, side by side.

    python benchmarks/optimizer_speed.py --datasets eth hotel univ zara1 zara2 sdd nba robo \
        --data-root ../shared/data

For each dataset's default config and each pretraining stage (the denoiser by Eq. 2, the
generator through the published denoiser, in the config's precision), two copies of the stage
start from the same weights: one steps PyTorch's default AdamW (on the CPU a loop over the
parameters), the other the fused one (``OptimConfig.fused``, ``train.loop.make_optimizer``).
They take the same training
batches in turn, batch by batch, with the same noise and dropout draws, round after round, so
both see the same machine load (which of the two goes first alternates); the first round is
warm-up and not timed. A step is what the loop times: forward, backward, the gradient clip and
the optimiser step (loading and augmentation, the same for both, are left out, so the ratio of
a whole epoch is a little closer to 1). Prints agent-windows per second of each, their ratio,
and the largest difference between the two copies' weights at the end (float rounding in fp32;
in bf16 the rounding of the activations lets it grow); writes
benchmarks/results/meta/optimizer_speed.json. The rule that reads it: docs/pretraining.md,
"Fused AdamW steps".
"""

from __future__ import annotations

import copy
import dataclasses
import time
from pathlib import Path

import torch
from precision_speed import step_timing_args, timing_batches, timing_stages

from trajpref.results import write_meta
from trajpref.train.loop import make_optimizer, precision_autocast

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "optimizer_speed.json"
ARMS = ("default", "fused")


def time_arms(stages: dict, optim_cfg, batches, rounds: int, device: torch.device) -> dict:
    """Seconds per arm over ``rounds`` timed rounds (one warm-up round first), each arm's
    stage stepping its own optimiser as the loop does; and the largest weight difference
    between the arms at the end."""
    opts, params = {}, {}
    for arm, stage in stages.items():
        params[arm] = [p for p in stage.trainable.parameters() if p.requires_grad]
        opts[arm] = make_optimizer(
            params[arm], dataclasses.replace(optim_cfg, fused=arm == "fused")
        )
        stage.objective.train()
    seconds = dict.fromkeys(stages, 0.0)
    for r in range(rounds + 1):
        for i, batch in enumerate(batches):
            order = list(stages.items())
            for arm, stage in order if (r + i) % 2 == 0 else order[::-1]:  # neither always first
                torch.manual_seed(1000 * r + i)  # the same dropout masks in both arms
                gen = torch.Generator().manual_seed(1000 * r + i)  # the same noise draws
                t0 = time.perf_counter()
                with precision_autocast(device, optim_cfg.precision):
                    loss, _ = stage.objective(batch, gen)
                opts[arm].zero_grad(set_to_none=True)
                loss.float().backward()
                torch.nn.utils.clip_grad_norm_(params[arm], optim_cfg.grad_clip)
                opts[arm].step()
                if r > 0:
                    seconds[arm] += time.perf_counter() - t0
    a, b = (params[arm] for arm in ARMS)
    diff = max(float((x - y).detach().abs().max()) for x, y in zip(a, b, strict=True))
    return {"seconds": seconds, "max_weight_difference": diff}


def main() -> None:
    args = step_timing_args(__doc__.splitlines()[0], "hotel", OUT)
    device = torch.device("cpu")

    entries = {}
    for dataset in args.datasets:
        cfg, train, raw, agents = timing_batches(dataset, args, device)
        torch.manual_seed(0)
        entry = {}
        torch.manual_seed(0)  # the denoiser stage's fresh weights, the same each run
        for name, stage in timing_stages(cfg, train, dataset, device).items():
            optim_cfg = getattr(cfg, name)  # the stage's own optimisation section
            batches = raw if stage.context else [b.without_context() for b in raw]
            arms = {arm: copy.deepcopy(stage) for arm in ARMS}  # the same start
            out = time_arms(arms, optim_cfg, batches, args.rounds, device)
            sec = out["seconds"]
            entry[name] = {
                "precision": optim_cfg.precision,
                "agent_windows": agents,
                "default_per_second": round(agents / sec["default"], 1),
                "fused_per_second": round(agents / sec["fused"], 1),
                "speedup": round(sec["default"] / sec["fused"], 3),
                "max_weight_difference": out["max_weight_difference"],
            }
            print(f"{dataset:<9} {name:<9} ({optim_cfg.precision}) default "
                  f"{agents / sec['default']:7.1f}  fused {agents / sec['fused']:7.1f} "
                  f"agent-windows/s  fused is {sec['default'] / sec['fused']:.3f}x  largest "
                  f"weight difference {out['max_weight_difference']:.1e}", flush=True)  # fmt: skip
        entries[dataset] = entry
    write_meta(args.out, datasets=entries, batches=args.batches, rounds=args.rounds)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
