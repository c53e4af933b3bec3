"""Would an ensemble of generators beat one? A validation-only probe, no choice.

Each generator file predicts K samples per agent on a validation split; they are combined
without retraining in two ways and compared with each file alone (minADE_K / minFDE_K per
agent):

- ``matched``: every other file's K samples are matched to the first file's, per agent, by
  the assignment with the least summed squared distance over the whole paths (Hungarian), and
  each matched group is averaged (the first file's K slots, each the mean of one sample per
  file); ``matched-respread`` rescales each agent's averaged samples about their centroid to
  the mean spread of the single files' sets (averaging shrinks a set);
- ``medoids``: K of the union of all files' samples, by greedy K-medoids with swaps on the
  endpoints (``score.selection``'s ``medoids``, uniform weights).

Nothing published changes whatever it prints; no test split is read.

    python benchmarks/ensemble_probe.py --dataset eth --models models/eth/generator.safetensors \\
        runs/eth44/e320c-s0/generator.safetensors runs/eth44/e320c-s1/generator.safetensors \\
        --data-root ../shared/data
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment

from trajpref.data import load_dataset
from trajpref.evaluation import predict_dataset
from trajpref.metrics import min_ade_fde
from trajpref.models import checkpoint as ckpt
from trajpref.results import write_meta
from trajpref.score.selection import SelectionConfig, gather, select_samples

ROOT = Path(__file__).resolve().parent.parent


def min_errors(pred: np.ndarray, future: np.ndarray) -> dict[str, float]:
    """minADE / minFDE per agent of pred [K, N, T_f, 2] against future [N, T_f, 2], averaged
    over the agents (``metrics.min_ade_fde``)."""
    ade, fde = min_ade_fde(torch.from_numpy(pred), torch.from_numpy(future))  # [N] each
    return {"min_ade": float(ade.mean()), "min_fde": float(fde.mean())}


def matched_mean(sets: list[np.ndarray]) -> np.ndarray:
    """The first set's K slots, each averaged with its Hungarian match in every other set.
    sets: [K, N, T_f, 2] each -> [K, N, T_f, 2]."""
    first = sets[0]
    total = first.copy()
    for other in sets[1:]:
        for n in range(first.shape[1]):
            a, b = first[:, n].reshape(len(first), -1), other[:, n].reshape(len(other), -1)
            cost = ((a[:, None] - b[None]) ** 2).sum(-1)  # [K, K] squared path distances
            rows, cols = linear_sum_assignment(cost)
            total[rows, n] += other[cols, n]
    return total / len(sets)


def spread(pred: np.ndarray) -> np.ndarray:
    """Per agent, the root mean squared distance of the K samples from their centroid [N]."""
    centre = pred.mean(0, keepdims=True)  # [1, N, T_f, 2]
    return np.sqrt(((pred - centre) ** 2).sum(-1).mean((0, 2)))


def respread(avg: np.ndarray, sets: list[np.ndarray]) -> np.ndarray:
    """``avg`` rescaled about its centroid, per agent, to the single sets' mean spread."""
    centre = avg.mean(0, keepdims=True)
    target = np.mean([spread(s) for s in sets], 0)  # [N]
    gain = target / np.maximum(spread(avg), 1e-9)  # [N]
    return centre + (avg - centre) * gain[None, :, None, None]


def union_medoids(sets: list[np.ndarray], keep: int) -> np.ndarray:
    """``keep`` of the union's samples per agent by K-medoids on the endpoints."""
    union = torch.from_numpy(np.concatenate(sets, 0))  # [M K, N, T_f, 2]
    idx = select_samples(union, SelectionConfig(method="medoids", keep=keep))  # [keep, N]
    return gather(union, idx).numpy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument(
        "--models",
        nargs="+",
        type=Path,
        required=True,
        help="generator files, at least two; the first anchors the matching",
    )
    parser.add_argument("--split", default="val", choices=["val"],
                        help="validation only: the probe chooses nothing")  # fmt: skip
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--out", type=Path, default=None,
                        help="the record (default: meta/ensemble_<D>_val.json)")  # fmt: skip
    args = parser.parse_args()
    if len(args.models) < 2:
        parser.error("an ensemble needs at least two --models")

    data = load_dataset(args.dataset, args.split, args.data_root)
    sets, future = [], None
    rows = {}
    for path in args.models:
        predictor = ckpt.predictor_from_payload(ckpt.load(path)).eval()
        out = predict_dataset(predictor, data, args.samples, args.seed, "cpu")
        sets.append(out["pred"])
        future = out["future"]
        rows[str(path)] = min_errors(out["pred"], future)
        print(f"{path}: {rows[str(path)]['min_ade']:.4f} / {rows[str(path)]['min_fde']:.4f}")
    avg = matched_mean(sets)
    combined = {
        "matched": min_errors(avg, future),
        "matched-respread": min_errors(respread(avg, sets), future),
        "medoids": min_errors(union_medoids(sets, args.samples), future),
    }
    singles = np.mean([r["min_fde"] for r in rows.values()])
    for name, m in combined.items():
        print(f"{name}: {m['min_ade']:.4f} / {m['min_fde']:.4f} "
              f"({m['min_fde'] / singles - 1:+.1%} minFDE against the singles' mean)")  # fmt: skip
    out = args.out or ROOT / "benchmarks" / "results" / "meta" / f"ensemble_{args.dataset}_val.json"
    write_meta(out, dataset=args.dataset, split=args.split, samples=args.samples,
               seed=args.seed, singles=rows, combined=combined)  # fmt: skip
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
