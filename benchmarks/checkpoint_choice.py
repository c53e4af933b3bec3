"""How much does choosing the training epoch on the test split buy? A diagnosis, no choice.

Our rows keep the epoch with the best validation score and read the test split once. MoFlow's
ETH/UCY trainer instead validates on its test loader every epoch and keeps the epoch with the
lowest test minADE20 (docs/pretraining.md, "How much does choosing the epoch on the test split
buy?"). For generator runs trained with every epoch's weights kept (``--set
generator.eval_every=1 --set generator.keep_checkpoints=true``), this evaluates every kept
epoch on the test split (K = 20, seed 0, with the fold's *published* generator's sampling
settings: its speed clamp) and reports the test numbers of the epoch chosen

- by validation, as the training loop chose it (our protocol),
- by test minADE20 (MoFlow's protocol),
- by test minFDE20,

with the mean and standard deviation of test minFDE20 over the second half of training and
its correlation with validation minFDE20 there (does validation track the test from epoch to
epoch?).
Nothing published changes whatever it shows; its test numbers are read for this study alone.

    python benchmarks/checkpoint_choice.py runs/ckchoice/zara1 runs/ckchoice/eth \\
        --data-root ../shared/data
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from post_hoc import with_model_setting
from tqdm import tqdm

from trajpref.data import load_dataset
from trajpref.device import resolve_device
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.results import write_meta
from trajpref.train import read_metrics
from trajpref.viz import plot_curves

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = ("max_speed",)
"""Sampling settings taken from the fold's published generator (written in after training)."""


def first_min(epochs: list[dict[str, Any]], key: str) -> dict[str, Any]:
    """The earliest epoch record with the lowest ``key`` (the training loop keeps a new best
    only when it is strictly lower, so ties go to the earlier epoch)."""
    if not epochs:
        raise ValueError("no epochs to choose from")
    return min(epochs, key=lambda e: (e[key], e["epoch"]))


def choices(epochs: list[dict[str, Any]]) -> dict[str, Any]:
    """From per-epoch records (``epoch``, ``val_score``, ``val_min_fde``, ``test_min_ade``,
    ``test_min_fde``), the test numbers of the epoch each protocol keeps, and over the second
    half of the epochs (the later half when the count is odd) the spread of test minFDE20 and
    its correlation with validation minFDE20."""
    picks = {"validation": first_min(epochs, "val_score"),
             "test_min_ade": first_min(epochs, "test_min_ade"),
             "test_min_fde": first_min(epochs, "test_min_fde")}  # fmt: skip
    out: dict[str, Any] = {
        by: {"epoch": e["epoch"], "test_min_ade": e["test_min_ade"],
             "test_min_fde": e["test_min_fde"]}
        for by, e in picks.items()
    }  # fmt: skip
    ordered = sorted(epochs, key=lambda e: e["epoch"])
    half = ordered[len(ordered) // 2 :]
    late = np.array([e["test_min_fde"] for e in half])
    val = np.array([e["val_min_fde"] for e in half])
    # does validation track the test from epoch to epoch? (NaN with fewer than two epochs)
    corr = float(np.corrcoef(val, late)[0, 1]) if len(half) > 1 else float("nan")
    out["late_test_min_fde"] = {"mean": float(late.mean()), "std": float(late.std()),
                                "epochs": len(late), "corr_with_val_min_fde": corr}  # fmt: skip
    base = out["validation"]["test_min_fde"]
    for by in ("test_min_ade", "test_min_fde"):
        out[by]["change_pct"] = 100.0 * (out[by]["test_min_fde"] / base - 1.0)
    return out


def published_settings(dataset: str, models: Path) -> dict[str, Any]:
    """``SETTINGS`` of the fold's published default generator."""
    path = models / dataset / f"generator{ckpt.SUFFIX}"
    if not path.is_file():
        raise SystemExit(f"{dataset}: no published generator at {path}")
    model = ckpt.load(path)["config"]["model"]
    return {name: model[name] for name in SETTINGS if name in model}


def with_settings(payload: dict, settings: dict[str, Any]) -> dict:
    """A copy of a generator payload whose model config takes ``settings``."""
    for name, value in settings.items():
        payload = with_model_setting(payload, name, value)  # copies; the input stays as it was
    return payload


def study_run(run: Path, args: argparse.Namespace) -> dict[str, Any]:
    """Every kept epoch of one run on the test split, and the choices."""
    cfg_path = run / "config.yaml"
    if not cfg_path.is_file():
        raise SystemExit(f"{run}: no config.yaml (not a training run folder)")
    dataset = yaml.safe_load(cfg_path.read_text())["data"]["dataset"]
    logged = {r["epoch"]: r for r in read_metrics(run, "generator") if "val_score" in r}
    files = sorted(p for p in run.glob(f"generator_epoch*{ckpt.SUFFIX}")
                   if ".replaced-" not in p.name)  # an earlier run's, set aside  # fmt: skip
    if not files:
        raise SystemExit(f"{run}: no generator_epoch*{ckpt.SUFFIX} (train with --set "
                         "generator.keep_checkpoints=true)")  # fmt: skip
    settings = published_settings(dataset, args.models)
    test = load_dataset(dataset, "test", args.data_root)
    epochs = []
    for path in tqdm(files, desc=f"{dataset} epochs on test", unit="ckpt"):
        payload = ckpt.load(path)
        epoch = int(payload["meta"]["epoch"])
        if epoch not in logged:
            raise SystemExit(f"{path}: epoch {epoch} has no validation in the run's metrics log")
        predictor = ckpt.predictor_from_payload(with_settings(payload, settings))
        model = predictor.to(resolve_device(args.device)).eval()  # "auto" as evaluate reads it
        res = evaluate(model, test, args.samples, args.seed, args.device, progress=False,
                       collision_radius=None)  # fmt: skip
        epochs.append({"epoch": epoch, "val_score": logged[epoch]["val_score"],
                       "val_min_ade": logged[epoch]["val_min_ade"],
                       "val_min_fde": logged[epoch]["val_min_fde"],
                       **{f"test_{k}": res[k] for k in ("min_ade", "min_fde", "joint_min_ade",
                                                        "joint_min_fde")}})  # fmt: skip
    return {"dataset": dataset, "run": str(run), "settings": settings, "epochs": epochs,
            "choices": choices(epochs)}  # fmt: skip


def _cell(choice: dict[str, Any]) -> str:
    change = f", {choice['change_pct']:+.1f} %" if "change_pct" in choice else ""
    return (f"{choice['test_min_ade']:.3f} / {choice['test_min_fde']:.3f} "
            f"(epoch {choice['epoch']}{change})")  # fmt: skip


def table(studies: list[dict[str, Any]]) -> str:
    """The docs table: test minADE20 / minFDE20 of the epoch each protocol keeps."""
    lines = ["| fold | epoch chosen by validation (ours) | by test minADE20 (MoFlow's) | "
             "by test minFDE20 | test minFDE20 over the second half, mean +- std | "
             "its correlation with validation minFDE20 |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for s in studies:
        c = s["choices"]
        late = c["late_test_min_fde"]
        cells = " | ".join(_cell(c[by]) for by in ("validation", "test_min_ade", "test_min_fde"))
        lines.append(f"| {s['dataset']} | {cells} | {late['mean']:.3f} +- {late['std']:.3f} | "
                     f"{late['corr_with_val_min_fde']:+.2f} |")  # fmt: skip
    return "\n".join(lines)


def plot(studies: list[dict[str, Any]], out: Path) -> None:
    """Per fold, validation and test minFDE20 by epoch (two panels: their scales differ),
    with the epoch each protocol keeps marked on the test curve."""
    panels = {}
    marks = {"validation": ("o", "kept by validation (ours)"),
             "test_min_ade": ("X", "kept by test minADE (MoFlow's)"),
             "test_min_fde": ("s", "kept by test minFDE")}  # fmt: skip
    for s in studies:
        e = sorted(s["epochs"], key=lambda r: r["epoch"])
        x = np.array([r["epoch"] for r in e])
        test = [(x, [r["test_min_fde"] for r in e], {"label": "minFDE20", "color": "tab:red"})]
        for by, (marker, label) in marks.items():
            c = s["choices"][by]
            test.append(([c["epoch"]], [c["test_min_fde"]],
                          {"label": label, "marker": marker, "markersize": 8, "ls": "",
                           "color": "black", "zorder": 3}))  # fmt: skip
        panels[f"{s['dataset']}: test"] = test  # first: the legend goes on the first panel
        panels[f"{s['dataset']}: validation (as trained)"] = [
            (x, [r["val_min_fde"] for r in e], {"label": "minFDE20", "color": "tab:blue"})
        ]
    title = "Choosing the epoch on validation or on test (one run per fold, seed 0)"
    plot_curves(panels, out, "epoch", "minFDE20", title=title, columns=2)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="generator run folders")
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--models",
        type=Path,
        default=ROOT / "models",
        help="where the published generators (their settings) are",
    )
    parser.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks/results/meta/checkpoint_choice.json"
    )
    parser.add_argument("--plot", type=Path, default=ROOT / "docs/checkpoint-choice.png")
    args = parser.parse_args(argv)
    studies = [study_run(run, args) for run in args.runs]
    write_meta(args.out, split="test", purpose="diagnosis: no choice is made from it",
               samples=args.samples, seed=args.seed, studies=studies)  # fmt: skip
    if args.plot is not None:
        plot(studies, args.plot)
    print(table(studies))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
