"""Retire a dataset's fine-tuning start after its default generator was replaced.

    python benchmarks/retire_start.py --dataset robo --name tau5          # do it
    python benchmarks/retire_start.py --dataset robo --name tau5 --dry-run

The equal-budget rows (``control``, ``rlhf``, ...) of a dataset were measured from the default
generator of their day. When ``benchmarks/pretrain.py --keep-replaced NAME`` publishes another
default, those rows no longer describe runs from today's start. This renames them
``<method>-NAME`` (``finetune_start`` then pairs them with the kept row ``pretrained-NAME``;
``-NAME`` must be one of ``trajpref.results.RETIRED_STARTS``), renames the start's validation
record ``meta/finetune_start_<D>.json`` to ``finetune_start_<D>-NAME.json``, and moves the run
folders begun from another generator than today's (``runs/<D>-<method>-s<seed>[-<tag>]``, by the
weights hash in their ``start.json``) to ``<folder>-NAME``, so that new runs from today's
default start afresh instead of being refused. Rows renamed earlier by hand are left as they
are; their folders are still moved. A retired row's checkpoint path is given the folder's new
name whether or not the folder is on this machine (``runs/`` is not tracked, and a new checkout
lacks it), so that it never names the folder a later run from today's default writes to.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from trajpref.io import read_checkpoint_header
from trajpref.models import checkpoint as ckpt
from trajpref.results import FINETUNE_START, RETIRED_STARTS, finetune_start, write_rows

ROOT = Path(__file__).resolve().parent.parent
TUNED = ("control", "rlhf")
"""Fine-tuning methods start with one of these (``control-lr3e-5``, ``rlhf-res-smooth``)."""


def _is_tuned(method: str) -> bool:
    return method.split("-")[0] in TUNED


def _retired_checkpoint(checkpoint: str, dataset: str, suffix: str) -> str:
    """``runs/<D>-<method>-s<seed>[-<tag>]/<file>`` -> the same in ``<folder><suffix>``; any other
    path (a model file, a folder already suffixed) is returned as it is."""
    folder, _, file = checkpoint.rpartition("/")
    match = re.fullmatch(rf"runs/{re.escape(dataset)}-(.+)-s\d+(-.+)?", folder)
    if not match or not _is_tuned(match.group(1)) or folder.endswith(suffix):
        return checkpoint
    return f"{folder}{suffix}/{file}"


def retire(root: Path, dataset: str, name: str, dry_run: bool = False) -> dict[str, list[str]]:
    """Rename the rows, the start record and the run folders (see the module docstring).
    Returns what was (or, with ``dry_run``, would be) done, by kind."""
    suffix = f"-{name}"
    if suffix not in RETIRED_STARTS:
        raise SystemExit(f"--name {name}: add '{suffix}' to trajpref.results.RETIRED_STARTS "
                         "first (with the date and what replaced it)")  # fmt: skip
    kept = root / "benchmarks" / "results" / f"pretrained_{dataset}_{name}.json"
    if not kept.is_file():
        raise SystemExit(f"no {kept.name}: keep the replaced default's row first "
                         "(benchmarks/pretrain.py --keep-replaced)")  # fmt: skip
    done: dict[str, list[str]] = {"rows": [], "paths": [], "records": [], "folders": []}
    today = read_checkpoint_header(root / "models" / dataset / f"generator{ckpt.SUFFIX}")["hash"]
    for record in sorted((root / "runs").glob(f"{dataset}-*-s[0-9]*/start.json")):
        folder = record.parent
        rest = folder.name.removeprefix(f"{dataset}-")
        if not _is_tuned(rest) or rest.endswith(tuple(RETIRED_STARTS)):
            continue
        if json.loads(record.read_text()).get("hash") == today:
            continue  # a run from today's default
        target = folder.with_name(folder.name + suffix)
        if target.exists():
            raise SystemExit(f"{target} exists already: move it away first")
        done["folders"].append(f"{folder.name} -> {target.name}")
        if not dry_run:
            folder.rename(target)
    for path in sorted((root / "benchmarks" / "results").glob(f"finetune_{dataset}*.json")):
        rows, changed = json.loads(path.read_text()), False
        for row in rows:
            if row["dataset"] != dataset or not _is_tuned(row["method"]):
                continue
            if finetune_start(row["method"]) == FINETUNE_START:
                done["rows"].append(f"{path.name}: {row['method']} seed {row['seed']}")
                row["method"] += suffix
                changed = True
            if row["method"].endswith(suffix) and row["checkpoint"]:
                path_now = _retired_checkpoint(row["checkpoint"], dataset, suffix)
                if path_now != row["checkpoint"]:
                    done["paths"].append(f"{path.name}: {row['checkpoint']} -> {path_now}")
                    row["checkpoint"] = path_now
                    changed = True
        if changed and not dry_run:
            write_rows(path, rows)
    meta = root / "benchmarks" / "results" / "meta"
    start = meta / f"finetune_start_{dataset}.json"
    if start.is_file():
        target = meta / f"finetune_start_{dataset}{suffix}.json"
        if target.exists() and target.read_text() != start.read_text():
            raise SystemExit(f"{target} exists already with another record")
        done["records"].append(f"{start.name} -> {target.name}")
        if not dry_run:
            start.replace(target)  # a copy made by hand before is the same record
    return done


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--name", required=True, help="the kept row's name: pretrained-NAME")
    parser.add_argument("--dry-run", action="store_true", help="say what would change")
    args = parser.parse_args()
    done = retire(ROOT, args.dataset, args.name, args.dry_run)
    for kind, items in done.items():
        print(f"{kind}: {len(items)}{' (dry run)' if args.dry_run else ''}")
        for item in items:
            print(f"  {item}")


if __name__ == "__main__":
    main()
