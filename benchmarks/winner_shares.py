"""How evenly a generator uses its K samples: for each sample index k, the share of a split's
agents whose nearest endpoint (and nearest path) is sample k. A best-of-K loss trains only
the nearest sample, so an index that seldom wins seldom learns; the shares say how much of
the K = 20 budget a generator actually spends. A diagnosis: it decides nothing.

    python benchmarks/winner_shares.py --data-root ../shared/data \
        --models zara1/generator [runs/awta/zara1/generator.safetensors ...]

Writes benchmarks/results/meta/winner_shares_<split>.json and prints one line per model.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch
from post_hoc import study_parser, write_study

from trajpref.data import load_dataset
from trajpref.device import resolve_device
from trajpref.evaluation import predict_dataset
from trajpref.metrics import ade_fde
from trajpref.models import checkpoint as ckpt

OUT = Path(__file__).parent / "results" / "meta"


def winner_shares(pred: np.ndarray, future: np.ndarray) -> dict[str, np.ndarray | float]:
    """Shares [K] of the fully observed agents won by each sample, by endpoint (``fde``) and
    by path (``ade``), from samples ``pred`` [K, N, T_f, 2] and futures [N, T_f, 2]; with the
    minADE / minFDE over the same agents and the entropy of each share in bits."""
    seen = np.isfinite(future).all(axis=(1, 2))  # [N]
    ade, fde = ade_fde(torch.from_numpy(pred[:, seen]), torch.from_numpy(future[seen]))
    k = pred.shape[0]
    out: dict[str, np.ndarray | float] = {"agents": int(seen.sum())}
    for name, dist in (("ade", ade.numpy()), ("fde", fde.numpy())):  # [K, N'] each
        share = np.bincount(dist.argmin(0), minlength=k) / dist.shape[1]  # [K]
        nonzero = share[share > 0]
        out[f"{name}_share"] = share
        out[f"{name}_entropy_bits"] = float(-(nonzero * np.log2(nonzero)).sum())
        out[f"min_{name}"] = float(dist.min(0).mean())
    return out


def main() -> None:
    parser = study_parser(__doc__)
    parser.add_argument("--models", nargs="+", required=True,
                        help="published names (zara1/generator) or checkpoint files")  # fmt: skip
    parser.add_argument("--split", default="val", choices=["train", "val"])
    args = parser.parse_args()
    rows = []
    for spec in args.models:
        payload = ckpt.load(spec)  # a published name or a file (checkpoint.resolve_path)
        model = ckpt.predictor_from_payload(payload).to(resolve_device(args.device))
        dataset = payload["config"]["data"]["dataset"]
        data = load_dataset(dataset, args.split, args.data_root)
        arrays = predict_dataset(model, data, args.samples, args.seed, args.device, progress=False)
        res = winner_shares(arrays["pred"], arrays["future"])
        share = res["fde_share"]
        rows.append({"model": spec, "dataset": dataset,
                     **{k: v.round(4).tolist() if isinstance(v, np.ndarray) else v
                        for k, v in res.items()}})  # fmt: skip
        print(f"{spec}: {dataset} {args.split} minADE {res['min_ade']:.4f} minFDE "
              f"{res['min_fde']:.4f} | endpoint winner shares {100 * share.min():.1f}-"
              f"{100 * share.max():.1f} %, entropy {res['fde_entropy_bits']:.2f} of "
              f"{np.log2(len(share)):.2f} bits")  # fmt: skip
    command = "python benchmarks/" + " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])
    out = OUT / f"winner_shares_{args.split}.json"
    write_study(out, command, rows, {"note": "a diagnosis; decides nothing"}, split=args.split)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
