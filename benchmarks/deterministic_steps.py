"""Posterior-mean (deterministic) against ancestral (stochastic) tau denoising steps, for every
published generator, on its validation split; and, with ``--apply``, the switch of the
published generators to the winner.

    # the evidence: each published generator evaluated both ways on its validation split
    python benchmarks/deterministic_steps.py --data-root ../shared/data
    # then set the published files to the chosen setting (weights untouched)
    python benchmarks/deterministic_steps.py --apply --data-root ../shared/data

The leapfrog sampler's tau denoising steps add DDPM's ancestral noise unless a generator's
``model.stochastic_steps`` is false, in which case each step is the posterior mean. Only the
evaluation differs between the two columns: the same weights, samples, seed and batches.

The rule, fixed before the numbers of this script were seen (docs/pretraining.md): the library
has one default, so the switch is made for every published generator at once, when the mean
relative change over all of them is negative for both minADE20 and minFDE20 on validation. The
test splits are not read here; ``benchmarks/pretrain.py --published`` re-measures each switched
model's test row afterwards (once).

Writes benchmarks/results/meta/deterministic_steps_val.json and prints the table for
docs/pretraining.md.
"""

from __future__ import annotations

import json
from datetime import date
from pathlib import Path

from post_hoc import (
    apply_setting,
    published_generators,
    study_parser,
    validation_metrics,
    write_study,
)

from trajpref.data import load_dataset
from trajpref.models import checkpoint as ckpt

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "deterministic_steps_val.json"


def decide(rows: list[dict]) -> dict:
    """The rule: switch when the mean relative change of both metrics is negative."""
    change = {
        metric: sum(r["deterministic"][metric] / r["stochastic"][metric] - 1 for r in rows)
        / len(rows)
        for metric in ("min_ade", "min_fde")
    }
    return {"mean_change": change, "switch": all(v < 0 for v in change.values())}


def main() -> None:
    parser = study_parser(__doc__)
    parser.add_argument(
        "--apply",
        action="store_true",
        help="set model.stochastic_steps in the published generators as the stored "
        "validation rows decide (no evaluation)",
    )
    args = parser.parse_args()

    if args.apply:
        note = (f"{date.today()}: posterior-mean tau steps by default "
                "(benchmarks/deterministic_steps.py, docs/pretraining.md)")  # fmt: skip
        stored = json.loads(OUT.read_text())
        done = apply_setting(ROOT, stored, "switch", "stochastic_steps", lambda row: False, note)
        if not done:
            print("the validation rows do not favour deterministic steps: nothing changed")
        for name, changed in done:
            print(f"{name}: {'switched' if changed else 'already deterministic'}")
        return

    rows, data = [], {}
    for dataset, path in published_generators(ROOT / "models"):
        if dataset not in data:
            data[dataset] = load_dataset(dataset, "val", args.data_root)
        predictor = ckpt.load_predictor(path, sampler="leapfrog", device=args.device)
        trained = ckpt.config_of(ckpt.load(path)).model.stochastic_steps
        row = {"dataset": dataset, "checkpoint": str(path.relative_to(ROOT)),
               "trained_stochastic": trained}  # fmt: skip
        for name, stochastic in (("stochastic", True), ("deterministic", False)):
            predictor.stochastic = stochastic
            row[name] = validation_metrics(
                predictor, data[dataset], args.samples, args.seed, args.device
            )
        rows.append(row)
        s, d = row["stochastic"], row["deterministic"]
        print(f"{row['checkpoint']:<45} stochastic {s['min_ade']:.4f} / {s['min_fde']:.4f}  "
              f"deterministic {d['min_ade']:.4f} / {d['min_fde']:.4f}  "
              f"({d['min_ade'] / s['min_ade'] - 1:+.1%} / {d['min_fde'] / s['min_fde'] - 1:+.1%})",
              flush=True)  # fmt: skip
    decision = decide(rows)
    write_study(OUT, "python benchmarks/deterministic_steps.py --data-root ../shared/data",
                rows, decision, samples=args.samples, seed=args.seed)  # fmt: skip
    print(json.dumps(decision, indent=2))
    print()
    print("| validation minADE20 / minFDE20 | stochastic | deterministic | change |")
    print("|---|---|---|---|")
    for r in rows:
        s, d = r["stochastic"], r["deterministic"]
        ade, fde = (d[m] / s[m] - 1 for m in ("min_ade", "min_fde"))
        print(f"| `{r['checkpoint'].removeprefix('models/')}` | {s['min_ade']:.4f} / "
              f"{s['min_fde']:.4f} | {d['min_ade']:.4f} / {d['min_fde']:.4f} | "
              f"{ade:+.1%} / {fde:+.1%} |")  # fmt: skip


if __name__ == "__main__":
    main()
