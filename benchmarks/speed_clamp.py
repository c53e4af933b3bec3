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
    # the lower-clamp study of the ETH/UCY folds: several quantiles, the lowest that
    # validation tolerates (docs/pretraining.md, "A lower clamp"), then write it in
    python benchmarks/speed_clamp.py --sweep 0.99 0.95 0.9 0.8 0.7 0.5 --data-root ../shared/data
    python benchmarks/speed_clamp.py --apply-sweep
    # a generator trained with a clamp on, swept beside the published default (the rule of
    # docs/pretraining.md, "Training eth's generator with a low clamp on")
    python benchmarks/speed_clamp.py --sweep 0.9 0.8 0.7 0.5 --tag trained-clamp \
        --checkpoints RUN/generator.safetensors models/eth/generator.safetensors

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
import torch
from post_hoc import (
    apply_setting,
    published_generators,
    study_parser,
    validation_metrics,
    with_model_setting,
    write_study,
)

from trajpref.data import load_dataset
from trajpref.data.transforms import observed_pace
from trajpref.device import resolve_device
from trajpref.models import checkpoint as ckpt
from trajpref.types import TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "speed_clamp_val.json"
VARIANT = "clamp"
"""The variant name of a generator published with its clamp beside the default."""
TOLERANCE = 0.005
"""The largest relative worsening of a generator's validation minFDE20 the rule accepts."""
SWEEP_OUT = ROOT / "benchmarks" / "results" / "meta" / "speed_clamp_sweep_val.json"
TRAINED_TOLERANCE = 0.01
"""A clamp-trained generator's allowance against the published default (a retrain's seed
spread, ``meta/retrain_seed_spread.json``): both are trained, so 0.5 % would be noise."""
PEDESTRIAN = ("eth", "hotel", "univ", "zara1", "zara2")
"""The generators the lower-clamp study covers (``--sweep`` without ``--datasets``)."""


def observed_step(dataset: TrajectoryDataset, scale: float) -> np.ndarray:
    """Each agent's observed displacement per step, first to last observed position, in model
    units: [N over the split]."""
    history = torch.from_numpy(np.concatenate([s.history for s in dataset.scenes]))  # [N, T_h, 2]
    return observed_pace(history, scale).numpy()


def decide(rows: list[dict]) -> dict:
    """The rule: apply when no generator's validation minFDE20 worsens by more than 0.5 %."""
    change = {r["checkpoint"]: r["clamped"]["min_fde"] / r["off"]["min_fde"] - 1 for r in rows}
    return {"change_min_fde": change, "apply": all(v <= TOLERANCE for v in change.values())}


def decide_sweep(rows: list[dict]) -> dict:
    """The lower-clamp rule: the lowest quantile at which no generator's validation minFDE20
    is more than ``TOLERANCE`` worse than unclamped (None when no quantile qualifies)."""
    quantiles = sorted({float(q) for r in rows for q in r["by_quantile"]})
    change = {
        str(q): {r["checkpoint"]: r["by_quantile"][str(q)]["min_fde"] / r["off"]["min_fde"] - 1
                 for r in rows}
        for q in quantiles
    }  # fmt: skip
    ok = [q for q in quantiles if all(v <= TOLERANCE for v in change[str(q)].values())]
    return {"change_min_fde": change, "quantile": min(ok) if ok else None, "apply": bool(ok)}


def clamp_shares(splits: dict[str, TrajectoryDataset], scale: float, bound: float) -> dict:
    """The share of each split's agents whose observed step exceeds ``bound``."""
    return {name: float((observed_step(ds, scale) > bound).mean()) for name, ds in splits.items()}


def main() -> None:
    parser = study_parser(__doc__)
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
    parser.add_argument(
        "--sweep",
        nargs="+",
        type=float,
        default=None,
        metavar="Q",
        help="the lower-clamp study: validation at each training-split quantile Q (default "
        "generators: the ETH/UCY folds), into meta/speed_clamp_sweep_val.json; with "
        "--datasets, those generators' rows replace theirs in the stored record",
    )
    parser.add_argument(
        "--checkpoints",
        nargs="+",
        default=None,
        metavar="PATH",
        help="with --sweep: sweep these generators instead of the published ones; the first is "
        "the candidate, the last the reference (the rule for a generator trained with a clamp "
        "on), into meta/speed_clamp_sweep_val_<tag>.json",
    )
    parser.add_argument("--tag", default="checkpoints", help="the --checkpoints record's name")
    parser.add_argument(
        "--apply-sweep",
        action="store_true",
        help="write the quantile the stored sweep chose into its generators (no evaluation)",
    )
    args = parser.parse_args()
    models = ROOT / "models"
    if args.sweep is not None and not all(0 < q < 1 for q in args.sweep):
        parser.error("--sweep quantiles must lie strictly between 0 and 1")
    if args.checkpoints is not None and (args.sweep is None or len(args.checkpoints) < 2):
        parser.error("--checkpoints needs --sweep and two generators: the candidate, then the "
                     "reference")  # fmt: skip

    if args.apply_sweep:
        stored = json.loads(SWEEP_OUT.read_text())
        q = stored["decision"]["quantile"]
        if q is None:
            print("no quantile passed the rule: nothing changed")
            return
        note = (
            f"{date.today()}: input speed clamp at the training split's {q:.0%} quantile "
            '(benchmarks/speed_clamp.py --sweep, docs/pretraining.md, "A lower clamp")'
        )
        done = apply_setting(ROOT, stored, "apply", "max_speed",
                             lambda r: r["by_quantile"][str(q)]["max_speed"], note)  # fmt: skip
        for name, changed in done:
            print(f"{name}: {'clamped' if changed else 'already clamped'} at the {q:.0%} quantile")
        return

    if args.checkpoints is not None:
        sweep_checkpoints(args)
        return
    if args.sweep is not None:
        sweep(args, models)
        return

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
        share = clamp_shares({"train": train, "val": val, "test": test}, scale, bound)
        row = {"dataset": name, "checkpoint": str(path.relative_to(ROOT)), "max_speed": bound,
               "share_clamped": share}  # fmt: skip
        for key, value in (("off", 0.0), ("clamped", bound)):
            row[key] = _clamped_metrics(args, payload, val, value)
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


def sweep(args: argparse.Namespace, models: Path) -> None:
    """Validation of each generator unclamped and at each ``--sweep`` quantile's clamp."""
    found = published_generators(models, args.datasets or list(PEDESTRIAN), variants=False)
    rows = sweep_rows(args, found)
    rows = merge_sweep_rows(json.loads(SWEEP_OUT.read_text())["rows"], rows) if (
        args.datasets and SWEEP_OUT.is_file()) else rows  # fmt: skip
    decision = decide_sweep(rows)
    qs = " ".join(f"{q:g}" for q in sorted(args.sweep, reverse=True))
    only = f" --datasets {' '.join(args.datasets)}" if args.datasets else ""
    write_study(SWEEP_OUT, f"python benchmarks/speed_clamp.py --sweep {qs}{only} --data-root "
                "../shared/data", rows, decision, samples=args.samples, seed=args.seed)  # fmt: skip
    print(sweep_table(rows, decision))


def sweep_checkpoints(args: argparse.Namespace) -> None:
    """The rule for a generator trained with a clamp on: the candidate (first checkpoint)
    swept beside the reference (last), both on the candidate's dataset's validation split."""
    paths = [Path(p).resolve() for p in args.checkpoints]
    for p in paths:
        if not p.is_file():
            raise SystemExit(f"{p}: no such generator")
    name = ckpt.config_of(ckpt.load(paths[0])).data.dataset
    rows = sweep_rows(args, [(name, p) for p in paths])
    decision = decide_trained(rows[0], rows[-1])
    out = SWEEP_OUT.with_name(f"speed_clamp_sweep_val_{args.tag}.json")
    qs = " ".join(f"{q:g}" for q in sorted(args.sweep, reverse=True))
    given = " ".join(_relative(p) for p in paths)
    write_study(out, f"python benchmarks/speed_clamp.py --sweep {qs} --checkpoints {given} "
                f"--tag {args.tag} --data-root ../shared/data", rows, decision,
                samples=args.samples, seed=args.seed)  # fmt: skip
    print(sweep_table(rows, decision))
    print(json.dumps(decision, indent=2))


def decide_trained(candidate: dict, reference: dict, reference_q: str = "0.9") -> dict:
    """The lowest quantile at which the candidate's validation minFDE20 is within
    ``TRAINED_TOLERANCE`` of the reference's at its own clamp (``reference_q``); None if
    none is."""
    ref = reference["by_quantile"][reference_q]["min_fde"]
    change = {q: m["min_fde"] / ref - 1 for q, m in candidate["by_quantile"].items()}
    ok = [float(q) for q, c in change.items() if c <= TRAINED_TOLERANCE]
    return {"reference": reference["checkpoint"], "reference_quantile": float(reference_q),
            "reference_min_fde": ref, "change_min_fde": change,
            "quantile": min(ok) if ok else None, "apply": bool(ok)}  # fmt: skip


def _relative(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def sweep_rows(args: argparse.Namespace, generators) -> list[dict]:
    """One row per (name, path): validation unclamped and at each ``--sweep`` quantile of the
    generator's training split."""
    rows = []
    for name, path in generators:
        payload = ckpt.load(path)
        cfg, scale = ckpt.config_of(payload), payload["scale"]
        splits = {"train": load_dataset(cfg.data.dataset, "train", args.data_root),
                  "val": load_dataset(name, "val", args.data_root),
                  "test": load_dataset(name, "test", args.data_root)}  # fmt: skip
        steps = observed_step(splits["train"], scale)
        off = _clamped_metrics(args, payload, splits["val"], 0.0)
        row = {"dataset": name, "checkpoint": _relative(path), "off": off,
               "by_quantile": {}}  # fmt: skip
        for q in sorted(args.sweep, reverse=True):
            bound = float(np.quantile(steps, q))
            on = _clamped_metrics(args, payload, splits["val"], bound)
            share = clamp_shares(splits, scale, bound)
            row["by_quantile"][str(q)] = {"max_speed": bound, **on, "share_clamped": share}
            print(f"{name:<6} q {q:.2f} max_speed {bound:.3f}  val minFDE20 "
                  f"{off['min_fde']:.4f} -> {on['min_fde']:.4f} "
                  f"({on['min_fde'] / off['min_fde'] - 1:+.2%})", flush=True)  # fmt: skip
        rows.append(row)
    return rows


def merge_sweep_rows(stored: list[dict], new: list[dict]) -> list[dict]:
    """The stored sweep's rows with each newly measured generator's row replaced (a
    ``--datasets`` sweep re-measures some generators and the rule re-decides over all)."""
    quantiles = {q for r in stored for q in r["by_quantile"]}
    for r in new:
        if set(r["by_quantile"]) != quantiles:
            raise SystemExit(f"{r['dataset']}: swept at {sorted(r['by_quantile'])}, the stored "
                             f"sweep at {sorted(quantiles)}: sweep the same quantiles")  # fmt: skip
    replaced = {r["dataset"] for r in new}
    return [r for r in stored if r["dataset"] not in replaced] + new


def _clamped_metrics(args: argparse.Namespace, payload: dict, val, max_speed: float) -> dict:
    """Validation metrics of a generator payload with ``model.max_speed`` set."""
    predictor = ckpt.predictor_from_payload(with_model_setting(payload, "max_speed", max_speed))
    model = predictor.to(resolve_device(args.device)).eval()  # "auto" as evaluate reads it
    return validation_metrics(model, val, args.samples, args.seed, args.device)


def sweep_table(rows: list[dict], decision: dict) -> str:
    """The docs table: validation minFDE20 change per fold and quantile, and the choice."""
    quantiles = sorted({float(q) for r in rows for q in r["by_quantile"]}, reverse=True)
    head = "| generator | unclamped minADE20 / minFDE20 | " + " | ".join(
        f"q = {q:g}" for q in quantiles) + " |"  # fmt: skip
    lines = [head, "|" + "---|" * (2 + len(quantiles))]
    for r in rows:
        cells = []
        for q in quantiles:
            m = r["by_quantile"][str(q)]
            cells.append(f"{m['min_fde'] / r['off']['min_fde'] - 1:+.2%} (test "
                         f"{m['share_clamped']['test']:.0%} clamped)")  # fmt: skip
        lines.append(f"| `{r['checkpoint'].removeprefix('models/')}` | {r['off']['min_ade']:.4f}"
                     f" / {r['off']['min_fde']:.4f} | " + " | ".join(cells) + " |")  # fmt: skip
    chosen = decision["quantile"]
    lines.append("")
    lines.append(f"Chosen: q = {chosen:g}" if chosen is not None else "Chosen: none")
    return "\n".join(lines)


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


if __name__ == "__main__":
    main()
