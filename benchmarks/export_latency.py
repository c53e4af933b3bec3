"""An exported predictor's cost against the model's own call, in ms per scene, side by side.

    OMP_NUM_THREADS=1 python benchmarks/export_latency.py --dataset zara1 --sizes 1 3 7 15 \
        --calls 15 --data-root ../shared/data

For each scene size P (the first P agents of the first validation scene with at least P, as
``planner_latency.py`` picks them), times on the same histories, interleaved (one call of each
in turn, ``--calls`` rounds after one warm-up round), and keeps each call's median:
``predict_scene`` (K = 20, with its checks of the histories and warnings), the exported
program of the same generator (``trajpref.models.export``: the graph alone, no check), and the
largest difference between their futures (0 where they agree exactly). Writes
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
from trajpref.score import predict_scene


@torch.no_grad()
def main(argv: list[str] | None = None) -> dict:
    args = latency_args(__doc__, "a dataset with a published generator", argv)
    model = load_predictor(f"{args.dataset}/generator", device="cpu")
    program = export_predictor(model, max_agents=max(2, *args.sizes)).module()
    val = load_dataset(args.dataset, "val", args.data_root)
    rows = []
    for p, history in scene_histories(val, args.sizes).items():
        tensor, types = torch.from_numpy(history), torch.zeros(p, dtype=torch.long)
        gap = float(
            np.abs(program(tensor, types).numpy() - predict_scene(model, history, 20)).max()
        )
        calls = {"predict_scene": lambda h=history: predict_scene(model, h, 20),
                 "exported": lambda t=tensor, y=types: program(t, y)}  # fmt: skip
        ms = median_ms(calls, args.calls)
        ratio = ms["predict_scene"] / ms["exported"]
        rows.append({"agents": p, **ms, "ratio": round(ratio, 2), "max_difference": gap})
        print(
            f"P={p}: predict_scene {ms['predict_scene']:.1f} ms, exported {ms['exported']:.1f} "
            f"ms ({ratio:.2f}x), largest difference {gap:.3g}",
            flush=True,
        )
    out = Path(args.out_dir) / f"export_latency_{args.dataset}.json"
    record = write_meta(out, dataset=args.dataset, split="val", samples=20, calls=args.calls,
                        rows=rows)  # fmt: skip
    print(f"wrote {out}")
    return record


if __name__ == "__main__":
    main()
