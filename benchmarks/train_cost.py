"""What each default config costs to train on this machine, measured side by side in one run.

    python benchmarks/train_cost.py --data-root ../shared/data

The training minutes that ``benchmarks/pretrain.py`` records are those of the real runs, which
often shared the two cores with other jobs. This script measures every dataset's two stages
alone, one after the other in one process: ``--steps`` training steps of each stage
(throughput in agent-windows per second) and one validation pass, then extrapolates to the
config's schedule:

    minutes = (epochs x training agent-windows / throughput + evaluations x one validation) / 60

The probe is warm by default (``--warm 3``): it trains three short epochs, each validated,
before the one it times, and adds what those took beyond the timed epoch once, as
``warmup_seconds``. bf16 steps keep getting faster over the first epochs while oneDNN builds
a kernel for each new batch shape (docs/pretraining.md, "oneDNN's kernel cache"), so a cold
probe (``--warm 0``, the method until 2026-11-28) errs high on the bf16 defaults; it also
errs, less, on a stage's first steps. A compiled stage (``compile: true``) is always probed at
least once warm: its first epoch is its compilation. Each entry records its probe (``warm``,
``steps``) and the machine that measured it.

``--set KEY=VALUE`` changes every measured config (``--set generator.epochs=80`` estimates a
longer schedule); such an estimate is not the defaults' and needs ``--out``.
``--compiled`` measures each dataset a second time with both stages compiled
(``denoiser.compile=true generator.compile=true``), side by side in the same process, always
warm, and records both estimates and their ratio in ``meta/train_cost_compile.json``:

    python benchmarks/train_cost.py --datasets eth zara1 --compiled

A stage with a time budget (``max_minutes``; the defaults anneal to it, ``budget_schedule``)
is estimated at the budget where its schedule would take longer, with the share of its
schedule it trains (``schedule_share``) and what the whole schedule would take
(``unguarded_minutes``) beside it.

The generator stage is timed from the dataset's published denoiser. Writes
benchmarks/results/meta/train_cost.json (with ``--datasets`` naming a subset, the other
datasets keep their earlier entries; each entry carries the date it was measured);
``python benchmarks/update_readme.py`` shows it in the README's cost table beside the
measured minutes. An estimate, labelled as one: real runs add
data loading and checkpoint writes (seconds).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import tempfile
from pathlib import Path

from trajpref.config import load_config
from trajpref.results import machine, write_meta
from trajpref.train import read_metrics
from trajpref.train.run import STAGE_NAMES, train_stage

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "train_cost.json"
OUT_COMPILE = ROOT / "benchmarks" / "results" / "meta" / "train_cost_compile.json"
COMPILED = ("denoiser.compile=true", "generator.compile=true")
DATASETS = ("eth", "hotel", "univ", "zara1", "zara2", "sdd", "nba", "robo", "robo-mix")


def evaluations(epochs: int, every: int) -> int:
    """Validation passes in a schedule: every ``every`` epochs, and always after the last."""
    return epochs // every + (0 if epochs % every == 0 else 1)


def short_run(cfg, stage: str, data_root, steps: int, epochs: int,
              denoiser: Path | None) -> tuple[dict, list[dict]]:  # fmt: skip
    """Train ``epochs`` short epochs of ``steps`` steps of one stage, each validated, in a
    temporary folder: the loop's summary and its metric records (one per epoch)."""
    section = STAGE_NAMES[stage]  # the config section and the stage's file names
    short = dataclasses.replace(getattr(cfg, section), epochs=epochs,
                                steps_per_epoch=steps, eval_every=1)  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        summary = train_stage(stage, dataclasses.replace(cfg, **{section: short}), run,
                              data_root, "cpu", denoiser=denoiser, progress=False)  # fmt: skip
        return summary, read_metrics(run, section)


def epoch_seconds(records: list[dict]) -> list[float]:
    """Each epoch's own training seconds, from the records' cumulative ``train_seconds``."""
    cumulative = [0.0] + [r["train_seconds"] for r in records]
    return [b - a for a, b in zip(cumulative, cumulative[1:], strict=False)]


def probe(cfg, stage: str, data_root, steps: int, denoiser: Path | None,
          warm: int = 0) -> dict:  # fmt: skip
    """Time ``steps`` training steps of one stage (one short epoch; its first steps' warm-up
    counts, so the rate errs low) and the validation pass that follows them. ``warm`` > 0:
    ``warm`` such epochs before the timed one, each validated; the last is timed, and what the
    first ``warm`` took beyond it is returned once as ``warmup_seconds`` (compilation, and the
    kernels oneDNN builds for each new batch shape, which later epochs mostly find cached)."""
    summary, records = short_run(cfg, stage, data_root, steps, 1 + warm, denoiser)
    if not warm:
        return {
            "rate": summary["samples_per_second"],  # agent-windows per second of the steps
            "val_seconds": summary["wall_seconds"] - summary["train_seconds"],
            "train_agents": summary["train_agents"],
        }
    train = epoch_seconds(records)
    last, last_val = train[-1], records[-1]["val_seconds"]
    extra = [max(0.0, t - last) + max(0.0, r["val_seconds"] - last_val)
             for t, r in zip(train[:-1], records[:-1], strict=True)]  # fmt: skip
    return {
        "rate": summary["samples_per_second"],  # of the last epoch
        "val_seconds": last_val,
        "train_agents": summary["train_agents"],
        "warmup_seconds": sum(extra),  # the untimed epochs' time beyond the timed one's
    }


def guarded(steps_seconds: float, val_seconds: float,
            max_minutes: float | None) -> tuple[float, float]:  # fmt: skip
    """A stage's estimated seconds under its time budget, and the share of its schedule it
    trains: the training steps stop at ``max_minutes`` (``OptimConfig.max_minutes``, counted
    here as wall time) and the validations, spread over the schedule, with them."""
    if max_minutes is None or steps_seconds <= 60 * max_minutes:
        return steps_seconds + val_seconds, 1.0
    share = 60 * max_minutes / steps_seconds
    return 60 * max_minutes + share * val_seconds, share


def estimate(cfg, dataset: str, data_root, steps: tuple[int, int], warm: int) -> dict:
    """Both stages' estimated minutes for ``cfg`` (see the module docstring)."""
    denoiser = ROOT / "models" / dataset / "denoiser.safetensors"
    entry = {}
    for stage, n, optim in (("diffusion", steps[0], cfg.denoiser),
                            ("generator", steps[1], cfg.generator)):  # fmt: skip
        key = STAGE_NAMES[stage]
        if stage == "generator" and not denoiser.is_file():
            entry[key] = None
            continue
        # a compiled stage's first epoch is its compilation
        warm_here = warm or (1 if optim.compile else 0)
        p = probe(cfg, stage, data_root, n,
                  denoiser if stage == "generator" else None, warm_here)  # fmt: skip
        n_eval = evaluations(optim.epochs, optim.eval_every)
        steps_s = optim.epochs * p["train_agents"] / p["rate"] + p.get("warmup_seconds", 0.0)
        seconds, share = guarded(steps_s, n_eval * p["val_seconds"], optim.max_minutes)
        entry[key] = {
            "epochs": optim.epochs, "train_agents": p["train_agents"],
            "agents_per_second": round(p["rate"], 1), "evaluations": n_eval,
            "val_seconds": round(p["val_seconds"], 1), "minutes": round(seconds / 60, 1),
        }  # fmt: skip
        if warm_here:
            entry[key]["warmup_seconds"] = round(p["warmup_seconds"], 1)
        if optim.max_minutes is not None:
            entry[key]["budget_minutes"] = optim.max_minutes
            entry[key]["schedule_share"] = round(share, 3)
            if share < 1:  # what the whole schedule would take without its budget
                unguarded = steps_s + n_eval * p["val_seconds"]
                entry[key]["unguarded_minutes"] = round(unguarded / 60, 1)
    entry["minutes"] = round(sum(v["minutes"] for v in entry.values() if v is not None), 1)
    return entry


def _line(entry: dict) -> str:
    # the stages' entries only: an estimate of other settings also holds a "settings" dict
    parts = " + ".join(f"{k[0].upper()} {v['minutes']:.1f}" for k, v in entry.items()
                       if isinstance(v, dict) and "minutes" in v)  # fmt: skip
    return f"{parts} = {entry['minutes']:.1f} min"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--datasets", nargs="+", default=list(DATASETS))
    parser.add_argument(
        "--steps",
        type=int,
        nargs=2,
        default=(20, 60),
        metavar=("D", "G"),
        help="timed training steps of the denoiser and generator stages",
    )
    parser.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="config overrides for every dataset, e.g. generator.epochs=80",
    )
    parser.add_argument(
        "--warm",
        type=int,
        nargs="?",
        const=1,
        default=3,
        metavar="N",
        help="train N short epochs (1 when no N is given; 0: a cold probe) before the timed "
        "one; add their extra time once (default: 3)",
    )
    parser.add_argument("--compiled", action="store_true",
                        help="also estimate with both stages compiled, side by side (warm); "
                        f"writes benchmarks/results/meta/{OUT_COMPILE.name}")  # fmt: skip
    parser.add_argument("--out", default=None, help=f"default: benchmarks/results/meta/{OUT.name}")
    args = parser.parse_args()
    if args.compiled:
        compare(args)
        return
    out = Path(args.out or OUT)
    if args.set and out.resolve() == OUT.resolve():
        raise SystemExit(f"--set estimates other settings than {OUT.name}'s: name --out")

    entries = {}
    for dataset in args.datasets:
        cfg = load_config(ROOT / "configs" / f"{dataset}.yaml", args.set)
        entry = estimate(cfg, dataset, args.data_root, args.steps, args.warm)
        entry["probe"] = {"warm": args.warm, "steps": list(args.steps)}
        if args.set:
            entry["settings"] = {"set": args.set}
        entries[dataset] = entry
        print(f"{dataset:<9} {_line(entry)} (estimated, alone on the machine)", flush=True)
    kept = {}
    if out.is_file() and set(args.datasets) != set(DATASETS):
        # a subset re-estimated (e.g. after its configs changed): the other datasets keep
        # their earlier entries, each stamped with the date of the run that measured it
        before = json.loads(out.read_text())
        kept = {name: {"date": before["date"], "machine": before["machine"], **entry}
                for name, entry in before["datasets"].items() if name not in entries}  # fmt: skip
    today, here = datetime.date.today().isoformat(), machine()
    entries = {name: {"date": today, "machine": here, **entry} for name, entry in entries.items()}
    write_meta(out, datasets={**kept, **entries})
    print(f"wrote {out}")


def compare(args) -> None:
    """Eager and compiled estimates of each dataset, one after the other in one process."""
    out = Path(args.out or OUT_COMPILE)
    entries = json.loads(out.read_text())["datasets"] if out.is_file() else {}
    for dataset in args.datasets:
        runs = {}
        for name, extra in (("eager", []), ("compiled", list(COMPILED))):
            cfg = load_config(ROOT / "configs" / f"{dataset}.yaml", [*args.set, *extra])
            runs[name] = estimate(cfg, dataset, args.data_root, args.steps, warm=1)
            print(f"{dataset:<9} {name:<8} {_line(runs[name])}", flush=True)
        speedup = {
            key: round(runs["compiled"][key]["agents_per_second"]
                       / runs["eager"][key]["agents_per_second"], 2)
            for key in ("denoiser", "generator") if runs["eager"].get(key)
        }  # fmt: skip
        print(f"{dataset:<9} compiled steps / eager steps (throughput): {speedup}", flush=True)
        entries[dataset] = {"date": datetime.date.today().isoformat(), "set": args.set, **runs,
                            "step_speedup": speedup}  # fmt: skip
        write_meta(out, datasets=entries)  # after each dataset: a stopped run keeps its part
        print(f"wrote {out}", flush=True)


if __name__ == "__main__":
    main()
