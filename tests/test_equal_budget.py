"""benchmarks/equal_budget.py: runs from another published start get their own row names, run
folders, start row and control, and never mix with the default start's."""

import json
import subprocess
from argparse import Namespace
from pathlib import Path

import pytest
from bench import load_benchmark

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def eb(tmp_path, monkeypatch):
    module = load_benchmark("equal_budget")
    monkeypatch.setattr(module, "ROOT", tmp_path)
    return module


def test_a_longer_start_renames_every_method_and_keeps_each_methods_own_tag(eb):
    assert eb.job_args("control", "generator") == ["--methods", "control"]
    assert eb.job_args("control", "generator-long") == [
        "--methods", "control", "--tag", "long", "--start", "generator-long"]  # fmt: skip
    args = eb.job_args("rlhf-set", "generator-long")
    assert args[args.index("--tag") + 1] == "set-long" and "finetune.reward=set" in args
    assert eb.row_name("control-lr3e-5", "generator-long") == "control-lr3e-5-long"
    assert eb._split("control-lr3e-5-long") == ("control-lr3e-5", "long")
    assert eb._split("rlhf-res") == ("rlhf-res", "")
    assert eb.VARIANTS == {"": "generator", "long": "generator-long"}


def test_the_start_check_reads_the_validation_record_finetune_py_writes(eb, tmp_path):
    ft = load_benchmark("finetune")
    for start in ("generator", "generator-long"):
        record = ft.start_meta("walks", start)
        assert (
            record.name == f"finetune_start_walks{'' if start == 'generator' else '_' + start}.json"
        )
        # finetune.py keeps it where equal_budget.py looks (both under their ROOT)
        mine = tmp_path / record.relative_to(ft.ROOT)
        mine.parent.mkdir(parents=True, exist_ok=True)
        mine.write_text(json.dumps({"val": {"score": 0.5}}))
        tag = "" if start == "generator" else "-long"
        run = tmp_path / "runs" / f"walks-control-s0{tag}"
        run.mkdir(parents=True)
        (run / "finetune_metrics.jsonl").write_text(json.dumps({"val_score": 0.4}) + "\n")
        assert eb._beats_start("walks", "control" + tag, 0) is True
        mine.write_text(json.dumps({"val": {"score": 0.3}}))
        assert eb._beats_start("walks", "control" + tag, 0) is False


def test_run_jobs_skips_only_the_rows_of_the_same_start(eb, tmp_path, monkeypatch):
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    # the default start's control is measured; the long start's is not
    (results / "finetune_walks.json").write_text(json.dumps([{"method": "control", "seed": 0}]))
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    ns = Namespace(datasets=["walks"], methods=["control"], seeds=[0], minutes=1.0, warmup=4,
                   eval_minutes=0.5, workers=1, data_root=None, start="generator")  # fmt: skip
    eb.run_jobs(ns)
    assert seen == []
    eb.run_jobs(Namespace(**{**vars(ns), "start": "generator-long"}))
    assert len(seen) == 1
    cmd = seen[0]
    assert cmd[cmd.index("--start") + 1] == "generator-long"
    assert cmd[cmd.index("--tag") + 1] == "long"
    assert "finetune.eval_every_minutes=0.5" in cmd  # every method validates by CPU time


def _row(method: str, seed: int, fde: float) -> dict:
    return {"dataset": "walks", "split": "test", "protocol": "all", "method": method,
            "seed": seed, "samples": 20, "min_ade": fde / 2, "min_fde": fde,
            "joint_min_ade": fde, "joint_min_fde": 2 * fde, "max_ats": 0.1, "max_fts": 0.1,
            "top1_recall_ats": None, "top5_recall_ats": None, "train_seconds": 240.0,
            "ms_per_scene": None, "checkpoint": None, "command": None, "date": "2026-11-25",
            "machine": "test", "uses_score": False}  # fmt: skip


def test_each_start_is_compared_with_its_own_start_row(eb, tmp_path):
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40), _row("pretrained-long", 0, 0.30),
            _row("control", 0, 0.44), _row("control-long", 0, 0.33)]  # fmt: skip
    (results / "rows.json").write_text(json.dumps(rows))
    table = eb.report(["walks"], ["control"])
    lines = {line.split(" | ")[1]: line for line in table.splitlines()[2:]}
    assert set(lines) == {"start (pretrained)", "control", "start (pretrained-long)",
                          "control-long"}  # fmt: skip
    assert "+10.0 %" in lines["control"] and "+10.0 %" in lines["control-long"]


def test_each_start_is_compared_with_its_own_control_when_no_run_folder_is_left(eb, tmp_path):
    """Without run folders (a fresh checkout) the control cannot be chosen on validation;
    a longer start's rows are then compared with that start's own plain control, never with
    the default start's (the report did that until 2026-11-27)."""
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40), _row("pretrained-long", 0, 0.30),
            _row("control", 0, 0.50), _row("control-long", 0, 0.30),
            _row("control-lr3e-5-long", 0, 0.32), _row("rlhf-long", 0, 0.33)]  # fmt: skip
    (results / "rows.json").write_text(json.dumps(rows))
    table = eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"])
    lines = {line.split(" | ")[1]: line.split(" | ") for line in table.splitlines()[2:]}
    # columns: dataset, method, seeds, ADE, FDE, vs start, vs the control chosen on val
    assert lines["control-long"][6] == "–"  # it is the control
    assert lines["rlhf-long"][6] == "+10.0 %"  # against control-long (0.30), not control (0.50)
    assert lines["control-lr3e-5-long"][6] == "+6.7 %"


def test_the_control_is_chosen_on_the_seeds_whose_run_folders_are_left(eb, tmp_path):
    """eth's seed 0 was run in a checkout whose run folders were lost, its seeds 1 and 2 in
    the next (2026-12-03): the control is then chosen on seeds 1 and 2, where the lower
    learning rate validates better, instead of falling back to the plain control."""
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40)] + [
        _row(m, s, f) for s in (0, 1, 2)
        for m, f in (("control", 0.44), ("control-lr3e-5", 0.46), ("rlhf", 0.42))
    ]  # fmt: skip
    (results / "rows.json").write_text(json.dumps(rows))
    for seed in (1, 2):
        for folder, val in ((f"walks-control-s{seed}", 0.50), (f"walks-control-s{seed}-lr3e-5",
                                                               0.45)):  # fmt: skip
            run = tmp_path / "runs" / folder
            run.mkdir(parents=True)
            (run / "finetune_metrics.jsonl").write_text(json.dumps({"val_score": val}) + "\n")
    lines = {line.split(" | ")[1]: line.split(" | ")
             for line in eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"])
             .splitlines()[2:]}  # fmt: skip
    assert lines["control-lr3e-5"][6] == "–"  # chosen: 0.45 < 0.50 on seeds 1 and 2
    assert lines["rlhf"][6] == "-8.7 %"  # 0.42 against the chosen control's 0.46
    assert lines["control"][6] == "-4.3 %"


def test_without_run_folders_the_previous_tables_lines_stay_while_their_rows_do(eb, tmp_path):
    """A new checkout has no run folders, so it cannot choose the control on validation or
    count the runs that beat the start; regenerating the table dropped those cells (and could
    change which control the others are compared with) until 2026-11-29. The previous table's
    lines now stay, unless the rows changed (another minFDE20 cell)."""
    results = tmp_path / "benchmarks" / "results"
    (results / "meta").mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40), _row("control", 0, 0.44), _row("rlhf", 0, 0.42)]
    (results / "rows.json").write_text(json.dumps(rows))
    fresh = eb.report(["walks"], ["control", "rlhf"]).splitlines()
    assert fresh[3].split(" | ")[-1] == "– |"  # no folder: no count of runs beating the start
    # the same table from the machine that had the run folders: its last cells are counted
    chosen_elsewhere = fresh[:3] + [line[: line.rindex("– |")] + "1 of 1 |" for line in fresh[3:]]
    (results / "meta" / "equal_budget.md").write_text("\n".join(chosen_elsewhere) + "\n")
    assert eb.report(["walks"], ["control", "rlhf"]).splitlines() == chosen_elsewhere
    rows[2]["min_fde"] = 0.41  # rlhf's rows changed: its group is computed again
    (results / "rows.json").write_text(json.dumps(rows))
    assert eb.report(["walks"], ["control", "rlhf"]).splitlines()[4].endswith("| – |")


def test_a_run_on_one_dataset_keeps_the_other_datasets_of_the_table(eb, tmp_path, monkeypatch):
    """``equal_budget.py --datasets robo`` used to write a table of robo alone, so the next
    ``--report`` of every dataset had no previous lines to keep for the others (2026-11-29,
    thirty-eighth session). The table now shows every dataset the previous one showed."""
    results = tmp_path / "benchmarks" / "results"
    (results / "meta").mkdir(parents=True)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "rlhf.md").write_text("<!-- equal-budget:start -->\n"
                                               "<!-- equal-budget:end -->\n")  # fmt: skip
    rows = [_row("pretrained", 0, 0.40), _row("control", 0, 0.44)]
    rows += [dict(r, dataset="other") for r in rows]
    (results / "rows.json").write_text(json.dumps(rows))
    table = results / "meta" / "equal_budget.md"
    table.write_text(eb.report(["walks"], ["control"]).replace("| – |\n", "| 1 of 1 |\n") + "\n")
    kept = [line for line in table.read_text().splitlines() if line.startswith("| walks")]
    assert any(line.endswith("| 1 of 1 |") for line in kept)  # a cell only the table holds
    assert eb.previous_datasets(eb.previous_table(table)) == ["walks"]
    monkeypatch.setattr("sys.argv", ["equal_budget.py", "--datasets", "other", "--report"])
    eb.main()
    written = table.read_text().splitlines()
    assert [line for line in written if line.startswith("| walks")] == kept
    assert any(line.startswith("| other | control") for line in written)
    assert "| walks | control" in (tmp_path / "docs" / "rlhf.md").read_text()
