"""What each default config costs to train on this machine, measured side by side in one run.

    python benchmarks/train_cost.py --data-root ../shared/data

The training minutes that ``benchmarks/pretrain.py`` records are those of the real runs, which
often shared the two cores with other jobs. This script measures every dataset's two stages
alone, one after the other in one process: ``--steps`` training steps of each stage
(throughput in agent-windows per second, the first ``--skip`` steps' warm-up excluded) and one
validation pass, then extrapolates to the config's schedule:

    minutes = (epochs x training agent-windows / throughput + evaluations x one validation) / 60

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
from trajpref.results import write_meta
from trajpref.train.run import train_stage

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "train_cost.json"
DATASETS = ("eth", "hotel", "univ", "zara1", "zara2", "sdd", "nba", "robo", "robo-mix")


def evaluations(epochs: int, every: int) -> int:
    """Validation passes in a schedule: every ``every`` epochs, and always after the last."""
    return epochs // every + (0 if epochs % every == 0 else 1)


def probe(cfg, stage: str, data_root, steps: int, denoiser: Path | None) -> dict:
    """Time ``steps`` training steps of one stage (one short epoch; its first steps' warm-up
    counts, so the rate errs low) and the validation pass that follows them."""
    section = "denoiser" if stage == "diffusion" else "generator"
    short = dataclasses.replace(getattr(cfg, section), epochs=1, steps_per_epoch=steps,
                                eval_every=1)  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        summary = train_stage(stage, dataclasses.replace(cfg, **{section: short}),
                              Path(tmp) / "run", data_root, "cpu", denoiser=denoiser,
                              progress=False)  # fmt: skip
    return {
        "rate": summary["samples_per_second"],  # agent-windows per second of the timed steps
        "val_seconds": summary["wall_seconds"] - summary["train_seconds"],
        "train_agents": summary["train_agents"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--datasets", nargs="+", default=list(DATASETS))
    parser.add_argument(
        "--steps",
        type=int,
        nargs=2,
        default=(40, 12),
        metavar=("D", "G"),
        help="timed training steps of the denoiser and generator stages",
    )
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args()

    entries = {}
    for dataset in args.datasets:
        cfg = load_config(ROOT / "configs" / f"{dataset}.yaml")
        denoiser = ROOT / "models" / dataset / "denoiser.safetensors"
        entry = {}
        for stage, steps, optim in (("diffusion", args.steps[0], cfg.denoiser),
                                    ("generator", args.steps[1], cfg.generator)):  # fmt: skip
            if stage == "generator" and not denoiser.is_file():
                entry["generator"] = None
                continue
            p = probe(cfg, stage, args.data_root, steps,
                      denoiser if stage == "generator" else None)  # fmt: skip
            n_eval = evaluations(optim.epochs, optim.eval_every)
            seconds = optim.epochs * p["train_agents"] / p["rate"] + n_eval * p["val_seconds"]
            entry["denoiser" if stage == "diffusion" else "generator"] = {
                "epochs": optim.epochs, "train_agents": p["train_agents"],
                "agents_per_second": round(p["rate"], 1), "evaluations": n_eval,
                "val_seconds": round(p["val_seconds"], 1), "minutes": round(seconds / 60, 1),
            }  # fmt: skip
        total = sum(v["minutes"] for v in entry.values() if v is not None)
        entry["minutes"] = round(total, 1)
        entries[dataset] = entry
        parts = " + ".join(f"{k[0].upper()} {v['minutes']:.1f}" for k, v in entry.items()
                           if isinstance(v, dict))  # fmt: skip
        print(f"{dataset:<9} {parts} = {total:.1f} min (estimated, alone on the machine)",
              flush=True)  # fmt: skip
    out = Path(args.out)
    kept = {}
    if out.is_file() and set(args.datasets) != set(DATASETS):
        # a subset re-estimated (e.g. after its configs changed): the other datasets keep
        # their earlier entries, each stamped with the date of the run that measured it
        before = json.loads(out.read_text())
        kept = {name: {"date": before["date"], **entry}
                for name, entry in before["datasets"].items() if name not in entries}  # fmt: skip
    today = datetime.date.today().isoformat()
    entries = {name: {"date": today, **entry} for name, entry in entries.items()}
    write_meta(out, datasets={**kept, **entries})
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
