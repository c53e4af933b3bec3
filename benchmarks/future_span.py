"""How far real futures lie from the generator's smooth output span (``model.future_rank``):
each validation future, relative to its agent's last observed position, projected per
coordinate onto the polynomials t, ..., t^r of the future step, and the projection's ADE /
FDE against the future itself. It bounds what ``future_rank = r`` can cost; a principal-
component basis of the training futures is printed beside it for comparison.

    python benchmarks/future_span.py --data-root ../shared/data   # zara1, hotel, eth; r = 3..6

Writes benchmarks/results/meta/future_span_val.json and prints the table for docs/.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from post_hoc import study_parser, write_study

from trajpref.data import load_dataset
from trajpref.models.generator import time_projection

OUT = Path(__file__).parent / "results" / "meta" / "future_span_val.json"


def relative_futures(dataset) -> np.ndarray:
    """[M, T_f, 2] every fully observed future, relative to its last observed position."""
    fut = np.concatenate([s.future - s.history[:, -1:, :] for s in dataset.scenes])
    return fut[np.isfinite(fut).all(axis=(1, 2))]


def projection_error(futures: np.ndarray, projection: np.ndarray) -> tuple[float, float]:
    """(ADE, FDE) of the futures [M, T_f, 2] against their projection [T_f, T_f] in time."""
    err = np.linalg.norm(np.einsum("ts,msd->mtd", projection, futures) - futures, axis=-1)
    return float(err.mean()), float(err[:, -1].mean())  # [M, T_f] -> ADE, FDE


def main() -> None:
    parser = study_parser(__doc__)
    parser.add_argument("--datasets", nargs="+", default=["zara1", "hotel", "eth"])
    parser.add_argument("--ranks", nargs="+", type=int, default=[3, 4, 5, 6])
    args = parser.parse_args()
    rows = []
    for name in args.datasets:
        train = relative_futures(load_dataset(name, "train", args.data_root))
        val = relative_futures(load_dataset(name, "val", args.data_root))
        t_fut = val.shape[1]
        series = train.transpose(0, 2, 1).reshape(-1, t_fut)  # [2M, T_f] one coordinate each
        _, _, components = np.linalg.svd(series, full_matrices=False)  # rows: [T_f] directions
        for r in args.ranks:
            poly = time_projection(t_fut, r).double().numpy()  # [T_f, T_f]
            pca = components[:r].T @ components[:r]  # [T_f, T_f]
            (ade, fde), (pca_ade, pca_fde) = projection_error(val, poly), projection_error(val, pca)
            rows.append({"dataset": name, "rank": r, "agents": len(val), "ade": ade, "fde": fde,
                         "pca_ade": pca_ade, "pca_fde": pca_fde})  # fmt: skip
            print(f"{name:6s} r={r}: polynomial ADE {ade:.4f} FDE {fde:.4f} | "
                  f"principal components ADE {pca_ade:.4f} FDE {pca_fde:.4f}")  # fmt: skip
    command = "python benchmarks/" + " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])
    write_study(OUT, command, rows, {"note": "decides nothing; bounds model.future_rank's cost"})
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
