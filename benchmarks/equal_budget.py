"""The equal-budget table: every fine-tuning method from the same start for the same CPU time.

    python benchmarks/equal_budget.py --datasets zara1 eth robo --seeds 0 1 2 --minutes 4 \
        --workers 2 --data-root ../shared/data
    python benchmarks/equal_budget.py --datasets zara1 eth robo --report   # the table only

Each job (dataset, method, seed) is one ``benchmarks/finetune.py`` process on one thread,
starting from ``models/<dataset>/generator.safetensors``, that trains until ``--minutes`` of its
own CPU time are spent on training steps (``finetune.budget_clock=cpu``: validation and the test
evaluation are not counted, and other jobs sharing the machine do not eat into it), validates
after every ``--eval-minutes`` of that time (default ``--minutes`` / 4, as ``trajpref finetune
--equal-budget``: the published 4-minute rows validated every minute; until 2026-11-27 every 3
epochs, which ``--eval-epochs 3`` asks for again), keeps the checkpoint chosen on validation and
writes its test row. Without any of ``--minutes``, ``--warmup``, ``--eval-minutes`` and
``--eval-epochs`` a start's jobs take the budget its stored rows have (``stored_budget``: the
published ``-long`` rows' 4 CPU min, warm-up 4, validation every 3 epochs, so that ``--start
generator-long --methods rlhf-sda`` extends that table), else 4 CPU minutes, warm-up 4,
validation every minute. Validation happens only at the end of an epoch (the first epoch after
which the interval has passed, and after the last): a method whose epochs are longer than the
interval validates once per epoch, so fewer times. Methods:

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
is balanced; rows finished under the same budget are skipped when it is run again, and an
interrupted job resumes from its ``finetune_last.pt``. A row's budget (minutes, warm-up,
validation interval) is read from its ``command``, which holds finetune.py's ``--set`` budget
arguments (``row_budget``; a row whose command names none has the published budget,
``PUBLISHED_BUDGET``). One table compares one budget per start: jobs whose dataset and start
already have rows (or run folders) of another budget are refused before anything runs, and so
is a report of such rows (to measure another budget, measure it in folders of its own, below).
The table (mean +- std over seeds, the change of minFDE20 against the start and against the
control) is printed, each start's budget after it, written to
``benchmarks/results/meta/equal_budget.md`` and put in ``docs/rlhf.md``'s generated block.

``--runs DIR --results DIR --models DIR`` (all three or none, as finetune.py's:
``benchmarks/paths.py``) measure out of the repository, leaving it as it is::

    python benchmarks/equal_budget.py --datasets zara1 --seeds 0 --minutes 1 \
        --runs ~/eb/runs --results ~/eb/results --models ~/eb/models --data-root ../shared/data

Every job's finetune.py is given the same three options: the run folders and their logs
(``<runs>/logs/``) are there, the rows and their ``meta/`` (the start records
``meta/finetune_start_*.json``, the table ``meta/equal_budget.md``) are read and written in
``<results>``, and the jobs start from ``<models>/<D>/<START>.safetensors`` (refused before
anything runs when it is missing: copy or link the published ones). The table is printed and
written to ``<results>/meta/equal_budget.md``; ``docs/rlhf.md`` is not touched. The start rows
(``pretrained``, ``pretrained-long``) and the start records are read from ``<results>`` too: for
the columns against the start, copy the repository's ``pretrained_<D>[_long].json`` there and
validate the start there first (finetune.py ``--start-only`` with the same three options).
``--report`` with the three options reports that folder's rows.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import yaml
from paths import ELSEWHERE, add_elsewhere_options, require_all_or_none, shown
from tqdm import tqdm

from trajpref.models.checkpoint import SUFFIX
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
from trajpref.rl.presets import (
    EQUAL_BUDGET_WARMUP,
    equal_budget_args,
    equal_budget_overrides,
)
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


@dataclass(frozen=True)
class Where:
    """The folders a table is measured in: the run folders (with the jobs' ``logs/``), the rows
    (with their ``meta/``: the start records and the table) and the published models the jobs
    start from. ``in_repo``: the repository's own (no ``--runs``, ``--results`` and
    ``--models``), the only case in which ``docs/rlhf.md`` is updated."""

    runs: Path
    results: Path
    models: Path
    in_repo: bool = True

    @property
    def logs(self) -> Path:
        """The jobs' logs, one file per job."""
        return self.runs / "logs"

    @property
    def table(self) -> Path:
        """``meta/equal_budget.md``: the table this script writes, and reads back next time."""
        return self.results / "meta" / "equal_budget.md"

    def options(self) -> list[str]:
        """finetune.py's arguments that send a job here ([] for the repository's folders)."""
        if self.in_repo:
            return []
        return ["--runs", str(self.runs), "--results", str(self.results),
                "--models", str(self.models)]  # fmt: skip

    def start(self, dataset: str, start: str) -> Path:
        """The published model a job of ``dataset`` starts from (finetune.py's ``--start``)."""
        return self.models / dataset / f"{start}{SUFFIX}"


def where_of(args: argparse.Namespace | None = None) -> Where:
    """The folders that ``args``' ``--runs``, ``--results`` and ``--models`` name (made
    absolute, as finetune.py does: its jobs run from the same working folder); the repository's
    (under ``ROOT`` as it is now) when they name none, or without ``args``. Some but not all
    are refused earlier (``paths.require_all_or_none``)."""
    runs, results, models = (getattr(args, name, None) for name in ELSEWHERE)
    if runs is None and results is None and models is None:
        return Where(ROOT / "runs", ROOT / "benchmarks" / "results", ROOT / "models")
    if runs is None or results is None or models is None:
        raise ValueError("--runs, --results and --models go together: all or none")
    return Where(Path(runs).absolute(), Path(results).absolute(), Path(models).absolute(),
                 in_repo=False)  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["zara1", "eth", "robo"])
    parser.add_argument("--methods", nargs="+", default=["control", "rlhf", "rlhf-res", "rlhf-set"],
                        choices=list(METHODS))  # fmt: skip
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--minutes", type=float, default=None,
                        help=f"CPU minutes of training (default {DEFAULT_MINUTES:g}, or the "
                        "budget of the start's stored rows: see --eval-epochs)")  # fmt: skip
    parser.add_argument(
        "--warmup",
        type=int,
        default=None,
        help="learning-rate warm-up steps, the same for every method (default "
        f"{EQUAL_BUDGET_WARMUP}: the fine-tuning default 20 would leave the RL methods, which "
        "fit ~16 steps in 4 CPU minutes, below the full rate)",
    )
    every = parser.add_mutually_exclusive_group()
    every.add_argument(
        "--eval-minutes",
        type=float,
        default=None,
        help="validate at the end of the first epoch after every this many CPU minutes of "
        "training (and after the last), the same for every method (default: --minutes / 4, "
        "as trajpref finetune --equal-budget; 1.0 for the published 4-minute rows); before "
        "2026-11-27 every 3 epochs, which gave a supervised control with cheap epochs many "
        "more checkpoints to choose from than the RL methods",
    )
    every.add_argument(
        "--eval-epochs",
        type=int,
        default=None,
        help="validate every this many epochs instead (finetune.eval_every; no "
        "eval_every_minutes), as the published generator-long rows did (3). Given none of "
        "--minutes, --warmup, --eval-minutes and --eval-epochs, the jobs take the budget the "
        "start's stored rows of these datasets have",
    )
    parser.add_argument("--workers", type=int, default=2, help="jobs at once (one thread each)")
    parser.add_argument(
        "--start",
        default="generator",
        choices=list(RUNNABLE_STARTS),
        help="the published generator every method starts from (models/<D>/<START>, or under "
        "--models); another than the default names its rows <method>-<variant>, e.g. "
        "generator-long: control-long",
    )
    parser.add_argument("--data-root", default=None)
    add_elsewhere_options(
        parser,
        runs="the folder of the jobs' run folders and of their logs/ (default: the repository's "
        "runs/); given to every job's finetune.py",
        results="where the rows and meta/ (the start records, the table equal_budget.md) are "
        "read and written (default: the repository's benchmarks/results/); given to every "
        "job's finetune.py",
        models="the published models the jobs start from, DIR/<dataset>/<START>.safetensors "
        "(default: the repository's models/); given to every job's finetune.py. With the three, "
        "docs/rlhf.md is left as it is",
    )
    parser.add_argument("--report", action="store_true", help="only print the table")
    args = parser.parse_args()
    require_all_or_none(parser, args)
    where = where_of(args)
    if args.report and not where.in_repo and not where.results.is_dir():
        parser.error(f"--results {args.results}: no such folder, no rows to report")
    if not args.report:
        run_jobs(args, where)
    # the table always shows every method with rows, from every start: the control chosen on
    # validation is chosen among all controls of a start, whichever methods this invocation ran;
    # and every dataset the previous table showed, so that a run on one dataset keeps the others
    before = previous_table(where.table)
    datasets = previous_datasets(before)
    datasets += [d for d in args.datasets if d not in datasets]
    table = report(datasets, list(METHODS), before, where)
    if len(table.splitlines()) == 2:  # the header alone
        table = "_No equal-budget rows from the current generators yet._"
    where.table.parent.mkdir(parents=True, exist_ok=True)
    where.table.write_text(table + "\n")
    budgets = table_budgets(datasets, list(METHODS), where)
    if where.in_repo:
        note = (
            "\n\n_Generated by `python benchmarks/equal_budget.py --report` "
            "from `benchmarks/results/` (every method with rows); mean ± std over the seeds "
            "listed; changes are of the mean minFDE20._"
        )
        update_readme(ROOT / "docs" / "rlhf.md", "equal-budget", table + note)
    print(table)
    for (dataset, start), budget in budgets.items():
        print(f"{dataset} from {start}: {budget}")
    if not where.in_repo:
        print(f"written to {where.table} (docs/rlhf.md, the repository's table, is left as it is)")


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


@dataclass(frozen=True)
class Budget:
    """What an equal-budget run was given: CPU minutes of training steps, warm-up steps, and
    validation every ``eval_minutes`` CPU minutes or (the protocol before 2026-11-27) every
    ``eval_epochs`` epochs. None: not named where it was read (the config's own default)."""

    minutes: float | None
    warmup: int | None
    eval_minutes: float | None = None
    eval_epochs: int | None = None

    def __str__(self) -> str:
        def num(x: float | int | None) -> str:
            return "the config's" if x is None else f"{x:g}"

        every = (f"every {self.eval_minutes:g} CPU min" if self.eval_minutes is not None
                 else f"every {num(self.eval_epochs)} epochs")  # fmt: skip
        return f"{num(self.minutes)} CPU min, warm-up {num(self.warmup)}, validation {every}"


BUDGET_KEYS = ("finetune.max_minutes", "finetune.warmup_steps", "finetune.eval_every_minutes",
               "finetune.eval_every")  # fmt: skip
"""The ``--set`` keys of the budget (``rl.presets.equal_budget_overrides`` writes all but the
last; the rows of before 2026-11-27 have ``finetune.eval_every`` instead of the minutes)."""

PUBLISHED_BUDGET = Budget(4.0, EQUAL_BUDGET_WARMUP, 1.0)
"""The budget of a row whose command names none: the published table's. Every row of the
published equal-budget table from the default generators names ``finetune.max_minutes=4.0``,
``finetune.warmup_steps=4`` and ``finetune.eval_every_minutes=1.0`` in its ``command`` (the
script's defaults: ``--minutes 4``, ``--warmup 4``, validation every 4 / 4 minutes); the rows
from ``generator-long`` name ``finetune.eval_every=3`` instead (validation every 3 epochs)."""


def budget_of(sets: list[str]) -> Budget:
    """The budget that finetune.py's ``--set key=value`` overrides give (the last of a key
    wins, as in ``config.load_config``); ``PUBLISHED_BUDGET`` when they name none of its keys."""
    values = {}
    for item in sets:
        key, sep, value = item.partition("=")
        if sep and key.strip() in BUDGET_KEYS:
            values[key.strip()] = value.strip()
    if not values:
        return PUBLISHED_BUDGET

    def get(key: str, kind: type) -> float | int | None:
        value = values.get(key)
        return None if value is None or value.lower() in ("null", "none") else kind(value)

    minutes_every = get("finetune.eval_every_minutes", float)
    return Budget(get("finetune.max_minutes", float), get("finetune.warmup_steps", int),
                  minutes_every, get("finetune.eval_every", int) if minutes_every is None
                  else None)  # fmt: skip


def row_budget(row: dict) -> Budget:
    """The budget a row was measured under, from the ``--set`` arguments of its ``command``
    (finetune.py's command line, which this script's jobs give the budget); a row without a
    command, or whose command names no budget, has ``PUBLISHED_BUDGET``."""
    try:
        words = shlex.split(row.get("command") or "")
    except ValueError:  # an unbalanced quote: read it word by word
        words = (row.get("command") or "").split()
    sets = [w.removeprefix("--set=") for w in words if w.startswith("--set=")]
    sets += [b for a, b in zip(words, words[1:], strict=False) if a == "--set"]
    return budget_of(sets)


def requested_budget(minutes: float, warmup: int, eval_minutes: float | None) -> Budget:
    """The budget of this invocation's jobs (``eval_minutes`` None: ``minutes`` / 4)."""
    return budget_of(equal_budget_overrides(minutes, warmup, eval_minutes))


def folder_budget(run: Path) -> Budget | None:
    """The budget a run folder's fine-tuning was started with (its ``finetune_config.yaml``);
    None without one."""
    path = run / "finetune_config.yaml"
    if not path.is_file():
        return None
    ft = (yaml.safe_load(path.read_text()) or {}).get("finetune") or {}
    every = ft.get("eval_every_minutes")
    return Budget(None if ft.get("max_minutes") is None else float(ft["max_minutes"]),
                  ft.get("warmup_steps"), None if every is None else float(every),
                  ft.get("eval_every") if every is None else None)  # fmt: skip


def run_folder(dataset: str, name: str, seed: int, where: Where | None = None) -> Path:
    """The run folder of a table row (``name``: its method, e.g. ``control-lr3e-5-long``),
    under ``where.runs`` (default: the repository's runs/)."""
    method, var = _split(name)
    tag = _tag(method, var)
    suffix = f"-{tag}" if tag else ""
    runs = (where or where_of()).runs
    return runs / f"{dataset}-{_arg(method, '--methods')}-s{seed}{suffix}"


def _best_val(dataset: str, name: str, seed: int, where: Where | None = None) -> float | None:
    """The run's best validation score (lower is better); None without its run folder."""
    log = read_metrics(run_folder(dataset, name, seed, where), "finetune")
    if not log:
        return None
    scores = [epoch.get("val_score") for epoch in log]
    return min((v for v in scores if v is not None), default=None)


def _beats_start(dataset: str, method: str, seed: int, where: Where | None = None) -> bool | None:
    """Whether the run's best validation score beats the start's (the fine-tuning stage's
    own validation of the untouched start, meta/finetune_start_<D>[_<start>].json); None when
    the run folder or the start's record is missing (e.g. in a fresh checkout)."""
    where = where or where_of()
    start = where.results / "meta" / start_record(dataset, VARIANTS[_split(method)[1]])
    best = _best_val(dataset, method, seed, where)
    if best is None or not start.is_file():
        return None
    return best < json.loads(start.read_text())["val"]["score"]


NOT_CHOSEN = "control not chosen on validation"
"""The cell of every method in a start's group whose control could not be chosen on validation:
several controls have rows, and no seed has a run folder of each (a fresh checkout)."""


def _chosen_control(dataset: str, rows: list[dict], methods: list[str], where: Where) -> str | None:
    """Of the control variants with rows in the table, the one with the best mean validation
    score over the seeds whose run folders every one of them still has (a seed's folders can
    be lost with a checkout while later seeds are run in another); the only one when there is
    one; None when there are several and no seed has a validated run of each: the control is
    then not chosen on validation (``NOT_CHOSEN``), never one of them silently."""
    controls = [m for m in methods
                if m.startswith("control") and any(r["method"] == m for r in rows)]  # fmt: skip
    if len(controls) < 2:
        return controls[0] if controls else None
    vals = {m: {r["seed"]: _best_val(dataset, m, r["seed"], where)
                for r in rows if r["method"] == m} for m in controls}  # fmt: skip
    validated = [{s for s, v in by_seed.items() if v is not None} for by_seed in vals.values()]
    common = set.intersection(*validated)
    if not common:
        return None
    scores = {m: statistics.mean(vals[m][s] for s in common) for m in controls}
    return min(scores, key=scores.get)


def row_name(method: str, start: str) -> str:
    """The method name of a table method's rows when run from ``start``."""
    return _suffixed(method, variant(start))


def _suffixed(method: str, var: str) -> str:
    """A method's row name from a start variant ("" keeps the plain name)."""
    return f"{method}-{var}" if var else method


def _done(dataset: str, method: str, seed: int, start: str, budget: Budget, where: Where) -> bool:
    """Whether the job's row is stored, measured under ``budget`` (``_one_budget`` has refused
    a row of the same method and seed under another)."""
    return any(row_budget(r) == budget for r in _stored(dataset, method, seed, start, where))


def _stored(dataset: str, method: str, seed: int, start: str, where: Where) -> list[dict]:
    """The stored rows of a job (its results file's rows of its method name and seed)."""
    tag = _tag(method, variant(start))
    name = f"finetune_{dataset}{'_' + tag if tag else ''}.json"
    path = where.results / name
    rows = json.loads(path.read_text()) if path.is_file() else []
    return [r for r in rows if (r["method"], r["seed"]) == (row_name(method, start), seed)]


def _one_budget(jobs: list[tuple[str, str, int]], start: str, budget: Budget, where: Where) -> None:
    """Refuse jobs that would put rows of two budgets in one table: their dataset has rows of
    a table method from ``start`` measured under another budget (finetune.py keys its rows on
    method and seed alone, so it would overwrite them, and the table would compare methods
    given different budgets), or a job's run folder was started with another budget
    (finetune.py would resume it, or take its finished run as this one)."""
    rows = merge_rows(read_rows(where.results, protocol="all"))
    names = {row_name(m, start) for m in METHODS}
    problems = []
    for dataset in dict.fromkeys(d for d, _, _ in jobs):
        other: dict[Budget, list[dict]] = {}
        for r in rows:
            if r["dataset"] == dataset and r["method"] in names and row_budget(r) != budget:
                other.setdefault(row_budget(r), []).append(r)
        problems += [f"{dataset} from {start} has rows measured under {b}: {_which(which)}"
                     for b, which in other.items()]  # fmt: skip
    for dataset, method, seed in jobs:
        run = run_folder(dataset, row_name(method, start), seed, where)
        have = folder_budget(run)
        if have is not None and have != budget:
            problems.append(f"{shown(run, ROOT)} was started under {have}")
    if problems:
        sys.exit(
            f"these jobs ask for {budget}, but\n  " + "\n  ".join(problems) + "\none table "
            f"compares one budget: to measure another, move those rows out of "
            f"{shown(where.results, ROOT)}/ (and those folders out of {shown(where.runs, ROOT)}/) "
            "first, or measure it in folders of its own (--runs, --results and --models)"
        )


def _which(rows: list[dict]) -> str:
    """Rows by method and seeds: ``control s0,1,2; rlhf s0``."""
    seeds: dict[str, list[int]] = {}
    for r in rows:
        seeds.setdefault(r["method"], []).append(r["seed"])
    return "; ".join(f"{m} s{','.join(str(s) for s in sorted(v))}" for m, v in seeds.items())


DEFAULT_MINUTES = 4.0
"""``--minutes`` when no budget is given and the start has no stored rows."""


def stored_budget(datasets: list[str], start: str, where: Where | None = None) -> Budget | None:
    """The one budget of the stored rows (in ``where.results``, default the repository's) of
    ``start``'s table methods in ``datasets``; None when there are none. Rows of several
    budgets: an error naming them (``_one_budget`` would refuse any of them)."""
    rows = merge_rows(read_rows((where or where_of()).results, protocol="all"))
    names = {row_name(m, start) for m in METHODS}
    found: dict[Budget, list[dict]] = {}
    for r in rows:
        if r["dataset"] in datasets and r["method"] in names:
            found.setdefault(row_budget(r), []).append(r)
    if len(found) > 1:
        lines = "\n  ".join(f"{b}: {_which(these)}" for b, these in found.items())
        sys.exit(f"the stored rows from {start} of {', '.join(datasets)} have several "
                 f"budgets:\n  {lines}\nname the budget (--minutes, --warmup, --eval-minutes "
                 "or --eval-epochs)")  # fmt: skip
    return next(iter(found), None)


def job_budget(args: argparse.Namespace, where: Where | None = None) -> Budget:
    """The budget of this invocation's jobs: the options given (``--eval-epochs`` N:
    validation every N epochs), the others at their defaults; none given, the budget the
    start's stored rows of these datasets have (``stored_budget``), else the defaults (4 CPU
    minutes, warm-up ``EQUAL_BUDGET_WARMUP``, validation every minutes / 4)."""
    epochs = getattr(args, "eval_epochs", None)
    given = (args.minutes, args.warmup, args.eval_minutes, epochs)
    if all(v is None for v in given):
        stored = stored_budget(list(args.datasets), args.start, where)
        if stored is not None:
            return stored
    if epochs is not None and args.eval_minutes is not None:
        sys.exit("--eval-minutes and --eval-epochs exclude each other")
    minutes = DEFAULT_MINUTES if args.minutes is None else args.minutes
    warmup = EQUAL_BUDGET_WARMUP if args.warmup is None else args.warmup
    if epochs is not None:
        if epochs < 1:
            sys.exit(f"--eval-epochs must be >= 1, got {epochs}")
        return Budget(minutes, warmup, None, epochs)
    return requested_budget(minutes, warmup, args.eval_minutes)


def budget_args(budget: Budget) -> list[str]:
    """finetune.py's ``--set`` arguments of a budget: ``rl.presets.equal_budget_args``, with
    ``finetune.eval_every=N`` in place of the minutes for validation every N epochs (as the
    published ``-long`` rows' commands); ``row_budget`` reads the budget back from them."""
    out: list[str] = []
    if budget.minutes is not None and budget.warmup is not None:
        out = equal_budget_args(budget.minutes, budget.warmup, budget.eval_minutes)
        if budget.eval_minutes is None and budget.eval_epochs is not None:
            out = [
                f"finetune.eval_every={budget.eval_epochs}"
                if a.startswith("finetune.eval_every_minutes=")
                else a
                for a in out
            ]
    sets = [b for a, b in zip(out, out[1:], strict=False) if a == "--set"]
    if not out or budget_of(sets) != budget:  # the rows' commands would say another
        sys.exit(
            f"cannot run jobs under {budget} (stored rows' budget?): name the budget "
            "with --minutes, --warmup and --eval-minutes or --eval-epochs"
        )
    return out


def run_jobs(args: argparse.Namespace, where: Where | None = None) -> None:
    """Run the jobs of ``args`` not yet measured, one finetune.py process each, in ``where``
    (default: the folders of ``args``' --runs, --results and --models, ``where_of``)."""
    where = where or where_of(args)
    jobs = [(d, m, s) for s in args.seeds for d in args.datasets for m in args.methods]
    budget = job_budget(args, where)
    _one_budget(jobs, args.start, budget, where)
    todo = [j for j in jobs if not _done(*j, args.start, budget, where)]
    print(f"{len(jobs) - len(todo)} of {len(jobs)} rows already measured under {budget}; "
          f"{len(todo)} to run")  # fmt: skip
    if not where.in_repo:  # finetune.py would refuse each job, after its log is opened
        missing = [str(where.start(d, args.start)) for d in dict.fromkeys(d for d, _, _ in todo)
                   if not where.start(d, args.start).is_file()]  # fmt: skip
        if missing:
            sys.exit(f"no published {args.start} in --models {where.models}: "
                     f"{', '.join(missing)} (copy or link the repository's "
                     "models/<dataset>/)")  # fmt: skip
    logs = where.logs
    logs.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    sets = budget_args(budget)
    data = ["--data-root", args.data_root] if args.data_root else []

    def one(job: tuple[str, str, int]) -> tuple[tuple[str, str, int], int, float]:
        dataset, method, seed = job
        cmd = [sys.executable, str(ROOT / "benchmarks" / "finetune.py"), "--dataset", dataset,
               *job_args(method, args.start), "--seeds", str(seed), "--skip-done",
               "--no-start-validation",
               *sets, *data, *where.options()]  # fmt: skip
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
        sys.exit(f"{len(failed)} jobs failed (logs in {shown(logs, ROOT)}/): {failed}")


def _fmt(x: float | None) -> str:
    return "–" if x is None else f"{x:.3f}"


def _ms(xs: list[float]) -> str:
    if len(xs) < 2:
        return f"{xs[0]:.3f}" if xs else "–"
    return f"{statistics.mean(xs):.3f} ± {statistics.stdev(xs):.3f}"


def previous_table(path: Path) -> dict[tuple[str, str], str]:
    """The lines of an earlier table (``meta/equal_budget.md``) by their first two cells."""
    return table_lines(path.read_text() if path.is_file() else "")


def previous_datasets(before: dict[tuple[str, str], str]) -> list[str]:
    """The datasets of an earlier table (``previous_table``'s lines), in its order."""
    return list(dict.fromkeys(dataset for dataset, _ in before))


HEADER = ("dataset", "method", "seeds", "minADE20", "minFDE20", "minFDE20 vs start",
          "vs the control chosen on val", "joint minADE / minFDE", "maxATS", "train wall min",
          "runs beating the start on val")  # fmt: skip
"""The table's columns."""
FROM_VALIDATION = (HEADER.index("vs the control chosen on val"),
                   HEADER.index("runs beating the start on val"))  # fmt: skip
"""The columns computed from the run folders' validation (which control, which runs beat the
start); every other cell comes from the stored rows alone."""


def _table_groups(
    datasets: list[str], methods: list[str], rows: list[dict]
) -> list[tuple[str, str, list[str], list[dict], dict | None]]:
    """Each (dataset, start variant) of the table with rows of ``methods``: the dataset, the
    variant, the method names from that start, the dataset's test rows at K = 20 and the start's
    row (None without one)."""
    out = []
    for dataset in datasets:
        pick = [r for r in rows if r["dataset"] == dataset and r["split"] == "test"]
        pick = [r for r in pick if r["samples"] == 20]
        for var in VARIANTS:  # each start with its own methods, start row and control
            names = [_suffixed(m, var) for m in methods]
            if not any(r["method"] in names for r in pick):
                continue
            start = next((r for r in pick if r["method"] == finetune_start(names[0])), None)
            out.append((dataset, var, names, pick, start))
    return out


def _group_budget(
    dataset: str, var: str, pick: list[dict], names: list[str], where: Where
) -> Budget:
    """The one budget of a start's rows; refuses rows of several (their methods would be
    compared as if given the same compute)."""
    budgets: dict[Budget, list[dict]] = {}
    for r in pick:
        if r["method"] in names:
            budgets.setdefault(row_budget(r), []).append(r)
    if len(budgets) > 1:
        results = shown(where.results, ROOT)
        sys.exit(
            f"{dataset} from {VARIANTS[var]}: the rows of {results}/ were measured "
            "under different budgets, which one table cannot compare:\n  "
            + "\n  ".join(f"{b}: {_which(which)}" for b, which in budgets.items())
            + f"\nmove the rows of all but one budget out of {results}/"
        )
    return next(iter(budgets))


def table_budgets(
    datasets: list[str], methods: list[str], where: Where | None = None
) -> dict[tuple[str, str], Budget]:
    """The budget of each (dataset, start) of the table (refusing mixed ones, as ``report``)."""
    where = where or where_of()
    rows = merge_rows(read_rows(where.results, protocol="all"))
    return {(dataset, VARIANTS[var]): _group_budget(dataset, var, pick, names, where)
            for dataset, var, names, pick, _ in _table_groups(datasets, methods, rows)}  # fmt: skip


def report(
    datasets: list[str],
    methods: list[str],
    before: dict[tuple[str, str], str] | None = None,
    where: Where | None = None,
) -> str:
    """Mean +- std over seeds of each method's test rows, against the start and the control.
    A start's rows must share one budget (``row_budget``): rows of several are refused. Where
    some of a start's run folders are absent here (a new checkout has no ``runs/``), its
    method lines are the previous table's when every cell that the rows give is still today's
    (the rows are the same runs'): the validation that chose its control and counted the runs
    beating the start lives in those folders. The start's own line is always today's.
    ``before`` is that table's lines (read from ``where.table`` when not given); ``where``:
    the folders of the rows and run folders (default: the repository's)."""
    where = where or where_of()
    before = previous_table(where.table) if before is None else before
    rows = merge_rows(read_rows(where.results, protocol="all"))
    lines = [
        "| " + " | ".join(HEADER) + " |",
        "|" + "---|" * len(HEADER),
    ]
    for dataset, var, names, pick, start in _table_groups(datasets, methods, rows):
        _group_budget(dataset, var, pick, names, where)
        group = _rows(dataset, pick, names, start, where)
        lines += group if _all_runs_here(dataset, pick, names, where) else _kept(group, before)
    return "\n".join(lines)


def _all_runs_here(dataset: str, pick: list[dict], names: list[str], where: Where) -> bool:
    """Whether every row of a start's methods has its run folder's validation here."""
    return all(_best_val(dataset, r["method"], r["seed"], where) is not None
               for r in pick if r["method"] in names)  # fmt: skip


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.split("|")[1:-1]]


def _from_rows(line: str) -> list[str]:
    """A table line's cells that the stored rows give (all but ``FROM_VALIDATION``)."""
    return [c for i, c in enumerate(_cells(line)) if i not in FROM_VALIDATION]


def _is_start(line: str) -> bool:
    return _cells(line)[1].startswith("start (")


def _kept(group: list[str], before: dict[tuple[str, str], str]) -> list[str]:
    """``group``'s method lines as the previous table had them, when it has every one of them
    with the same cells from the rows, in every column (the rows are the same runs'), and the
    start's line as today's; otherwise ``group`` itself."""
    methods = [line for line in group if not _is_start(line)]
    old = [before.get(row_key(line)) for line in methods]
    same = all(o is not None and _from_rows(o) == _from_rows(line)
               for o, line in zip(old, methods, strict=True))  # fmt: skip
    if not (same and methods):
        return group
    kept = dict(zip(methods, old, strict=True))
    return [kept.get(line, line) for line in group]


def _rows(
    dataset: str, pick: list[dict], names: list[str], start: dict | None, where: Where
) -> list[str]:
    """One start's lines of the table: the start, then each method with rows."""
    lines = []
    chosen = _chosen_control(dataset, pick, names, where)
    control = [r["min_fde"] for r in pick if r["method"] == chosen]
    controls = any(r["method"].startswith("control") for r in pick if r["method"] in names)
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
        beats = [_beats_start(dataset, method, r["seed"], where) for r in own]
        known = [b for b in beats if b is not None]
        beat = f"{sum(known)} of {len(known)}" if known else "–"
        vs_start = f"{100 * (statistics.mean(fde) / start['min_fde'] - 1):+.1f} %" if start else "–"
        if controls and chosen is None:
            vs_control = NOT_CHOSEN
        elif control and method != chosen:
            vs_control = f"{100 * (statistics.mean(fde) / statistics.mean(control) - 1):+.1f} %"
        else:
            vs_control = "–"
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
