"""What the studies of a post-training generator setting share (``deterministic_steps.py``,
``speed_clamp.py``, ``spread_scale.py``): their common options, which published generators
they cover, the validation metrics they compare, the record they store beside the decision,
and the ``--apply`` step that writes the chosen setting into the published files
(``checkpoint.set_generator_setting``; weights untouched). Each study keeps its own rule,
fixed before its numbers were seen.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from datetime import date
from pathlib import Path
from typing import Any

from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.results import machine

METRICS = ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde")
"""The validation metrics a study stores for each setting."""


def study_parser(doc: str) -> argparse.ArgumentParser:
    """A study's parser with the options every study takes: ``--data-root``, ``--device``,
    ``--samples`` (K) and ``--seed``."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    return parser


def published_generators(
    models: Path, datasets: list[str] | None = None, variants: bool = True
) -> list[tuple[str, Path]]:
    """(dataset, file) of the published generators under ``models`` (``zoo.generators``), in
    a stable order: every ``generator*`` file, or only each folder's default ``generator`` when
    ``variants`` is false; ``datasets`` keeps only the named folders (an unknown name is an
    error)."""
    if datasets is not None:
        unknown = sorted(d for d in datasets if not (models / d).is_dir())
        if unknown:
            raise SystemExit(f"no published models for {', '.join(unknown)} under {models}")
    found = zoo.generators(datasets, root=models)
    return sorted((name.split("/")[0], path) for name, path in found.items()
                  if variants or name.endswith("/generator"))  # fmt: skip


def with_model_setting(payload: dict, name: str, value: Any) -> dict:
    """A copy of a generator payload whose config sets ``model.<name>`` (the payload itself,
    its config sections included, is left as it was)."""
    config = {section: dict(values) if isinstance(values, dict) else values
              for section, values in payload["config"].items()}  # fmt: skip
    config["model"][name] = value
    return {**payload, "config": config}


def validation_metrics(predictor, dataset, samples: int, seed: int, device: str) -> dict:
    """``METRICS`` (and the seconds it took) of one predictor on one validation split."""
    res = evaluate(predictor, dataset, samples, seed, device)
    return {**{k: res[k] for k in METRICS}, "seconds": res.get("seconds")}


def write_study(out: Path, command: str, rows: list[dict], decision: dict, **fields: Any) -> None:
    """Store a study's rows and decision with the date, machine and command that made them."""
    record = {"date": str(date.today()), "machine": machine(), "command": command,
              "split": "val", **fields, "rows": rows, "decision": decision}  # fmt: skip
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(record, indent=2) + "\n")


def apply_setting(
    root: Path,
    stored: dict,
    allowed: str,
    name: str,
    value_of: Callable[[dict], Any],
    note: str,
) -> list[tuple[str, bool]]:
    """Write setting ``name`` (``value_of(row)``) into each generator a stored study (the
    record ``write_study`` wrote) covers, when its decision's ``allowed`` key is true. Returns
    (checkpoint, changed) per row; an empty list when the decision does not allow the change
    (nothing is written)."""
    if not stored["decision"][allowed]:
        return []
    return [
        (row["checkpoint"], ckpt.set_generator_setting(
            root / row["checkpoint"], name, value_of(row), note=note))
        for row in stored["rows"]
    ]  # fmt: skip
