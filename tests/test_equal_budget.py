"""benchmarks/equal_budget.py: runs from another published start get their own row names, run
folders, start row and control, and never mix with the default start's."""

import json
import re
import subprocess
from argparse import Namespace
from pathlib import Path

import pytest
from bench import load_benchmark

from trajpref.rl.presets import equal_budget_args

ROOT = Path(__file__).resolve().parent.parent
NOT_CHOSEN = "control not chosen on validation"


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
    # the default start's control is measured (under this budget); the long start's is not
    done = _row("control", 0, 0.44, command=_command(1.0, 4, 0.5))
    (results / "finetune_walks.json").write_text(json.dumps([done]))
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


def _row(method: str, seed: int, fde: float, command: str | None = None) -> dict:
    return {"dataset": "walks", "split": "test", "protocol": "all", "method": method,
            "seed": seed, "samples": 20, "min_ade": fde / 2, "min_fde": fde,
            "joint_min_ade": fde, "joint_min_fde": 2 * fde, "max_ats": 0.1, "max_fts": 0.1,
            "top1_recall_ats": None, "top5_recall_ats": None, "train_seconds": 240.0,
            "ms_per_scene": None, "checkpoint": None, "command": command,
            "date": "2026-11-25", "machine": "test", "uses_score": False}  # fmt: skip


def _command(minutes: float, warmup: int, eval_minutes: float | None) -> str:
    """finetune.py's command line as this script runs it (the ``command`` of its rows)."""
    budget = equal_budget_args(minutes, warmup, eval_minutes)
    return " ".join(["python", "benchmarks/finetune.py", "--dataset", "walks", "--methods",
                     "control", "--seeds", "0", "--skip-done", *budget])  # fmt: skip


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


def _validated(root: Path, folder: str, val: float) -> None:
    """A run folder whose fine-tuning validated once, at ``val``."""
    run = root / "runs" / folder
    run.mkdir(parents=True)
    (run / "finetune_metrics.jsonl").write_text(json.dumps({"val_score": val}) + "\n")


def test_each_start_is_compared_with_its_own_control(eb, tmp_path):
    """A longer start's rows are compared with the control chosen among that start's own
    controls, never with the default start's (the report did that until 2026-11-27)."""
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40), _row("pretrained-long", 0, 0.30),
            _row("control", 0, 0.50), _row("control-long", 0, 0.30),
            _row("control-lr3e-5-long", 0, 0.32), _row("rlhf-long", 0, 0.33)]  # fmt: skip
    (results / "rows.json").write_text(json.dumps(rows))
    _validated(tmp_path, "walks-control-s0-long", 0.40)
    _validated(tmp_path, "walks-control-s0-lr3e-5-long", 0.45)
    table = eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"])
    lines = {line.split(" | ")[1]: line.split(" | ") for line in table.splitlines()[2:]}
    # columns: dataset, method, seeds, ADE, FDE, vs start, vs the control chosen on val
    assert lines["control-long"][6] == "–"  # it is the control
    assert lines["rlhf-long"][6] == "+10.0 %"  # against control-long (0.30), not control (0.50)
    assert lines["control-lr3e-5-long"][6] == "+6.7 %"
    assert lines["control"][6] == "–"  # the default start's only control


def test_a_control_that_cannot_be_chosen_on_validation_is_named_so(eb, tmp_path):
    """With several controls and no seed validated by each of them, the report fell back to
    the plain control under the header "vs the control chosen on val" (walkthrough: a run
    folder of ``control`` alone turned RLHF's +0.3 % against the chosen control-lr3e-5 into
    -1.3 %). It now says that no control was chosen on validation."""
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40)] + [
        _row(m, s, f) for s in (0, 1)
        for m, f in (("control", 0.44), ("control-lr3e-5", 0.46), ("rlhf", 0.42))
    ]  # fmt: skip
    (results / "rows.json").write_text(json.dumps(rows))
    methods = ["control", "control-lr3e-5", "rlhf"]

    def vs_control() -> dict[str, str]:
        table = eb.report(["walks"], methods, {})
        return {line.split(" | ")[1]: line.split(" | ")[6] for line in table.splitlines()[3:]}

    assert set(vs_control().values()) == {NOT_CHOSEN}  # no run folder at all
    _validated(tmp_path, "walks-control-s0", 0.40)  # only the plain control's
    assert set(vs_control().values()) == {NOT_CHOSEN}
    _validated(tmp_path, "walks-control-s1-lr3e-5", 0.30)  # each has one, not the same seed
    assert set(vs_control().values()) == {NOT_CHOSEN}
    _validated(tmp_path, "walks-control-s0-lr3e-5", 0.35)  # seed 0 has both: 0.35 < 0.40
    assert vs_control() == {"control": "-4.3 %", "control-lr3e-5": "–", "rlhf": "-8.7 %"}


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
    counted = eb.report(["walks"], ["control"]).replace("0 | 4.0 | – |", "0 | 4.0 | 1 of 1 |")
    table.write_text(counted + "\n")
    kept = [line for line in table.read_text().splitlines() if line.startswith("| walks")]
    assert any(line.endswith("| 1 of 1 |") for line in kept)  # a cell only the table holds
    assert eb.previous_datasets(eb.previous_table(table)) == ["walks"]
    monkeypatch.setattr("sys.argv", ["equal_budget.py", "--datasets", "other", "--report"])
    eb.main()
    written = table.read_text().splitlines()
    assert [line for line in written if line.startswith("| walks")] == kept
    assert any(line.startswith("| other | control") for line in written)
    assert "| walks | control" in (tmp_path / "docs" / "rlhf.md").read_text()


PUBLISHED = ("--set finetune.max_minutes=4.0 --set finetune.budget_clock=cpu "
             "--set finetune.epochs=100000")  # fmt: skip
"""The budget arguments of the published rows' commands, before their validation interval."""


def _jobs(**kw) -> Namespace:
    args = dict(datasets=["walks"], methods=["control"], seeds=[0], minutes=4.0, warmup=4,
                eval_minutes=None, workers=1, data_root=None, start="generator")  # fmt: skip
    return Namespace(**{**args, **kw})


def _published_rows(results: Path) -> None:
    """walks' 4-minute table: control, control-lr3e-5 and rlhf-set over seeds 0-2."""
    results.mkdir(parents=True, exist_ok=True)
    (results / "pretrained_walks.json").write_text(json.dumps([_row("pretrained", 0, 0.40)]))
    for method, fde, tag in (("control", 0.44, ""), ("control-lr3e-5", 0.42, "_lr3e-5"),
                             ("rlhf-set", 0.43, "_set")):  # fmt: skip
        rows = [_row(method, s, fde, command=_command(4.0, 4, None)) for s in (0, 1, 2)]
        (results / f"finetune_walks{tag}.json").write_text(json.dumps(rows))


def test_a_row_is_done_only_under_the_budget_asked_for(eb, tmp_path, monkeypatch, capsys):
    """``--minutes 0.1`` found the 4-minute rows "already measured" (2 of 2, 0 to run) and
    printed the old table: the rows were keyed on method and seed alone (walkthrough). Rows of
    another budget are now refused before anything runs (finetune.py would skip them too)."""
    _published_rows(tmp_path / "benchmarks" / "results")
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    with pytest.raises(SystemExit, match=r"0\.1 CPU min.*\n.*4 CPU min.*control s0"):
        eb.run_jobs(_jobs(minutes=0.1, methods=["control", "rlhf-set"]))
    assert seen == []
    eb.run_jobs(_jobs(methods=["control", "rlhf-set"]))  # the published budget: done
    assert seen == [] and "2 of 2 rows already measured" in capsys.readouterr().out


def test_a_new_seed_of_another_budget_is_refused_not_averaged_in(eb, tmp_path, monkeypatch):
    """``--seeds 7 --minutes 0.05`` ran a 3-second control that the table then averaged into
    the 4-minute control's rows (walkthrough). It is refused, and so is a report of such rows."""
    results = tmp_path / "benchmarks" / "results"
    _published_rows(results)
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    with pytest.raises(SystemExit, match="one table compares one budget"):
        eb.run_jobs(_jobs(seeds=[7], minutes=0.05))
    assert seen == []
    rows = json.loads((results / "finetune_walks.json").read_text())
    rows.append(_row("control", 7, 0.50, command=_command(0.05, 4, None)))
    (results / "finetune_walks.json").write_text(json.dumps(rows))
    with pytest.raises(SystemExit, match=r"(?s)different budgets.*0\.05 CPU min[^\n]*control s7"):
        eb.report(["walks"], ["control", "control-lr3e-5", "rlhf-set"], {})
    # another start's rows are another table's
    rows[-1]["method"] = "control-long"
    (results / "finetune_walks.json").write_text(json.dumps(rows))
    assert "| walks | control-long | 7 |" in eb.report(["walks"], ["control"], {})


def test_a_run_folder_started_under_another_budget_is_refused(eb, tmp_path, monkeypatch):
    """finetune.py resumes a job's run folder, or takes a finished run as the job's: one
    started under another budget would give this budget's row another budget's model."""
    (tmp_path / "benchmarks" / "results").mkdir(parents=True)
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    run = tmp_path / "runs" / "walks-control-s0"
    run.mkdir(parents=True)
    (run / "finetune_config.yaml").write_text(
        "finetune:\n  max_minutes: 0.05\n  warmup_steps: 4\n  eval_every_minutes: 0.0125\n"
        "  eval_every: 5\n"
    )
    with pytest.raises(SystemExit, match="runs/walks-control-s0 was started under 0.05 CPU"):
        eb.run_jobs(_jobs())
    assert seen == []
    eb.run_jobs(_jobs(minutes=0.05))
    assert len(seen) == 1


def test_the_budget_of_a_row_is_read_from_its_command(eb):
    published = f"python benchmarks/finetune.py --dataset zara1 --methods control {PUBLISHED}"
    assert eb.row_budget({"command": published + " --set finetune.eval_every_minutes=1.0 "
                          "--set finetune.warmup_steps=4"}) == eb.PUBLISHED_BUDGET  # fmt: skip
    # the rows of before 2026-11-27 validated every 3 epochs
    old = eb.row_budget({"command": published + " --set finetune.eval_every=3 "
                         "--set finetune.warmup_steps=4"})  # fmt: skip
    assert old == eb.Budget(4.0, 4, None, 3) and old != eb.PUBLISHED_BUDGET
    assert str(old) == "4 CPU min, warm-up 4, validation every 3 epochs"
    # a row whose command names no budget (or has none) is taken as the published table's
    assert eb.row_budget({"command": None}) == eb.PUBLISHED_BUDGET
    assert eb.row_budget({"command": "python x.py --set finetune.lr=3e-5"}) == eb.PUBLISHED_BUDGET
    assert eb.requested_budget(4.0, 4, None) == eb.PUBLISHED_BUDGET  # 4 / 4 = every minute
    assert eb.requested_budget(2.0, 4, None) == eb.Budget(2.0, 4, 0.5)
    assert eb.row_budget({"command": _command(0.1, 4, None)}) == eb.requested_budget(0.1, 4, None)


def test_validation_defaults_to_a_quarter_of_the_budget_as_the_cli(eb, tmp_path, monkeypatch):
    """``trajpref finetune --equal-budget M`` validates every M / 4 minutes; the script
    validated every minute whatever ``--minutes`` was (walkthrough)."""
    (tmp_path / "benchmarks" / "results" / "meta").mkdir(parents=True)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "rlhf.md").write_text("<!-- equal-budget:start -->\n"
                                               "<!-- equal-budget:end -->\n")  # fmt: skip
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    monkeypatch.setattr("sys.argv", ["equal_budget.py", "--datasets", "walks", "--methods",
                                     "control", "--seeds", "0", "--minutes", "2"])  # fmt: skip
    eb.main()
    assert "finetune.eval_every_minutes=0.5" in seen[0]
    assert "finetune.max_minutes=2.0" in seen[0]


def _table(eb, tmp_path: Path, rows: list[dict]) -> list[str]:
    results = tmp_path / "benchmarks" / "results"
    (results / "meta").mkdir(parents=True, exist_ok=True)
    (results / "rows.json").write_text(json.dumps(rows))
    return eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"], {}).splitlines()


def _three_seeds() -> list[dict]:
    return [_row("pretrained", 0, 0.40)] + [
        _row(m, s, f) for s in (0, 1, 2)
        for m, f in (("control", 0.44), ("control-lr3e-5", 0.46), ("rlhf", 0.42))
    ]  # fmt: skip


def _counted(lines: list[str]) -> list[str]:
    """A table's lines as a machine with every run folder wrote them: the control chosen on
    validation (control-lr3e-5) and the runs that beat the start counted."""
    out = lines[:2]
    for line in lines[2:]:
        cells = line.split(" | ")
        if cells[1] in ("control", "rlhf"):
            cells[6] = "-4.3 %" if cells[1] == "control" else "-8.7 %"
        if not cells[1].startswith("start"):
            cells[-1] = "2 of 3 |"
        out.append(" | ".join(cells))
    return out


def test_a_few_run_folders_keep_the_lines_that_the_other_folders_gave(eb, tmp_path):
    """The previous lines were dropped as soon as one run folder of the start existed here,
    e.g. of a new seed: the control fell back and "runs beating the start" became "0 of 1"
    (walkthrough). They are now kept unless every row has its run folder."""
    lines = _table(eb, tmp_path, _three_seeds())
    before = _counted(lines)
    (tmp_path / "benchmarks" / "results" / "meta" / "equal_budget.md").write_text(
        "\n".join(before) + "\n")  # fmt: skip
    _validated(tmp_path, "walks-control-s0", 0.40)
    assert eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"]).splitlines() == before


def test_a_changed_cell_in_any_column_is_noticed(eb, tmp_path):
    """Only the minFDE20 cell was compared, so a stale start maxATS (zara1: 0.298 in the
    table, 0.304 in the rows and the README) and other cells survived regenerations. The
    start's line is now always today's, and a method line that changed in any column from
    the rows has its start's lines computed again."""
    rows = _three_seeds()
    lines = _table(eb, tmp_path, rows)
    before = _counted(lines)
    stale = before[2].replace("| 0.100 | – | – |", "| 0.098 | – | – |")
    assert stale != before[2]
    meta = tmp_path / "benchmarks" / "results" / "meta" / "equal_budget.md"
    meta.write_text("\n".join([*before[:2], stale, *before[3:]]) + "\n")
    assert eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"]).splitlines() == before
    for r in rows:  # rlhf's maxATS re-measured, its minFDE20 the same
        if r["method"] == "rlhf":
            r["max_ats"] = 0.2
    (tmp_path / "benchmarks" / "results" / "rows.json").write_text(json.dumps(rows))
    again = eb.report(["walks"], ["control", "control-lr3e-5", "rlhf"]).splitlines()
    assert again == _table(eb, tmp_path, rows)  # computed from the rows alone
    assert again[-1].split(" | ")[6] == NOT_CHOSEN and "| 0.200 ± 0.000 |" in again[-1]


def test_the_published_table_is_what_the_stored_rows_give():
    """docs/rlhf.md's equal-budget table and meta/equal_budget.md regenerate unchanged from
    benchmarks/results/ in a checkout without run folders (this repository's)."""
    eb = load_benchmark("equal_budget")
    eb._best_val = lambda *a: None  # a fresh checkout: no run folder
    path = eb.where_of().table  # the repository's meta/equal_budget.md, as main reads it
    before = eb.previous_table(path)
    table = eb.report(eb.previous_datasets(before), list(eb.METHODS), before)
    assert table + "\n" == path.read_text()
    assert f"<!-- equal-budget:start -->\n{table}\n" in (ROOT / "docs" / "rlhf.md").read_text()
    budgets = eb.table_budgets(eb.previous_datasets(before), list(eb.METHODS))
    assert {b for (_, start), b in budgets.items() if start == "generator"} == {
        eb.PUBLISHED_BUDGET}  # fmt: skip
    assert {b for (_, start), b in budgets.items() if start == "generator-long"} == {
        eb.Budget(4.0, 4, None, 3)}  # fmt: skip


# ---- review of walkthrough 66: the -long rows' budget (validation every 3 epochs) ----------


def _long_command(method: str, seed: int) -> str:
    """A published generator-long row's command: validation every 3 epochs."""
    return (f"python benchmarks/finetune.py --dataset walks --methods {method} --tag long "
            f"--start generator-long --seeds {seed} --skip-done --no-start-validation "
            f"{PUBLISHED} --set finetune.eval_every=3 --set finetune.warmup_steps=4")  # fmt: skip


def _main(eb, tmp_path, monkeypatch, *argv) -> list[list[str]]:
    """``equal_budget.py ARGV`` with finetune.py's processes recorded, not run."""
    (tmp_path / "benchmarks" / "results" / "meta").mkdir(parents=True, exist_ok=True)
    (tmp_path / "docs").mkdir(exist_ok=True)
    (tmp_path / "docs" / "rlhf.md").write_text("<!-- equal-budget:start -->\n"
                                               "<!-- equal-budget:end -->\n")  # fmt: skip
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    monkeypatch.setattr("sys.argv", ["equal_budget.py", *argv])
    eb.main()
    return seen


def test_the_long_starts_rows_are_extended_under_the_budget_they_have(eb, tmp_path, monkeypatch):
    """``--start generator-long --methods rlhf-sda`` was refused: the published -long rows
    validated every 3 epochs, and the script could only ask for validation every N CPU
    minutes. Given no budget, the jobs now take the budget of the start's stored rows."""
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    rows = [_row("control-long", s, 0.4, command=_long_command("control", s)) for s in (0, 1)]
    (results / "finetune_walks_long.json").write_text(json.dumps(rows))
    assert {eb.row_budget(r) for r in rows} == {eb.Budget(4.0, 4, None, 3)}
    seen = _main(eb, tmp_path, monkeypatch, "--start", "generator-long", "--datasets", "walks",
                 "--methods", "rlhf-sda", "--seeds", "0")  # fmt: skip
    assert len(seen) == 1
    cmd = seen[0]
    assert "finetune.eval_every=3" in cmd and not any("eval_every_minutes" in a for a in cmd)
    assert cmd[cmd.index("--tag") + 1] == "sda-long"
    # the command, as finetune.py stores it in the row, reads back as the same budget
    assert eb.row_budget({"command": " ".join(cmd)}) == eb.Budget(4.0, 4, None, 3)
    # named, the same budget runs too; another is refused as before
    seen = _main(eb, tmp_path, monkeypatch, "--start", "generator-long", "--datasets", "walks",
                 "--methods", "rlhf-sda", "--seeds", "0", "--eval-epochs", "3")  # fmt: skip
    assert len(seen) == 1 and "finetune.eval_every=3" in seen[0]
    with pytest.raises(SystemExit, match="one table compares one budget"):
        _main(eb, tmp_path, monkeypatch, "--start", "generator-long", "--datasets", "walks",
              "--methods", "rlhf-sda", "--seeds", "0", "--minutes", "4")  # fmt: skip


def test_eval_epochs_and_the_defaults_without_stored_rows(eb, tmp_path, monkeypatch):
    seen = _main(eb, tmp_path, monkeypatch, "--datasets", "walks", "--methods", "control",
                 "--seeds", "0", "--eval-epochs", "2", "--minutes", "1")  # fmt: skip
    assert eb.row_budget({"command": " ".join(seen[0])}) == eb.Budget(1.0, 4, None, 2)
    seen = _main(eb, tmp_path, monkeypatch, "--datasets", "walks", "--methods", "control",
                 "--seeds", "1")  # fmt: skip
    assert eb.row_budget({"command": " ".join(seen[0])}) == eb.PUBLISHED_BUDGET
    with pytest.raises(SystemExit):  # one interval or the other
        _main(eb, tmp_path, monkeypatch, "--datasets", "walks", "--eval-epochs", "2",
              "--eval-minutes", "1")  # fmt: skip


def test_stored_rows_of_several_budgets_need_the_budget_named(eb, tmp_path, monkeypatch):
    results = tmp_path / "benchmarks" / "results"
    _published_rows(results)
    rows = [_row("control-long", 0, 0.4, command=_long_command("control", 0))]
    (results / "finetune_walks_long.json").write_text(json.dumps(rows))
    assert eb.stored_budget(["walks"], "generator") == eb.PUBLISHED_BUDGET
    assert eb.stored_budget(["walks"], "generator-long") == eb.Budget(4.0, 4, None, 3)
    assert eb.stored_budget(["other"], "generator") is None
    rows.append(_row("rlhf-long", 0, 0.4, command=_command(4.0, 4, None)))
    (results / "finetune_walks_long.json").write_text(json.dumps(rows))
    with pytest.raises(SystemExit, match=r"(?s)several budgets.*every 3 epochs.*name the "):
        eb.stored_budget(["walks"], "generator-long")


# ---- --runs, --results and --models: a table measured out of the repository ----------------


def _repository(eb, tmp_path: Path, monkeypatch) -> Path:
    """A repository (the script's ROOT) with rows, a table, a start record, a run folder and
    docs/rlhf.md's block, none of which a run kept out of it may touch."""
    repo = tmp_path / "repo"
    monkeypatch.setattr(eb, "ROOT", repo)
    results = repo / "benchmarks" / "results"
    _published_rows(results)
    (results / "meta").mkdir()
    (results / "meta" / "finetune_start_walks.json").write_text(json.dumps({"val": {"score": 0.5}}))
    (results / "meta" / "equal_budget.md").write_text("the repository's table\n")
    _validated(repo, "walks-control-s0", 0.9)  # does not beat the repository's start
    (repo / "models" / "walks").mkdir(parents=True)
    (repo / "models" / "walks" / "generator.safetensors").write_bytes(b"the repository's")
    (repo / "docs").mkdir()
    (repo / "docs" / "rlhf.md").write_text("<!-- equal-budget:start -->\nthe published table\n"
                                           "<!-- equal-budget:end -->\n")  # fmt: skip
    return repo


def _snapshot(root: Path) -> dict[str, tuple[bytes | None, int]]:
    """Every file and folder under ``root``: its content (files) and modification time."""
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None,
                                       p.stat().st_mtime_ns)
            for p in sorted(root.rglob("*"))}  # fmt: skip


def _elsewhere(mine: Path) -> list[str]:
    return ["--runs", str(mine / "runs"), "--results", str(mine / "results"),
            "--models", str(mine / "models")]  # fmt: skip


def _finetune_py(seen: list[list[str]], fde: float):
    """subprocess.call as finetune.py: records the command, writes its row into the results
    folder it was given and a line into the log it was given."""

    def call(cmd: list[str], **kw) -> int:
        seen.append(cmd)
        results = Path(cmd[cmd.index("--results") + 1])
        seed = int(cmd[cmd.index("--seeds") + 1])
        row = _row(cmd[cmd.index("--methods") + 1], seed, fde, command=" ".join(cmd[1:]))
        results.mkdir(parents=True, exist_ok=True)
        (results / "finetune_walks.json").write_text(json.dumps([row]))
        print("finetune.py ran", file=kw["stdout"])
        return 0

    return call


def test_a_run_elsewhere_writes_there_and_leaves_the_repository_as_it_is(
    eb, tmp_path, monkeypatch, capsys
):
    """equal_budget.py had no --runs, --results and --models: its jobs, logs, rows, table and
    docs/rlhf.md were the repository's, and its docstring advised measuring another budget in
    a copy of the repository. Given the three, every job's finetune.py gets them, and the
    repository is left as it is (another budget than its rows' is no longer refused)."""
    repo = _repository(eb, tmp_path, monkeypatch)
    mine = tmp_path / "mine"
    (mine / "models" / "walks").mkdir(parents=True)
    (mine / "models" / "walks" / "generator.safetensors").write_bytes(b"mine")
    before = _snapshot(repo)
    seen = []
    monkeypatch.setattr(subprocess, "call", _finetune_py(seen, 0.5))
    monkeypatch.chdir(tmp_path)  # relative folders are given to the jobs as absolute ones
    monkeypatch.setattr("sys.argv", ["equal_budget.py", "--datasets", "walks", "--methods",
                                     "control", "--seeds", "0", "--minutes", "1", "--runs",
                                     "mine/runs", "--results", "mine/results", "--models",
                                     "mine/models"])  # fmt: skip
    eb.main()
    assert len(seen) == 1
    cmd = seen[0]
    for option, folder in (("--runs", "runs"), ("--results", "results"), ("--models", "models")):
        assert cmd[cmd.index(option) + 1] == str(mine / folder)
    assert "finetune.max_minutes=1.0" in cmd  # not refused for the repository's 4-minute rows
    log = mine / "runs" / "logs" / "equal_budget-walks-control-s0.log"
    assert log.read_text() == "finetune.py ran\n"
    table = (mine / "results" / "meta" / "equal_budget.md").read_text()
    assert "| walks | control | 0 | 0.250 | 0.500 |" in table
    out = capsys.readouterr().out
    assert table in out + "\n"  # printed, not put in docs/rlhf.md
    assert f"written to {mine / 'results' / 'meta' / 'equal_budget.md'}" in out
    assert _snapshot(repo) == before


def test_some_of_runs_results_and_models_are_refused(eb, tmp_path, monkeypatch, capsys):
    """The ones left out would be the repository's: all three or none (exit 2, before any job)."""
    repo = _repository(eb, tmp_path, monkeypatch)
    before = _snapshot(repo)
    seen = []
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: seen.append(cmd) or 0)
    given = _elsewhere(tmp_path / "mine")
    for keep in ((0,), (2,), (4,), (0, 2), (0, 4), (2, 4)):
        argv = [a for i in keep for a in given[i : i + 2]]
        for report in ([], ["--report"]):
            monkeypatch.setattr("sys.argv", ["equal_budget.py", "--datasets", "walks",
                                             "--methods", "control", *report, *argv])  # fmt: skip
            with pytest.raises(SystemExit) as exit:
                eb.main()
            assert exit.value.code == 2
            err = capsys.readouterr().err
            assert "--runs, --results and --models go together" in err
            missing = [given[i] for i in (0, 2, 4) if i not in keep]
            assert " and ".join(missing) + " missing" in err
    assert seen == [] and _snapshot(repo) == before
    assert not (tmp_path / "mine").exists()


def test_report_elsewhere_reads_the_rows_run_folders_and_start_records_there(
    eb, tmp_path, monkeypatch, capsys
):
    """``--report`` with the three: the table of the rows, run folders and start records there
    (the repository's rows, run folders and start record say otherwise), written there."""
    repo = _repository(eb, tmp_path, monkeypatch)
    mine = tmp_path / "mine"
    results = mine / "results"
    (results / "meta").mkdir(parents=True)
    rows = [_row("pretrained", 0, 0.40), _row("control", 0, 0.50, command=_command(1.0, 4, None))]
    (results / "finetune_walks.json").write_text(json.dumps(rows))
    (results / "meta" / "finetune_start_walks.json").write_text(json.dumps({"val": {"score": 0.5}}))
    _validated(mine, "walks-control-s0", 0.4)  # beats its start (the repository's run: 0.9)
    before = _snapshot(repo)
    monkeypatch.setattr("sys.argv", ["equal_budget.py", "--datasets", "walks", "--report",
                                     *_elsewhere(mine)])  # fmt: skip
    eb.main()
    out = capsys.readouterr().out
    lines = {line.split(" | ")[1]: line for line in out.splitlines() if line.startswith("| walks")}
    assert set(lines) == {"start (pretrained)", "control"}  # not the repository's other methods
    assert "| 0.500 | +25.0 % |" in lines["control"]  # its rows, not the repository's 0.44
    assert lines["control"].endswith("| 1 of 1 |")  # its run folder and start record
    assert "walks from generator: 1 CPU min, warm-up 4, validation every 0.25 CPU min" in out
    assert lines["control"] in (results / "meta" / "equal_budget.md").read_text()
    assert _snapshot(repo) == before
    # a results folder that is not there has no rows to report
    monkeypatch.setattr("sys.argv", ["equal_budget.py", "--report", *_elsewhere(tmp_path / "no")])
    with pytest.raises(SystemExit) as exit:
        eb.main()
    assert exit.value.code == 2 and "no such folder" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()


def test_a_run_elsewhere_needs_its_start_in_its_models_folder(eb, tmp_path, monkeypatch):
    """The jobs start from <models>/<D>/<START>.safetensors: missing there (the repository's
    does not count), nothing runs; a run folder there of another budget is named by its path."""
    repo = _repository(eb, tmp_path, monkeypatch)
    mine = tmp_path / "mine"
    before = _snapshot(repo)
    seen = []
    monkeypatch.setattr(subprocess, "call", _finetune_py(seen, 0.5))
    args = _jobs(minutes=1.0, runs=mine / "runs", results=mine / "results", models=mine / "models")
    with pytest.raises(SystemExit, match=r"no published generator in --models .*mine/models: "
                       r".*mine/models/walks/generator\.safetensors"):  # fmt: skip
        eb.run_jobs(args)
    assert seen == [] and not (mine / "runs").exists()
    (mine / "models" / "walks").mkdir(parents=True)
    (mine / "models" / "walks" / "generator.safetensors").write_bytes(b"mine")
    eb.run_jobs(args)
    assert len(seen) == 1 and "--models" in seen[0]
    (mine / "runs" / "walks-control-s0").mkdir()
    (mine / "runs" / "walks-control-s0" / "finetune_config.yaml").write_text(
        "finetune:\n  max_minutes: 0.05\n  warmup_steps: 4\n  eval_every_minutes: 0.0125\n"
    )
    folder = re.escape(str(mine / "runs" / "walks-control-s0"))
    with pytest.raises(SystemExit, match=f"{folder} was started under 0.05 CPU min"):
        eb.run_jobs(Namespace(**{**vars(args), "minutes": 2.0}))
    assert _snapshot(repo) == before
