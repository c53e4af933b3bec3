"""The generator's input speed clamp (``model.max_speed``) on every published default
generator: the clamp each training split implies, how many agents it touches, and validation
with and without it; with ``--apply``, the clamp written into the published files.

    # the evidence: validation both ways, and the share of agents clamped per split
    python benchmarks/speed_clamp.py --data-root ../shared/data
    # then write the clamp into the published generators (weights untouched)
    python benchmarks/speed_clamp.py --apply --data-root ../shared/data
    # or publish it beside a default, as models/<D>/generator-clamp.safetensors, and read the
    # test split once for it
    python benchmarks/speed_clamp.py --variant eth
    python benchmarks/pretrain.py --dataset eth --variant clamp --published \
        --data-root ../shared/data

The clamp of a generator is the ``--quantile`` (0.99) of its training split's observed
displacement per step (first to last observed position over T_h - 1 steps), in the model's
units (the data scale stored with the model). Agents faster than that are seen at that speed
and their prediction is scaled back up (``models/encoder.py`` ``speed_factor``). Only the
observed histories decide who is clamped; the share of clamped agents on the test split is
computed from its histories alone (a covariate shift visible at deployment, no future read).

The rule, fixed before this script's validation numbers were seen (docs/pretraining.md): the
clamp changes nothing for agents within the training range, so it is not expected to gain on
validation; it is written into every published default generator when no generator's
validation minFDE20 gets worse by more than 0.5 % with it. The test splits are then
re-measured once per generator by ``benchmarks/pretrain.py --dataset D --published``.

Writes benchmarks/results/meta/speed_clamp_val.json and prints the table for docs/.
"""

from __future__ import annotations

import argparse
import json
from datetime import date
from pathlib import Path

import numpy as np
from post_hoc import apply_setting, published_generators, validation_metrics, write_study

from trajpref.data import load_dataset
from trajpref.models import checkpoint as ckpt
from trajpref.types import TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "speed_clamp_val.json"
VARIANT = "clamp"
"""The variant name of a generator published with its clamp beside the default."""
TOLERANCE = 0.005
"""The largest relative worsening of a generator's validation minFDE20 the rule accepts."""


def observed_step(dataset: TrajectoryDataset, scale: float) -> np.ndarray:
    """Each agent's observed displacement per step, first to last observed position, in model
    units: [N over the split]."""
    steps = [
        np.linalg.norm(s.history[:, -1] - s.history[:, 0], axis=-1) / (s.history.shape[1] - 1)
        for s in dataset.scenes
    ]
    return np.concatenate(steps) / scale


def decide(rows: list[dict]) -> dict:
    """The rule: apply when no generator's validation minFDE20 worsens by more than 0.5 %."""
    change = {r["checkpoint"]: r["clamped"]["min_fde"] / r["off"]["min_fde"] - 1 for r in rows}
    return {"change_min_fde": change, "apply": all(v <= TOLERANCE for v in change.values())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quantile", type=float, default=0.99)
    parser.add_argument("--datasets", nargs="+", default=None, help="default: every folder")
    parser.add_argument(
        "--apply",
        action="store_true",
        help="write the stored clamps into the published generators, if the stored "
        "validation rows allow it (no evaluation)",
    )
    parser.add_argument(
        "--variant",
        nargs="+",
        default=None,
        metavar="DATASET",
        help="publish each named dataset's default generator with its stored clamp as "
        "models/<D>/generator-clamp.safetensors (the same weights and training records)",
    )
    args = parser.parse_args()
    models = ROOT / "models"

    if args.variant:
        stored = {r["dataset"]: r for r in json.loads(OUT.read_text())["rows"]}
        for name in args.variant:
            if name not in stored:
                parser.error(f"{name}: no stored clamp in {OUT.name}; run without --variant first")
            path = publish_variant(name, stored[name]["max_speed"])
            print(f"{path.relative_to(ROOT)}: max_speed {stored[name]['max_speed']:.3f}")
        return

    if args.apply:
        stored = json.loads(OUT.read_text())
        note = (f"{date.today()}: input speed clamp at the training split's "
                f"{stored['quantile']:.0%} quantile (benchmarks/speed_clamp.py, "
                "docs/pretraining.md)")  # fmt: skip
        done = apply_setting(ROOT, stored, "apply", "max_speed", lambda r: r["max_speed"], note)
        if not done:
            print("validation got worse somewhere: nothing changed")
        for name, changed in done:
            print(f"{name}: {'clamped' if changed else 'already clamped'}")
        return

    rows = []
    for name, path in published_generators(models, args.datasets, variants=False):
        payload = ckpt.load(path)
        cfg, scale = ckpt.config_of(payload), payload["scale"]
        train = load_dataset(cfg.data.dataset, "train", args.data_root)
        val = load_dataset(name, "val", args.data_root)
        test = load_dataset(name, "test", args.data_root)
        bound = float(np.quantile(observed_step(train, scale), args.quantile))
        share = {
            split: float((observed_step(ds, scale) > bound).mean())
            for split, ds in (("train", train), ("val", val), ("test", test))
        }
        row = {"dataset": name, "checkpoint": str(path.relative_to(ROOT)), "max_speed": bound,
               "share_clamped": share}  # fmt: skip
        for key, value in (("off", 0.0), ("clamped", bound)):
            predictor = ckpt.predictor_from_payload(_with_clamp(payload, value))
            row[key] = validation_metrics(predictor.to(args.device).eval(), val, args.samples,
                                          args.seed, args.device)  # fmt: skip
        rows.append(row)
        off, on = row["off"], row["clamped"]
        print(f"{name:<9} max_speed {bound:.3f}  clamped train {share['train']:.1%} val "
              f"{share['val']:.1%} test {share['test']:.1%}  val minFDE20 {off['min_fde']:.4f} "
              f"-> {on['min_fde']:.4f} ({on['min_fde'] / off['min_fde'] - 1:+.2%})",
              flush=True)  # fmt: skip
    decision = decide(rows)
    write_study(OUT, "python benchmarks/speed_clamp.py --data-root ../shared/data", rows,
                decision, quantile=args.quantile, samples=args.samples, seed=args.seed)  # fmt: skip
    print(json.dumps(decision, indent=2))
    print()
    print("| generator | max_speed | agents clamped: train / val / test | validation minADE20 / "
          "minFDE20, off -> clamped | change |")  # fmt: skip
    print("|---|---|---|---|---|")
    for r in rows:
        off, on, s = r["off"], r["clamped"], r["share_clamped"]
        print(f"| `{r['checkpoint'].removeprefix('models/')}` | {r['max_speed']:.3f} | "
              f"{s['train']:.1%} / {s['val']:.1%} / {s['test']:.1%} | {off['min_ade']:.4f} / "
              f"{off['min_fde']:.4f} -> {on['min_ade']:.4f} / {on['min_fde']:.4f} | "
              f"{on['min_fde'] / off['min_fde'] - 1:+.2%} |")  # fmt: skip


def publish_variant(dataset: str, max_speed: float) -> Path:
    """models/<D>/generator-clamp.safetensors: the default generator's weights (by reference,
    ``checkpoint.publish_variant``) with the clamp set, and its training records
    (meta/pretrained_<D>_clamp.json) copied from the default's, for
    ``benchmarks/pretrain.py --variant clamp --published`` to measure."""
    folder = ROOT / "models" / dataset
    variant = folder / f"generator-{VARIANT}{ckpt.SUFFIX}"
    ckpt.publish_variant(
        folder / f"generator{ckpt.SUFFIX}", variant, {"max_speed": max_speed},
        note=f"{date.today()}: the default generator with an input speed clamp at its training "
        "split's 99 % quantile (benchmarks/speed_clamp.py --variant)",
    )  # fmt: skip
    meta = ROOT / "benchmarks" / "results" / "meta"
    target = meta / f"pretrained_{dataset}_{VARIANT}.json"
    if not target.is_file():  # pretrain.py --published adds its measurements to it
        record = json.loads((meta / f"pretrained_{dataset}.json").read_text())
        target.write_text(json.dumps({**record, "variant": VARIANT}, indent=2) + "\n")
    return variant


def _with_clamp(payload: dict, max_speed: float) -> dict:
    """A copy of a generator payload whose config sets ``model.max_speed``."""
    config = {section: dict(values) if isinstance(values, dict) else values
              for section, values in payload["config"].items()}  # fmt: skip
    config["model"]["max_speed"] = max_speed
    return {**payload, "config": config}


if __name__ == "__main__":
    main()
