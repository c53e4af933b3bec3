"""benchmarks/reproduce.py: the paper's numbers file, quick mode's tables, resuming, and full
mode's training jobs (run by a fake runner), on the tiny synthetic run."""

import json
import shutil
import subprocess
import sys
from argparse import Namespace
from pathlib import Path

import pytest
from bench import load_benchmark

from trajpref.data import load_dataset
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint
from trajpref.results import make_row, write_rows
from trajpref.score.scorer import TrajectoryScorer

ROOT = Path(__file__).resolve().parents[1]


reproduce = load_benchmark("reproduce")
SAMPLES = ["--samples", "4"]


@pytest.fixture
def setup(tiny_run, walks, tmp_path):
    """A repository of two datasets: ``walks`` with a published generator and denoiser, and
    ``bare`` (the same scenes) with no model; empty results and no configs."""
    models = tmp_path / "models"
    checkpoint.publish(
        tiny_run / "generator.safetensors", models / "walks" / "generator.safetensors"
    )
    results = tmp_path / "results"
    results.mkdir()
    (tmp_path / "configs").mkdir()
    return reproduce.Setup(
        models=models, results=results, configs=tmp_path / "configs",
        doc=tmp_path / "docs" / "reproduce.md", logs=tmp_path / "logs",
        sources={"walks": str(walks), "bare": str(walks)},
    )  # fmt: skip


def _row(method: str, seed: int, min_ade: float, min_fde: float, **extra) -> dict:
    return make_row(dataset="walks", split="test", method=method, seed=seed, samples=4,
                    min_ade=min_ade, min_fde=min_fde, date="2026-11-23", **extra)  # fmt: skip


def _counting(monkeypatch, fail_at: int | None = None) -> list:
    """Count reproduce's evaluate calls; raise KeyboardInterrupt at call ``fail_at``."""
    calls = []

    def wrapped(*args, **kwargs):
        calls.append(args[1].info.name)
        if fail_at is not None and len(calls) == fail_at:
            raise KeyboardInterrupt
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(reproduce, "evaluate", wrapped)
    return calls


# ----------------------------------------------------------------------------- the paper


def test_the_paper_numbers_parse_cover_the_datasets_and_match_their_avg_row():
    paper = json.loads((ROOT / "benchmarks" / "paper_tables.json").read_text())
    assert "Table 1" in paper["source"] and "Table 2" in paper["source"]
    assert paper["datasets"] == ["eth", "hotel", "univ", "zara1", "zara2", "nba", "robo"]
    assert set(paper["datasets"]) | {"sdd"} == set(reproduce.DATASETS)  # SDD: text only
    assert "sdd" in paper["text_only"]
    for table in ("table1", "table2"):
        rows = paper["tables"][table]["rows"]
        assert list(rows) == [*paper["datasets"], "avg"]
        for row in rows.values():
            assert set(row) == set(paper["columns"])
            assert all(len(v) == 2 and all(isinstance(x, float) for x in v) for v in row.values())
        # a typing check: the printed AVG is the mean of the seven printed rows, to rounding
        for col in paper["columns"]:
            for i in (0, 1):
                mean = sum(rows[d][col][i] for d in paper["datasets"]) / 7
                assert mean == pytest.approx(rows["avg"][col][i], abs=0.005 + 1e-9), (table, col)
    assert paper["tables"]["table1"]["rows"]["robo"]["RLHF-ReS"] == [0.21, 0.29]
    assert paper["tables"]["table2"]["rows"]["avg"]["RLHF-ReS"] == [0.34, -0.29]
    assert set(reproduce.PAPER_COLUMNS) <= set(paper["columns"])


def test_the_comparison_puts_the_papers_numbers_beside_ours_and_averages_the_folds():
    paper = json.loads((ROOT / "benchmarks" / "paper_tables.json").read_text())
    cells = {}
    for i, dataset in enumerate(reproduce.ETH_UCY):
        cells[dataset] = {c: reproduce.missing_cell("not trained", "") for c in reproduce.COLUMNS}
        cells[dataset]["cv"] = {"min_ade": 0.1 * (i + 1), "min_fde": 0.2 * (i + 1),
                                "source": "evaluated", "units": "m"}  # fmt: skip
    table = reproduce.comparison_table(cells, paper, "table1", "rlhf-set").splitlines()
    assert table[2] == ("| eth | 0.100 / 0.200 | not trained | not trained | not trained "
                        "| not trained | not trained | 0.33 / 0.60 | 0.34 / 0.53 | 0.31 / 0.48 "
                        "| 0.39 / 0.58 |")  # fmt: skip
    # ours: (0.1 + ... + 0.5) / 5 = 0.3; the paper's LED: (0.33 + 0.20 + 0.31 + 0.18 + 0.16) / 5
    # = 0.236 and (0.60 + 0.40 + 0.62 + 0.31 + 0.28) / 5 = 0.442
    assert table[-1].startswith("| mean of the 5 ETH/UCY folds | 0.300 / 0.600 | – (0 of 5) |")
    assert "| 0.24 / 0.44 |" in table[-1]
    del cells["zara2"]
    table = reproduce.comparison_table(cells, paper, "table2", "rlhf-set").splitlines()
    assert not table[-1].startswith("| mean")  # not every fold: no mean
    assert table[2].startswith("| eth | – | not trained |")  # no maxATS in the cell


# ----------------------------------------------------------------------------- quick mode


def test_quick_mode_builds_both_tables_with_our_columns_beside_the_papers(setup, walks):
    # the published generator evaluated directly (seed 0, scored by its denoiser)
    gen = setup.models / "walks" / "generator.safetensors"
    model, test = (
        checkpoint.load_predictor(gen, sampler="leapfrog"),
        load_dataset(str(walks), "test"),
    )
    direct = evaluate(model, test, 4, 0, progress=False,
                      scorer=TrajectoryScorer.from_checkpoint(gen))  # fmt: skip
    write_rows(setup.results / "finetune_walks.json",
               [_row("rlhf", 0, 0.5, 1.0, max_ats=0.2, max_fts=0.1),
                _row("rlhf", 1, 0.7, 1.2, max_ats=0.4, max_fts=0.3)])  # fmt: skip
    write_rows(setup.results / "pretrained_walks.json",
               [_row("pretrained", 0, direct["min_ade"], direct["min_fde"]),
                _row("cv", 0, 9.0, 9.0)])  # fmt: skip
    out = reproduce.main(["--quick", "--datasets", "walks", "bare", *SAMPLES], setup)

    walks_cells, bare = out["cells"]["walks"], out["cells"]["bare"]
    for column in ("cv", "full-sampler", "pretrained"):
        assert walks_cells[column]["source"] == "evaluated"
        assert walks_cells[column]["max_ats"] is not None  # scored by walks' denoiser
    assert walks_cells["pretrained"]["min_ade"] == pytest.approx(direct["min_ade"])
    assert walks_cells["pretrained"]["max_ats"] == pytest.approx(direct["max_ats"])
    # an evaluation is checked against an existing row of the same measurement
    assert "; matches the `pretrained` rows in" in walks_cells["pretrained"]["detail"]
    assert "; DIFFERS from the `cv` rows in" in walks_cells["cv"]["detail"]
    assert "rows in" not in walks_cells["full-sampler"]["detail"]  # no such row
    # RLHF from the rows (mean over the two seeds), RLHF-ReS and the best method not trained
    assert walks_cells["rlhf"]["source"] == "rows"
    assert walks_cells["rlhf"]["min_ade"] == pytest.approx(0.6)
    assert walks_cells["rlhf"]["seeds"] == [0, 1]
    assert "trained 2026-11-23" in walks_cells["rlhf"]["detail"]
    assert walks_cells["rlhf-res"]["note"] == "not trained"
    assert walks_cells["best"]["note"] == "not trained"
    # no model: constant velocity only, and unscored
    assert bare["cv"]["source"] == "evaluated" and bare["cv"]["max_ats"] is None
    assert all(bare[c]["note"] == "no model" for c in reproduce.COLUMNS[1:])

    doc = setup.doc.read_text()
    assert doc.startswith("<!-- Generated by benchmarks/reproduce.py")
    header = ("| dataset | CV | full sampler | pretrained | RLHF | RLHF-ReS | best with the score "
              "(rlhf-set) | paper: LED | paper: RLHF | paper: RLHF-ReS |")  # fmt: skip
    assert doc.count(header) == 2  # Tables 1 and 2
    assert "| 0.600 / 1.100 † |" in doc  # Table 1's RLHF cell, from rows
    assert "| 0.300 / 0.200 † |" in doc  # Table 2's
    table2_bare = [x for x in doc.splitlines() if x.startswith("| bare |")][-1]
    assert "| no scorer | no model |" in table2_bare
    assert "| not in the paper's table |" in table2_bare
    # the paper's Table 1 as printed, all seven columns
    assert "| eth | 0.63 / 1.03 | 0.55 / 0.86 | 0.46 / 0.73 | 0.43 / 0.69 | 0.33 / 0.60 " in doc
    summary = json.loads(setup.summary.read_text())
    assert summary["mode"] == "quick" and summary["cells"]["walks"]["cv"]["source"] == "evaluated"
    assert summary["cpu_hours"]["this_invocation_hours"] > 0


def test_the_full_sampler_is_capped_to_evenly_spaced_scenes_on_a_large_split(
    setup, walks, monkeypatch
):
    test = load_dataset(str(walks), "test")
    cap = test.num_agents // 2
    seen = {}

    def recording(model, data, *args, **kwargs):
        seen[model.sampler if hasattr(model, "sampler") else "cv"] = data
        return evaluate(model, data, *args, **kwargs)

    monkeypatch.setattr(reproduce, "evaluate", recording)
    args = ["--quick", "--datasets", "walks", *SAMPLES, "--full-sampler-agents", str(cap)]
    out = reproduce.main(args, setup)
    full = seen["full"]
    assert full.num_agents <= cap < test.evenly_spaced(len(full) + 1).num_agents  # the most
    assert len(full) < len(test)
    assert [s.scene_id for s in full.scenes] == [
        s.scene_id for s in test.evenly_spaced(len(full)).scenes
    ]
    assert seen["leapfrog"].num_agents == seen["cv"].num_agents == test.num_agents
    cells = out["cells"]["walks"]
    assert cells["full-sampler"]["subset"] and not cells["pretrained"]["subset"]
    assert f"{len(full)} scenes of {len(test)}, evenly spaced" in cells["full-sampler"]["detail"]
    doc = setup.doc.read_text()
    row = [x for x in doc.splitlines() if x.startswith("| walks |")][0]
    assert row.count(" ‡") == 1
    # another cap is another full-sampler measurement; the other columns are untouched
    calls = _counting(monkeypatch)
    reproduce.main([*args[:-1], "0"], setup)
    assert len(calls) == 1


def test_a_second_run_does_no_work_and_an_interrupted_run_resumes(setup, monkeypatch):
    args = ["--quick", "--datasets", "walks", "bare", *SAMPLES]
    calls = _counting(monkeypatch, fail_at=3)
    with pytest.raises(KeyboardInterrupt):
        reproduce.main(args, setup)
    assert len(calls) == 3  # two finished and were stored, the third was interrupted
    log = json.loads((setup.state / "invocations.json").read_text())
    assert log[-1]["interrupted"] is True and log[-1]["jobs_run"] == 0

    calls = _counting(monkeypatch)
    out = reproduce.main(args, setup)
    assert len(calls) == 2  # walks cv + full sampler + pretrained, bare cv: 4 - 2 done
    assert out["jobs"]["skipped"] == 2

    calls = _counting(monkeypatch)
    out = reproduce.main(args, setup)
    assert calls == [] and out["jobs"]["skipped"] == 4
    assert out["cells"]["walks"]["pretrained"]["source"] == "evaluated"
    assert out["cpu_hours"]["invocations"] == 3
    # --report runs nothing and keeps the stored cells
    out = reproduce.main([*args[1:], "--report"], setup)
    assert calls == [] and out["cells"]["walks"]["full-sampler"]["source"] == "evaluated"
    assert out["cpu_hours"]["invocations"] == 3  # a report is not a run
    assert "The last run that measured: `" in setup.doc.read_text()
    # another K is another measurement
    calls = _counting(monkeypatch)
    reproduce.main(["--quick", "--datasets", "walks", "--samples", "3"], setup)
    assert len(calls) == 3


def test_a_changed_checkpoint_is_evaluated_again(setup, tiny_run, monkeypatch):
    args = ["--quick", "--datasets", "walks", *SAMPLES]
    reproduce.main(args, setup)
    gen = setup.models / "walks" / "generator.safetensors"
    shutil.copy(tiny_run / "generator.safetensors", gen)  # the same model in other bytes
    calls = _counting(monkeypatch)
    reproduce.main(args, setup)
    assert len(calls) == 2  # full sampler and pretrained; constant velocity is unchanged


def test_a_sampling_change_re_evaluates_the_generator_but_not_the_full_sampler(setup, monkeypatch):
    args = ["--quick", "--datasets", "walks", *SAMPLES]
    reproduce.main(args, setup)
    gen = setup.models / "walks" / "generator.safetensors"
    stochastic = checkpoint.config_of(checkpoint.load(gen)).model.stochastic_steps
    assert checkpoint.set_stochastic_steps(gen, not stochastic, note="test")
    calls = _counting(monkeypatch)
    out = reproduce.main(args, setup)
    assert len(calls) == 1  # the full sampler runs the denoiser only: still current
    assert out["jobs"]["skipped"] == 2


def test_another_layout_of_the_scores_noise_re_evaluates_every_scored_cell(setup, monkeypatch):
    args = ["--quick", "--datasets", "walks", *SAMPLES]
    reproduce.main(args, setup)
    monkeypatch.setattr(reproduce, "NOISE_LAYOUT", "batch-index")
    calls = _counting(monkeypatch)
    reproduce.main(args, setup)
    assert len(calls) == 3  # constant velocity too: its Table 2 cell is scored
    calls = _counting(monkeypatch)
    reproduce.main(args, setup)
    assert calls == []


# ----------------------------------------------------------------------------- full mode


def test_full_mode_trains_the_missing_rows_once(setup, monkeypatch):
    commands = []

    def fake_run(cmd, log):
        """Stand in for finetune.py: write the row the real script would."""
        commands.append(cmd)
        method = cmd[cmd.index("--methods") + 1]
        tag = cmd[cmd.index("--tag") + 1] if "--tag" in cmd else ""
        name = f"{method}-{tag}" if tag else method
        path = setup.results / f"finetune_walks{'_' + tag if tag else ''}.json"
        rows = json.loads(path.read_text()) if path.is_file() else []
        write_rows(path, [*rows, _row(name, int(cmd[cmd.index("--seeds") + 1]), 0.4, 0.8)])
        return 0

    monkeypatch.setattr(reproduce, "run_command", fake_run)
    args = ["--datasets", "walks", "bare", *SAMPLES, "--seeds", "0", "1"]
    out = reproduce.main(args, setup)
    trained = sorted((c[c.index("--methods") + 1], "--tag" in c, c[c.index("--seeds") + 1])
                     for c in commands)  # fmt: skip
    assert trained == [
        ("rlhf", False, "0"),
        ("rlhf", False, "1"),
        ("rlhf", True, "0"),
        ("rlhf", True, "1"),
        ("rlhf-res", False, "0"),
        ("rlhf-res", False, "1"),
    ]
    assert all("finetune.budget_clock=cpu" in c and "--skip-done" in c for c in commands)
    cells = out["cells"]["walks"]
    assert all(cells[c]["source"] == "rows" and cells[c]["seeds"] == [0, 1]
               for c in ("rlhf", "rlhf-res", "best"))  # fmt: skip
    assert out["cells"]["bare"]["rlhf"]["note"] == "no model"  # no config: nothing to train

    commands.clear()
    out = reproduce.main(args, setup)
    assert commands == [] and out["jobs"]["run"] == []


def test_full_mode_pretrains_a_dataset_that_has_a_config_but_no_model(setup):
    (setup.configs / "bare.yaml").write_text("{}\n")
    opts = reproduce.parse_args(["--datasets", "bare"], setup)
    jobs = reproduce.plan(opts, setup)
    assert [j.label for j in jobs] == [
        "pretrain bare pretrained", "evaluate bare cv", "evaluate bare full-sampler",
        "evaluate bare pretrained", "finetune bare rlhf seed 0", "finetune bare rlhf-res seed 0",
        "finetune bare rlhf-set seed 0",
    ]  # fmt: skip
    cmd = reproduce.training_command(jobs[0], opts, setup)
    assert cmd[1].endswith("pretrain.py") and cmd[2:] == [
        "--dataset", "bare", "--train", "--no-full-eval", "--device", "cpu"]  # fmt: skip
    quick = reproduce.plan(reproduce.parse_args(["--quick", "--datasets", "bare"], setup), setup)
    assert [j.label for j in quick] == ["evaluate bare cv"]


def test_full_mode_trains_with_the_equal_budget_tables_arguments(setup, tmp_path, monkeypatch):
    """The fine-tuning jobs run exactly what benchmarks/equal_budget.py runs, so their rows
    are the equal-budget table's."""
    equal_budget = load_benchmark("equal_budget")
    monkeypatch.setattr(equal_budget, "ROOT", tmp_path / "eb")
    seen = []

    def fake_call(cmd, **kwargs):
        seen.append(cmd)
        return 0

    monkeypatch.setattr(subprocess, "call", fake_call)
    ns = Namespace(datasets=["walks"], methods=list(reproduce.TRAIN_ARGS), seeds=[0],
                   minutes=4.0, warmup=4, eval_minutes=1.0, workers=1, data_root="/data",
                   start="generator")  # fmt: skip
    equal_budget.run_jobs(ns)
    start = setup.results / "meta" / "finetune_start_walks.json"
    start.parent.mkdir(parents=True)
    start.write_text("{}")
    opts = reproduce.parse_args(["--datasets", "walks", "--data-root", "/data"], setup)
    for theirs in seen:
        method = next(m for m, a in equal_budget.METHODS.items()
                      if theirs[4:4 + len(a) + 1] == [*a, "--seeds"])  # fmt: skip
        job = reproduce.Job("finetune", "walks", method, seed=0)
        mine = reproduce.training_command(job, opts, setup)
        assert mine[0] == sys.executable and mine[1].endswith("finetune.py")
        device = mine.index("--device")
        assert mine[2:device] + mine[device + 2 :] == theirs[2:]
    assert len(seen) == len(reproduce.TRAIN_ARGS)


def test_a_run_on_some_datasets_keeps_the_stored_cells_of_the_others(setup, monkeypatch):
    reproduce.main(["--quick", "--datasets", "walks", "bare", *SAMPLES], setup)
    calls = _counting(monkeypatch)
    out = reproduce.main(["--quick", "--datasets", "bare", *SAMPLES], setup)
    assert calls == []  # bare's constant velocity was stored by the first run
    assert out["datasets"] == ["bare"]
    assert out["table_datasets"] == ["walks", "bare"]
    assert out["cells"]["walks"]["pretrained"]["source"] == "evaluated"
    doc = setup.doc.read_text()
    assert sum(line.startswith("| walks |") for line in doc.splitlines()) == 2  # Tables 1, 2
    # a stored cell of a left-out dataset still counts only while its key matches
    out = reproduce.main(["--quick", "--datasets", "bare", "--samples", "3"], setup)
    assert out["cells"]["walks"]["pretrained"]["note"] == "not measured"


def test_a_published_fine_tune_fills_its_column_only_when_it_started_from_todays_generator(
    setup, tiny_run, tmp_path
):
    gen = setup.models / "walks" / "generator.safetensors"
    today = reproduce.read_checkpoint_header(gen)["hash"]

    def publish_tuned(start_hash: str) -> None:
        payload = checkpoint.load(tiny_run / "generator.safetensors")
        payload["meta"] = {**payload.get("meta", {}), "method": "rlhf-res", "from": start_hash}
        checkpoint.save(tmp_path / "tuned.safetensors", payload)
        checkpoint.publish(tmp_path / "tuned.safetensors", gen.parent / "rlhf-res.safetensors")

    def labels(argv: list[str]) -> set[str]:
        return {j.label for j in reproduce.plan(reproduce.parse_args(argv, setup), setup)}

    publish_tuned(today)
    quick = ["--quick", "--datasets", "walks"]
    assert "evaluate walks rlhf-res" in labels(quick)
    publish_tuned("0123456789abcdef")  # fine-tuned from a default since replaced
    assert "evaluate walks rlhf-res" not in labels(quick)
    assert any(label.startswith("finetune walks rlhf-res") for label in labels(quick[1:]))


# ----------------------------------------------------------------------------- walkthrough 67-E


def _files(*folders: Path) -> dict[Path, bytes]:
    """Every file under the folders, with its bytes."""
    return {p: p.read_bytes() for f in folders if f.is_dir() for p in f.rglob("*") if p.is_file()}


def test_a_subset_run_keeps_the_whole_splits_state_and_tables(setup, tmp_path, monkeypatch):
    """A smoke run (--max-scenes) once replaced eth's whole-split cells with 10-scene ones and
    rewrote docs/reproduce.md with "not measured" in every other dataset's cells."""
    setup.scratch = tmp_path / "runs" / "reproduce"
    args = ["--quick", "--datasets", "walks", "bare", *SAMPLES]
    reproduce.main(args, setup)
    before = _files(setup.results, setup.doc.parent)
    calls = _counting(monkeypatch)
    reproduce.main(["--quick", "--datasets", "walks", *SAMPLES, "--max-scenes", "1"], setup)
    assert len(calls) == 3  # measured, into files of its own
    assert _files(setup.results, setup.doc.parent) == before
    stored = json.loads((setup.scratch / "state" / "walks_cv_scenes1.json").read_text())
    assert stored["scenes"] == 1 and stored["key"]["max_scenes"] == 1
    report = (setup.scratch / "reproduce_scenes1.md").read_text()
    assert "use 1 evenly spread test scenes per dataset" in report
    assert "| not measured |" not in report  # its tables list the subset's datasets only
    assert (setup.scratch / "reproduce_scenes1.json").is_file()
    # the whole split's tables keep every cell, and the subset resumes from its own files
    out = reproduce.main(["--report", "--datasets", "walks", "bare", *SAMPLES], setup)
    assert out["cells"]["walks"]["pretrained"]["source"] == "evaluated"
    assert "| not measured |" not in setup.doc.read_text()
    calls = _counting(monkeypatch)
    reproduce.main(["--quick", "--datasets", "walks", *SAMPLES, "--max-scenes", "1"], setup)
    assert calls == []


def test_out_sends_the_scripts_own_files_elsewhere_and_leaves_the_repository_alone(
    setup, tmp_path, monkeypatch
):
    args = ["--quick", "--datasets", "walks", "bare", *SAMPLES]
    reproduce.main(args, setup)
    before = _files(setup.results, setup.doc.parent, setup.models)
    elsewhere = tmp_path / "elsewhere"
    calls = _counting(monkeypatch)
    reproduce.main([*args, "--out", str(elsewhere)], setup)
    assert len(calls) == 4  # a new folder starts from nothing
    assert _files(setup.results, setup.doc.parent, setup.models) == before
    assert (elsewhere / "reproduce.md").read_text().startswith("<!-- Generated")
    summary = json.loads((elsewhere / "reproduce.json").read_text())
    assert summary["cells"]["walks"]["pretrained"]["source"] == "evaluated"
    assert (elsewhere / "state" / "walks_pretrained.json").is_file()
    assert len(json.loads((elsewhere / "state" / "invocations.json").read_text())) == 1
    calls = _counting(monkeypatch)
    reproduce.main([*args, "--out", str(elsewhere)], setup)
    assert calls == []  # resumes from the folder
    # full mode: the training logs go there too (and the training: test_full_mode_with_out_*)
    logs = []
    monkeypatch.setattr(reproduce, "run_command", lambda cmd, log: logs.append(log) or 1)
    reproduce.main(["--datasets", "walks", *SAMPLES, "--out", str(elsewhere)], setup)
    assert len(logs) == 3 and all(log.parent == elsewhere / "logs" for log in logs)
    assert _files(setup.results, setup.doc.parent, setup.models) == before


def test_fresh_measures_again_and_the_report_says_how_to_reproduce(setup, monkeypatch):
    args = ["--quick", "--datasets", "walks", *SAMPLES]
    reproduce.main(args, setup)
    calls = _counting(monkeypatch)
    reproduce.main(args, setup)
    assert calls == []
    reproduce.main([*args, "--fresh"], setup)
    assert len(calls) == 3
    with pytest.raises(SystemExit):
        reproduce.parse_args(["--report", "--fresh"], setup)
    doc = setup.doc.read_text()
    section = doc[doc.index("## How to reproduce") : doc.index("## Table 1")]
    needles = ("--fresh", "--out", "Quick mode", "Full mode", "benchmarks/equal_budget.py",
               "benchmarks/pretrain.py", "about 3 h of fine-tuning", "about 177 min")  # fmt: skip
    for needle in needles:
        assert needle in section, needle
    assert "No quick run of all eight datasets from scratch is logged" in section
    # quick mode's cost is the newest logged run of every dataset that found nothing stored
    log = setup.state / "invocations.json"
    entries = json.loads(log.read_text())
    scratch = {**entries[0], "datasets": list(reproduce.DATASETS), "jobs_run": 24,
               "jobs_skipped": 0, "wall_seconds": 4182.1, "date": "2026-12-05"}  # fmt: skip
    log.write_text(json.dumps([*entries, scratch]))
    reproduce.main(["--report", *args[1:]], setup)
    assert "it took 70 min (4,182 s) on 2026-12-05" in setup.doc.read_text()
    assert "(minutes)" not in reproduce.__doc__


def test_the_note_on_groupnets_zara1_maxats_does_its_arithmetic():
    paper = json.loads((ROOT / "benchmarks" / "paper_tables.json").read_text())
    rows = paper["tables"]["table2"]["rows"]
    values = [rows[d]["GroupNet"][0] for d in paper["datasets"]]
    assert rows["zara1"]["GroupNet"][0] == 1.05
    (note,) = [n for n in paper["notes"] if "GroupNet" in n]
    total = sum(values)
    instead = total - 1.05 + 0.05
    assert f"sum to {total:.2f}" in note and f"sum to {instead:.2f}" in note
    assert f"the mean would be {instead / 7:.2f}" in note  # -0.06, not 0.06


def test_the_notes_name_the_departures_that_bear_on_the_rlhf_columns(setup):
    import re

    reproduce.main(["--quick", "--datasets", "bare", *SAMPLES], setup)
    doc = setup.doc.read_text()
    notes = doc[doc.index("## Notes") : doc.index("## Where each cell comes from")]
    for needle in ("`--preset paper`", "alpha_p = 1, alpha_v = 5", "0.3 / 1.5",
                   "4 minutes of its own CPU time", "100 epochs over 12 hours", "robo-sim",
                   "(`all`;", "not measured apart"):  # fmt: skip
        assert needle in notes, needle
    linked = re.findall(r'(docs/\w+\.md), "([^"]+)"', notes)
    assert len(linked) >= 6
    for name, section in linked:  # each names a section its document has
        headings = [x.lstrip("#").strip() for x in (ROOT / name).read_text().splitlines()
                    if x.startswith("#")]  # fmt: skip
        assert any(h.startswith(section) for h in headings), (name, section)


# Walkthrough 67, fixer F9: ``reproduce.py --out DIR`` in full mode left its training in the
# repository (finetune.py and pretrain.py wrote ``runs/``, ``benchmarks/results/`` and
# ``models/`` of the repository whatever the folder). Both scripts now take ``--runs``,
# ``--results`` and ``--models``, and reproduce.py passes them under ``--out``.


@pytest.fixture
def repo_setup(repo, walks, tmp_path):
    (tmp_path / "configs").mkdir()
    return reproduce.Setup(
        models=repo / "models", results=repo / "benchmarks" / "results",
        configs=tmp_path / "configs", doc=repo / "docs" / "reproduce.md",
        logs=repo / "runs" / "logs", sources={"walks": str(walks), "bare": str(walks)},
    )  # fmt: skip


def _option(cmd: list[str], name: str) -> str | None:
    return cmd[cmd.index(name) + 1] if name in cmd else None


def test_full_mode_with_out_trains_into_the_folder_and_reads_its_rows_from_there(
    repo_setup, repo, tmp_path, monkeypatch
):
    """HEAD passed no folders: the fine-tuning wrote runs/ and rows in the repository, and
    the tables read the repository's rows only."""
    out = tmp_path / "elsewhere"
    commands = []

    def fake_run(cmd, log):
        """Stand in for finetune.py: write its row where the command says."""
        commands.append(cmd)
        assert cmd[1].endswith("finetune.py")
        method, tag = _option(cmd, "--methods"), _option(cmd, "--tag")
        path = Path(_option(cmd, "--results")) / f"finetune_walks{'_' + tag if tag else ''}.json"
        rows = json.loads(path.read_text()) if path.is_file() else []
        row = make_row(dataset="walks", split="test", method=f"{method}-{tag}" if tag else method,
                       seed=0, samples=4, min_ade=0.4, min_fde=0.8, date="2026-12-07")  # fmt: skip
        write_rows(path, [*rows, row])
        return 0

    monkeypatch.setattr(reproduce, "run_command", fake_run)
    before = _files(repo)
    args = ["--datasets", "walks", "--samples", "4", "--out", str(out)]
    summary = reproduce.main(args, repo_setup)
    assert len(commands) == 3
    for cmd in commands:
        assert _option(cmd, "--runs") == str(out / "runs")
        assert _option(cmd, "--results") == str(out / "results")
        assert _option(cmd, "--models") == str(repo_setup.models)  # the start the tables evaluate
    assert _files(repo) == before
    cell = summary["cells"]["walks"]["rlhf"]
    assert cell["source"] == "rows" and cell["min_fde"] == 0.8
    assert str(out / "results" / "finetune_walks.json") in cell["detail"]
    commands.clear()
    assert reproduce.main(args, repo_setup)["jobs"]["run"] == [] and commands == []  # read back
    # without --out nothing changes: the rows of the repository, the commands of before
    opts = reproduce.parse_args(["--datasets", "walks"], repo_setup)
    cmd = reproduce.training_command(reproduce.Job("finetune", "walks", "rlhf"), opts, repo_setup)
    assert "--runs" not in cmd and "--results" not in cmd and "--models" not in cmd


def test_full_mode_with_out_pretrains_into_the_folder_and_evaluates_that_generator(
    repo_setup, tiny_run, tmp_path
):
    (repo_setup.configs / "bare.yaml").write_text("{}\n")
    out = tmp_path / "elsewhere"
    trained = reproduce.replace(repo_setup, out=out, trained=out)
    opts = reproduce.parse_args(["--datasets", "bare", "--out", str(out)], trained)
    job = reproduce.plan(opts, trained)[0]
    assert job.label == "pretrain bare pretrained"
    cmd = reproduce.training_command(job, opts, trained)
    assert cmd[1].endswith("pretrain.py") and cmd[cmd.index("--device") + 2:] == [
        "--runs", str(out / "runs"), "--results", str(out / "results"),
        "--models", str(out / "models")]  # fmt: skip
    # what the pretraining publishes there is the dataset's generator from then on
    gen = out / "models" / "bare" / "generator.safetensors"
    checkpoint.publish(tiny_run / "generator.safetensors", gen)
    assert reproduce.is_done(job, opts, trained, [])
    assert reproduce.generator_path(trained, "bare") == gen
    assert reproduce.denoiser_path(trained, "bare") == gen.parent / "denoiser.safetensors"
    tune = reproduce.Job("finetune", "bare", "rlhf")
    assert _option(reproduce.training_command(tune, opts, trained), "--models") == str(
        out / "models")  # fmt: skip
    assert not (repo_setup.models / "bare").exists()


def test_the_reports_row_sources_read_as_before_without_out(repo_setup):
    write_rows(repo_setup.results / "finetune_walks.json", [make_row(
        dataset="walks", split="test", method="rlhf", seed=0, samples=4, min_ade=0.4,
        min_fde=0.8, date="2026-12-07")])  # fmt: skip
    summary = reproduce.main(["--report", "--datasets", "walks", "--samples", "4"], repo_setup)
    assert "method `rlhf` in `benchmarks/results/finetune_walks.json`, mean over 1 seed (0)" in (
        summary["cells"]["walks"]["rlhf"]["detail"])  # fmt: skip


def test_a_row_of_the_out_folder_replaces_the_repositorys_of_the_same_measurement(
    repo_setup, tmp_path
):
    def row(method: str, min_fde: float) -> dict:
        return make_row(dataset="walks", split="test", method=method, seed=0, samples=4,
                        min_ade=0.4, min_fde=min_fde, date="2026-12-07")  # fmt: skip

    write_rows(repo_setup.results / "finetune_walks.json", [row("rlhf", 0.9), row("rlhf-res", 0.7)])
    out = tmp_path / "elsewhere"
    write_rows(out / "results" / "finetune_walks.json", [row("rlhf", 0.8)])
    assert [r["min_fde"] for r in reproduce.result_rows(repo_setup)] == [0.9, 0.7]  # no --out
    rows = reproduce.result_rows(reproduce.replace(repo_setup, trained=out))
    assert sorted((r["method"], r["min_fde"], r["_file"]) for r in rows) == [
        ("rlhf", 0.8, str(out / "results" / "finetune_walks.json")),
        ("rlhf-res", 0.7, "benchmarks/results/finetune_walks.json"),
    ]
