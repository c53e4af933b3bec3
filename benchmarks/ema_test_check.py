"""Does the weight average's test gain hold for another seed? Raw against averaged weights of
one training run, on a test split; nothing is chosen or published.

A generator run trained with ``generator.ema_epochs > 0`` keeps two checkpoints:
``generator.safetensors`` (the averaged weights' best validation epoch) and
``generator_raw.safetensors`` (the raw weights' best: the run's own control, same seed and
batches). Both get the sampling settings of the dataset's published default
(``checkpoint.POST_HOC_SETTINGS``: its input speed clamp; same training split, so the same
value), then the test split is read with each (K = 20, seed 0). Seed 0 is the published pair:
the ``pretrained`` row (averaged) against the ``pretrained-raw`` row (the raw-weights default
it replaced).

    python benchmarks/ema_test_check.py runs/seed1/zara1-ema runs/seed1/zara2-ema \\
        runs/seed1/univ-ema --data-root ../shared/data

Writes benchmarks/results/meta/ema_test_check.json and prints the table for docs/.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import yaml

from trajpref.data import load_dataset
from trajpref.evaluation import evaluate
from trajpref.io import read_checkpoint_header
from trajpref.models import checkpoint as ckpt
from trajpref.results import read_rows, write_meta

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
METRICS = ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde")


def match_settings(run_file: Path, published: Path) -> dict[str, Any]:
    """Give ``run_file`` the sampling settings of ``published`` (weights untouched); returns
    them."""
    model = ckpt.config_of(read_checkpoint_header(published)).model  # defaults filled in
    values = {name: getattr(model, name) for name in ckpt.POST_HOC_SETTINGS}
    for name, value in values.items():
        ckpt.set_generator_setting(run_file, name, value, note=f"as {published.name} (published)")
    return values


def published_pair(dataset: str) -> dict[str, dict[str, float]]:
    """Seed 0: the published averaged default's test row and the raw one it replaced."""
    rows = read_rows(RESULTS, protocol="all")
    out = {}
    for weights, method in (("averaged", "pretrained"), ("raw", "pretrained-raw")):
        row = next((r for r in rows if r["dataset"] == dataset and r["method"] == method
                    and r["split"] == "test" and r["seed"] == 0), None)  # fmt: skip
        if row is None:
            raise SystemExit(f"{dataset}: no {method} test row in benchmarks/results")
        out[weights] = {k: row[k] for k in METRICS}
    return out


def change(pair: dict[str, dict[str, float]], metric: str) -> float:
    """Percent change of ``metric`` from the raw to the averaged weights."""
    return 100 * (pair["averaged"][metric] / pair["raw"][metric] - 1)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", type=Path, nargs="+", help="run folders trained with an average")
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", type=Path, default=RESULTS / "meta" / "ema_test_check.json")
    args = parser.parse_args(argv)
    records = []
    for run in args.runs:
        files = {
            "averaged": run / "generator.safetensors",
            "raw": run / "generator_raw.safetensors",
        }
        missing = [str(p) for p in files.values() if not p.is_file()]
        if missing:
            parser.error(f"{run}: missing {', '.join(missing)} (trained with ema_epochs > 0?)")
        cfg = yaml.safe_load((run / "config.yaml").read_text())
        dataset, seed = cfg["data"]["dataset"], int(cfg["seed"])
        published = ROOT / "models" / dataset / "generator.safetensors"
        settings = {w: match_settings(f, published) for w, f in files.items()}
        test = load_dataset(dataset, "test", args.data_root)
        measured = {}
        for weights, path in files.items():
            model = ckpt.load_predictor(path, sampler="leapfrog", device=args.device)
            res = evaluate(model, test, 20, 0, args.device, progress=False)
            measured[weights] = {k: res[k] for k in METRICS}
        for s, pair in ((0, published_pair(dataset)), (seed, measured)):
            records.append({"dataset": dataset, "seed": s, **pair,
                            "change_fde_pct": change(pair, "min_fde"),
                            "change_ade_pct": change(pair, "min_ade"),
                            "run": "published rows" if s == 0 else str(run),
                            "settings": settings["averaged"] if s else None})  # fmt: skip
    print("| fold | seed | test minADE20 / minFDE20, raw -> averaged | change minFDE20 | "
          "change minADE20 |")  # fmt: skip
    print("|---|---|---|---|---|")
    for r in records:
        raw, avg = r["raw"], r["averaged"]
        print(f"| {r['dataset']} | {r['seed']} | {raw['min_ade']:.4f} / {raw['min_fde']:.4f} -> "
              f"{avg['min_ade']:.4f} / {avg['min_fde']:.4f} | {r['change_fde_pct']:+.2f} % | "
              f"{r['change_ade_pct']:+.2f} % |")  # fmt: skip
    write_meta(args.out, split="test", samples=20, records=records)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
