"""Where does a model's error come from? minFDE_K on a test split broken down by each agent's
observed speed, against constant velocity, with the training split's speed distribution beside
it (a speed shift between train and test shows up here).

    python benchmarks/speed_breakdown.py --dataset eth --data-root ../shared/data

Also evaluates a test-time fix for a speed shift: each scene scaled down (about its centroid)
so that no agent's observed speed exceeds the training split's 99th percentile, predicted,
and scaled back (the rule was fixed before looking at its result).

Writes benchmarks/results/meta/speed_breakdown_<dataset>[_<name>].json and prints a markdown
table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from trajpref.data import load_dataset
from trajpref.data.transforms import scene_centroids
from trajpref.evaluation import evaluate, predict_dataset
from trajpref.metrics import min_ade_fde
from trajpref.models import checkpoint as ckpt
from trajpref.models.baseline import ConstantVelocity
from trajpref.results import command_line, machine
from trajpref.types import Batch

ROOT = Path(__file__).resolve().parent.parent
EDGES = (0.0, 0.3, 0.8, 1.3, 2.0, float("inf"))
"""Observed-speed bins in m/s (standing, slow, walking, brisk, running)."""


def observed_speed(history: torch.Tensor, dt: float) -> torch.Tensor:
    """Mean speed over the observed frames: history [N, T_h, 2] -> [N]."""
    return history.diff(dim=1).norm(dim=-1).mean(1) / dt


class SpeedCapped:
    """Wraps a predictor: scenes whose fastest agent exceeds ``cap`` (m/s) are scaled by
    c = cap / that speed about their centroid before predicting, and the samples scaled back."""

    name = "speed-capped"

    def __init__(self, model, cap: float, dt: float):
        self.model, self.cap, self.dt = model, cap, dt

    def predict(self, batch: Batch, num_samples: int, generator=None) -> torch.Tensor:
        speed = observed_speed(batch.history, self.dt)  # [N]
        fastest = torch.zeros(batch.num_scenes, dtype=speed.dtype).scatter_reduce(
            0, batch.scene, speed, "amax"
        )  # [B]
        c = (self.cap / fastest.clamp(min=1e-6)).clamp(max=1.0)[batch.scene][:, None, None]
        o = scene_centroids(batch)[batch.scene][:, None, :]  # [N, 1, 2]
        scaled = Batch(history=(batch.history - o) * c + o, future=(batch.future - o) * c + o,
                       scene=batch.scene, agent_type=batch.agent_type,
                       num_scenes=batch.num_scenes, scene_ids=batch.scene_ids)  # fmt: skip
        pred = self.model.predict(scaled, num_samples, generator)  # [K, N, T_f, 2]
        return (pred - o) / c + o


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument(
        "--model", default=None, help="default models/<dataset>/generator.safetensors"
    )
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--name", default="", help="names the output for a --model")
    args = parser.parse_args()

    model_path = (
        Path(args.model)
        if args.model
        else ROOT / "models" / args.dataset / f"generator{ckpt.SUFFIX}"
    )
    test = load_dataset(args.dataset, "test", args.data_root)
    train = load_dataset(args.dataset, "train", args.data_root)
    dt = test.info.frame_interval
    predictor = ckpt.load_predictor(model_path, sampler="leapfrog", device="cpu")

    def min_errors(model) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-agent minADE_K / minFDE_K over the test split (agents in dataset order)."""
        out = predict_dataset(model, test, args.samples, 0, "cpu", progress=False)
        return min_ade_fde(torch.from_numpy(out["pred"]), torch.from_numpy(out["future"]))

    speed = observed_speed(torch.cat([torch.from_numpy(s.history) for s in test.scenes]), dt)
    a_model, f_model = min_errors(predictor)  # [N]
    _, f_cv = min_errors(ConstantVelocity())  # [N]
    train_speed = observed_speed(torch.cat([torch.from_numpy(s.history) for s in train.scenes]),
                                 dt).numpy()  # fmt: skip
    cap = float(np.percentile(train_speed, 99))
    capped = evaluate(SpeedCapped(predictor, cap, dt), test, args.samples, 0, "cpu",
                      progress=False)  # fmt: skip
    plain = {"min_ade": float(a_model.mean()), "min_fde": float(f_model.mean())}
    speed, f_model, f_cv = speed.numpy(), f_model.numpy(), f_cv.numpy()

    bins = []
    for lo, hi in zip(EDGES, EDGES[1:], strict=False):
        k = (speed >= lo) & (speed < hi)
        bins.append({
            "speed_m_s": [lo, None if hi == float("inf") else hi],
            "agents": int(k.sum()),
            "test_share": float(k.mean()),
            "train_share": float(((train_speed >= lo) & (train_speed < hi)).mean()),
            "min_fde_model": float(f_model[k].mean()) if k.any() else None,
            "min_fde_cv": float(f_cv[k].mean()) if k.any() else None,
            "share_of_model_error": float(f_model[k].sum() / f_model.sum()),
        })  # fmt: skip
    out = {
        "dataset": args.dataset,
        "model": str(model_path),
        "samples": args.samples,
        "min_fde_model": float(f_model.mean()),
        "min_fde_cv": float(f_cv.mean()),
        "train_speed_p50_p90_p99": [float(np.percentile(train_speed, q)) for q in (50, 90, 99)],
        "test_speed_p50_p90_p99": [float(np.percentile(speed, q)) for q in (50, 90, 99)],
        "bins": bins,
        "speed_cap_m_s": cap,
        "min_ade_min_fde": [plain["min_ade"], plain["min_fde"]],
        "min_ade_min_fde_speed_capped": [capped["min_ade"], capped["min_fde"]],
        "command": command_line(),
        "machine": machine(),
    }
    suffix = f"_{args.name}" if args.name else ""
    meta = ROOT / "benchmarks" / "results" / "meta" / f"speed_breakdown_{args.dataset}{suffix}.json"
    meta.write_text(json.dumps(out, indent=2) + "\n")

    print(f"| observed speed (m/s) | test agents | share of test / of train | minFDE{args.samples} "
          "model / CV | share of the model's error |")  # fmt: skip
    print("|---|---|---|---|---|")
    for b in bins:
        lo, hi = b["speed_m_s"]
        rng = f"{lo:.1f}-{hi:.1f}" if hi is not None else f">= {lo:.1f}"
        vals = ("–" if b["min_fde_model"] is None
                else f"{b['min_fde_model']:.3f} / {b['min_fde_cv']:.3f}")  # fmt: skip
        print(f"| {rng} | {b['agents']} | {100 * b['test_share']:.0f} % / "
              f"{100 * b['train_share']:.1f} % | {vals} | "
              f"{100 * b['share_of_model_error']:.0f} % |")  # fmt: skip
    print(
        f"train speed p50/p90/p99 {out['train_speed_p50_p90_p99']}, "
        f"test {out['test_speed_p50_p90_p99']}"
    )
    print(f"minADE/minFDE {plain['min_ade']:.3f} / {plain['min_fde']:.3f}; speed capped at "
          f"{cap:.2f} m/s: {capped['min_ade']:.3f} / {capped['min_fde']:.3f}")  # fmt: skip


if __name__ == "__main__":
    main()
