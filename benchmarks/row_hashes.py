"""Which checkpoint did each results row measure? Fill and check the rows' ``model_hash``.

Rows written since 2026-11-26 carry ``model_hash`` (``trajpref.models.checkpoint.model_hash``
of the checkpoint they measured: weights, denoiser, data scale and model settings), and
``results.merge_rows`` refuses to merge rows of one measurement taken on different
checkpoints. Older rows were written without it; ``--backfill`` traces each of them through the
git history of its results file: the commit from which the row has stood unchanged in the file
is taken as the one that recorded it, and the checkpoint file committed at that commit (its
``checkpoint`` path, or the ``git show REV:PATH`` it names) gives the hash. A row whose
checkpoint was never tracked (``runs/...``) keeps null, and so does every ``-ancestral`` row
(measured before the sampling switch rewrote its file's settings). Assumption, stated: the weights
committed with a row are the ones it measured (true when a measurement and its weights land in
one commit, or the weights landed first).

    python benchmarks/row_hashes.py --backfill   # once: add the field to every row
    python benchmarks/row_hashes.py              # report rows that cannot be merged, rows
                                                 # whose checkpoint file now holds other weights,
                                                 # and rows without a hash whose file is gone
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from collections import defaultdict
from pathlib import Path
from typing import Any

from trajpref.errors import TrajprefError
from trajpref.models import checkpoint as ckpt
from trajpref.results import ANCESTRAL_SUFFIX, FIELDS, ROW_KEY, sampler_of

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
ZOO = "src/trajpref/zoo/"
"""Where ``models/`` (a link) points: the path git tracks the published files under."""


def _git(*args: str, root: Path | None = None) -> bytes:
    """``git`` in ``root`` (default: this repository, ``ROOT``)."""
    where = str(root or ROOT)
    return subprocess.run(["git", "-C", where, *args], check=True, capture_output=True).stdout


def _identity(row: dict[str, Any]) -> str:
    """A row's content without ``model_hash`` (to follow it through history)."""
    return json.dumps({k: v for k, v in row.items() if k != "model_hash"}, sort_keys=True)


def recorded_at(path: Path) -> dict[str, str]:
    """For each row now in ``path`` (by content), the commit from which it has stood there
    unchanged. Rows not committed yet are absent."""
    rel = str(path.relative_to(ROOT))
    commits = _git("log", "--format=%H", "--reverse", "--", rel).decode().split()
    since: dict[str, str] = {}
    for commit in commits:
        try:
            rows = json.loads(_git("show", f"{commit}:{rel}"))
        except subprocess.CalledProcessError:  # the file was removed in this commit
            rows = []
        present = {_identity(r) for r in rows}
        since = {i: since.get(i, commit) for i in present}
    return since


class Blobs:
    """``model_hash`` of checkpoint files as committed, cached by git blob; ``root``: the
    repository (default ``ROOT``)."""

    def __init__(self, root: Path | None = None) -> None:
        self.by_blob: dict[tuple[str, str], str | None] = {}
        self.root = root

    def hash_at(self, commit: str, checkpoint: str, sampler: str = "leapfrog") -> str | None:
        if checkpoint.startswith("git show "):
            commit, _, checkpoint = checkpoint.removeprefix("git show ").partition(":")
        candidates = [checkpoint]
        if checkpoint.startswith("models/"):
            candidates.append(ZOO + checkpoint.removeprefix("models/"))
        for rel in candidates:
            try:
                blob = _git("rev-parse", "--verify", "-q", f"{commit}:{rel}",
                            root=self.root).decode().strip()  # fmt: skip
            except subprocess.CalledProcessError:
                continue
            if (blob, sampler) not in self.by_blob:
                self.by_blob[blob, sampler] = self._digest(blob, Path(rel).suffix, sampler)
            return self.by_blob[blob, sampler]
        return None  # never tracked at that commit (a run folder)

    def _digest(self, blob: str, suffix: str, sampler: str) -> str | None:
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"checkpoint{suffix}"
            path.write_bytes(_git("cat-file", "blob", blob, root=self.root))
            try:
                return ckpt.model_hash(path, sampler)
            except TrajprefError:
                return None  # a git-lfs pointer or a damaged file


def backfill() -> None:
    blobs = Blobs()
    for path in sorted(RESULTS.glob("*.json")):
        rows = json.loads(path.read_text())
        since = recorded_at(path)
        filled = 0
        out = []
        for row in rows:
            value = row.get("model_hash")
            commit = since.get(_identity(row))
            # an -ancestral row measured its file before the sampling switch rewrote the
            # file's settings, often in the commit that renamed the row: no committed file
            # holds what it measured, so it stays untraced
            measurable = not row["method"].endswith(ANCESTRAL_SUFFIX)
            if value is None and row.get("checkpoint") and commit is not None and measurable:
                value = blobs.hash_at(commit, row["checkpoint"], sampler_of(row["method"]))
                filled += value is not None
            out.append({k: value if k == "model_hash" else row.get(k) for k in FIELDS})
        path.write_text(json.dumps(out, indent=2) + "\n")
        print(f"{path.name:<44} {len(rows):>3} rows, {filled:>3} traced to their checkpoint")


def check() -> int:
    """Print rows of one measurement with different hashes, rows whose checkpoint file now
    holds other weights or settings, and rows without a hash whose checkpoint file is gone
    (``untraceable``: counted apart, listed where the file was a published one, so that "0
    rows whose checkpoint file has changed" is not read as all of them checked); 1 when any
    of the first kind exists."""
    groups: dict[tuple, list[tuple[str, dict[str, Any]]]] = defaultdict(list)
    stale, unknown = [], []
    for path in sorted(RESULTS.glob("*.json")):
        for row in json.loads(path.read_text()):
            groups[tuple(row[k] for k in ROW_KEY)].append((path.name, row))
            file = ROOT / (row.get("checkpoint") or "-")
            if row.get("model_hash") and file.is_file():
                now = ckpt.model_hash(file, sampler_of(row["method"]))
                if now != row["model_hash"]:
                    stale.append((path.name, row, now))
            elif untraceable(row):
                unknown.append((path.name, row))
    conflicts = 0
    for key, members in groups.items():
        hashes = {r["model_hash"] for _, r in members if r.get("model_hash")}
        if len(hashes) > 1:
            conflicts += 1
            print("cannot merge", dict(zip(ROW_KEY, key, strict=True)))
            for name, r in members:
                print(f"    {r.get('model_hash')}  {name}  {r['date']}  {r['command']}")
    for name, row, now in stale:
        print(f"{name}: {row['dataset']} {row['method']} seed {row['seed']} measured "
              f"{row['model_hash']}; {row['checkpoint']} is now {now}")  # fmt: skip
    published = [(n, r) for n, r in unknown if _published_path(r["checkpoint"])]
    for name, row in published:
        print(f"{name}: {row['dataset']} {row['method']} seed {row['seed']} ({row['date']}) "
              f"names no model_hash and {row['checkpoint']} no longer exists: what it "
              "measured is unknown")  # fmt: skip
    print(f"{conflicts} measurements with rows of different checkpoints; {len(stale)} rows "
          f"whose checkpoint file has changed since; {len(unknown)} rows without a model_hash "
          f"whose checkpoint file is gone, so unchecked ({len(published)} of a published file, "
          f"listed; {len(unknown) - len(published)} of a run folder)")  # fmt: skip
    return 1 if conflicts else 0


def untraceable(row: dict[str, Any]) -> bool:
    """A row that names a checkpoint file but no ``model_hash``, whose file is gone: nothing
    says which weights it measured (a ``git show REV:PATH`` checkpoint is pinned to its
    commit, so it is not counted)."""
    checkpoint = row.get("checkpoint")
    if row.get("model_hash") or not checkpoint or checkpoint.startswith("git show "):
        return False
    return not (ROOT / checkpoint).is_file()


def _published_path(checkpoint: str) -> bool:
    """Whether a checkpoint path names a file of the zoo (``models/``, its target ``ZOO``)."""
    return checkpoint.startswith(("models/", ZOO))


def timed_weights(name: str, entry: dict, record: Path, zoo_dir: Path) -> tuple[str, str]:
    """Whether ``record``'s (meta/speed.json's) timing ``entry`` of the published ``name``
    timed the weights its file holds now, as ``(status, detail)``: ``same``; ``other`` (the
    file has changed since; detail: the two hashes); ``unknown`` (nothing tells; detail: why).
    The rule: the ``model_hash`` the entry records (``benchmarks/speed.py`` since 2026-12-06)
    against the file's; an entry without one is traced as ``row_hashes.py --backfill`` traces
    a results row, the file committed with the record (in the record's last commit, when the
    record has not changed since) standing for the one it timed; without git, or with the
    record or the file not committed, the status is ``unknown``, never a silent pass."""
    file = zoo_dir / f"{name}.safetensors"
    if not file.is_file():
        return "unknown", "no such file now"
    now = ckpt.model_hash(file)
    was = entry.get("model_hash")
    if not was:
        was, commit = _committed_hash(record, file)
        if was is None:
            return "unknown", "no hash recorded, and git cannot trace one"
        if was != now:
            return "other", f"{was} in {commit}, now {now}"
        return "same", ""
    return ("same", "") if was == now else ("other", f"timed {was}, now {now}")


def _committed_hash(record: Path, file: Path) -> tuple[str | None, str]:
    """``model_hash`` of ``file`` as committed in the last commit that wrote ``record``, and
    that commit's short name; (None, "") when git cannot tell (no repository, ``record`` not
    committed or changed since, ``file`` not tracked in that commit, a shallow clone)."""

    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(record.parent), *args], check=True,
                              capture_output=True, text=True).stdout.strip()  # fmt: skip

    try:
        top = Path(git("rev-parse", "--show-toplevel")).resolve()
        if git("rev-parse", "--is-shallow-repository") == "true":
            return None, ""  # its oldest commit is a graft: it would stand for older ones
        if git("status", "--porcelain", "--", str(record)):
            return None, ""  # the record has changed since its last commit
        commit = git("log", "-1", "--format=%h", "--", str(record))
        rel = str(file.resolve().relative_to(top))
        return (Blobs(top).hash_at(commit, rel) if commit else None), commit
    except (OSError, ValueError, subprocess.CalledProcessError):
        return None, ""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backfill", action="store_true",
                        help="add model_hash to every row, traced through git history")  # fmt: skip
    args = parser.parse_args(argv)
    if args.backfill:
        backfill()
    return check()


if __name__ == "__main__":
    raise SystemExit(main())
