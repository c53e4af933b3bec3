"""Which weights a published number measured (the reproducibility audit of walk 67): a card's
test row must name its file's digest, rows without one whose file is gone are counted, and
the README's latencies are checked against the files they timed."""

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from bench import load_benchmark
from synthetic import tiny_generator_file

from trajpref.models import checkpoint as ckpt
from trajpref.results import make_row

ROOT = Path(__file__).resolve().parent.parent
ZARA2 = ROOT / "models" / "zara2"


def _row(method, checkpoint, date, model_hash=None, **fields):
    return {"dataset": "zara2", "method": method, "seed": 0, "split": "test", "samples": 20,
            "protocol": "all", "checkpoint": checkpoint, "model_hash": model_hash,
            "machine": "m, 2 CPU cores, 2 threads", "min_ade": 0.1, "min_fde": 0.2,
            "joint_min_ade": 0.3, "joint_min_fde": 0.4, "date": date,
            "command": "python benchmarks/x.py", **fields}  # fmt: skip


def test_a_denoiser_card_shows_the_row_that_names_its_files_digest(monkeypatch):
    """zara2/denoiser's card showed the full-sampler row of 2026-11-22, which names
    ``generator.pt`` (replaced by fp16 .safetensors on 2026-11-23) and no digest: the first
    row of that path won, whatever its hash. A row naming the file's digest is preferred,
    even when an undigested row is newer."""
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    digest = ckpt.model_hash(ZARA2 / "denoiser.safetensors", "full")
    old = _row("full-sampler", "models/zara2/generator.pt", "2026-11-22", min_fde=0.325)
    new = _row("full-sampler", "models/zara2/generator.safetensors", "2026-12-06", digest,
               min_fde=0.326)  # fmt: skip
    later = _row("full-sampler", "models/zara2/generator.safetensors", "2026-12-07",
                 min_fde=0.999)  # fmt: skip
    entry = zoo.describe("zara2/denoiser", ZARA2 / "denoiser.safetensors", [old, new, later])
    assert entry["test"]["min_fde"] == 0.326
    assert "_unverified" not in entry


def test_a_card_whose_rows_name_none_of_its_files_digest_is_reported(monkeypatch):
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    old = _row("full-sampler", "models/zara2/generator.pt", "2026-11-22")
    entry = zoo.describe("zara2/denoiser", ZARA2 / "denoiser.safetensors", [old])
    assert entry["test"]["date"] == "2026-11-22"  # still shown, but reported
    assert "names no model_hash" in entry.get("_unverified", "")
    # a generator's newest row of other weights does not stand for the file either
    path = ZARA2 / "generator.safetensors"
    digest = ckpt.model_hash(path)
    rows = [_row("pretrained", "models/zara2/generator.safetensors", "2026-12-01", digest,
                 min_fde=0.21),
            _row("pretrained", "models/zara2/generator.safetensors", "2026-12-05",
                 "0123456789ab", min_fde=0.5)]  # fmt: skip
    assert zoo.describe("zara2/generator", path, rows)["test"]["min_fde"] == 0.21
    entry = zoo.describe("zara2/generator", path, rows[1:])
    assert "measured 0123456789ab" in entry.get("_unverified", "")


def test_the_zoo_check_says_when_everything_is_up_to_date(tmp_path, monkeypatch, capsys):
    """``--check`` printed nothing when it passed."""
    zoo = load_benchmark("zoo_index")
    (tmp_path / "zoo").mkdir()
    (tmp_path / "README.md").write_text("x\n<!-- models:start -->\n<!-- models:end -->\n")
    monkeypatch.setattr(zoo.zoo, "ZOO_DIR", tmp_path / "zoo")
    monkeypatch.setattr(zoo, "ROOT", tmp_path)
    monkeypatch.setattr("sys.argv", ["zoo_index.py"])
    zoo.main()
    capsys.readouterr()
    monkeypatch.setattr("sys.argv", ["zoo_index.py", "--check"])
    with pytest.raises(SystemExit) as done:
        zoo.main()
    assert done.value.code == 0
    assert "models/index.json and 0 cards are up to date" in capsys.readouterr().out


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


def test_the_readme_drops_an_undigested_row_of_a_gone_file_beside_a_re_measurement():
    """eth's full-sampler line merged the minADE of 2026-11-22 (``generator.pt``, no digest)
    with the maxATS of 2026-12-06 (the re-measurement that names the digest)."""
    update = load_benchmark("update_readme")
    old = _row("full-sampler", "models/zara2/generator.pt", "2026-11-22", min_ade=0.17)
    new = _row("full-sampler", "models/zara2/generator.safetensors", "2026-12-06",
               "c3d1512d2041", min_ade=0.18)  # fmt: skip
    alone = _row("full-sampler", "models/zara2/generator.pt", "2026-11-22")
    alone["dataset"] = "hotel"  # no re-measurement: it stays
    kept = update.without_superseded([old, new, alone])
    assert kept == [new, alone]
    present = _row("cv", None, "2026-11-22")  # no checkpoint at all: never dropped
    assert update.without_superseded([present, new]) == [present, new]


def _speed_record(meta: Path, entry: dict) -> None:
    meta.mkdir(parents=True, exist_ok=True)
    record = {"machine": "m", "threads": 1, "date": "2026-12-03", "command": "speed.py",
              "samples": 20, "models": {"d/generator": {
                  "dataset": "d", "scenes": 10, "leapfrog_ms_per_scene": 2.0,
                  "full_ms_per_scene": 80.0, "full_over_leapfrog": 40.0, **entry}}}  # fmt: skip
    (meta / "speed.json").write_text(json.dumps(record))


def test_the_latency_table_marks_a_file_that_changed_since_it_was_timed(tmp_path):
    update = load_benchmark("update_readme")
    zoo_dir, meta = tmp_path / "zoo", tmp_path / "meta"
    now = tiny_generator_file(zoo_dir / "d" / "generator.safetensors", seed=1)
    _speed_record(meta, {"model_hash": now})
    table = update.speed_table(meta, zoo_dir=zoo_dir)
    assert "| 2.0 | 80.0 | 40.0x |" in table and "†" not in table
    assert "each is its file's today" in table
    _speed_record(meta, {"model_hash": "0123456789ab"})
    table = update.speed_table(meta, zoo_dir=zoo_dir)
    assert "| 2.0† | 80.0† | 40.0x† |" in table
    assert f"`d/generator` (timed 0123456789ab, now {now})" in table
    _speed_record(meta, {})  # no hash, and no git repository to trace one: unknown, said so
    table = update.speed_table(meta, zoo_dir=zoo_dir)
    assert "| 2.0 | 80.0 | 40.0x |" in table
    assert "unknown for `d/generator` (no hash recorded, and git cannot trace one)" in table


def _repository(repo: Path):
    """A new git repository at ``repo`` and a function that commits everything in it."""
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]

    def commit(message: str) -> None:
        subprocess.run([*git, "add", "-A"], check=True, capture_output=True)
        subprocess.run([*git, "commit", "-qm", message], check=True, capture_output=True)

    return repo, commit


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_a_record_without_hashes_is_traced_to_the_files_committed_with_it(tmp_path):
    update = load_benchmark("update_readme")
    repo, commit = _repository(tmp_path / "repo")
    zoo_dir, meta = repo / "zoo", repo / "meta"
    first = tiny_generator_file(zoo_dir / "d" / "generator.safetensors", seed=1)
    _speed_record(meta, {})
    commit("weights and their timing")
    assert "| 2.0 | 80.0 | 40.0x |" in update.speed_table(meta, zoo_dir=zoo_dir)
    second = tiny_generator_file(zoo_dir / "d" / "generator.safetensors", seed=2)
    commit("new weights, not timed")
    table = update.speed_table(meta, zoo_dir=zoo_dir)
    assert "| 2.0† | 80.0† | 40.0x† |" in table
    assert f"({first} in " in table and f"now {second})" in table


@pytest.mark.skipif(shutil.which("git") is None, reason="needs git")
def test_a_shallow_clone_does_not_trace_a_record_to_its_graft(tmp_path):
    """The review of 622c5ae: in a clone of depth 1 the record's last commit is the graft,
    which holds today's files, so an old timing read as today's weights' (the † marks went
    away without a word). A shallow clone now cannot trace: unknown, said so."""
    update = load_benchmark("update_readme")
    repo, commit = _repository(tmp_path / "repo")
    zoo_dir, meta = repo / "zoo", repo / "meta"
    tiny_generator_file(zoo_dir / "d" / "generator.safetensors", seed=1)
    _speed_record(meta, {})
    commit("weights and their timing")
    tiny_generator_file(zoo_dir / "d" / "generator.safetensors", seed=2)
    commit("new weights, not timed")
    shallow = tmp_path / "shallow"
    subprocess.run(["git", "clone", "-q", "--depth", "1", f"file://{repo}", str(shallow)],
                   check=True, capture_output=True)  # fmt: skip
    table = update.speed_table(shallow / "meta", zoo_dir=shallow / "zoo")
    assert "| 2.0 | 80.0 | 40.0x |" in table  # not marked as today's either: unknown
    assert "unknown for `d/generator` (no hash recorded, and git cannot trace one)" in table


def test_speed_records_the_hash_of_each_file_it_times(tmp_path, monkeypatch):
    speed = load_benchmark("speed")
    path = tmp_path / "d" / "generator.safetensors"
    digest = tiny_generator_file(path, seed=1)

    class Split:
        num_agents = 3

        def __len__(self):
            return 3

    written = {}
    monkeypatch.setattr(speed.zoo, "generators", lambda datasets: {"d/generator": path})
    monkeypatch.setattr(speed, "load_dataset", lambda *a: Split())
    monkeypatch.setattr(speed.ckpt, "load_predictor", lambda *a, **k: None)
    monkeypatch.setattr(speed, "time_predictors",
                        lambda *a: {"scenes": 3, "leapfrog": 1.0, "full": 40.0})  # fmt: skip
    monkeypatch.setattr(speed, "write_meta", lambda out, **fields: written.update(fields))
    monkeypatch.setattr("sys.argv", ["speed.py", "--out", str(tmp_path / "speed.json")])
    speed.main()
    assert written["models"]["d/generator"]["model_hash"] == digest


def test_a_denoiser_card_says_its_generators_ratio_was_timed_before_the_file_changed():
    """eth/denoiser's card quoted 26.1x beside `eth/generator`, timed on 2026-12-03 before
    the file changed (2026-12-06)."""
    zoo = load_benchmark("zoo_index")
    speed = {"date": "2026-12-03", "models": {"eth/generator": {"full_over_leapfrog": 26.07}}}
    assert "as it was then" not in zoo.speed_note(speed, "eth")
    text = zoo.speed_note(speed, "eth", changed=True)
    assert "26.1x beside `eth/generator` as it was then (its file has changed since" in text
