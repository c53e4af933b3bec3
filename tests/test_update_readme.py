"""benchmarks/update_readme.py: which rows the README's results table keeps."""

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from bench import load_benchmark
from helpers import _row
from synthetic import tiny_generator_file

ROOT = Path(__file__).resolve().parent.parent


def _module():
    module = load_benchmark("update_readme")
    return module


def test_old_equal_budget_rows_stay_only_until_a_newer_start_has_rows():
    keep = _module()._latest_equal_budget
    old = {("robo", "control-ancestral"), ("robo", "rlhf-ancestral"),
           ("robo", "pretrained-ancestral"), ("robo", "rlhf-res-steps36-ancestral")}  # fmt: skip
    assert keep({"dataset": "robo", "method": "rlhf-ancestral"}, old)
    assert keep({"dataset": "robo", "method": "pretrained-ancestral"}, old)
    assert not keep({"dataset": "robo", "method": "rlhf-res-steps36-ancestral"}, old)  # ablation
    newer = old | {("robo", "control")}
    assert not keep({"dataset": "robo", "method": "rlhf-ancestral"}, newer)
    # runs from a later default that was itself replaced since also supersede the old table
    # (their own rows are kept out of the README, so the dataset then shows none)
    retired = old | {("robo", "rlhf-set-noclamp")}
    assert not keep({"dataset": "robo", "method": "control-ancestral"}, retired)
    assert not keep({"dataset": "robo", "method": "pretrained-ancestral"}, retired)
    # a dataset that never had the table keeps no old rows
    assert not keep({"dataset": "hotel", "method": "pretrained-ancestral"},
                    {("hotel", "pretrained-ancestral")})  # fmt: skip


def test_the_cost_table_reads_the_defaults_record_not_a_replaced_ones(tmp_path):
    """``pretrained_<D>_raw.json`` (the record of a replaced default) sorts after the
    default's own ``pretrained_<D>.json`` and must not stand in for it."""
    import json

    def record(minutes):
        return {"dataset": "zara1", "params": {"denoiser": 1e6, "generator": 7e5},
                "stage_seconds": {"denoiser": 600.0, "generator": 60.0 * minutes},
                "samples_per_second": {"denoiser": 3000.0, "generator": 800.0},
                "ms_per_scene": {"leapfrog": 6.0, "full": 80.0},
                "speedup_full_over_leapfrog": 13.3}  # fmt: skip

    (tmp_path / "pretrained_zara1.json").write_text(json.dumps(record(21.6)))
    (tmp_path / "pretrained_zara1_raw.json").write_text(json.dumps(record(60.9)))
    (tmp_path / "pretrained_robo-mix.json").write_text(
        json.dumps({**record(18.1), "dataset": "robo-mix"})
    )
    table = _module().speed_table(tmp_path)
    assert "| zara1/generator | 1.00 M / 0.70 M | 10.0 / 21.6 |" in table
    assert "60.9" not in table
    assert "| robo-mix/generator |" in table  # a hyphen in the name is not a suffix


def test_the_cost_note_names_the_probe_and_the_older_entries_machine_and_probe():
    module = _module()
    run = {"date": "2026-11-28", "machine": "host B", "command": "python x.py"}
    estimates = {
        "eth": {"date": "2026-11-28", "machine": "host B", "probe": {"warm": 3}},
        "sdd": {"date": "2026-11-24", "machine": "host A"},  # before probes were recorded
        "nba": {"date": "2026-11-27", "machine": "host B", "probe": {"warm": 3}},
    }
    assert module._probe(estimates, run) == "after 3 untimed warm-up epochs"
    note = module._older(estimates, run)
    assert "sdd from 2026-11-24 (on host A, in a cold probe)" in note
    assert "nba from 2026-11-27." in note  # same machine and probe: only its date


def test_the_score_column_says_which_run_measured_it(tmp_path):
    """The score column comes from benchmarks/score.py's own run, not from the latencies' run:
    its note gives the date, machine and command of that run's rows."""
    import json

    meta = tmp_path / "meta"
    meta.mkdir()
    record = {"dataset": "zara1", "params": {"denoiser": 1e6, "generator": 7e5},
              "stage_seconds": {"denoiser": 600.0, "generator": 600.0},
              "samples_per_second": {"denoiser": 3000.0, "generator": 800.0},
              "ms_per_scene": {"leapfrog": 6.0, "full": 80.0},
              "speedup_full_over_leapfrog": 13.3}  # fmt: skip
    (meta / "pretrained_zara1.json").write_text(json.dumps(record))
    (meta / "score_zara1.json").write_text(
        json.dumps(
            {"ms_to_rank_k_samples_per_scene": 42.39, "timing_threads": 2, "timing_scenes": 100}
        )
    )
    (tmp_path / "score_zara1.json").write_text(json.dumps([
        {"method": "pretrained", "date": "2026-12-06", "machine": "host X, 2 threads",
         "command": "python benchmarks/score.py --dataset zara1 --data-root d"}]))  # fmt: skip
    table = _module().speed_table(meta)
    assert "| 42.4 |" in table
    note = table.splitlines()[-1]
    assert note.startswith("_Score K=20:")
    assert "zara1: `python benchmarks/score.py --dataset <D>" in note
    assert "2026-12-06, host X, 2 threads (100 test scenes, 2 threads)" in note


def _run(*args):
    import subprocess
    import sys

    script = ROOT / "benchmarks" / "update_readme.py"
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True,
                          timeout=120)  # fmt: skip


def test_help_describes_the_script_and_writes_nothing():
    """``--help`` ran the script, rewriting README.md."""
    before = (ROOT / "README.md").stat().st_mtime_ns
    done = _run("--help")
    assert done.returncode == 0, done.stderr
    assert "--check" in done.stdout and "Regenerate the README's generated tables" in done.stdout
    assert (ROOT / "README.md").stat().st_mtime_ns == before


def test_check_says_whether_the_readme_would_change_and_writes_nothing(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text((ROOT / "README.md").read_text())
    assert _module().main(["--readme", str(readme)]) == 0  # rewritten: now up to date
    current = readme.read_text()
    assert _module().main(["--check", "--readme", str(readme)]) == 0
    stale = current.replace("<!-- results-sgan:start -->\n",
                            "<!-- results-sgan:start -->\nan old line\n", 1)  # fmt: skip
    assert stale != current
    readme.write_text(stale)
    done = _run("--check", "--readme", str(readme))
    assert done.returncode == 1
    assert "-an old line" in done.stdout and "would change" in done.stdout
    assert readme.read_text() == stale  # nothing written


# Which weights a published number measured (the reproducibility audit of walk 67): a card's
# test row must name its file's digest, rows without one whose file is gone are counted, and
# the README's latencies are checked against the files they timed.


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


# benchmarks/zoo_index.py: a card's test-row command names no machine's data path
# (walkthrough 67, F6).


def test_the_readme_shows_no_machine_specific_data_root():
    """The README's generated footnotes showed the measuring machine's --data-root
    (/work/shared/data); update_readme.py now shows each command as the cards do."""
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    assert not re.search(r"--data-root[ =]/", readme)
