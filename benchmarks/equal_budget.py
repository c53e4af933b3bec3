"""The equal-budget table: every fine-tuning method from the same start for the same CPU time.

    python benchmarks/equal_budget.py --datasets zara1 eth robo --seeds 0 1 2 --minutes 4 \
        --workers 2 --data-root ../shared/data
    python benchmarks/equal_budget.py --datasets zara1 eth robo --report   # the table only

Each job (dataset, method, seed) is one ``benchmarks/finetune.py`` process on one thread,
starting from ``models/<dataset>/generator.safetensors``, that trains until ``--minutes`` of its
own CPU time are spent on training steps (``finetune.budget_clock=cpu``: validation and the test
evaluation are not counted, and other jobs sharing the machine do not eat into it), validates
after every ``--eval-minutes`` of that time (the same number of chosen-from checkpoints for every
method; until 2026-11-27 every 3 epochs), keeps the checkpoint chosen on validation and writes
its test row. Methods:

- ``control``: the supervised generator loss alone (no score), the equal-budget control;
- ``rlhf``, ``rlhf-res``: the paper's methods at the fine-tuning defaults;
- ``rlhf-set``: RLHF with the set-aware reward (``finetune.reward=set``);
- ``control-lr3e-5``: the control at a tenth of the fine-tuning learning rate (the default
  3e-4 makes the supervised loss drift away from the converged start);
- ``rlhf-res-smooth``: RLHF-ReS exploring in smooth directions (``finetune.explore=smooth``,
  a velocity and an acceleration offset per sample, RMS 0.1 per step).

``--start generator-long`` runs the same methods from a dataset's published longer generator
(``models/<D>/generator-long.safetensors``); their rows are named ``<method>-long`` and the table
gives them their own start row (``pretrained-long``) and control. Every job skips the start's
validation: measure it once per start first, ``python benchmarks/finetune.py --dataset D
--start-only [--start generator-long --tag long]``.

Jobs run seed-major (every dataset and method of seed 0 first), so that an interrupted table
is balanced; finished rows are skipped when it is run again, and an interrupted job resumes
from its ``finetune_last.pt``. The table (mean +- std over seeds, the change of minFDE20
against the start and against the control) is printed and written to
``benchmarks/results/meta/equal_budget.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from tqdm import tqdm

from trajpref.results import (
    RUNNABLE_STARTS,
    finetune_start,
    merge_rows,
    read_rows,
    row_key,
    start_record,
    start_suffix,
    table_lines,
    update_readme,
)
from trajpref.rl.presets import EQUAL_BUDGET_WARMUP, equal_budget_args
from trajpref.train import read_metrics

ROOT = Path(__file__).resolve().parent.parent
METHODS = {
    "control": ["--methods", "control"],
    "rlhf": ["--methods", "rlhf"],
    "rlhf-res": ["--methods", "rlhf-res"],
    "rlhf-set": ["--methods", "rlhf", "--tag", "set", "--set", "finetune.reward=set"],
    "rlhf-sda": ["--methods", "rlhf", "--tag", "sda", "--set", "finetune.reward=sda"],
    "control-lr3e-5": ["--methods", "control", "--tag", "lr3e-5", "--set", "finetune.lr=3e-5"],
    "rlhf-res-smooth": [
        "--methods",
        "rlhf-res",
        "--tag",
        "smooth",
        "--set",
        "finetune.explore=smooth",
        "--set",
        "finetune.explore_std=0.1",
    ],
}
"""Each table method and the finetune.py arguments that produce its rows."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["zara1", "eth", "robo"])
    parser.add_argument("--methods", nargs="+", default=["control", "rlhf", "rlhf-res", "rlhf-set"],
                        choices=list(METHODS))  # fmt: skip
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--minutes", type=float, default=4.0, help="CPU minutes of training")
    parser.add_argument(
        "--warmup",
        type=int,
        default=EQUAL_BUDGET_WARMUP,
        help="learning-rate warm-up steps, the same for every method (the default 20 would "
        "leave the RL methods, which fit ~16 steps in 4 CPU minutes, below the full rate)",
    )
    parser.add_argument(
        "--eval-minutes",
        type=float,
        default=1.0,
        help="validate after every this many CPU minutes of training (and at the end), the "
        "same for every method; before 2026-11-27 every 3 epochs, which gave a supervised "
        "control with cheap epochs many more checkpoints to choose from than the RL methods",
    )
    parser.add_argument("--workers", type=int, default=2, help="jobs at once (one thread each)")
    parser.add_argument(
        "--start",
        default="generator",
        choices=list(RUNNABLE_STARTS),
        help="the published generator every method starts from (models/<D>/<START>); another "
        "than the default names its rows <method>-<variant>, e.g. generator-long: control-long",
    )
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--report", action="store_true", help="only print the table")
    args = parser.parse_args()
    if not args.report:
        run_jobs(args)
    # the table always shows every method with rows, from every start: the control chosen on
    # validation is chosen among all controls of a start, whichever methods this invocation ran;
    # and every dataset the previous table showed, so that a run on one dataset keeps the others
    before = previous_table(table_path())
    shown = previous_datasets(before)
    table = report(shown + [d for d in args.datasets if d not in shown], list(METHODS), before)
    if len(table.splitlines()) == 2:  # the header alone
        table = "_No equal-budget rows from the current generators yet._"
    table_path().write_text(table + "\n")
    note = (
        "\n\n_Generated by `python benchmarks/equal_budget.py --report` "
        "from `benchmarks/results/` (every method with rows); mean ± std over the seeds "
        "listed; changes are of the mean minFDE20._"
    )
    update_readme(ROOT / "docs" / "rlhf.md", "equal-budget", table + note)
    print(table)


def _arg(method: str, flag: str) -> str:
    """The value of ``flag`` in a table method's finetune.py arguments ("" when absent)."""
    args = METHODS[method]
    return args[args.index(flag) + 1] if flag in args else ""


def variant(start: str) -> str:
    """A start's row suffix without its dash: "" for the default generator, "long" for
    generator-long (``results.RUNNABLE_STARTS``)."""
    return start_suffix(start).lstrip("-")


VARIANTS = {variant(start): start for start in RUNNABLE_STARTS}
"""Each start's variant ("" first, the default generator) -> the start."""


def _split(name: str) -> tuple[str, str]:
    """A table row's method name -> (its METHODS entry, its start's variant)."""
    for var in filter(None, VARIANTS):
        if name.endswith("-" + var) and name.removesuffix("-" + var) in METHODS:
            return name.removesuffix("-" + var), var
    return name, ""


def _tag(method: str, var: str) -> str:
    """The finetune.py --tag of a table method run from a start variant."""
    return "-".join(t for t in (_arg(method, "--tag"), var) if t)


def job_args(method: str, start: str) -> list[str]:
    """finetune.py's arguments for a table method run from ``start``."""
    args = list(METHODS[method])
    var = variant(start)
    if var:
        if "--tag" in args:
            args[args.index("--tag") + 1] = _tag(method, var)
        else:
            args += ["--tag", var]
        args += ["--start", start]
    return args


def _best_val(dataset: str, name: str, seed: int) -> float | None:
    """The run's best validation score (lower is better); None without its run folder."""
    method, var = _split(name)
    tag = _tag(method, var)
    run = ROOT / "runs" / f"{dataset}-{_arg(method, '--methods')}-s{seed}{'-' + tag if tag else ''}"
    log = read_metrics(run, "finetune")
    if not log:
        return None
    scores = [epoch.get("val_score") for epoch in log]
    return min((v for v in scores if v is not None), default=None)


def _beats_start(dataset: str, method: str, seed: int) -> bool | None:
    """Whether the run's best validation score beats the start's (the fine-tuning stage's
    own validation of the untouched start, meta/finetune_start_<D>[_<start>].json); None when
    the run folder or the start's record is missing (e.g. in a fresh checkout)."""
    start = ROOT / "benchmarks" / "results" / "meta"
    start = start / start_record(dataset, VARIANTS[_split(method)[1]])
    best = _best_val(dataset, method, seed)
    if best is None or not start.is_file():
        return None
    return best < json.loads(start.read_text())["val"]["score"]


def _chosen_control(dataset: str, rows: list[dict], methods: list[str]) -> str:
    """Of the control variants in the table, the one with the best mean validation score
    over the seeds whose run folders every control still has (a seed's folders can be lost
    with a checkout while later seeds are run in another); the start's plain supervised
    control (``control``, ``control-long``) when no seed has them all (a fresh checkout)."""
    controls = [m for m in methods if m.startswith("control")]
    vals = {m: {r["seed"]: _best_val(dataset, m, r["seed"]) for r in rows if r["method"] == m}
            for m in controls}  # fmt: skip
    vals = {m: v for m, v in vals.items() if v}  # controls with rows
    common = set.intersection(*(set(s for s, b in v.items() if b is not None)
                                for v in vals.values())) if vals else set()  # fmt: skip
    if common:
        scores = {m: statistics.mean(v[s] for s in common) for m, v in vals.items()}
        return min(scores, key=scores.get)
    return min(controls, key=len) if controls else "control"  # no -lr3e-5: the plain one


def row_name(method: str, start: str) -> str:
    """The method name of a table method's rows when run from ``start``."""
    return _suffixed(method, variant(start))


def _suffixed(method: str, var: str) -> str:
    """A method's row name from a start variant ("" keeps the plain name)."""
    return f"{method}-{var}" if var else method


def _done(dataset: str, method: str, seed: int, start: str) -> bool:
    tag = _tag(method, variant(start))
    name = f"finetune_{dataset}{'_' + tag if tag else ''}.json"
    path = ROOT / "benchmarks" / "results" / name
    rows = json.loads(path.read_text()) if path.is_file() else []
    return any((r["method"], r["seed"]) == (row_name(method, start), seed) for r in rows)


def run_jobs(args: argparse.Namespace) -> None:
    jobs = [(d, m, s) for s in args.seeds for d in args.datasets for m in args.methods]
    todo = [j for j in jobs if not _done(*j, args.start)]
    print(f"{len(jobs) - len(todo)} of {len(jobs)} rows already measured; {len(todo)} to run")
    logs = ROOT / "runs" / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    budget = equal_budget_args(args.minutes, args.warmup, args.eval_minutes)
    data = ["--data-root", args.data_root] if args.data_root else []

    def one(job: tuple[str, str, int]) -> tuple[tuple[str, str, int], int, float]:
        dataset, method, seed = job
        cmd = [sys.executable, str(ROOT / "benchmarks" / "finetune.py"), "--dataset", dataset,
               *job_args(method, args.start), "--seeds", str(seed), "--skip-done",
               "--no-start-validation",
               *budget, *data]  # fmt: skip
        t0 = time.perf_counter()
        name = row_name(method, args.start)
        with open(logs / f"equal_budget-{dataset}-{name}-s{seed}.log", "a") as log:
            code = subprocess.call(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
        return job, code, time.perf_counter() - t0

    failed = []
    with ThreadPoolExecutor(args.workers) as pool:
        bar = tqdm(pool.map(one, todo), total=len(todo), desc="equal-budget jobs", unit="job")
        for (dataset, method, seed), code, seconds in bar:
            status = "ok" if code == 0 else f"FAILED (exit {code})"
            tqdm.write(f"{dataset} {method} seed {seed}: {status} in {seconds / 60:.1f} min")
            if code != 0:
                failed.append((dataset, method, seed))
    if failed:
        sys.exit(f"{len(failed)} jobs failed (logs in runs/logs/): {failed}")


def _fmt(x: float | None) -> str:
    return "–" if x is None else f"{x:.3f}"


def _ms(xs: list[float]) -> str:
    if len(xs) < 2:
        return f"{xs[0]:.3f}" if xs else "–"
    return f"{statistics.mean(xs):.3f} ± {statistics.stdev(xs):.3f}"


def table_path() -> Path:
    """``meta/equal_budget.md``: the table this script writes, and reads back the next time."""
    return ROOT / "benchmarks" / "results" / "meta" / "equal_budget.md"


def previous_table(path: Path) -> dict[tuple[str, str], str]:
    """The lines of an earlier table (``meta/equal_budget.md``) by their first two cells."""
    return table_lines(path.read_text() if path.is_file() else "")


def previous_datasets(before: dict[tuple[str, str], str]) -> list[str]:
    """The datasets of an earlier table (``previous_table``'s lines), in its order."""
    return list(dict.fromkeys(dataset for dataset, _ in before))


def report(
    datasets: list[str], methods: list[str], before: dict[tuple[str, str], str] | None = None
) -> str:
    """Mean +- std over seeds of each method's test rows, against the start and the control.
    A start whose run folders are all absent here (a new checkout has no ``runs/``) keeps the
    previous table's lines when their minFDE20 cells are still today's: the validation that
    chose its control and counted the runs beating the start lives in those folders.
    ``before`` is that table's lines (read from ``table_path()`` when not given)."""
    before = previous_table(table_path()) if before is None else before
    rows = merge_rows(read_rows(ROOT / "benchmarks" / "results", protocol="all"))
    lines = [
        "| dataset | method | seeds | minADE20 | minFDE20 | minFDE20 vs start "
        "| vs the control chosen on val "
        "| joint minADE / minFDE | maxATS | train wall min | runs beating the start on val |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for dataset in datasets:
        pick = [r for r in rows if r["dataset"] == dataset and r["split"] == "test"]
        pick = [r for r in pick if r["samples"] == 20]
        for var in VARIANTS:  # each start with its own methods, start row and control
            names = [_suffixed(m, var) for m in methods]
            if not any(r["method"] in names for r in pick):
                continue
            start = next((r for r in pick if r["method"] == finetune_start(names[0])), None)
            group = _rows(dataset, pick, names, start)
            lines += _kept(group, before) if _no_runs_here(dataset, pick, names) else group
    return "\n".join(lines)


def _no_runs_here(dataset: str, pick: list[dict], names: list[str]) -> bool:
    return all(_best_val(dataset, r["method"], r["seed"]) is None
               for r in pick if r["method"] in names)  # fmt: skip


def _kept(group: list[str], before: dict[tuple[str, str], str]) -> list[str]:
    """``group``'s lines as the previous table had them, when it has every one of them with
    the same minFDE20 cell (the rows are the same runs'); otherwise ``group`` itself."""
    old = [before.get(row_key(line)) for line in group]
    same = all(o is not None and o.split("|")[5] == line.split("|")[5]
               for o, line in zip(old, group, strict=True))  # fmt: skip
    return old if same and group else group


def _rows(dataset: str, pick: list[dict], names: list[str], start: dict | None) -> list[str]:
    """One start's lines of the table: the start, then each method with rows."""
    lines = []
    chosen = _chosen_control(dataset, pick, names)
    control = [r["min_fde"] for r in pick if r["method"] == chosen]
    if start is not None:
        lines.append(
            f"| {dataset} | start ({start['method']}) | – | {_fmt(start['min_ade'])} "
            f"| {_fmt(start['min_fde'])} | – | – | {_fmt(start['joint_min_ade'])} / "
            f"{_fmt(start['joint_min_fde'])} | {_fmt(start['max_ats'])} | – | – |"
        )
    for method in names:
        own = sorted((r for r in pick if r["method"] == method), key=lambda r: r["seed"])
        if not own:
            continue
        fde = [r["min_fde"] for r in own]
        beats = [_beats_start(dataset, method, r["seed"]) for r in own]
        known = [b for b in beats if b is not None]
        beat = f"{sum(known)} of {len(known)}" if known else "–"
        vs_start = f"{100 * (statistics.mean(fde) / start['min_fde'] - 1):+.1f} %" if start else "–"
        vs_control = (
            f"{100 * (statistics.mean(fde) / statistics.mean(control) - 1):+.1f} %"
            if control and method != chosen
            else "–"
        )
        lines.append(
            f"| {dataset} | {method} | {','.join(str(r['seed']) for r in own)} "
            f"| {_ms([r['min_ade'] for r in own])} | {_ms(fde)} | {vs_start} | {vs_control} "
            f"| {_ms([r['joint_min_ade'] for r in own])} / "
            f"{_ms([r['joint_min_fde'] for r in own])} | {_ms([r['max_ats'] for r in own])} "
            f"| {statistics.mean(r['train_seconds'] for r in own) / 60:.1f} | {beat} |"
        )
    return lines


if __name__ == "__main__":
    main()
