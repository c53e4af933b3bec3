"""Where finetune.py and pretrain.py write when told to keep out of the repository: the
options ``--runs``, ``--results`` and ``--models`` that go together, and the paths their rows
record. Not a script: imported by its neighbours (run as ``python benchmarks/x.py``, which puts
this folder on the path)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

ELSEWHERE = ("runs", "results", "models")
"""The options that move a script's run folders, rows (with their ``meta/``) and published
models out of the repository: all three or none."""


def add_elsewhere_options(parser: argparse.ArgumentParser, **helps: str) -> None:
    """``--runs``, ``--results`` and ``--models`` (each a folder, default None: the
    repository's), their help texts by name, in a group that says they go together."""
    group = parser.add_argument_group(
        "out of the repository", "--runs, --results and --models go together: all or none"
    )
    for name in ELSEWHERE:
        group.add_argument(f"--{name}", type=Path, default=None, metavar="DIR", help=helps[name])


def require_all_or_none(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse (``parser.error``, exit 2) a run that names some of ``--runs``, ``--results``
    and ``--models`` but not all: the ones left out would be the repository's, so a start
    read from another models folder would rewrite the repository's rows and start records,
    and rows written elsewhere would publish into, or read from, the repository's models."""
    given = [name for name in ELSEWHERE if getattr(args, name) is not None]
    if given and len(given) < len(ELSEWHERE):
        missing = " and ".join(f"--{name}" for name in ELSEWHERE if name not in given)
        parser.error(f"--runs, --results and --models go together (the ones left out are the "
                     f"repository's, which a run kept out of it must not touch): {missing} "
                     "missing (name the repository's own folder to mean it)")  # fmt: skip


def shown(path: Path, root: Path) -> str:
    """``path`` as rows and records name it: relative to ``root`` (the repository) when it lies
    inside it (the rows written so far), otherwise absolute, so that ``root / shown(p, root)``
    is ``p`` either way. Made absolute with ``..`` taken out but links kept (``models/`` may be a
    link)."""
    path = Path(os.path.abspath(path))
    return str(path.relative_to(root)) if path.is_relative_to(root) else str(path)
