"""Exported programs' cost against the library's own calls, in ms per scene, side by side.

    OMP_NUM_THREADS=1 python benchmarks/export_latency.py --dataset zara1 --sizes 1 3 7 15 \
        --calls 15 --data-root ../shared/data

For each scene size P (the first P agents of the first validation scene with at least P, as
``planner_latency.py`` picks them), times on the same histories, interleaved (one call of each
in turn, ``--calls`` rounds after one warm-up round), and keeps each call's median:
``predict_scene`` (K = 20, with its checks of the histories and warnings), the exported
program of the same generator (``trajpref.models.export``: the graph alone, no check), and the
largest difference between their futures (0 where they agree exactly); then ``rank_samples``
of those 20 futures by the dataset's denoiser at 2 score steps (every 50th, the cheap
setting) against the exported scorer (``trajpref.score.export``), with the largest relative
difference of their residuals and whether the orders agree. Writes
benchmarks/results/meta/export_latency_<dataset>.json (with machine, threads, command and
date).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from planner_latency import latency_args, median_ms, scene_histories

from trajpref.data import load_dataset
from trajpref.models.export import export_predictor
from trajpref.models.registry import load_predictor
from trajpref.results import write_meta
from trajpref.score import predict_scene, rank_samples, score_timesteps
from trajpref.score.export import export_scorer
from trajpref.score.scorer import TrajectoryScorer


@torch.no_grad()
def main(argv: list[str] | None = None) -> dict:
    args = latency_args(__doc__, "a dataset with a published generator", argv)
    model = load_predictor(f"{args.dataset}/generator", device="cpu")
    program = export_predictor(model, max_agents=max(2, *args.sizes)).module()
    scorer = TrajectoryScorer.from_checkpoint(f"{args.dataset}/denoiser")
    scorer = scorer.with_steps(score_timesteps(scorer.schedule.num_steps, 50))  # 2 steps
    ranker = export_scorer(scorer, max_agents=max(2, *args.sizes)).module()
    val = load_dataset(args.dataset, "val", args.data_root)
    rows = []
    for p, history in scene_histories(val, args.sizes).items():
        tensor, types = torch.from_numpy(history), torch.zeros(p, dtype=torch.long)
        gap = float(
            np.abs(program(tensor, types).numpy() - predict_scene(model, history, 20)).max()
        )
        samples = predict_scene(model, history, 20)  # [K, P, T_f, 2]
        order, total = rank_samples(scorer, history, samples)  # [K], [K]
        futures = torch.from_numpy(samples)
        exported = (
            ranker(tensor, futures, types).sum(-1).sum(-1).numpy()
        )  # [K], as rank_samples adds
        rank_gap = float(np.abs(exported - total).max() / np.abs(total).max())
        same = bool((exported.argsort() == order).all())
        calls = {"predict_scene": lambda h=history: predict_scene(model, h, 20),
                 "exported": lambda t=tensor, y=types: program(t, y),
                 "rank_samples": lambda h=history, s=samples: rank_samples(scorer, h, s),
                 "rank_exported": lambda t=tensor, s=futures, y=types:
                     ranker(t, s, y).sum(-1).sum(-1).argsort()}  # fmt: skip
        ms = median_ms(calls, args.calls)
        ratio = ms["predict_scene"] / ms["exported"]
        rank_ratio = ms["rank_samples"] / ms["rank_exported"]
        rows.append({"agents": p, **ms, "ratio": round(ratio, 2), "max_difference": gap,
                     "rank_ratio": round(rank_ratio, 2), "rank_max_relative": rank_gap,
                     "same_order": same})  # fmt: skip
        print(
            f"P={p}: predict_scene {ms['predict_scene']:.1f} ms, exported {ms['exported']:.1f} "
            f"ms ({ratio:.2f}x), largest difference {gap:.3g}; rank_samples "
            f"{ms['rank_samples']:.1f} ms, exported {ms['rank_exported']:.1f} ms "
            f"({rank_ratio:.2f}x), relative difference {rank_gap:.2g}, same order {same}",
            flush=True,
        )
    out = Path(args.out_dir) / f"export_latency_{args.dataset}.json"
    record = write_meta(out, dataset=args.dataset, split="val", samples=20, calls=args.calls,
                        rows=rows)  # fmt: skip
    print(f"wrote {out}")
    return record


if __name__ == "__main__":
    main()
