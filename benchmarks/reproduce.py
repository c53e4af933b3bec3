"""The paper's Tables 1 and 2 for every dataset here, ours beside the paper's, in one command.

Table 1 is minADE20 / minFDE20, Table 2 maxATS20 / maxFTS20.

    # from the published checkpoints and the existing result rows, no training (about 70 min
    # for all eight datasets from scratch on 2 cores; nothing to do where every cell is stored)
    python benchmarks/reproduce.py --quick --data-root ../shared/data [--datasets zara1 eth robo]
    # measure every evaluated cell again, into a folder of its own (the repository untouched)
    python benchmarks/reproduce.py --quick --fresh --out out/reproduce --data-root ../shared/data
    # a smoke run: 10 scenes per dataset, written under runs/reproduce/ (not the tables)
    python benchmarks/reproduce.py --quick --max-scenes 10 --data-root ../shared/data
    # also train what is missing (pretraining, RLHF, RLHF-ReS, the best method), resuming
    python benchmarks/reproduce.py --data-root ../shared/data
    # only rebuild the tables from what is stored
    python benchmarks/reproduce.py --report

Our columns, per dataset (K = 20, test split, seed 0):

- ``cv``, ``full-sampler``, ``pretrained``: constant velocity, and the full 100-step sampler and
  the leapfrog generator of ``models/<D>/generator.safetensors``, evaluated here, each scored
  by the dataset's published denoiser for Table 2 (``TrajectoryScorer``, every 3rd step);
- ``rlhf``, ``rlhf-res``: evaluated when ``models/<D>/<method>.safetensors`` is published,
  otherwise the mean over seeds of the rows in ``benchmarks/results/`` (the equal-budget rows
  of ``benchmarks/equal_budget.py``; their weights are not published);
- ``best``: the best score-using method at K = 20 (``--best``, default ``rlhf-set``: RLHF with
  the set-aware reward, ``finetune_<D>_set.json``). The score-guided selections of
  docs/selection.md keep K' <= 5 of 20, so they have no best-of-20 row; of the fine-tuning
  methods in the equal-budget table, RLHF-set is the one whose runs beat their start on
  validation on every dataset measured, a choice made without the test split.

A dataset without a published generator gets constant velocity only ("no model" elsewhere;
full mode pretrains one when ``configs/<D>.yaml`` exists). In full mode the missing rows are
trained by ``benchmarks/pretrain.py`` and ``benchmarks/finetune.py`` (with the equal-budget
table's arguments), one subprocess per job, logs in ``runs/logs/``; they write their run folders,
rows and (pretraining) published generator in the repository, or under ``--out``.

Resuming: every evaluation is stored in ``benchmarks/results/meta/reproduce/<D>_<column>.json``
with a key (checkpoint and denoiser hashes, sampler, K, seed, scenes); a run skips the
evaluations whose key matches, the training jobs whose rows exist and the pretraining whose
generator is published, so an interrupted run loses at most the job it was in. A progress bar
weighted by each job's estimated cost gives the ETA. CPU time (this process plus its finished
children, ``resource.getrusage``) is logged per invocation in
``benchmarks/results/meta/reproduce/invocations.json`` and summed.

``--datasets`` limits what a run measures or trains, not what the tables list: a dataset left
out keeps the cells that earlier runs stored for it (while their keys still match).
``--fresh`` evaluates every cell again even where its key matches (training jobs are still
skipped where their rows exist).

Writes docs/reproduce.md (generated) and benchmarks/results/meta/reproduce.json; no rows are
added to benchmarks/results/*.json by this script itself. ``--out DIR`` sends this script's own
files there instead (``DIR/state/`` for the stored evaluations and ``invocations.json``,
``DIR/reproduce.md``, ``DIR/reproduce.json``, ``DIR/logs/``), so the repository's tables and
state stay as they are; a new folder starts from nothing. Full mode's training subprocesses
then write there too: ``--runs DIR/runs --results DIR/results`` (run folders, result rows with
their ``meta/``) and, for pretraining, ``--models DIR/models`` (the published generator;
fine-tuning reads its start from the folder the tables evaluate). The tables read the rows of
``DIR/results/`` beside the repository's (a row there replaces the repository's of the same
measurement and file name) and a generator of ``DIR/models/<D>/`` before the repository's; a
training job is still skipped where the repository has its row or generator. So a full-mode
run with ``--out`` leaves the repository's files as they are. A ``--max-scenes`` run (a smoke
run) never touches the whole-split state or docs/reproduce.md: it writes under
``runs/reproduce/`` unless ``--out`` is given (its training, as any run's without ``--out``,
into the repository's places), and its files are named after the subset
(``<D>_<column>_scenes<N>.json``, ``reproduce_scenes<N>.md``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace
from datetime import date
from pathlib import Path
from typing import Any, Literal

import numpy as np
from tqdm import tqdm

from trajpref.data import load_dataset
from trajpref.errors import TrajprefError
from trajpref.evaluation import evaluate
from trajpref.io import read_checkpoint_header, write_json
from trajpref.models import checkpoint as ckpt
from trajpref.models.baseline import ConstantVelocity
from trajpref.results import ROW_KEY, command_line, machine
from trajpref.rl.presets import EQUAL_BUDGET_WARMUP, equal_budget_args
from trajpref.score.scorer import NOISE_LAYOUT, TrajectoryScorer
from trajpref.types import TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent
DATASETS = ("eth", "hotel", "univ", "zara1", "zara2", "sdd", "nba", "robo")
"""Every dataset here, in the order the tables list them."""
ETH_UCY = DATASETS[:5]
COLUMNS = ("cv", "full-sampler", "pretrained", "rlhf", "rlhf-res", "best")
"""Our columns, in table order."""
LABELS = {"cv": "CV", "full-sampler": "full sampler", "pretrained": "pretrained",
          "rlhf": "RLHF", "rlhf-res": "RLHF-ReS"}  # fmt: skip
PAPER_COLUMNS = ("LED", "RLHF", "RLHF-ReS")
"""The paper's columns printed beside ours (its whole tables follow below them)."""
LED_REFERENCE = "LED (its authors)"
TRAIN_ARGS = {
    "rlhf": ["--methods", "rlhf"],
    "rlhf-res": ["--methods", "rlhf-res"],
    "rlhf-set": ["--methods", "rlhf", "--tag", "set", "--set", "finetune.reward=set"],
}
"""finetune.py arguments of each method full mode can train: the same as
benchmarks/equal_budget.py's, so the rows land where that table reads them (tested)."""
SAMPLERS = {"full-sampler": "full", "pretrained": "leapfrog"}
RESULT_KEYS = ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "max_ats", "max_fts",
               "top1_recall_ats", "top5_recall_ats")  # fmt: skip
"""The metrics a cell keeps (from an evaluation or from result rows)."""
COST = {"cv": 0.025, "full-sampler": 0.104, "pretrained": 0.026, "unscored": 0.002,
        "finetune": 600.0, "pretrain": 3600.0}  # fmt: skip
"""Rough cost of a job for the progress bar's ETA: seconds per test agent of an evaluation
with the scorer (one busy core, eth, 2026-11-23), or seconds per training job. Only the
ratios matter: the bar's rate calibrates itself as jobs finish."""
ROW_TOLERANCE = 5e-4
"""An evaluation "matches" an existing result row of the same measurement within this."""


@dataclass
class Setup:
    """Where the script reads and writes: the repository by default (tests point it at a
    temporary folder; the training subprocesses write into the repository unless ``trained``
    is set). With ``out`` set, the script's own files (state, report, summary, invocation log,
    training logs) go there and it reads models, rows, configs and the paper from the fields
    above it (and from ``trained``)."""

    models: Path = ROOT / "models"
    """The published checkpoints, ``<dataset>/generator.safetensors`` etc."""
    results: Path = ROOT / "benchmarks" / "results"
    """The result rows (``*.json``) and ``meta/``."""
    configs: Path = ROOT / "configs"
    """``<dataset>.yaml``: a dataset full mode can pretrain."""
    paper: Path = ROOT / "benchmarks" / "paper_tables.json"
    """The paper's numbers, typed in from its Tables 1 and 2."""
    doc: Path = ROOT / "docs" / "reproduce.md"
    """The generated markdown."""
    logs: Path = ROOT / "runs" / "logs"
    """Logs of the training subprocesses."""
    sources: dict[str, str] = field(default_factory=dict)
    """Extra datasets: table name -> what ``load_dataset`` reads (a folder)."""
    out: Path | None = None
    """``--out``: the folder of this script's own files (None: the repository's places)."""
    scratch: Path = ROOT / "runs" / "reproduce"
    """The ``out`` of a ``--max-scenes`` run that names none (``runs/`` is not tracked)."""
    trained: Path | None = None
    """``--out``: where full mode's training subprocesses write (``runs/``, ``results/``,
    ``models/``), read beside ``results`` and before ``models`` (None: they write into the
    repository, the places above)."""

    def __post_init__(self) -> None:
        bad = set(self.sources) & set(DATASETS)
        if bad:
            raise ValueError(f"sources may not redefine built-in datasets: {sorted(bad)}")

    @property
    def state(self) -> Path:
        """The stored evaluations (``<D>_<column>[_scenes<N>].json``) and the invocation log."""
        return self.out / "state" if self.out else self.results / "meta" / "reproduce"

    @property
    def summary(self) -> Path:
        return self.summary_file(None)

    def summary_file(self, max_scenes: int | None) -> Path:
        """The summary (cells, jobs, CPU) of a whole-split or a ``--max-scenes`` run."""
        return (self.out or self.results / "meta") / f"reproduce{subset_suffix(max_scenes)}.json"

    def report(self, max_scenes: int | None) -> Path:
        """The markdown report: docs/reproduce.md, or ``reproduce[_scenes<N>].md`` in ``out``."""
        return self.out / f"reproduce{subset_suffix(max_scenes)}.md" if self.out else self.doc

    @property
    def repository_log(self) -> Path:
        """The repository's invocation log (the measured cost of a run from scratch)."""
        return self.results / "meta" / "reproduce" / "invocations.json"


def subset_suffix(max_scenes: int | None) -> str:
    """What names a ``--max-scenes`` run's files apart from the whole split's."""
    return f"_scenes{max_scenes}" if max_scenes else ""


@dataclass
class Job:
    """One unit of work: an evaluation, a pretraining or a fine-tuning run."""

    kind: Literal["evaluate", "pretrain", "finetune"]
    """What the job does."""
    dataset: str
    """The table's dataset name."""
    column: str
    """Our table column it fills (``evaluate``); the trained method (``finetune``)."""
    model: Path | None = None
    """``evaluate``: the checkpoint (None: constant velocity)."""
    sampler: str | None = None
    """``evaluate``: ``full`` or ``leapfrog`` (None for constant velocity)."""
    seed: int = 0
    """``finetune``: the training seed."""

    @property
    def label(self) -> str:
        what = self.column + (f" seed {self.seed}" if self.kind == "finetune" else "")
        return f"{self.kind} {self.dataset} {what}"


# ----------------------------------------------------------------------------- small helpers


_HASHES: dict[tuple[Path, int], str] = {}


def sha256(path: Path) -> str:
    """The file's content hash (memoised per path and modification time)."""
    key = (path.resolve(), path.stat().st_mtime_ns)
    if key not in _HASHES:
        _HASHES[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return _HASHES[key]


def sampled_weights(model: Path, sampler: str | None) -> Path:
    """The file whose content a sampler's output depends on: a generator file, or, for the
    full sampler of a generator, the denoiser file it names (``denoiser_ref``)."""
    if sampler != "full":
        return model
    ref = read_checkpoint_header(model).get("denoiser_ref")
    return model.parent / ref["path"] if ref else model


def cpu_seconds() -> tuple[float, float]:
    """(this process, its finished children): user + system CPU seconds so far."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


def rel(path: Path | None) -> str | None:
    """A path relative to the repository when it lies inside it."""
    if path is None:
        return None
    absolute = Path(os.path.abspath(path))  # not resolved: models/ is a link into src/
    try:
        return str(absolute.relative_to(ROOT))
    except ValueError:
        return str(path)


def read_json(path: Path, default: Any = None) -> Any:
    return json.loads(path.read_text()) if path.is_file() else default


def result_rows(setup: Setup) -> list[dict[str, Any]]:
    """Every row of ``results/*.json`` measured under the default protocol (``all``, the
    paper's), each with the file it came from (``_file``, as the report names it); with
    ``setup.trained``, also the rows its training wrote there, each replacing a repository row
    of the same measurement (``ROW_KEY``) in a file of the same name."""

    def read(folder: Path, name) -> list[dict[str, Any]]:
        return [{**r, "_file": name(path), "_key": (*(r[k] for k in ROW_KEY), path.name)}
                for path in sorted(folder.glob("*.json")) for r in json.loads(path.read_text())
                if r["protocol"] == "all"]  # fmt: skip

    rows = read(setup.results, lambda path: f"benchmarks/results/{path.name}")
    if setup.trained is not None:
        own = read(trained_results(setup), rel)
        replaced = {r["_key"] for r in own}
        rows = [r for r in rows if r["_key"] not in replaced] + own
    return [{k: v for k, v in r.items() if k != "_key"} for r in rows]


def matching_rows(rows, dataset: str, method: str, samples: int, seed: int | None = None):
    """The test rows of one measurement (every seed when ``seed`` is None)."""
    return [r for r in rows if r["dataset"] == dataset and r["method"] == method
            and r["split"] == "test" and r["samples"] == samples
            and (seed is None or r["seed"] == seed)]  # fmt: skip


def trained_results(setup: Setup) -> Path:
    """Where full mode's fine-tuning writes its rows (and ``meta/``)."""
    return setup.results if setup.trained is None else setup.trained / "results"


def models_of(setup: Setup, dataset: str) -> Path:
    """The folder of a dataset's models: the one full mode pretrained under ``--out`` when
    it holds a generator, otherwise the repository's."""
    if setup.trained is not None:
        own = setup.trained / "models" / dataset
        if (own / f"generator{ckpt.SUFFIX}").is_file():
            return own
    return setup.models / dataset


def generator_path(setup: Setup, dataset: str, name: str = "generator") -> Path:
    return models_of(setup, dataset) / f"{name}{ckpt.SUFFIX}"


def denoiser_path(setup: Setup, dataset: str) -> Path:
    return models_of(setup, dataset) / ckpt.DENOISER_NAME


def column_method(column: str, best: str) -> str:
    """The method name of the result rows behind a column."""
    return best if column == "best" else column


# ----------------------------------------------------------------------------- planning


def evaluation_job(
    opts: argparse.Namespace, setup: Setup, dataset: str, column: str, will_pretrain: bool = False
) -> Job | None:
    """The evaluation that fills a column, or None where the column is not evaluated here
    (no model, or a method whose weights are not published: its cell comes from rows)."""
    gen = generator_path(setup, dataset)
    if column == "cv":
        return Job("evaluate", dataset, "cv")
    if column in SAMPLERS:
        return Job("evaluate", dataset, column, gen, SAMPLERS[column]) if (
            gen.is_file() or will_pretrain) else None  # fmt: skip
    published = generator_path(setup, dataset, column_method(column, opts.best))
    if not (published.is_file() and tuned_from_today(published, gen)):
        return None
    return Job("evaluate", dataset, column, published, "leapfrog")


def tuned_from_today(tuned: Path, generator: Path) -> bool:
    """Whether a published fine-tuned generator started from the dataset's published default
    (the start's weights hash that fine-tuning writes into ``meta.from``). One fine-tuned from
    a default since replaced is not today's column: its cell comes from rows of runs from
    today's start, or full mode trains them."""
    if not generator.is_file():
        return False
    start = (read_checkpoint_header(tuned).get("meta") or {}).get("from")
    return start is not None and start == read_checkpoint_header(generator).get("hash")


def plan(opts: argparse.Namespace, setup: Setup) -> list[Job]:
    """Every job of the tables, done or not, in the order they run."""
    jobs: list[Job] = []
    for dataset in opts.datasets:
        has_model = generator_path(setup, dataset).is_file()
        trainable = (setup.configs / f"{dataset}.yaml").is_file()
        pretrain = not has_model and not opts.quick and trainable
        if pretrain:
            jobs.append(Job("pretrain", dataset, "pretrained"))
        for column in COLUMNS:
            job = evaluation_job(opts, setup, dataset, column, pretrain)
            method = column_method(column, opts.best)
            if job is not None:
                jobs.append(job)
            elif (has_model or pretrain) and not opts.quick and method in TRAIN_ARGS:
                jobs += [Job("finetune", dataset, method, seed=s) for s in opts.seeds]
    unique = {job.label: job for job in reversed(jobs)}  # e.g. --best rlhf-res: one job
    return [job for job in jobs if unique[job.label] is job]


def eval_key(job: Job, opts: argparse.Namespace, setup: Setup) -> dict[str, Any] | None:
    """What an evaluation's result depends on; None while its checkpoint does not exist."""
    if job.model is not None and not job.model.is_file():
        return None
    den = denoiser_path(setup, job.dataset)
    # the full sampler runs the generator's denoiser only: a change of the generator's own
    # weights or sampling setting does not invalidate it
    weights = sampled_weights(job.model, job.sampler) if job.model else None
    return {
        "dataset": job.dataset, "column": job.column,
        "checkpoint": rel(job.model), "checkpoint_sha256": sha256(weights) if weights else None,
        "scorer": rel(den) if den.is_file() else None,
        "scorer_sha256": sha256(den) if den.is_file() else None,
        "score_noise": NOISE_LAYOUT if den.is_file() else None,
        "sampler": job.sampler, "samples": opts.samples, "seed": opts.seed,
        "max_scenes": opts.max_scenes,
        **({"full_sampler_agents": opts.full_sampler_agents} if job.sampler == "full" else {}),
    }  # fmt: skip


def state_file(setup: Setup, dataset: str, column: str, max_scenes: int | None = None) -> Path:
    """A column's stored evaluation; a ``--max-scenes`` subset's is a file of its own, so a
    smoke run never replaces the whole split's."""
    return setup.state / f"{dataset}_{column}{subset_suffix(max_scenes)}.json"


def is_done(job: Job, opts: argparse.Namespace, setup: Setup, rows) -> bool:
    if job.kind == "pretrain":
        return generator_path(setup, job.dataset).is_file()
    if job.kind == "finetune":
        return bool(matching_rows(rows, job.dataset, job.column, opts.samples, job.seed))
    key = eval_key(job, opts, setup)
    stored = read_json(state_file(setup, job.dataset, job.column, opts.max_scenes))
    return key is not None and stored is not None and stored.get("key") == key


class Splits:
    """Test splits (and scorers), loaded once per dataset."""

    def __init__(self, opts: argparse.Namespace, setup: Setup):
        self.opts, self.setup = opts, setup
        self._data: dict[str, TrajectoryDataset] = {}
        self._scorers: dict[str, TrajectoryScorer | None] = {}

    def test(self, dataset: str) -> TrajectoryDataset:
        if dataset not in self._data:
            source = self.setup.sources.get(dataset, dataset)
            data = load_dataset(source, "test", self.opts.data_root)
            n = self.opts.max_scenes
            if n is not None and n < len(data):
                idx = np.unique(np.linspace(0, len(data) - 1, n).round().astype(int))
                data = TrajectoryDataset([data.scenes[i] for i in idx], data.info)
            self._data[dataset] = data
        return self._data[dataset]

    def of(self, job: Job) -> TrajectoryDataset:
        """The scenes a job evaluates: the test split, or for the full sampler (100 denoiser
        passes per sample) the most evenly spaced scenes that hold at most
        ``--full-sampler-agents`` agents when the split holds more."""
        data = self.test(job.dataset)
        cap = self.opts.full_sampler_agents
        if job.sampler != "full" or cap is None or data.num_agents <= cap:
            return data
        lo, hi = 1, len(data)  # the largest n whose evenly spaced subset fits the cap
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if data.evenly_spaced(mid).num_agents <= cap else (lo, mid - 1)
        return data.evenly_spaced(lo)

    def scorer(self, dataset: str) -> TrajectoryScorer | None:
        """The dataset's published denoiser as the scorer (None when there is none)."""
        if dataset not in self._scorers:
            den = denoiser_path(self.setup, dataset)
            self._scorers[dataset] = (
                TrajectoryScorer.from_checkpoint(den, self.opts.device) if den.is_file() else None
            )
        return self._scorers[dataset]


def cost(job: Job, splits: Splits) -> float:
    """The job's estimated cost (COST's units), for the progress bar."""
    if job.kind == "pretrain":
        return COST["pretrain"]
    agents = splits.of(job).num_agents
    if job.kind == "finetune":
        return COST["finetune"] + COST["pretrained"] * agents
    scored = denoiser_path(splits.setup, job.dataset).is_file()
    per_agent = COST.get(job.column, COST["pretrained"]) if scored else COST["unscored"]
    return per_agent * agents


# ----------------------------------------------------------------------------- running


def run_evaluation(job: Job, opts: argparse.Namespace, setup: Setup, splits: Splits) -> None:
    """Evaluate one column on the test split and store it with its key."""
    key = eval_key(job, opts, setup)
    if key is None:
        raise FileNotFoundError(f"{job.model} does not exist")
    test = splits.of(job)
    whole = splits.test(job.dataset)
    model = (ConstantVelocity() if job.model is None else
             ckpt.load_predictor(job.model, sampler=job.sampler, device=opts.device))  # fmt: skip
    wall, cpu = time.perf_counter(), cpu_seconds()[0]
    res = evaluate(model, test, opts.samples, opts.seed, opts.device, progress=False,
                   scorer=splits.scorer(job.dataset))  # fmt: skip
    record = {
        "key": key,
        "result": {k: v for k, v in res.items() if k != "bins"},
        "scenes": len(test), "agents": test.num_agents, "units": test.info.units,
        "split_scenes": len(whole), "split_agents": whole.num_agents,
        "wall_seconds": round(time.perf_counter() - wall, 2),
        "cpu_seconds": round(cpu_seconds()[0] - cpu, 2),
        "date": date.today().isoformat(), "machine": machine(), "command": command_line(),
    }  # fmt: skip
    write_json(state_file(setup, job.dataset, job.column, opts.max_scenes), record)


def training_command(job: Job, opts: argparse.Namespace, setup: Setup) -> list[str]:
    """The benchmark script that trains a job's missing model or rows; with ``setup.trained``
    (``--out``) it writes its run folders, rows and models there, and fine-tuning starts from
    the generator the tables evaluate (``models_of``)."""
    data = ["--data-root", opts.data_root] if opts.data_root else []
    scripts = ROOT / "benchmarks"
    where = []
    if setup.trained is not None:
        own = setup.trained.absolute()
        models = own / "models" if job.kind == "pretrain" else models_of(setup, job.dataset).parent
        where = ["--runs", str(own / "runs"), "--results", str(own / "results"),
                 "--models", str(models.absolute())]  # fmt: skip
    if job.kind == "pretrain":
        return [sys.executable, str(scripts / "pretrain.py"), "--dataset", job.dataset,
                "--train", "--no-full-eval", "--device", opts.device, *data, *where]  # fmt: skip
    start = trained_results(setup) / "meta" / f"finetune_start_{job.dataset}.json"
    return [sys.executable, str(scripts / "finetune.py"), "--dataset", job.dataset,
            *TRAIN_ARGS[job.column], "--seeds", str(job.seed), "--skip-done",
            *(["--no-start-validation"] if start.is_file() else []),
            *equal_budget_args(opts.minutes, opts.warmup,
                               opts.eval_minutes or opts.minutes / 4),  # fmt: skip
            "--device", opts.device, *data, *where]  # fmt: skip


def run_command(cmd: list[str], log: Path) -> int:
    """Run a training subprocess (one thread), its output appended to ``log``."""
    log.parent.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with open(log, "a") as handle:
        return subprocess.call(cmd, env=env, stdout=handle, stderr=subprocess.STDOUT)


def run_jobs(jobs: list[Job], opts, setup: Setup, splits: Splits) -> tuple[list, list]:
    """Run the jobs (in order) under one progress bar; returns (finished, failed) jobs."""
    done, failed = [], []
    total = sum(cost(j, splits) for j in jobs)
    bar = tqdm(total=total, desc="reproduce", unit="est-s", dynamic_ncols=True,
               bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} est-s [{elapsed}<{remaining}] "
               "{postfix}")  # fmt: skip
    with bar:
        for i, job in enumerate(jobs):
            bar.set_postfix_str(f"job {i + 1}/{len(jobs)}: {job.label}")
            wall = time.perf_counter()
            try:
                if job.kind == "evaluate":
                    run_evaluation(job, opts, setup, splits)
                    code = 0
                else:
                    name = f"reproduce-{job.kind}-{job.dataset}-{job.column}-s{job.seed}.log"
                    code = run_command(training_command(job, opts, setup), setup.logs / name)
            except (FileNotFoundError, TrajprefError) as exc:
                code, reason = 1, str(exc)
            else:
                reason = f"exit {code}"
            status = "ok" if code == 0 else f"FAILED ({reason})"
            tqdm.write(f"{job.label}: {status} in {(time.perf_counter() - wall) / 60:.1f} min")
            (done if code == 0 else failed).append(job)
            bar.update(cost(job, splits))
    return done, failed


# ----------------------------------------------------------------------------- cells


def cell_from_state(job: Job, opts: argparse.Namespace, setup: Setup, rows) -> dict | None:
    """The stored evaluation of a column, when its key matches the checkpoint there now."""
    record = read_json(state_file(setup, job.dataset, job.column, opts.max_scenes))
    key = eval_key(job, opts, setup)
    if record is None or key is None or record.get("key") != key:
        return None
    res = record["result"]
    cell = {k: res.get(k) for k in RESULT_KEYS}
    what = "constant velocity" if key["checkpoint"] is None else (
        f"`{key['checkpoint']}` ({key['sampler']} sampler)")  # fmt: skip
    subset = record.get("split_scenes", record["scenes"]) != record["scenes"]
    scenes = f"{record['scenes']} scenes" + (
        f" (--max-scenes {key['max_scenes']})" if key["max_scenes"] else
        f" of {record['split_scenes']}, evenly spaced ({record['agents']} of "
        f"{record['split_agents']} agents; --full-sampler-agents)" if subset else "")  # fmt: skip
    detail = f"evaluated {record['date']}: {what}, {scenes}, {record['wall_seconds']:.0f} s"
    method = column_method(job.column, opts.best)
    same = matching_rows(rows, job.dataset, method, key["samples"], key["seed"])
    if same and key["max_scenes"] is None and not subset:
        agree = all(abs(r[k] - cell[k]) <= ROW_TOLERANCE for r in same
                    for k in ("min_ade", "min_fde", "max_ats", "max_fts")
                    if r.get(k) is not None and cell.get(k) is not None)  # fmt: skip
        files = ", ".join(f"`{f}`" for f in sorted({r["_file"] for r in same}))
        detail += f"; {'matches' if agree else 'DIFFERS from'} the `{method}` rows in {files}"
    return {**cell, "source": "evaluated", "detail": detail, "units": record.get("units"),
            "date": record["date"], "seeds": [key["seed"]], "subset": subset,
            "seconds": record["wall_seconds"]}  # fmt: skip


def cell_from_rows(rows, dataset: str, method: str, samples: int) -> dict | None:
    """The mean over seeds of a method's test rows."""
    own = sorted(matching_rows(rows, dataset, method, samples), key=lambda r: r["seed"])
    if not own:
        return None
    cell = {}
    for k in RESULT_KEYS:
        xs = [r[k] for r in own if r.get(k) is not None]
        cell[k] = sum(xs) / len(xs) if xs else None
    seeds = [r["seed"] for r in own]
    dates = sorted({r["date"] for r in own})
    files = sorted({r["_file"] for r in own})
    detail = (f"from results rows, trained {', '.join(dates)}: method `{method}` in "
              + ", ".join(f"`{f}`" for f in files)
              + f", mean over {len(seeds)} seed{'s' if len(seeds) > 1 else ''} "
              f"({', '.join(map(str, seeds))})")  # fmt: skip
    return {**cell, "source": "rows", "detail": detail, "date": dates[-1], "seeds": seeds}


def missing_cell(note: str, detail: str) -> dict:
    return {**dict.fromkeys(RESULT_KEYS), "source": "missing", "note": note, "detail": detail}


def table_datasets(opts: argparse.Namespace, setup: Setup) -> list[str]:
    """The datasets the tables list, in table order: the ones this run was asked for and every
    other one that an earlier run stored an evaluation of, so that ``--datasets zara1`` adds to
    docs/reproduce.md instead of replacing it (their cells still count only while their
    stored keys match today's checkpoints and options)."""
    names = (*DATASETS, *setup.sources)
    stored = {
        d for d in names if any(state_file(setup, d, c, opts.max_scenes).is_file() for c in COLUMNS)
    }
    return [d for d in names if d in opts.datasets or d in stored]


def build_cells(opts: argparse.Namespace, setup: Setup, failed: list[Job]) -> dict:
    """Every cell of our side: {dataset: {column: cell}}, for ``table_datasets``."""
    rows = result_rows(setup)
    cells: dict[str, dict[str, dict]] = {}
    for dataset in table_datasets(opts, setup):
        out = cells[dataset] = {}
        gen = generator_path(setup, dataset)
        trainable = (setup.configs / f"{dataset}.yaml").is_file()
        for column in COLUMNS:
            method = column_method(column, opts.best)
            job = evaluation_job(opts, setup, dataset, column)
            if job is not None:
                cell = cell_from_state(job, opts, setup, rows)
            elif gen.is_file():
                cell = cell_from_rows(rows, dataset, method, opts.samples)
            else:
                cell = None
            if cell is None:
                if column != "cv" and not gen.is_file():
                    why = f"no published `{rel(gen)}`" + (
                        "" if trainable else f" and no `configs/{dataset}.yaml` to train one"
                    )
                    cell = missing_cell("no model", why)
                elif any(f.dataset == dataset and f.column in (column, method) for f in failed):
                    cell = missing_cell("failed", f"its job failed (logs in {rel(setup.logs)}/)")
                elif job is None:
                    how = "full mode trains them" if method in TRAIN_ARGS else "not trainable here"
                    cell = missing_cell("not trained", f"no published weights and no `{method}` "
                                        f"rows; {how}")  # fmt: skip
                else:
                    cell = missing_cell("not measured", "not evaluated yet (or its checkpoint "
                                        "changed since); run without --report")  # fmt: skip
            if cell["source"] != "missing" and cell.get("max_ats") is None:
                cell["note2"] = ("no scorer" if not denoiser_path(setup, dataset).is_file()
                                 else "–")  # fmt: skip
            out[column] = cell
    return cells


# ----------------------------------------------------------------------------- tables


def _pair(a: float | None, b: float | None, digits: int) -> str:
    return "–" if a is None or b is None else f"{a:.{digits}f} / {b:.{digits}f}"


def our_cell(cell: dict, metrics: tuple[str, str]) -> str:
    if cell["source"] == "missing":
        return cell["note"]
    a, b = cell.get(metrics[0]), cell.get(metrics[1])
    if a is None or b is None:
        return cell.get("note2", "–")
    mark = " †" if cell["source"] == "rows" else " ‡" if cell.get("subset") else ""
    return _pair(a, b, 3) + mark


def pair_of(cell: dict, metrics: tuple[str, str]) -> tuple[float, float] | None:
    a, b = cell.get(metrics[0]), cell.get(metrics[1])
    return None if a is None or b is None else (a, b)


def eth_ucy_mean(values: list[tuple[float, float] | None]) -> tuple[float, float] | None:
    if len(values) != len(ETH_UCY) or any(v is None for v in values):
        return None
    return (sum(v[0] for v in values) / len(values), sum(v[1] for v in values) / len(values))


def comparison_table(cells: dict, paper: dict, table: str, best: str) -> str:
    """Ours beside the paper's: one line per dataset and the mean over the ETH/UCY folds."""
    spec = paper["tables"][table]
    metrics = tuple(spec["metrics"])
    reference = paper["references"][LED_REFERENCE] if table == "table1" else None
    ours = [LABELS.get(c, f"best with the score ({best})") for c in COLUMNS]
    theirs = [f"paper: {c}" for c in PAPER_COLUMNS] + (["LED (its authors)"] if reference else [])
    lines = ["| dataset | " + " | ".join(ours + theirs) + " |",
             "|---|" + "---|" * (len(ours) + len(theirs))]  # fmt: skip
    for dataset, row in cells.items():
        name = dataset + (" (px)" if row["cv"].get("units") == "px" else "")
        mine = [our_cell(row[c], metrics) for c in COLUMNS]
        printed = spec["rows"].get(dataset)
        if printed is None:
            paper_cells = ["not in the paper's table"] * len(PAPER_COLUMNS)
        else:
            paper_cells = [_pair(*printed[c], 2) for c in PAPER_COLUMNS]
        if reference:
            ref = reference["rows"].get(dataset)
            paper_cells.append(_pair(*ref, 2) if ref else "–")
        lines.append(f"| {name} | " + " | ".join(mine + paper_cells) + " |")
    if all(d in cells for d in ETH_UCY):
        mine = []
        for c in COLUMNS:
            vals = [pair_of(cells[d][c], metrics) for d in ETH_UCY]
            mean = eth_ucy_mean(vals)
            have = sum(v is not None for v in vals)
            mine.append(_pair(*mean, 3) if mean else f"– ({have} of 5)")
        paper_cells = [_pair(*eth_ucy_mean([spec["rows"][d][c] for d in ETH_UCY]), 2)
                       for c in PAPER_COLUMNS]  # fmt: skip
        if reference:
            paper_cells.append(_pair(*eth_ucy_mean([reference["rows"][d] for d in ETH_UCY]), 2))
        lines.append("| mean of the 5 ETH/UCY folds | " + " | ".join(mine + paper_cells) + " |")
    return "\n".join(lines)


def paper_table(paper: dict, table: str) -> str:
    """The paper's table as printed (all its columns and its AVG row)."""
    spec = paper["tables"][table]
    cols = paper["columns"]
    lines = ["| dataset | " + " | ".join(paper["column_names"][c] for c in cols) + " |",
             "|---|" + "---|" * len(cols)]  # fmt: skip
    for dataset, row in spec["rows"].items():
        lines.append(f"| {dataset} | " + " | ".join(_pair(*row[c], 2) for c in cols) + " |")
    return "\n".join(lines)


def sources_list(cells: dict, best: str) -> str:
    lines = []
    for dataset, row in cells.items():
        for column in COLUMNS:
            cell = row[column]
            label = LABELS.get(column, f"best ({best})")
            lines.append(f"- {dataset}, {label}: {cell['detail']}")
    return "\n".join(lines)


FULL_MODE_COST = (
    "about 3 h of fine-tuning (3 methods x 8 datasets x 1 seed, the default `--seeds 0`, at "
    "about 7.6 wall minutes a job: in the repository's invocation log, the full-mode runs of "
    "2026-12-03 (zara2, univ) and 2026-12-06 (sdd) took 4,100 s for 9 fine-tuning jobs and one "
    "12 s evaluation, 4.8-10.1 min a job by dataset), plus about 177 min to pretrain the "
    "eight generators (the sum of the eight "
    "default configs' \"estimated alone\" minutes in the README's cost table, "
    "`benchmarks/results/meta/train_cost.json`; run beside other jobs they took longer), plus "
    "quick mode's evaluations"
)
"""Full mode's cost from scratch, from the stored logs named in it (not measured as a whole)."""


def quick_cost(setup: Setup, cells: dict) -> dict:
    """What quick mode costs from scratch: the newest logged run that evaluated every dataset
    with nothing stored (the repository's log), and the evaluated cells' own times."""
    runs = [e for e in read_json(setup.repository_log, [])
            if e["mode"] == "quick" and set(DATASETS) <= set(e["datasets"])
            and e["jobs_skipped"] == 0 and e["jobs_run"] > 0 and not e["jobs_failed"]
            and not e["interrupted"] and not e.get("max_scenes")]  # fmt: skip
    per_dataset = {d: sum(c.get("seconds") or 0 for c in row.values()) for d, row in cells.items()}
    return {"run": runs[-1] if runs else None, "cells": per_dataset}


def how_to(cost: dict) -> str:
    """The "How to reproduce" section: the commands and what they cost."""
    run, per = cost["run"], cost["cells"]
    top = sorted((d for d in per if per[d]), key=per.get, reverse=True)[:2]
    timed = (
        f"the evaluation times of the cells listed at the end add up to "
        f"{sum(per.values()) / 60:.0f} min, {' and '.join(top)} {sum(per[d] for d in top) / 60:.0f}"
        " min of it, most of that Table 2's scoring (the script's estimates per agent: "
        f"constant velocity {COST['cv']} s scored, {COST['unscored']} s unscored)"
        if top
        else "no cell here has an evaluation time yet"
    )
    if run is None:
        measured = f"No quick run of all eight datasets from scratch is logged; {timed}."
    else:
        measured = (
            f"From scratch on all eight datasets it took {run['wall_seconds'] / 60:.0f} min "
            f"({run['wall_seconds']:,.0f} s) on {run['date']}, {run['machine']} (the "
            f"repository's log, `benchmarks/results/meta/reproduce/invocations.json`); {timed}."
        )
    return "\n".join(
        [
            "## How to reproduce",
            "",
            "Every stored cell keys on what it depends on (checkpoint and denoiser hashes, "
            "sampler, K, seed), so a run on a tree whose cells are all stored finds every job "
            "done and measures nothing. To measure again:",
            "",
            "- **Quick mode**, no training: `python benchmarks/reproduce.py --quick --fresh --out "
            "out/reproduce --data-root ../shared/data` evaluates constant velocity and the "
            "published checkpoints' full sampler and leapfrog generator on every test split, for "
            "both tables (the † cells are read from result rows, not trained), and writes "
            "`out/reproduce/reproduce.md`; `--out` keeps this page and its stored state as they "
            "are (a new folder starts from nothing, so `--fresh` is only needed without it, where "
            f"it re-measures into this page). {measured}",
            "- **Full mode**, `python benchmarks/reproduce.py --data-root ../shared/data`, also "
            "trains what is missing, one job at a time: the generator of a dataset that has a "
            "config but none published (`benchmarks/pretrain.py`) and the RLHF, RLHF-ReS and "
            "rlhf-set rows of each seed that has none (`benchmarks/finetune.py` with "
            "`benchmarks/equal_budget.py`'s arguments, 4 CPU minutes of training steps a run). "
            "Where every row exists and every generator is published it trains nothing: to "
            "retrain, work in a copy of the repository and move the rows "
            "(`benchmarks/results/finetune_<D>.json`, `finetune_<D>_set.json`) and run folders "
            "(`runs/<D>-<method>-s<seed>*`) away first. Its training writes `runs/`, `models/` "
            "and result rows in the repository it runs in, or with `--out DIR` under `DIR/runs/`, "
            "`DIR/models/` and `DIR/results/` (the tables read those rows beside the "
            "repository's), leaving the repository's files as they are. From scratch "
            f"it would take {FULL_MODE_COST}.",
            "- **One column by itself**: the † columns (RLHF, RLHF-ReS, best) are the rows of "
            "`python benchmarks/equal_budget.py --datasets D --methods rlhf rlhf-res rlhf-set "
            "--seeds 0 --minutes 4 --data-root ../shared/data` (docs/rlhf.md); the generators "
            "behind `full sampler` and `pretrained` are trained and published by `python "
            "benchmarks/pretrain.py --dataset D --train --data-root ../shared/data` "
            "(docs/pretraining.md). Both skip or resume what is already there.",
            "- **A smoke run**: `--max-scenes N` evaluates N evenly spread test scenes per dataset "
            "and writes under `runs/reproduce/` (or `--out`), never this page or its stored state.",
        ]
    )


DEPARTURES = (
    "RLHF settings: the RLHF, RLHF-ReS and best cells are runs at the project's fine-tuning "
    "defaults, not `--preset paper`; among their departures, RLHF's loss weights are 0.3 / 1.5 "
    "(RLHF-ReS's pair) where the paper's grid search gave alpha_p = 1, alpha_v = 5 (docs/rlhf.md, "
    '"The `paper` preset and the defaults that depart from it"). The weights were not measured '
    "apart; the `paper` preset as a whole diverged on zara1's validation split within 36 steps "
    '(docs/rlhf.md, "zara1: a first, small measurement (2026-11-22)").',
    "RLHF budget: each fine-tuning run trains for 4 minutes of its own CPU time on one thread "
    '(about 30 optimiser steps for the RL methods; docs/rlhf.md, "The equal-budget table '
    '(2026-11-23)"), where the paper trained for 100 epochs over 12 hours (ETH/UCY) or 24 hours '
    "(NBA, SDD, Robo) on a GPU (Sec. 7.1). At the defaults the longest runs recorded are a "
    '6-minute pilot (docs/rlhf.md, "An equal-budget pilot (2026-11-23)"); 240 steps at other '
    "settings (stronger exploration, RL alone, on a GPU) raised the reward and worsened "
    'minFDE20 on zara1, eth and Robo (docs/rlhf.md, "Can the reward be raised at all? RL '
    "alone and stronger exploration (2026-11-22)\"). The paper's budget was not run.",
    "Robo: the paper trained on its own Robo training split, which is not public; our Robo "
    "models train on robo-sim, our simulator of the scenario, are chosen on the official val "
    'split and tested on the official test split (docs/data.md, "Per dataset"; '
    "docs/robo_sim.md), so every Robo cell is a sim-to-real number. Real robots in training "
    '(`robo-mix`) were measured for the generator only (docs/pretraining.md, "Robo with real '
    'data in training (`robo-mix`, 2026-11-23)"), not for the RLHF columns.',
    "Protocol: every cell of ours counts every window with at least one fully observed agent "
    '(`all`; docs/data.md, "Evaluation protocols": the windows of LED\'s released ETH/UCY '
    "data); the paper does not name its protocol. Constant velocity and the pretrained "
    "generators of the ETH/UCY folds under `sgan` (at least two agents) are in "
    "`benchmarks/results/protocol_sgan.json`; the other columns were not measured under it.",
)
"""Notes on how our columns depart from the paper's setup, each with its measurement."""


def render(cells: dict, paper: dict, opts, cpu: dict, cost: dict | None = None) -> str:
    """docs/reproduce.md (or a ``--out`` folder's reproduce.md)."""
    last = cpu["last_run"]
    if last is None:
        runs = "Nothing has been measured by this script yet."
    else:
        runs = (
            f"The last run that measured: `{last['command']}` on {last['date']}, "
            f"{last['machine']}: {last['wall_seconds'] / 60:.1f} min, {_hours(last):.3f} "
            f"CPU-hours{' (interrupted)' if last['interrupted'] else ''}. All runs that built "
            f"the stored state ({cpu['invocations']}): "
            f"{cpu['all_invocations_hours']:.3f} CPU-hours (this script and its training "
            "subprocesses; rows taken from `benchmarks/results/` cost what their own "
            "`train_seconds` say)."
        )
    scenes = (f" Evaluated cells use {opts.max_scenes} evenly spread test scenes per dataset "
              "(`--max-scenes`), not the whole split." if opts.max_scenes else "")  # fmt: skip
    parts = [
        "<!-- Generated by benchmarks/reproduce.py; do not edit by hand: rerun it. -->",
        "",
        "# The paper's Tables 1 and 2, rebuilt",
        "",
        f"Tables written by `{command_line()}` on {date.today().isoformat()}. {runs}{scenes}",
        "",
        how_to(cost or {"run": None, "cells": {}}),
        "",
        f"Test splits, K = {opts.samples}, seed {opts.seed}. Our columns: constant velocity, the "
        "full 100-step sampler and the leapfrog generator (`pretrained`) of "
        "`models/<D>/generator.safetensors`, RLHF, RLHF-ReS, and the best score-using method "
        f"at K = 20 (`{opts.best}`; see the script's docstring for the choice). † marks a cell "
        "taken from `benchmarks/results/` rows (weights not published); the others were "
        "evaluated from the published checkpoints. ‡ marks a full-sampler cell measured on "
        "evenly spaced test scenes only (at most `--full-sampler-agents` agents, on the "
        'largest splits; sizes in the list at the end). "no model": no published generator for '
        'the dataset; "not trained": no rows yet (full mode trains them). The paper\'s numbers '
        'are typed in from its tables (`benchmarks/paper_tables.json`); "LED (its authors)" '
        "is LED's result as others quote it, for comparison with the paper's run of LED: its "
        "ETH/UCY cells as printed in the MoRE preprint's Table 1 (second-hand, not checked "
        "against LED's own paper), its SDD cell as the PPT paper quotes it, its NBA cell from "
        "LED's README (`benchmarks/peers.json`). When all "
        "five ETH/UCY folds are listed, a last line gives their mean (the paper's: our mean of "
        "its five printed rows).",
        "",
        "## Table 1: minADE20 / minFDE20 (lower is better; metres, SDD in pixels)",
        "",
        comparison_table(cells, paper, "table1", opts.best),
        "",
        "## Table 2: maxATS20 / maxFTS20 (higher is better)",
        "",
        "Each side is scored by its own denoiser (ours: `models/<D>/denoiser.safetensors`, every "
        "3rd of 100 steps, `docs/score.md`), so absolute values are not comparable between the "
        'paper and us; orderings within a row are, up to the score\'s noise. "no scorer": the '
        "dataset has no published denoiser. The cells without † are scored with the noise "
        "keyed to each agent's place in its own scene (since 2026-12-05; docs/score.md, \"The "
        'trajectory diffusion score", bullet "Common random numbers"; a stored cell keys on '
        "the layout and is measured again when it changes). The † cells are means of the "
        "equal-budget rows, scored before that change with the noise keyed to each agent's "
        "index in the evaluation batch; their weights are not published, so they cannot be "
        "scored again. Compare a † cell with the other † cells, not with the rest of its row: "
        "the change of layout alone moved the pretrained column's five-fold mean from "
        "0.436 / 0.371 to 0.444 / 0.383 (eth 0.668 / 0.572 -> 0.688 / 0.599, robo "
        "0.337 / 0.332 -> 0.338 / 0.328), while Table 1 did not change.",
        "",
        comparison_table(cells, paper, "table2", opts.best),
        "",
        "## Notes",
        "",
        *[f"- {n}" for n in paper["notes"]],
        f"- SDD: {paper['text_only']['sdd']}",
        *[f"- {n}" for n in DEPARTURES],
        "- Sampling: the published generators' tau denoising steps are posterior means since "
        '2026-11-24 (docs/pretraining.md, "The switch"), and the default generators have had '
        "none (`model.tau: 0`) since 2026-11-27 to 2026-12-01, so the evaluated `pretrained` "
        "cells are their samples as drawn; the RLHF, RLHF-ReS and best cells that come from "
        "result rows (†) are equal-budget runs from the current generators, each trained on "
        "the date its source line below gives (docs/rlhf.md); the older runs from the "
        "ancestral-step generators are rows with the suffix `-ancestral`.",
        "",
        "## Where each cell comes from",
        "",
        sources_list(cells, opts.best),
        "",
        "## The paper's tables as printed",
        "",
        f"Source: {paper['source']}.",
        "",
        paper_table(paper, "table1"),
        "",
        paper_table(paper, "table2"),
        "",
    ]
    return "\n".join(parts)


# ----------------------------------------------------------------------------- main


def parse_args(argv: list[str] | None, setup: Setup) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="no training: published checkpoints and existing rows only",
    )
    parser.add_argument(
        "--report", action="store_true", help="run nothing: rebuild the tables from what is stored"
    )
    parser.add_argument(
        "--fresh",
        action="store_true",
        help="evaluate every cell again, even where a stored evaluation matches (training jobs "
        "are still skipped where their rows exist)",
    )
    parser.add_argument(
        "--out",
        default=None,
        help="write this script's state, report (reproduce.md), summary (reproduce.json), "
        "invocation log and training logs under this folder instead of the repository "
        "(a new folder starts from nothing); full mode's training writes its run folders, "
        "result rows and pretrained models there too (runs/, results/, models/), and the "
        "tables read them beside the repository's",
    )
    names = (*DATASETS, *setup.sources)
    parser.add_argument(
        "--datasets",
        nargs="+",
        default=list(DATASETS),
        choices=names,
        help="measure or train these only (default: all); the tables also keep the stored "
        "cells of the others",
    )
    parser.add_argument(
        "--best",
        default="rlhf-set",
        help="the result-row method of the 'best with the score' column",
    )
    parser.add_argument(
        "--seeds", nargs="+", type=int, default=[0], help="full mode: the seeds to train"
    )
    parser.add_argument(
        "--minutes",
        type=float,
        default=4.0,
        help="full mode: CPU minutes of fine-tuning per run (equal_budget.py's)",
    )
    parser.add_argument(
        "--warmup",
        type=int,
        default=EQUAL_BUDGET_WARMUP,
        help="full mode: learning-rate warm-up steps (equal_budget.py's)",
    )
    parser.add_argument(
        "--eval-minutes",
        type=float,
        default=None,
        help="full mode: validate after every this many CPU minutes (default: --minutes / 4, "
        "as equal_budget.py and trajpref finetune --equal-budget)",
    )
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="evaluation seed")
    parser.add_argument(
        "--max-scenes",
        type=int,
        default=None,
        help="evaluate on this many evenly spread test scenes: a smoke run, stored apart from "
        "the whole split's cells and reported under --out (default runs/reproduce/), never in "
        "docs/reproduce.md",
    )
    parser.add_argument(
        "--full-sampler-agents",
        type=int,
        default=6000,
        help="evaluate the full sampler (100 steps, ~15x the leapfrog's cost) on the evenly "
        "spaced test scenes holding at most this many agents, on the splits that hold more "
        "(univ, NBA); 0: the whole split (default 6000)",
    )
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(argv)
    if args.full_sampler_agents < 0:
        parser.error("--full-sampler-agents must be >= 0")
    args.full_sampler_agents = args.full_sampler_agents or None
    if args.max_scenes is not None and args.max_scenes < 1:
        parser.error("--max-scenes must be >= 1")
    if args.samples < 1:
        parser.error("--samples must be >= 1")
    if args.fresh and args.report:
        parser.error("--fresh measures again; --report measures nothing")
    args.datasets = [d for d in names if d in args.datasets]  # table order, no repeats
    return args


def _hours(entry: dict) -> float:
    return (entry["cpu_seconds_own"] + entry["cpu_seconds_children"]) / 3600


def log_invocation(setup: Setup, entry: dict | None, max_scenes: int | None = None) -> dict:
    """Append a run's entry to the log (None: a ``--report``, not logged); returns the CPU
    totals and the last run that ran jobs (or tried to), over the runs of the same subset
    (``--max-scenes``; None: the whole split) only."""
    path = setup.state / "invocations.json"
    log = read_json(path, [])
    if entry is not None:
        log.append(entry)
        write_json(path, log)
    log = [e for e in log if e.get("max_scenes") == max_scenes]
    return {
        "this_invocation_hours": _hours(entry) if entry else 0.0,
        "all_invocations_hours": sum(_hours(e) for e in log),
        "invocations": len(log),
        "last_run": log[-1] if log else None,
    }


def main(argv: list[str] | None = None, setup: Setup | None = None) -> dict:
    setup = setup or Setup()
    opts = parse_args(argv, setup)
    if opts.out or (opts.max_scenes and setup.out is None):
        out = Path(opts.out) if opts.out else setup.scratch  # a subset never writes the tables
        # with --out the training subprocesses write there too (a smoke run's, without
        # --out, into the repository as a run without --max-scenes)
        setup = replace(setup, out=out, logs=out / "logs",
                        trained=out if opts.out else setup.trained)  # fmt: skip
    paper = json.loads(setup.paper.read_text())
    setup.state.mkdir(parents=True, exist_ok=True)
    wall0, (own0, kids0) = time.perf_counter(), cpu_seconds()
    done: list[Job] = []
    failed: list[Job] = []
    skipped = 0
    interrupted = True
    try:
        if not opts.report:
            splits = Splits(opts, setup)
            rows = result_rows(setup)
            jobs = plan(opts, setup)
            todo = [j for j in jobs if (opts.fresh and j.kind == "evaluate")
                    or not is_done(j, opts, setup, rows)]  # fmt: skip
            skipped = len(jobs) - len(todo)
            print(f"{skipped} of {len(jobs)} jobs already done; {len(todo)} to run")
            if setup.trained is None and setup.out and any(j.kind != "evaluate" for j in todo):
                print("note: the training jobs write runs/, models/ and result rows in the "
                      f"repository, not under {setup.out}", file=sys.stderr)  # fmt: skip
            done, failed = run_jobs(todo, opts, setup, splits)
        interrupted = False
    finally:
        own, kids = cpu_seconds()
        entry = {"date": date.today().isoformat(), "command": command_line(),
                 "machine": machine(), "mode": "quick" if opts.quick else "full",
                 "datasets": opts.datasets, "wall_seconds": round(time.perf_counter() - wall0, 1),
                 "cpu_seconds_own": round(own - own0, 3),
                 "cpu_seconds_children": round(kids - kids0, 3),
                 "jobs_run": len(done), "jobs_failed": len(failed), "jobs_skipped": skipped,
                 "interrupted": interrupted,
                 **({"max_scenes": opts.max_scenes} if opts.max_scenes else {})}  # fmt: skip
        cpu = log_invocation(setup, None if opts.report else entry, opts.max_scenes)
    cells = build_cells(opts, setup, failed)
    wall = time.perf_counter() - wall0
    doc = render(cells, paper, opts, cpu, quick_cost(setup, cells))
    summary = {
        "generated_by": command_line(), "date": date.today().isoformat(), "machine": machine(),
        "mode": "report" if opts.report else entry["mode"], "datasets": opts.datasets,
        "table_datasets": list(cells),
        "samples": opts.samples, "seed": opts.seed, "best_method": opts.best,
        "max_scenes": opts.max_scenes, "wall_seconds": round(wall, 1), "cpu_hours": cpu,
        "jobs": {"run": [j.label for j in done], "failed": [j.label for j in failed],
                 "skipped": skipped},
        "paper": rel(setup.paper), "cells": cells,
    }  # fmt: skip
    summary_path, report = setup.summary_file(opts.max_scenes), setup.report(opts.max_scenes)
    write_json(summary_path, summary)
    report.parent.mkdir(parents=True, exist_ok=True)
    report.write_text(doc)
    print(comparison_table(cells, paper, "table1", opts.best))
    print()
    print(comparison_table(cells, paper, "table2", opts.best))
    print(f"\n{wall / 60:.1f} min, {cpu['this_invocation_hours']:.3f} CPU-hours "
          f"({cpu['all_invocations_hours']:.3f} over {cpu['invocations']} invocations); "
          f"wrote {rel(report)} and {rel(summary_path)}")  # fmt: skip
    if failed:
        print(f"{len(failed)} jobs failed: {[j.label for j in failed]}", file=sys.stderr)
    return summary


if __name__ == "__main__":
    sys.exit(1 if main()["jobs"]["failed"] else 0)
