"""The SDA reward's groups and values on the test splits: what finetune.reward=sda would see.

    OMP_NUM_THREADS=1 python benchmarks/sda_groups.py --datasets eth hotel univ zara1 zara2 \\
        --data-root ../shared/data

For each dataset: the share of agents in a social group (rl/sda.py at the finetune.sda_*
defaults, or --radius/--drift/--tolerance), the groups' sizes and observed mate distances; the
per-step SDA reward (group members only; lone agents always get 1) of the ground-truth future
and of the published generator's K = 20 samples (seed 0); how much it separates one agent's
samples (the std over K of the mean per-step reward); and whether it points at accurate
samples: top-1 recall (the sample with the highest SDA reward is the min-ADE one; chance 1/K)
and the mean per-agent Spearman correlation of the reward with -ADE. No training. Writes
benchmarks/results/meta/sda_groups.json and prints the markdown table of docs/sda.md.
"""

from __future__ import annotations

import argparse
import datetime
import shlex
import sys
import time
from pathlib import Path

import torch

from trajpref.config import FinetuneConfig
from trajpref.data import load_dataset
from trajpref.io import write_json
from trajpref.models.checkpoint import load_predictor
from trajpref.rl.sda import sda_reward, social_groups
from trajpref.types import collate

ROOT = Path(__file__).resolve().parent.parent


def ranks(x: torch.Tensor) -> torch.Tensor:
    """Ranks 0..K-1 along the first axis: x [K, M] -> [K, M] float."""
    return x.argsort(0).argsort(0).to(torch.float32)


def spearman(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Per-column Spearman correlation of a, b [K, M] -> [M] (no ties expected)."""
    ra, rb = ranks(a), ranks(b)
    ra, rb = ra - ra.mean(0), rb - rb.mean(0)
    return (ra * rb).sum(0) / (ra.norm(dim=0) * rb.norm(dim=0)).clamp(min=1e-12)


def measure(name: str, args: argparse.Namespace) -> dict:
    data = load_dataset(name, "test", args.data_root).evenly_spaced(args.max_scenes)
    predictor = load_predictor(ROOT / "models" / name / "generator.safetensors")
    gen = torch.Generator().manual_seed(0)
    thresholds = (args.radius, args.drift)
    agents = grouped = 0
    sizes, mate_dist, r_gt, r_gt_last, r_pred, spread, top1, rho = ([] for _ in range(8))
    seconds = 0.0
    for start in range(0, len(data), args.scenes_per_batch):
        batch = collate(data.scenes[start : start + args.scenes_per_batch])
        labels = social_groups(batch.history, batch.scene, *thresholds, batch.agent_type)  # [N]
        count = torch.bincount(labels, minlength=batch.num_agents)  # [N]
        member = count[labels] > 1  # [N]
        agents += batch.num_agents
        grouped += int(member.sum())
        sizes.append(count[count > 1])
        for g in labels[member].unique():
            idx = (labels == g).nonzero()[:, 0]
            d = (batch.history[idx, None] - batch.history[None, idx]).norm(dim=-1).mean(-1)
            mate_dist.append(d[torch.triu_indices(len(idx), len(idx), 1).unbind()])
        pred = predictor.predict(batch, args.samples, gen)  # [K, N, T_f, 2]
        tic = time.perf_counter()
        r = sda_reward(
            batch.history, batch.scene, pred, *thresholds, args.tolerance, batch.agent_type
        )[:, member]  # [K, M, T_f]
        seconds += time.perf_counter() - tic
        gt = sda_reward(
            batch.history,
            batch.scene,
            batch.future[None],
            *thresholds,
            args.tolerance,
            batch.agent_type,
        )[0, member]  # [M, T_f]
        ade = (pred - batch.future).norm(dim=-1).mean(-1)[:, member]  # [K, M]
        total = r.mean(-1)  # [K, M] the mean per-step reward of each sample
        r_gt.append(gt.mean(-1))
        r_gt_last.append(gt[:, -1])
        r_pred.append(total.mean(0))
        spread.append(total.std(0) if member.any() else total.new_zeros(0))  # [M]
        top1.append(total.argmax(0) == ade.argmin(0))
        rho.append(spearman(total, -ade))
    cat = {k: torch.cat(v).float() for k, v in (("sizes", sizes), ("mate", mate_dist),
           ("gt", r_gt), ("gt_last", r_gt_last), ("pred", r_pred), ("spread", spread),
           ("top1", top1), ("rho", rho))}  # fmt: skip
    return {
        "scenes": len(data),
        "agents": agents,
        "grouped_share": grouped / agents,
        "groups": len(cat["sizes"]),
        "group_size_mean": float(cat["sizes"].mean()),
        "group_size_max": int(cat["sizes"].max()),
        "mate_distance_median": float(cat["mate"].median()),
        "reward_gt": float(cat["gt"].mean()),
        "reward_gt_final_step": float(cat["gt_last"].mean()),
        "reward_samples": float(cat["pred"].mean()),
        "reward_std_over_k": float(cat["spread"].mean()),
        "top1_recall_min_ade": float(cat["top1"].mean()),
        "spearman_with_minus_ade": float(cat["rho"].mean()),
        "reward_ms_per_batch": 1000 * seconds / -(-len(data) // args.scenes_per_batch),
    }


def table(results: dict[str, dict], samples: int) -> str:
    head = (
        "| dataset | scenes | agents in a group | groups (mean / max size) | median mate "
        "distance (m) | SDA r of the ground truth (mean / final step) | SDA r of the "
        f"{samples} samples | std over K | top-1 recall of min-ADE | Spearman with -ADE |"
    )
    rows = [head, "|" + "---|" * 10]
    for name, m in results.items():
        rows.append(
            f"| {name} | {m['scenes']} | {100 * m['grouped_share']:.0f} % | {m['groups']} "
            f"({m['group_size_mean']:.1f} / {m['group_size_max']}) | "
            f"{m['mate_distance_median']:.2f} | {m['reward_gt']:.2f} / "
            f"{m['reward_gt_final_step']:.2f} | {m['reward_samples']:.2f} | "
            f"{m['reward_std_over_k']:.2f} | {100 * m['top1_recall_min_ade']:.1f} % | "
            f"{m['spearman_with_minus_ade']:.2f} |"
        )
    return "\n".join(rows)


def main() -> None:
    defaults = FinetuneConfig()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["eth", "hotel", "univ", "zara1",
                                                          "zara2"])  # fmt: skip
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--max-scenes", type=int, default=None, help="evenly spread subset")
    parser.add_argument("--scenes-per-batch", type=int, default=32)
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--radius", type=float, default=defaults.sda_radius)
    parser.add_argument("--drift", type=float, default=defaults.sda_drift)
    parser.add_argument("--tolerance", type=float, default=defaults.sda_tolerance)
    parser.add_argument("--out", default=str(ROOT / "benchmarks/results/meta/sda_groups.json"))
    args = parser.parse_args()
    torch.set_grad_enabled(False)
    results = {}
    for name in args.datasets:
        tic = time.perf_counter()
        results[name] = measure(name, args)
        print(f"{name}: {time.perf_counter() - tic:.0f} s", file=sys.stderr)
    write_json(args.out, {
        "command": shlex.join(["python", "benchmarks/sda_groups.py", *sys.argv[1:]]),
        "date": datetime.date.today().isoformat(),
        "thresholds": {"radius": args.radius, "drift": args.drift, "tolerance": args.tolerance},
        "results": results,
    })  # fmt: skip
    print(table(results, args.samples))


if __name__ == "__main__":
    main()
