"""Validation curves of several training runs side by side, grouped by seed.

A candidate is judged against a control by the validation its runs kept (the epoch with the
lowest ``val_score``, the checkpoint the loop saved), over seeds, and by where its curve runs
at the same share of the schedule (docs/pretraining.md compares candidates this way). The
schedule is a run's epochs, or for a run that its time budget ended (``max_minutes``), the
budget: its validations stand at the budget clock's seconds they were logged at. This module
reads each run's ``<stage>_metrics.jsonl`` and ``<stage>_config.yaml`` and computes exactly
that; ``trajpref compare`` prints it. Fine-tuning's validation of its start (epoch 0) is no
epoch and is not read (``read_metrics``).
"""

from __future__ import annotations

import contextlib
import math
import statistics
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trajpref.config import load_config
from trajpref.errors import TrajprefError, TrajprefWarning
from trajpref.io import read_checkpoint_header
from trajpref.models.timing import UNKNOWN_UNITS, model_timing, same_units
from trajpref.train.loop import read_metrics
from trajpref.train.run import STAGE_NAMES

STAGES = tuple(STAGE_NAMES.values())
"""Stages whose runs can be compared, by the name their files carry (each is also the config
section with its ``epochs``)."""

DEFAULT_METRICS = {"denoiser": ("val_denoise_loss",)}
"""The metrics a stage shows unless told (``default_metrics``); the others validate the
generator's samples and show ``val_min_ade`` and ``val_min_fde``."""


def default_metrics(stage: str) -> tuple[str, ...]:
    """What ``trajpref compare --stage STAGE`` shows without ``--metrics``."""
    return DEFAULT_METRICS.get(stage, ("val_min_ade", "val_min_fde"))


def stage_config_path(run_dir: str | Path, stage: str) -> Path:
    """The resolved config a stage of ``run_dir`` trained with: ``<stage>_config.yaml``, which
    each stage writes, or for folders written before it the run's ``config.yaml`` (the last
    stage's, which may not hold an earlier stage's settings)."""
    own = Path(run_dir) / f"{stage}_config.yaml"
    return own if own.is_file() else Path(run_dir) / "config.yaml"


@dataclass(frozen=True)
class RunCurve:
    """One run's validation record."""

    run: str
    """The run folder, as given."""
    epochs: int
    """The stage's scheduled epochs (its ``<stage>_config.yaml``, ``stage_config_path``;
    without one, its last logged epoch)."""
    points: dict[int, dict[str, float]]
    """{epoch: {metric: value}} at each validated epoch, in order."""
    kept: int
    """The validated epoch with the lowest ``val_score``: the checkpoint the loop kept."""
    budget: float | None = None
    """The time budget in minutes (``max_minutes``) when it ended the run: the schedule is
    then the budget, not ``epochs``; None for a run that its epochs ended (or not yet)."""
    clock: str = "wall"
    """What the budget counted (``budget_clock``)."""
    seconds: dict[int, float] = field(default_factory=dict)
    """{epoch: seconds of the budget's clock} at each validated epoch (a budget-ended run)."""
    setting: dict[str, Any] = field(default_factory=dict)
    """What its validation was measured on (``run_setting``): the data, where it chose its
    epoch, units, pace and samples; ``setting_differences`` compares runs by it."""

    def at(self, epoch: int) -> dict[str, float]:
        """The metrics validated at ``epoch``."""
        return self.points[epoch]

    def nearest(self, share: float) -> int:
        """The validated epoch closest to ``share`` of the schedule (the earlier on a tie):
        of its epochs, or of its time budget for a run the budget ended. The whole schedule
        (``share`` 1) is the run's final validation: the step that crosses a time budget
        overshoots it, so the final validation can lie further past the budget than the one
        before lies short of it, and the nearest would miss the run's end."""
        if share >= 1:
            return max(self.points)
        if self.budget is not None:
            target = share * 60 * self.budget
            return min(self.points, key=lambda e: (abs(self.seconds[e] - target), e))
        target = share * self.epochs
        return min(self.points, key=lambda e: (abs(e - target), e))

    def schedule(self, epoch: int) -> str:
        """Where ``epoch`` stands in the schedule: ``4 of 8``, or for a budget-ended run
        ``22 (0.28 of 0.3 min, cpu budget)``."""
        if self.budget is None:
            return f"{epoch} of {self.epochs}"
        minutes = self.seconds[epoch] / 60
        return f"{epoch} ({minutes:.2g} of {self.budget:g} min, {self.clock} budget)"


SETTING_KEYS = ("data.dataset", "validated on", "units", "data.time_step", "seconds per step",
                "windows", "model.samples")  # fmt: skip
"""What ``run_setting`` records of a run, in the order a warning names them."""


def run_setting(run_dir: str | Path, stage: str) -> dict[str, Any]:
    """What a stage's validation numbers were measured on, from its ``<stage>_config.yaml``
    (``stage_config_path``) and, where it has one, its checkpoint's header (the units and
    seconds per step its data were read at, ``models.timing.model_timing``): the keys of
    ``SETTING_KEYS`` that it can tell (``validated on``: ``data.val_dataset``'s val split,
    else the dataset's own, with a held-out scene; ``windows``: the observed + future
    frames its data were cut into, ``model.t_hist`` + ``model.t_fut``; ``model.samples`` for
    the generator's
    stages only, the denoiser's validation draws none). Empty where neither can be read."""
    out: dict[str, Any] = {}
    config = stage_config_path(run_dir, stage)
    if config.is_file():
        with contextlib.suppress(TrajprefError, OSError, ValueError, TypeError):
            cfg = load_config(config)
            data = cfg.data
            val = f"{data.val_dataset}'s val split" if data.val_dataset else "its own val split"
            if data.holdout_scene:
                val = f"held-out scene {data.holdout_scene}*"
            out = {"data.dataset": data.dataset, "validated on": val,
                   "units": data.units, "data.time_step": data.time_step,
                   "windows": f"{cfg.model.t_hist} + {cfg.model.t_fut} frames"}  # fmt: skip
            if stage != "denoiser":
                out["model.samples"] = cfg.model.samples
    with contextlib.suppress(TrajprefError, OSError, ValueError, TypeError, KeyError):
        timing = model_timing(read_checkpoint_header(Path(run_dir) / f"{stage}.safetensors"))
        out["units"] = None if timing["units"] in UNKNOWN_UNITS else timing["units"]
        if timing["step"] is not None:
            out["seconds per step"] = round(float(timing["step"]), 6)
    return out


def _same_setting(key: str, a: Any, b: Any) -> bool:
    if key == "units":
        return same_units(str(a), str(b))
    if isinstance(a, float) and isinstance(b, (int, float)):
        return math.isclose(a, b, rel_tol=0.01)
    return a == b


def setting_differences(groups: dict[str, list[RunCurve]]) -> list[str]:
    """One line per run whose validation was measured on other data or settings than the
    first group's first run's (``RunCurve.setting``: dataset, validation data, units, time
    step, seconds per step, samples), naming the fields that differ, each ``theirs -> its``;
    empty when all match (a key one of the two cannot tell, None, is not compared: a
    built-in dataset's config leaves its units to the dataset, a run without its checkpoint
    cannot say them)."""
    curves = [c for cs in groups.values() for c in cs]
    if len(curves) < 2:
        return []
    first, lines = curves[0], []
    for c in curves[1:]:
        diff = [f"{k} {first.setting[k]} -> {c.setting[k]}" for k in SETTING_KEYS
                if first.setting.get(k) is not None and c.setting.get(k) is not None
                and not _same_setting(k, first.setting[k], c.setting[k])]  # fmt: skip
        if diff:
            lines.append(f"{c.run} was validated otherwise than {first.run} ({'; '.join(diff)}):"
                         " its numbers and their change are not measured alike")  # fmt: skip
    return lines


def read_curve(run_dir: str | Path, stage: str, metrics: tuple[str, ...]) -> RunCurve:
    """The validation curve of ``stage`` in ``run_dir`` for the named ``metrics`` (keys of the
    metrics log such as ``val_min_fde``). A clear error when the run has no log of that stage,
    no validation, or lacks a metric."""
    if stage not in STAGES:
        raise TrajprefError(f"stage must be one of {', '.join(STAGES)}, got {stage!r}")
    if not Path(run_dir).is_dir():
        raise TrajprefError(f"{run_dir}: no such run folder")
    rows = read_metrics(run_dir, stage)
    if not rows and read_metrics(run_dir, stage, start=True):  # the start's validation alone
        raise TrajprefError(f"{run_dir}: the {stage} stage has not validated an epoch yet "
                            "(its log holds the start's validation only)")  # fmt: skip
    if not rows:
        others = [s for s in STAGES if s != stage and read_metrics(run_dir, s)]
        hint = (f"; it holds {', '.join(others)} logs: --stage {others[-1]}" if others
                else " (is it a run folder?)")  # fmt: skip
        raise TrajprefError(f"{run_dir}: no {stage}_metrics.jsonl{hint}")
    validated = [r for r in rows if "val_score" in r]
    if not validated:
        raise TrajprefError(f"{run_dir}: the {stage} stage has not validated yet")
    for name in metrics:
        if name not in validated[0]:
            known = sorted(k for k in validated[0] if k.startswith("val_"))
            raise TrajprefError(f"{run_dir}: no metric {name!r}; validated: {', '.join(known)}")
    points = {int(r["epoch"]): {m: float(r[m]) for m in metrics} for r in validated}
    kept = int(min(validated, key=lambda r: r["val_score"])["epoch"])
    config = stage_config_path(run_dir, stage)
    setting = run_setting(run_dir, stage)
    if not config.is_file():
        return RunCurve(str(run_dir), int(rows[-1]["epoch"]), points, kept, setting=setting)
    section = getattr(load_config(config), stage)
    key = f"budget_{section.budget_clock}_seconds"  # the clock max_minutes counted
    ended = (section.max_minutes is not None and rows[-1]["epoch"] < section.epochs
             and all(key in r for r in validated)
             and rows[-1].get(key, 0.0) >= 60 * section.max_minutes)  # fmt: skip
    if not ended:
        return RunCurve(str(run_dir), int(section.epochs), points, kept, setting=setting)
    seconds = {int(r["epoch"]): float(r[key]) for r in validated}
    return RunCurve(str(run_dir), int(section.epochs), points, kept, section.max_minutes,
                    section.budget_clock, seconds, setting)  # fmt: skip


def parse_group(text: str) -> tuple[str, list[str]]:
    """``NAME=DIR[,DIR...]`` (a named group of seeds) or ``DIR`` (a group of one, named by it)."""
    name, sep, dirs = text.partition("=")
    if not sep:
        return text, [text]
    runs = [d for d in dirs.split(",") if d]
    if not name or not runs:
        raise TrajprefError(f"a group is NAME=DIR[,DIR...] or DIR, got {text!r}")
    return name, runs


def summarise(groups: dict[str, list[RunCurve]], metrics: tuple[str, ...]) -> dict[str, Any]:
    """Each group's kept values: mean and sample standard deviation (None for one run) per
    metric, and the relative change of the mean against the first group's. A ``TrajprefWarning``
    per run validated on other data or settings than the first run (``setting_differences``):
    the numbers are still summarised."""
    if not groups:
        raise TrajprefError("nothing to compare: give at least one run")
    for line in setting_differences(groups):
        warnings.warn(line, category=TrajprefWarning, stacklevel=2)
    out: dict[str, Any] = {}
    first: dict[str, float] | None = None
    for name, curves in groups.items():
        kept = {m: [c.at(c.kept)[m] for c in curves] for m in metrics}
        mean = {m: statistics.fmean(v) for m, v in kept.items()}
        sd = {m: statistics.stdev(v) if len(v) > 1 else None for m, v in kept.items()}
        if first is None:
            first = mean
        change = {m: (mean[m] / first[m] - 1) if first[m] else math.nan for m in metrics}
        out[name] = {
            "runs": [
                {
                    "run": c.run,
                    "kept_epoch": c.kept,
                    "epochs": c.epochs,
                    "budget_minutes": c.budget,
                    "schedule": c.schedule(c.kept),
                    **c.at(c.kept),
                }
                for c in curves
            ],  # fmt: skip
            "mean": mean,
            "sd": sd,
            "change": change,
        }
    return out


def curve_rows(
    groups: dict[str, list[RunCurve]], metrics: tuple[str, ...], shares: tuple[float, ...]
) -> list[dict[str, Any]]:
    """For each share of the schedule (of a budget-ended run's time budget), every run's
    metrics at its nearest validated epoch; at share 1, its final validation
    (``RunCurve.nearest``)."""
    for s in shares:
        if not 0 < s <= 1:
            raise TrajprefError(f"shares lie in (0, 1], got {s}")
    rows = []
    for s in shares:
        row: dict[str, Any] = {"share": s, "runs": []}
        for name, curves in groups.items():
            for c in curves:
                e = c.nearest(s)
                row["runs"].append({"group": name, "run": c.run, "epoch": e, **c.at(e)})
        rows.append(row)
    return rows


def _values(values: dict[str, Any], metrics: tuple[str, ...]) -> str:
    return " / ".join(f"{values[m]:.4f}" for m in metrics)


def format_report(
    groups: dict[str, list[RunCurve]], metrics: tuple[str, ...], shares: tuple[float, ...]
) -> str:
    """The kept values per run and per group, then the curves at the shares, as Markdown."""
    summary = summarise(groups, metrics)
    head = " / ".join(metrics)
    lines = [f"| group | run | kept epoch | {head} |", "|---|---|---|---|"]
    for name, g in summary.items():
        for r in g["runs"]:
            lines.append(f"| {name} | {r['run']} | {r['schedule']} | {_values(r, metrics)} |")
    lines += ["", f"| group | runs | mean {head} | sd | change against the first |"]
    lines.append("|---|---|---|---|---|")
    for name, g in summary.items():
        sd = " / ".join("-" if g["sd"][m] is None else f"{g['sd'][m]:.4f}" for m in metrics)
        change = " / ".join(f"{100 * g['change'][m]:+.1f} %" for m in metrics)
        n = len(g["runs"])
        lines.append(f"| {name} | {n} | {_values(g['mean'], metrics)} | {sd} | {change} |")
    rows = curve_rows(groups, metrics, shares)
    budgets = {c.run: c.budget for cs in groups.values() for c in cs}
    names = [f"{r['group']}: {r['run']}" + (f" (of its {budgets[r['run']]:g} min budget)"
             if budgets[r["run"]] is not None else "") for r in rows[0]["runs"]]  # fmt: skip
    head = "share of the schedule" + (
        " (epochs; of the time budget where it ended the run)"
        if any(v is not None for v in budgets.values())
        else ""
    )
    lines += ["", f"| {head} | " + " | ".join(names) + " |"]
    lines.append("|---" * (len(names) + 1) + "|")
    for row in rows:
        cells = [f"{_values(r, metrics)} ({r['epoch']})" for r in row["runs"]]
        lines.append(f"| {row['share']:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
