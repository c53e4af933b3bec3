"""A probe: is a noise-free residual as informative as the noisy one? (validation only)

    python benchmarks/noise_free_residual.py --dataset zara1 --scenes 300 --data-root ../shared/data

The score's residual at one step draws noise, and one step's outcome moves with the scorer's
seed. A deterministic alternative costs the same single pass: the sample scaled to a noise
level with the noise set to zero, sqrt(abar_s) Y, and ||eps_theta||^2. This prints, for the
paper's 34 noisy steps, one and two noisy steps and noise-free steps at several levels, the
per-agent Spearman correlation between the residual's order and the samples' FDE order over
the K = 20 samples, and minFDE_5 of the chosen selection shape (drop 20 %, score-facility,
temperature 2, bandwidth 1, the dataset's pace gate), beside the score-free facility location
and the generator's first 5 (docs/selection.md, "A noise-free residual"). It reads the
validation split only and writes nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from trajpref.data import load_dataset
from trajpref.data.loader import collate
from trajpref.data.transforms import to_model_frame
from trajpref.models.encoder import scene_features
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import TrajectoryScorer, score_timesteps
from trajpref.score.selection import SelectionConfig, select_samples, within_pace

TRUST = {"zara1": 0.445}
"""The chosen pace gate of each dataset's selection (model units per step; 0: none)."""

BATCH = 25
"""Scenes per pass."""


def settings(num_steps: int = 100) -> dict[str, tuple[str, list[int]]]:
    """name -> (noisy | zero, the score steps), named by the step of a 100-step schedule and
    scaled to the scorer's ``num_steps`` (the published denoisers have 100)."""

    def at(step: int) -> int:
        return step * num_steps // 100

    out = {"n34": ("noisy", score_timesteps(num_steps, max(1, at(3)))),
           "n1@0": ("noisy", [0]), "n1@99": ("noisy", [at(99)]),
           "n2": ("noisy", [0, at(50)])}  # fmt: skip
    for step in (0, 5, 10, 20, 40, 70, 99):
        out[f"z@{step}"] = ("zero", [at(step)])
    out["z@10,40"] = ("zero", [at(10), at(40)])
    return out


@torch.no_grad()
def zero_residual(scorer: TrajectoryScorer, batch, pred: torch.Tensor,
                  steps: list[int]) -> torch.Tensor:  # fmt: skip
    """[K, N, T_f] ||eps_theta(sqrt(abar_s) y, s)||^2 averaged over ``steps``: the residual
    with the noise set to zero (the sample scaled to each noise level, nothing added)."""
    context = scorer.denoiser.context(scene_features(batch, scorer.scale))  # [N, H]
    y = to_model_frame(pred, batch, scorer.scale)  # [K, N, T_f, 2]
    d = y.new_zeros(y.shape[:3])  # [K, N, T_f]
    for s in steps:
        y_s = scorer.schedule.add_noise(y, torch.zeros_like(y), torch.tensor(s))
        d += scorer.denoiser(y_s, s, context).pow(2).sum(-1)
    return d / len(steps)


def rank_correlation(residual: torch.Tensor, fde: torch.Tensor) -> torch.Tensor:
    """[N] Spearman correlation over the K samples of each agent: residual, fde [K, N]."""
    a = residual.argsort(0).argsort(0).float()  # [K, N] ranks
    b = fde.argsort(0).argsort(0).float()
    a, b = a - a.mean(0), b - b.mean(0)
    return (a * b).mean(0) / (a.std(0, unbiased=False) * b.std(0, unbiased=False))


@torch.no_grad()
def main(argv: list[str] | None = None) -> dict[str, dict[str, float]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", default="zara1")
    parser.add_argument("--model", default=None, help="default: DATASET/generator")
    parser.add_argument("--scenes", type=int, default=300, help="evenly spaced val scenes")
    parser.add_argument("--samples", type=int, default=20, help="K, the samples drawn")
    parser.add_argument("--data-root", default=None)
    args = parser.parse_args(argv)
    name = args.model or f"{args.dataset}/generator"
    model = load_predictor(name, device="cpu")
    scorer = TrajectoryScorer.from_checkpoint(name)
    data = load_dataset(args.dataset, "val", args.data_root)
    idx = np.linspace(0, len(data) - 1, min(args.scenes, len(data))).astype(int)
    trust = TRUST.get(args.dataset, 0.0)
    keep = min(5, args.samples)  # K' (5 of the 20)
    chosen = SelectionConfig(keep=keep, method="score-facility", drop=0.2, temperature=2.0,
                             bandwidth=1.0)  # fmt: skip
    free = {m: SelectionConfig(keep=keep, method=m, bandwidth=1.0) for m in ("facility", "first")}
    steps_of = settings(scorer.schedule.num_steps)
    found: dict[str, dict[str, list[torch.Tensor]]] = {}
    for start in range(0, len(idx), BATCH):
        batch = collate([data[int(i)] for i in idx[start : start + BATCH]])
        pred = model.predict(batch, args.samples, torch.Generator().manual_seed(0))  # [K,N,T,2]
        fde = (pred[:, :, -1] - batch.future[None, :, -1]).norm(dim=-1)  # [K, N]
        trusted = within_pace(batch, scorer.scale, trust)
        for method, cfg in free.items():
            kept = select_samples(pred, cfg, None, batch)  # [K', N]
            found.setdefault(method, {}).setdefault("fde5", []).append(
                fde.gather(0, kept).min(0).values
            )
        for key, (kind, steps) in steps_of.items():
            if kind == "noisy":
                d = scorer.with_steps(steps).residual(batch, pred)  # [K, N, T_f]
            else:
                d = zero_residual(scorer, batch, pred, steps)
            residual = d.sum(-1)  # [K, N]
            row = found.setdefault(key, {})
            row.setdefault("rho", []).append(rank_correlation(residual, fde))
            kept = select_samples(pred, chosen, residual, batch, trusted=trusted)  # [K', N]
            row.setdefault("fde5", []).append(fde.gather(0, kept).min(0).values)
    out = {key: {m: float(torch.cat(v).nanmean()) for m, v in row.items()}
           for key, row in found.items()}  # fmt: skip
    for key, row in out.items():
        cells = "  ".join(f"{m}={v:.4f}" for m, v in row.items())
        print(f"{args.dataset} {key:10s} {cells}")
    return out


if __name__ == "__main__":
    main()
