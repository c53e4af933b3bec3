"""benchmarks/row_hashes.py: tracing old results rows to the checkpoint committed with them,
and the repository's own rows (no two rows of one measurement on different checkpoints)."""

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from bench import load_benchmark
from synthetic import tiny_generator_file

from trajpref.models import checkpoint as ckpt
from trajpref.results import make_row, read_rows

ROOT = Path(__file__).resolve().parent.parent


def _row(method, checkpoint, fde):
    return make_row(dataset="d", split="test", method=method, seed=0, samples=20, min_fde=fde,
                    checkpoint=checkpoint, date="2026-11-20", machine="m", command="c")  # fmt: skip


def _commit(repo: Path, message: str) -> None:
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "add", "-A"], check=True, capture_output=True)
    subprocess.run([*git, "commit", "-qm", message], check=True, capture_output=True)


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_backfill_takes_the_checkpoint_committed_when_the_row_last_changed(tmp_path, monkeypatch):
    rh = load_benchmark("row_hashes")
    repo = tmp_path / "repo"
    results = repo / "benchmarks" / "results"
    results.mkdir(parents=True)
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    monkeypatch.setattr(rh, "ROOT", repo)
    monkeypatch.setattr(rh, "RESULTS", results)
    gen = "models/d/generator.safetensors"
    first = tiny_generator_file(repo / gen, seed=1)
    rows = [_row("pretrained", gen, 0.40), _row("control", "runs/x/finetune.safetensors", 0.5),
            _row("pretrained-old", gen, 0.45), _row("pretrained-ancestral", gen, 0.5)]  # fmt: skip
    for r in rows:
        del r["model_hash"]  # written before the field existed
    (results / "r.json").write_text(json.dumps(rows))
    _commit(repo, "first weights and rows")
    second = tiny_generator_file(repo / gen, seed=2)  # new weights; the rows stay as they were
    _commit(repo, "new weights")
    rows[0]["min_fde"] = 0.38  # re-measured on the new weights
    (results / "r.json").write_text(json.dumps(rows))
    _commit(repo, "re-measured")
    assert first != second

    rh.backfill()
    got = {r["method"]: r["model_hash"] for r in json.loads((results / "r.json").read_text())}
    assert got == {"pretrained": second, "control": None, "pretrained-old": first,
                   "pretrained-ancestral": None}  # fmt: skip
    assert rh.check() == 0  # three methods: nothing to merge


def test_no_two_rows_of_one_measurement_name_different_checkpoints(capsys):
    rh = load_benchmark("row_hashes")
    assert rh.check() == 0, capsys.readouterr().out


def test_published_rows_measured_the_weights_the_repository_ships():
    """Every row of a published model (``pretrained``, ``pretrained-long``, variants) whose
    checkpoint file is tracked names that file's weights and settings as they are now; the
    ``-ancestral`` rows, kept on purpose for the tables of their time (measured before the
    sampling switch rewrote the files' settings), are not traced."""
    stale, untraced = [], []
    for row in read_rows(ROOT / "benchmarks" / "results"):
        path = ROOT / (row["checkpoint"] or "-")
        published = row["method"].startswith("pretrained") and not row["method"].endswith(
            "-ancestral"
        )
        if not published or not path.is_file():
            continue
        if row["model_hash"] is None:
            untraced.append((row["dataset"], row["method"]))
        elif row["model_hash"] != ckpt.model_hash(path):
            stale.append((row["dataset"], row["method"], row["protocol"]))
    assert not stale, f"rows measured other weights than their checkpoint holds: {stale}"
    assert not untraced, f"published rows without a model_hash: {untraced}"


# Which weights a published number measured (the reproducibility audit of walk 67): a card's
# test row must name its file's digest, rows without one whose file is gone are counted, and
# the README's latencies are checked against the files they timed.


def test_rows_without_a_digest_whose_file_is_gone_are_counted(tmp_path, monkeypatch, capsys):
    """row_hashes.py skipped them and printed "0 rows whose checkpoint file has changed"."""
    rh = load_benchmark("row_hashes")
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    monkeypatch.setattr(rh, "ROOT", tmp_path)
    monkeypatch.setattr(rh, "RESULTS", results)
    rows = [make_row(dataset="d", split="test", method="full-sampler", seed=0, samples=20,
                     checkpoint="models/d/generator.pt", date="2026-11-22", machine="m",
                     command="c"),
            make_row(dataset="d", split="test", method="control", seed=0, samples=20,
                     checkpoint="runs/x/finetune.safetensors", date="2026-11-22", machine="m",
                     command="c")]  # fmt: skip
    (results / "r.json").write_text(json.dumps(rows))
    assert rh.check() == 0
    out = capsys.readouterr().out
    assert "d full-sampler seed 0 (2026-11-22) names no model_hash" in out
    assert "2 rows without a model_hash whose checkpoint file is gone" in out
    assert "(1 of a published file, listed; 1 of a run folder)" in out
