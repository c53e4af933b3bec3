"""The one training loop, shared by every stage (denoiser, generator, fine-tuning).

A stage supplies an ``objective`` module whose ``forward(batch, generator)`` returns
``(loss, logs)``, the ``trainable`` module to optimise and save, a ``validate`` callable, and a
``payload`` callable that turns the trainable module into a checkpoint. The loop does the rest:
augmentation, optimisation, DDP, progress bars, metric logs, best checkpoint, resume.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import math
import os
import re
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from torch import nn
from torch.nn.parallel import DistributedDataParallel
from tqdm.auto import tqdm

from trajpref.config import DataConfig, OptimConfig
from trajpref.data.transforms import augment
from trajpref.errors import ConfigError, TrajprefError
from trajpref.io import atomic_path, bar_options, dumps_json, load_tensors, write_failed
from trajpref.models import checkpoint as ckpt
from trajpref.results import machine
from trajpref.train.distributed import DistInfo, RankBatches, gather_generators, largest
from trajpref.train.ema import WeightAverage, ema_decay
from trajpref.train.stages import Stage
from trajpref.types import TrajectoryDataset

RUN_FILES = ("metrics.jsonl", "run.json")
"""A stage's files that accumulate over a run's sessions: its metrics log and its record of
sessions (``<stage>_run.json``, ``train.run.record_session``). A run started anew in the same
folder moves them aside (``set_aside``) rather than appending to another run's."""

RUN_STATE = (*RUN_FILES, "last.pt")
"""A run's log, record and resume state (``<stage>_<name>``)."""


def checkpoint_files(out_dir: str | Path, stage: str) -> list[str]:
    """The names of the checkpoints that ``fit`` writes for ``stage`` in ``out_dir`` and that
    exist there: ``<stage>.safetensors`` (the best), ``<stage>_raw.safetensors`` (the best raw
    weights, with ``ema_epochs``) and ``<stage>_epoch<E>.safetensors`` (``keep_checkpoints``);
    never one already set aside (``.replaced-<k>.``)."""
    out_dir = Path(out_dir)
    epoch = re.compile(rf"{re.escape(stage)}_epoch\d+{re.escape(ckpt.SUFFIX)}")
    names = [f"{stage}{ckpt.SUFFIX}", f"{stage}_raw{ckpt.SUFFIX}"]
    names += sorted(p.name for p in out_dir.glob(f"{stage}_epoch*{ckpt.SUFFIX}")
                    if epoch.fullmatch(p.name))  # fmt: skip
    return [n for n in names if (out_dir / n).is_file()]


def _aside_name(name: str, k: int) -> str:
    """``metrics.jsonl`` -> ``metrics.replaced-<k>.jsonl`` (the first dot's place)."""
    stem, _, ext = name.partition(".")
    return f"{stem}.replaced-{k}.{ext}"


def set_aside(out_dir: str | Path, stage: str, names: tuple[str, ...] = RUN_FILES,
              checkpoints: bool = False) -> list[str]:  # fmt: skip
    """Move an earlier run's ``<stage>_<name>`` files (of ``names``, those that exist), and
    with ``checkpoints`` its checkpoints (``checkpoint_files``), out of the way of a new run:
    ``<stage>_metrics.jsonl`` to ``<stage>_metrics.replaced-<k>.jsonl``, ``<stage>_run.json``
    to ``<stage>_run.replaced-<k>.json``, ``<stage>_last.pt`` to
    ``<stage>_last.replaced-<k>.pt``, ``<stage>.safetensors`` to
    ``<stage>.replaced-<k>.safetensors``, ``<stage>_raw.safetensors`` and
    ``<stage>_epoch<E>.safetensors`` alike: one ``k`` for all, free for every one of them (and
    of ``RUN_STATE`` and the best checkpoints), so that a run's log, record, state and
    checkpoints stay paired, and no file of the earlier run is left to be read as the new
    run's. Says so on stderr; returns the new names."""
    out_dir = Path(out_dir)
    files = [f"{stage}_{n}" for n in names if (out_dir / f"{stage}_{n}").exists()]
    models = checkpoint_files(out_dir, stage) if checkpoints else []
    if not files and not models:
        return []
    every = {f"{stage}_{n}" for n in (*RUN_STATE, *names)}
    every |= {f"{stage}{ckpt.SUFFIX}", f"{stage}_raw{ckpt.SUFFIX}", *files, *models}
    k = 1
    while any((out_dir / _aside_name(n, k)).exists() for n in every):
        k += 1
    for name in (*files, *models):
        (out_dir / name).rename(out_dir / _aside_name(name, k))
    moved = [_aside_name(n, k) for n in files]
    kept = [_aside_name(n, k) for n in models]
    epochs = [n for n in kept if "_epoch" in n]
    if len(epochs) > 2:  # the kept epochs' checkpoints, counted
        kept = [n for n in kept if n not in epochs]
        kept.append(f"{len(epochs)} {stage}_epoch<E>.replaced-{k}{ckpt.SUFFIX}")
    what = []
    if moved:
        what.append(f"moved aside to {' and '.join(moved)}")
    if kept:
        listed = ", ".join(kept[:-1]) + (" and " if kept[:-1] else "") + kept[-1]
        what.append(f"{'and ' if moved else 'moved '}its checkpoints to {listed}")
    print(f"[{stage}] {out_dir} held an earlier run: {', '.join(what)}; this run writes its "
          "own", file=sys.stderr)  # fmt: skip
    best = f"{stage}{ckpt.SUFFIX}"
    if stage == "denoiser" and best in models:
        note = trained_through_note(out_dir, _aside_name(best, k))
        if note is not None:
            print(f"[{stage}] {note}", file=sys.stderr)
    return [*moved, *(_aside_name(n, k) for n in models)]


def trained_through_note(out_dir: Path, old: str) -> str | None:
    """What a denoiser set aside (as ``old``, in ``out_dir``) beside the folder's generator
    files means for them (None when there are none): they were trained through the old
    denoiser, which their resume and their generator checkpoint still need."""
    generator = [n for n in (*checkpoint_files(out_dir, "generator"), "generator_last.pt")
                 if (out_dir / n).is_file()]  # fmt: skip
    if not generator:
        return None
    listed = ", ".join(generator[:-1]) + (" and " if generator[:-1] else "") + generator[-1]
    return (f"the folder's generator files ({listed}) were trained through the old denoiser, "
            f"now {old}, not the one this run trains: resume that generator with --denoiser "
            f"{out_dir / old}, or train a new generator through the new denoiser")  # fmt: skip


class MetricLog:
    """Per-epoch metrics to ``metrics.jsonl`` (and TensorBoard when it is installed)."""

    def __init__(self, out_dir: Path, stage: str, enabled: bool, fresh: bool = True,
                 through: int | None = None):  # fmt: skip
        """``fresh``: a run that starts from its first epoch moves an earlier run's log in
        the same folder aside (``<stage>_metrics.replaced-<k>.jsonl``, ``set_aside``), so
        that the log holds this run's epochs only; a resumed run appends to its own, after
        dropping its rows of epochs past ``through`` (the resume state's last epoch: a run
        stopped between an epoch's log row and its state's save runs that epoch again)."""
        self.enabled = enabled
        self.path = out_dir / f"{stage}_metrics.jsonl"
        self.stage = stage
        self.tb = None
        if enabled and fresh:
            set_aside(out_dir, stage, ("metrics.jsonl",))
        if enabled and not fresh and through is not None and self.path.is_file():
            self._drop_after(through)
        if enabled:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self.tb = SummaryWriter(str(out_dir / "tensorboard" / stage))
            except ImportError:
                self.tb = None

    def _drop_after(self, through: int) -> None:
        """Rewrite the log without its rows of epochs after ``through`` (blank lines and
        rows without an epoch kept)."""
        lines = self.path.read_text().splitlines(keepends=True)
        kept = [line for line in lines
                if not line.strip() or json.loads(line).get("epoch", 0) <= through]  # fmt: skip
        if len(kept) < len(lines):
            with atomic_path(self.path) as tmp:
                Path(tmp).write_text("".join(kept))

    def write(self, record: dict[str, Any]) -> None:
        if not self.enabled:
            return
        try:
            with self.path.open("a") as fh:
                fh.write(dumps_json(record) + "\n")
        except OSError as exc:  # a full disk's ENOSPC names no file
            raise write_failed(self.path, "the metrics log", exc) from None
        if self.tb is not None:
            for key, value in record.items():
                number = isinstance(value, (int, float)) and not isinstance(value, bool)
                if number and key not in ("epoch", "processes"):  # ``start: true``: no number
                    self.tb.add_scalar(f"{self.stage}/{key}", value, record["epoch"])
            self.tb.flush()


def read_metrics(run_dir: str | Path, stage: str, start: bool = False) -> list[dict[str, Any]]:
    """A run's ``<stage>_metrics.jsonl`` as written by :class:`MetricLog`: one dict per
    epoch, in order; ``[]`` when the run has not logged that stage (blank lines skipped).
    The validation of the start that fine-tuning logs first (``"epoch": 0, "start": true``)
    is no epoch and is left out, unless ``start``."""
    path = Path(run_dir) / f"{stage}_metrics.jsonl"
    if not path.is_file():
        return []
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return rows if start else [r for r in rows if not r.get("start")]


def fused_flag(cfg: OptimConfig) -> bool | None:
    """AdamW's ``fused`` argument for ``cfg``: True, or None (PyTorch's default: a loop over
    the parameters on the CPU, ``foreach`` on a GPU)."""
    return True if cfg.fused else None


def make_optimizer(params: list[nn.Parameter], cfg: OptimConfig) -> torch.optim.AdamW:
    """The stage's AdamW at ``cfg.lr`` and ``cfg.weight_decay``: PyTorch's default
    implementation, or its fused one with ``cfg.fused`` (the same arithmetic, equal up to
    float rounding; docs/pretraining.md, "Fused AdamW steps"). A resumed run takes the
    config's choice, not the one its saved state was made with (``fit``)."""
    return torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay,
                             fused=fused_flag(cfg))  # fmt: skip


def resume_optimizer(optimizer: torch.optim.AdamW, saved: dict[str, Any],
                     cfg: OptimConfig) -> None:  # fmt: skip
    """Load a resume state's optimiser state into ``optimizer``, in the implementation ``cfg``
    names (``fused_flag``), not the one the state was saved with. PyTorch's default AdamW
    keeps each parameter's ``step`` on the CPU, and ``load_state_dict`` leaves it there when
    the saved groups were not fused; the fused kernel reads it on the parameter's device (a
    CUDA kernel cannot read a CPU tensor), so a fused group's steps are moved there as float32,
    as ``load_state_dict`` does for a state saved fused. Their counts are kept."""
    optimizer.load_state_dict(saved)
    fused = fused_flag(cfg)
    for group in optimizer.param_groups:  # the state brings its own; the config decides
        group["fused"] = fused
        if not fused:
            continue
        for param in group["params"]:
            step = optimizer.state.get(param, {}).get("step")
            if isinstance(step, torch.Tensor):
                optimizer.state[param]["step"] = step.to(device=param.device, dtype=torch.float32)


def _lr_lambda(
    cfg: OptimConfig, total: int, budget_share: Callable[[], float] | None = None
) -> Callable[[int], float]:
    """The learning rate's factor at each step of ``total``: a linear warm-up, then a cosine
    decay to ``final_lr``. With ``cfg.budget_schedule`` the schedule stands at the larger of
    the step and ``budget_share() * total`` (the step the share of the time budget spent
    would be at): a run whose time keeps pace with its steps is not touched."""

    def f(step: int) -> float:
        if step < cfg.warmup_steps:
            return (step + 1) / cfg.warmup_steps
        at = float(step)
        if cfg.budget_schedule and budget_share is not None:
            at = max(at, budget_share() * total)
        progress = (at - cfg.warmup_steps) / max(1, total - cfg.warmup_steps)
        cosine = 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))  # 1 -> 0
        return cfg.final_lr + (1 - cfg.final_lr) * cosine

    return f


def warmup_note(name: str, cfg: OptimConfig, total: int) -> str | None:
    """A line for a stage ``name`` whose linear warm-up lasts as long as its ``total``
    optimiser steps or longer (a config written for a larger dataset, run on a small one:
    ``warmup_steps`` 200 at 3 steps an epoch), so that the learning rate reaches its peak at
    the last step at best and never decays, with the numbers and the setting that shortens it;
    None for any other (a warm-up that ends before the run does, fine-tuning's default 20 of 36
    steps among them, is a schedule of its own), and for a warm-up of one step or none, which
    runs its first step at the full rate and leaves nothing to shorten. The schedule itself is
    left as the config says."""
    warm = cfg.warmup_steps
    if warm <= 1 or warm < total or total <= 0:
        return None
    tenth = max(1, total // 10)  # < warm: warm >= 2 and warm >= total
    if warm == total:
        reach = f"reaches {name}.lr={cfg.lr:g} only at the last step"
    else:
        reach = (f"never reaches {name}.lr={cfg.lr:g} (it climbs to about "
                 f"{cfg.lr * total / warm:.2g})")  # fmt: skip
    return (f"[{name}] the warm-up ({name}.warmup_steps={warm}) lasts all of this run's "
            f"{total} optimiser steps: the learning rate {reach} and never decays; a shorter "
            f"warm-up: --set {name}.warmup_steps=N (e.g. N={tenth}"
            f"{', a tenth of the steps' if total >= 10 else ''})")  # fmt: skip


def _budget_share(seconds: float, cfg: OptimConfig, dist_info: DistInfo,
                  device: torch.device) -> float:  # fmt: skip
    """The share of ``cfg.max_minutes`` that ``seconds`` of the budget clock are (the largest
    over the ranks, so that every rank steps with the same learning rate); 0 without
    ``budget_schedule``."""
    if not cfg.budget_schedule or cfg.max_minutes is None:
        return 0.0
    return largest(seconds / (60 * cfg.max_minutes), dist_info, device)


def save_resume_state(path: Path, state: dict[str, Any]) -> None:
    """The state a run resumes from (weights, optimiser, schedules, random generators):
    tensors and plain values only, so it loads with ``torch.load(weights_only=True)``. A
    failed write (torch's ``RuntimeError`` on a full disk, an ``OSError``) is a one-line
    ``TrajprefError`` naming the file (``write_failed``); the state written before stays."""
    with atomic_path(path) as tmp:
        try:
            torch.save(state, tmp)
        except RuntimeError as exc:
            raise write_failed(path, "the resume state", exc) from None


RESUME_KEYS = ("stage", "trainable", "optimizer", "scheduler", "noise_gen", "aug_gen", "epoch",
               "step", "best", "elapsed")  # fmt: skip
"""What every resume state holds (``spent``, and each rank's random generators with the
process count, ``rank_generators`` and ``world_size``, were added later and may be missing, as
may torch's own generators in each rank's entry, ``torch_generators``)."""


def load_resume_state(path: str | Path, stage: str | None = None) -> dict[str, Any]:
    """Read a ``<stage>_last.pt`` resume state (never executing code); with ``stage``, check
    that it was written by that stage. Every way a file can be the wrong one is a one-line
    ``ConfigError`` that says which file to pass instead."""
    path = Path(path)
    want = f"{stage}_last.pt" if stage else "the <stage>_last.pt"
    if path.is_dir():
        raise ConfigError(f"--resume {path}: is a folder; pass {want} inside it")
    if not path.is_file():
        raise ConfigError(f"--resume {path}: no such file to resume from")
    with path.open("rb") as fh:
        head = fh.read(9)
    if len(head) == 9 and head[8:9] == b"{":  # a safetensors header: u64 length, then JSON
        raise ConfigError(f"--resume {path}: a best checkpoint (weights only) cannot be resumed; "
                          f"pass {want} from the same run folder")  # fmt: skip
    try:
        state = load_tensors(path)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for bad files
        raise ConfigError(
            f"--resume {path}: not a resume state ({exc.__class__.__name__}); pass {want}"
        ) from None
    if isinstance(state, dict) and "format" in state and "kind" in state:
        raise ConfigError(f"--resume {path}: a model checkpoint ({state.get('kind')}) cannot be "
                          f"resumed; pass {want} from the same run folder")  # fmt: skip
    missing = [k for k in RESUME_KEYS if k not in state] if isinstance(state, dict) else ["keys"]
    if not missing and not isinstance(state["trainable"], dict):
        missing = ["weights"]
    if missing:
        raise ConfigError(f"--resume {path}: not a resume state (no {missing[0]}); pass {want}")
    if stage is not None and state["stage"] != stage:
        raise ConfigError(f"--resume {path}: the state of a {state['stage']} stage, not of "
                          f"{stage}; pass {want}")  # fmt: skip
    return state


def check_resume_matches(state: dict[str, Any], module: nn.Module, path: str | Path,
                         averaged: bool = False) -> None:  # fmt: skip
    """The resume state's weights fit ``module`` (same names and shapes), and it holds a
    moving average of them when the run keeps one (``averaged``: ``ema_epochs > 0``), or a
    one-line ``ConfigError`` before anything is written."""
    if averaged and "ema" not in state:
        raise ConfigError(f"--resume {path}: this run averages its weights (ema_epochs > 0) but "
                          "the state has no average; resume with the run's own config")  # fmt: skip
    own = module.state_dict()
    saved = state["trainable"]
    for key in sorted(set(own) | set(saved)):
        if key not in own or key not in saved or own[key].shape != saved[key].shape:
            got = tuple(saved[key].shape) if key in saved else "missing"
            want = tuple(own[key].shape) if key in own else "not in this model"
            raise ConfigError(
                f"--resume {path}: its weights do not fit this run's model ({key}: {got} in the "
                f"file, {want} here); resume with the run's own config.yaml"
            )


def _rank_generators(state: dict[str, Any], rank: int) -> dict[str, torch.Tensor] | None:
    """The states of rank ``rank``'s random generators (``noise_gen``, ``aug_gen``, and
    torch's own, ``torch_generators``) in a resume state: its own (``rank_generators``, one
    entry per rank of the run that wrote it), or None for a rank that run did not have. A
    state written before each rank's were kept holds rank 0's alone (and no torch's), one
    written before torch's were kept holds no ``torch_rng``."""
    per_rank = state.get("rank_generators")
    if per_rank is None:
        per_rank = [{"noise_gen": state["noise_gen"], "aug_gen": state["aug_gen"]}]
    return per_rank[rank] if rank < len(per_rank) else None


def torch_generators(device: torch.device) -> dict[str, torch.Generator]:
    """torch's own random generators, which a step draws from where it passes none (dropout's
    masks): the CPU's (``torch_rng``) and, on a GPU, that GPU's (``cuda_rng``; CUDA is never
    touched on another device). The stage builder seeds them (``torch.manual_seed``); the
    resume state keeps each rank's, so that a resumed run does not draw its masks again from
    the seed."""
    generators = {"torch_rng": torch.default_generator}
    if device.type == "cuda":
        torch.cuda.init()  # no-op once the stage's weights are on the GPU
        index = device.index if device.index is not None else torch.cuda.current_device()
        generators["cuda_rng"] = torch.cuda.default_generators[index]
    return generators


def _duration(minutes: float) -> str:
    """``12 min``, ``3.5 h`` or ``41 days``: a rough duration for a message."""
    if minutes < 90:
        return f"{minutes:.0f} min"
    if minutes < 48 * 60:
        return f"{minutes / 60:.1f} h"
    return f"{minutes / 1440:,.0f} days"


def seed_rank_generators(seed: int, rank: int, device: torch.device) -> None:
    """Seed torch's own generators (``torch_generators``) of rank ``rank`` > 0 from ``seed``
    and the rank, after the stage is built: the builder seeds every rank alike
    (``torch.manual_seed(seed)``, so that the ranks start from the same weights), and dropout
    would then draw every rank's masks from one stream. Rank 0 (and a one-process run) keeps
    the builder's seed, so its draws are unchanged."""
    if rank == 0:
        return
    for generator in torch_generators(device).values():
        generator.manual_seed(seed * 1000 + 900 + rank)  # the loop's own: + rank, + 500 + rank


def _draws_dropout(module: nn.Module) -> bool:
    """Whether ``module`` in training mode drops anything out (from torch's own generator)."""
    return any(isinstance(m, nn.Dropout) and m.p > 0 for m in module.modules())


def _restore_torch_generators(own: dict[str, torch.Tensor], device: torch.device,
                              stage: Stage, main: bool) -> None:  # fmt: skip
    """Set torch's own generators (``torch_generators``) to a resume state's rank entry
    ``own``: right before the first step, so that nothing the loop sets up draws after it.
    Where the state lacks one (written before they were kept, or the CPU's state resumed on
    a GPU) and the stage drops out, says that the masks will not be an uninterrupted run's."""
    generators = torch_generators(device)
    for name, generator in generators.items():
        if name in own:
            generator.set_state(own[name])
    missing = [name for name in generators if name not in own]
    if missing and main and _draws_dropout(stage.objective):
        tqdm.write(f"[{stage.name}] the resume state holds no {' or '.join(missing)} "
                   "(torch's own random generator, which dropout draws from; it was written "
                   "by an earlier trajpref, or on another device): the resumed run draws "
                   "its dropout masks again from the seed, so it will not end bit for bit "
                   "where an uninterrupted run would")  # fmt: skip


def _summed(agents: int, sums: dict[str, float],
            device: torch.device) -> tuple[int, dict[str, float]]:  # fmt: skip
    """An epoch's agents and agent-weighted logs summed over the ranks (a collective; every
    rank logs the same keys, in the same order)."""
    keys = list(sums)
    t = torch.tensor([agents, *(sums[k] for k in keys)], dtype=torch.float64, device=device)
    torch.distributed.all_reduce(t)
    values = t.tolist()
    return int(values[0]), dict(zip(keys, values[1:], strict=True))


def _should_stop(step: int, max_steps: int | None, seconds: float, max_minutes: float | None,
                 dist_info: DistInfo, device: torch.device) -> bool:  # fmt: skip
    """Whether the step or time budget is spent (all ranks agree, or DDP would hang: a
    collective, unless neither limit is set, which every rank knows alike)."""
    if max_steps is None and max_minutes is None:
        return False
    stop = max_steps is not None and step >= max_steps
    stop = stop or (max_minutes is not None and seconds >= 60 * max_minutes)
    if dist_info.enabled:
        flag = torch.tensor(int(stop), device=device)
        torch.distributed.all_reduce(flag, op=torch.distributed.ReduceOp.MAX)
        stop = bool(flag)
    return stop


def idle_note(name: str, idle: int, steps: int, epoch: int, world_size: int) -> str:
    """The line that says how many (``idle``) of the ``steps`` batches that stage ``name``
    takes of epoch ``epoch`` (0-based: the first this session trains) leave one of the
    ``world_size`` processes without a scene."""
    return (f"[{name}] {idle} of the {steps} batches of epoch {epoch + 1} hold fewer scenes "
            f"than the {world_size} processes (each epoch's shuffle makes its own batches, "
            "so other epochs count their own): in each, a process without a scene repeats one "
            "at zero weight (the training is the same, that process's time is lost)")  # fmt: skip


def can_compile(device: torch.device) -> bool:
    """Whether ``torch.compile`` can generate code for ``device`` here: on a CPU it needs a
    C++ compiler (``$CXX``, ``c++``, ``g++`` or ``clang++`` on the PATH); a GPU uses Triton."""
    if device.type != "cpu":
        return True
    names = [os.environ.get("CXX", ""), "c++", "g++", "clang++"]
    return any(name and shutil.which(name) for name in names)


def bf16_is_fast(device: torch.device) -> bool:
    """Whether bfloat16 steps can be expected to beat float32 on ``device``: a CUDA GPU of
    compute capability 8 or more (Ampere and later; before it, a T4's 7.5 or a V100's 7.0,
    bfloat16 is emulated), another GPU, or a CPU whose oneDNN build finds bfloat16
    instructions (AVX512-BF16, AMX). Without them autocast emulates bfloat16 and a step is
    several times slower (docs/pretraining.md, "bfloat16 training steps": 7x on an AVX2-only
    AMD EPYC)."""
    if device.type == "cuda":
        return torch.cuda.get_device_capability(device)[0] >= 8
    if device.type != "cpu":
        return True
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):  # a build without the probe: assume it is
        return True


def bf16_note(stage: str, device: torch.device) -> str | None:
    """The line a stage with ``precision="bf16"`` prints where bfloat16 is slow on ``device``
    (``bf16_is_fast``), None where it is not."""
    if bf16_is_fast(device):
        return None
    if device.type == "cuda":
        major, minor = torch.cuda.get_device_capability(device)
        why = (f"this GPU (compute capability {major}.{minor}, before Ampere's 8.0) has no "
               "bfloat16 arithmetic")  # fmt: skip
    else:
        why = "this CPU has no bfloat16 instructions (AVX512-BF16, AMX)"
    return (f"[{stage}] precision bf16: {why}, so bf16 steps run several times slower than "
            f"fp32 here; --set {stage}.precision=fp32 trains faster")  # fmt: skip


def precision_autocast(device: torch.device, precision: str) -> torch.autocast:
    """The context a training step's forward pass runs in: bfloat16 autocast on ``device``
    for ``precision="bf16"``, a no-op for ``"fp32"`` (``OptimConfig.precision``)."""
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=precision == "bf16")


class Terminated(BaseException):
    """SIGTERM during training (a scheduler's cancel or preemption, forwarded by torchrun),
    raised by the CLI's signal handler (``cli.main``: exit status 143 and the resume advice).
    A ``BaseException``, as ``KeyboardInterrupt`` is: an ``except Exception`` on its way (a
    file reader's, a library's) does not take it for an error of its own, and
    ``keeps_interrupts`` keeps it when it lands in a finalizer (as an ``Exception`` it was
    printed as "Exception ignored" and dropped: the run trained on)."""


INTERRUPTS = (KeyboardInterrupt, Terminated)
"""What stops a run wherever it lands, a finalizer included (``keeps_interrupts``)."""

_swallowed: list[BaseException] = []
"""Interrupts (``INTERRUPTS``) that Python ignored during ``fit`` because they were raised in
a finalizer (``keeps_interrupts``), until ``_stop_if_interrupted`` raises one again."""


def keeps_interrupts(function: Callable[..., Any]) -> Callable[..., Any]:
    """``function`` stopped by every Ctrl-C and SIGTERM (``INTERRUPTS``). Python prints a
    KeyboardInterrupt raised while an object's finalizer runs (a progress bar's
    ``tqdm.__del__``, as the bar is freed in the training thread) as "Exception ignored in
    ..." and drops it: the run trained on to its end and exited with status 0 (1 Ctrl-C in
    9, sent as an epoch ended), and the CLI's ``Terminated`` alike (SIGTERM, which torchrun
    forwards). Closing the bars does not prevent it (their finalizer still runs).
    While ``function`` runs, Python's hook for such exceptions (``sys.unraisablehook``) keeps
    them instead (any other goes to the hook it replaced), and ``_stop_if_interrupted`` raises
    the first again: at the loop's next step, after its epoch's state is saved, or when
    ``function`` returns."""

    @functools.wraps(function)
    def kept(*args: Any, **kwargs: Any) -> Any:
        previous = sys.unraisablehook

        def hook(unraisable: Any) -> None:
            if unraisable.exc_type is not None and issubclass(unraisable.exc_type,
                                                              INTERRUPTS):  # fmt: skip
                value = unraisable.exc_value
                _swallowed.append(value if value is not None else unraisable.exc_type())
            else:
                previous(unraisable)

        _swallowed.clear()
        sys.unraisablehook = hook
        try:
            result = function(*args, **kwargs)
            _stop_if_interrupted()  # one ignored after the loop's last look
            return result
        finally:
            sys.unraisablehook = previous
            _swallowed.clear()

    return kept


def _stop_if_interrupted() -> None:
    """Raise the interrupt (a KeyboardInterrupt, or ``Terminated``) that a finalizer
    swallowed, if one did (``keeps_interrupts``): the first, as its own type."""
    if _swallowed:
        first = _swallowed[0]
        _swallowed.clear()
        raise first.with_traceback(None)


def _averaged(average: WeightAverage | None):
    """The averaged weights swapped into their module for a block, or nothing without one."""
    return average.swapped_in() if average is not None else contextlib.nullcontext()


@keeps_interrupts
def fit(
    stage: Stage,
    train: TrajectoryDataset,
    data_cfg: DataConfig,
    optim_cfg: OptimConfig,
    out_dir: str | Path,
    device: torch.device,
    seed: int = 0,
    resume: str | Path | dict[str, Any] | None = None,
    dist_info: DistInfo | None = None,
    progress: bool = True,
    max_steps: int | None = None,
    identity: str | None = None,
    run_meta: dict[str, Any] | None = None,
    equal_budget: float | None = None,
) -> dict[str, Any]:
    """Train ``stage`` and keep the checkpoint with the best validation ``score``.

    Writes ``<stage>.safetensors`` (best), ``<stage>_last.pt`` (for ``resume``) and
    ``<stage>_metrics.jsonl`` into ``out_dir`` (rank 0 only). With a moving average of the
    weights (``ema_epochs > 0``) the best checkpoint holds the average, and
    ``<stage>_raw.safetensors`` keeps the best raw weights by the same validation: the run's
    own control, same seed and batches. ``max_steps`` stops early
    (for tests). ``identity`` (what the run is: its config and start, as text) is kept in the
    resume state, so that a resume can be checked against it (``train.run``); ``run_meta`` is
    recorded with every checkpoint beside its validation (``train.run``: the data's digest).
    ``equal_budget``: the minutes of ``finetune --equal-budget`` that set ``max_minutes``
    (``rl.presets.equal_budget_overrides``), for the advice of a run its budget ended: that
    option, not the ``--set`` keys it refuses beside it.

    A stage with ``validate_start`` (fine-tuning) validates its start once, before its first
    step, on the same scenes: logged first as ``"epoch": 0, "start": true`` (never a kept
    checkpoint; ``read_metrics`` leaves it out unless asked), kept in the resume state so
    that a resumed run does not validate it again, and set against the kept epoch at the end.
    With ``progress``, validation shows its own bar, and a stage with ``max_minutes`` shows
    the share of its budget spent. Returns a summary with the best validation metrics (and
    the start's, ``start``) and the wall time.

    Under DDP (``dist_info``) the ranks share each of the one-process run's batches
    (``train.distributed.RankBatches``): the same steps, learning rates and batches as on one
    process, other random draws. The log's ``train_*`` values and ``samples_per_second`` are
    the whole batches', summed over the ranks; each rank's random generators are saved, and a
    resume restores each rank's own: the loop's noise and augmentation generators and torch's
    own (``torch_generators``, which dropout draws from), so that on the CPU a resumed run
    ends bit for bit where an uninterrupted one does (at the same thread count and with the
    same ``precision``, ``compile`` and ``fused``). On a GPU it ends close to it, not bit for
    bit: nothing calls ``torch.use_deterministic_algorithms``, and CUDA kernels that add with
    atomics (scatters, some backward passes) or that cuBLAS / cuDNN pick per run can round
    differently each time, as two uninterrupted GPU runs of one seed can differ. A time
    budget (``max_minutes``) is the busiest rank's: each rank reads its own clock
    (``budget_clock`` cpu: its own process's CPU time), the ranks stop together when one has
    spent the budget, and the seconds recorded (the log's ``budget_<clock>_seconds``, the
    resume state's ``spent``) are the largest over the ranks.
    """
    dist_info = dist_info or DistInfo()
    out_dir = Path(out_dir)
    main = dist_info.is_main
    if main:
        out_dir.mkdir(parents=True, exist_ok=True)
    # the one-process run's batches, each split among the ranks (train.distributed)
    loader = RankBatches(train, data_cfg.max_agents, seed, dist_info)
    steps_per_epoch = len(loader)
    if optim_cfg.steps_per_epoch is not None:
        steps_per_epoch = min(steps_per_epoch, optim_cfg.steps_per_epoch)
    total = steps_per_epoch * optim_cfg.epochs * stage.updates
    params = [p for p in stage.trainable.parameters() if p.requires_grad]
    optimizer = make_optimizer(params, optim_cfg)
    budget = {"share": 0.0}  # share of max_minutes spent, for OptimConfig.budget_schedule
    sched = torch.optim.lr_scheduler.LambdaLR(
        optimizer, _lr_lambda(optim_cfg, total, lambda: budget["share"])
    )
    noise_gen = torch.Generator().manual_seed(seed * 1000 + dist_info.rank)
    aug_gen = torch.Generator().manual_seed(seed * 1000 + 500 + dist_info.rank)
    average = None  # the weights' moving average (every rank keeps it: weights agree under DDP)
    if optim_cfg.ema_epochs > 0:
        decay = ema_decay(optim_cfg.ema_epochs, steps_per_epoch * stage.updates)
        average = WeightAverage(stage.trainable, decay)

    start_epoch, step, best, elapsed = 0, 0, {"score": math.inf}, 0.0
    best_raw: dict[str, Any] = {"score": math.inf}  # the raw weights' best, when averaging
    # what max_minutes counts: elapsed time, or this process's CPU time (fair under sharing)
    clock = time.process_time if optim_cfg.budget_clock == "cpu" else time.perf_counter
    spent = 0.0  # seconds of the budget's clock used by training steps
    validated_at = 0.0  # ``spent`` at the last validation (for ``eval_every_minutes``)
    start_val: dict[str, float] | None = None  # the start's validation (``validate_start``)
    trained_on = machine()  # recorded with every checkpoint (the zoo cards name it)
    resume_torch: dict[str, torch.Tensor] | None = None  # this rank's, from the resume state
    if resume is not None:
        state = resume if isinstance(resume, dict) else load_resume_state(resume, stage.name)
        where = "(state)" if isinstance(resume, dict) else resume
        check_resume_matches(state, stage.trainable, where, optim_cfg.ema_epochs > 0)
        stage.trainable.load_state_dict(state["trainable"])
        resume_optimizer(optimizer, state["optimizer"], optim_cfg)
        sched.load_state_dict(state["scheduler"])
        own = _rank_generators(state, dist_info.rank)
        if own is not None:  # a rank the state's run did not have keeps its seeded start
            noise_gen.set_state(own["noise_gen"])
            aug_gen.set_state(own["aug_gen"])
            resume_torch = own  # torch's own generators: set right before the first step
        start_epoch, step, best = state["epoch"] + 1, state["step"], state["best"]
        best_raw = state.get("best_raw", best_raw)
        elapsed = state["elapsed"]
        spent = state.get("spent", elapsed)  # states written before budget_clock: wall time
        validated_at = state.get("validated_at", spent)
        start_val = state.get("start_val")
        if average is not None:
            average.load_state_dict(state["ema"])

    budget["share"] = _budget_share(spent, optim_cfg, dist_info, device)  # a resumed run's
    if optim_cfg.compile and can_compile(device):
        for network in stage.networks:
            network.compile(dynamic=True)  # in place: same parameters, same state-dict keys
    elif optim_cfg.compile and main:
        tqdm.write(f"[{stage.name}] compile: no C++ compiler on this machine (CXX, c++, g++, "
                   "clang++); training without compiling")  # fmt: skip
    slow = bf16_note(stage.name, device) if optim_cfg.precision == "bf16" and main else None
    if slow is not None:
        tqdm.write(slow)
    objective: nn.Module = stage.objective
    if dist_info.enabled:
        device_ids = [device] if device.type == "cuda" else None
        # a stage whose steps leave trainable parameters without gradients (the control's
        # critic) has DDP look for them each step; they keep no gradient, as on one process
        unused = stage.unused_parameters
        objective = DistributedDataParallel(objective, device_ids=device_ids,
                                            find_unused_parameters=unused)  # fmt: skip
        idle = loader.idle_batches(start_epoch, steps_per_epoch)
        if idle and main:
            tqdm.write(idle_note(stage.name, idle, steps_per_epoch, start_epoch,
                                 dist_info.world_size))  # fmt: skip

    log = MetricLog(out_dir, stage.name, main, fresh=resume is None,
                    through=None if resume is None else start_epoch)  # fmt: skip
    show = progress and main  # bars: the epoch's steps, each validation pass
    if stage.validate_start and resume is None and main:
        v0 = time.perf_counter()
        stage.objective.eval()
        start_val = stage.validate(progress=show)
        stage.objective.train()
        log.write({"epoch": 0, "step": 0, "start": True,
                   **{f"val_{k}": v for k, v in start_val.items()},
                   "val_seconds": round(time.perf_counter() - v0, 4)})  # fmt: skip
        tqdm.write(f"[{stage.name}] start (epoch 0, not trained): " + " ".join(
            f"val_{k}={v:.4g}" for k, v in start_val.items()))  # fmt: skip
    rate = None  # agent-windows per second of the last epoch run here
    nonfinite = 0
    note = warmup_note(stage.name, optim_cfg, total)
    if note is not None and main and step < optim_cfg.warmup_steps:  # once, while it lasts
        tqdm.write(note)
    # a rank after the first draws its own dropout masks (rank 0: the builder's seed); a
    # resume state's own generators then replace those it holds (an old state may hold none)
    seed_rank_generators(seed, dist_info.rank, device)
    if resume_torch is not None:
        _restore_torch_generators(resume_torch, device, stage, main)
    for epoch in range(start_epoch, optim_cfg.epochs):
        t0, c0 = time.perf_counter(), clock()
        loader.set_epoch(epoch)
        stage.objective.train()
        sums: dict[str, float] = {}
        agents = 0
        stop = False
        if optim_cfg.max_minutes is not None:  # the budget, not the epochs, ends such a run
            desc = f"{stage.name} epoch {epoch + 1} ({optim_cfg.max_minutes:g} min budget)"
        else:
            desc = f"{stage.name} epoch {epoch + 1}/{optim_cfg.epochs}"
        # closed here, not by its finalizer: see keeps_interrupts
        with tqdm(itertools.islice(loader, steps_per_epoch), total=steps_per_epoch, desc=desc,
                  unit="batch", leave=False, **bar_options(show)) as bar:  # fmt: skip
            for batch, mine, whole in bar:
                _stop_if_interrupted()  # a Ctrl-C that a finalizer swallowed
                if not stage.context:
                    batch = batch.without_context()
                batch = augment(batch, aug_gen, rotate=data_cfg.rotate, flip=data_cfg.flip,
                                scale_range=data_cfg.scale_range,
                                reverse=data_cfg.reverse,
                                history_noise=data_cfg.history_noise,
                                drop_agents=data_cfg.drop_agents,
                                reverse_context=data_cfg.reverse_context).to(device)  # fmt: skip
                collected = ()
                if stage.collect is not None:  # in the update's precision: PPO's first ratio
                    with precision_autocast(device, optim_cfg.precision):  # is then exactly 1
                        collected = (stage.collect(batch, noise_gen),)
                for _ in range(stage.updates):
                    if stage.on_progress is not None:
                        stage.on_progress(max(step / total, min(1.0, budget["share"])))
                    with precision_autocast(device, optim_cfg.precision):  # validation stays fp32
                        loss, logs = objective(batch, noise_gen, *collected)
                    loss = loss.float()  # autocast may hand back a bfloat16 scalar
                    # DDP averages the ranks' gradients: weighted by their shares of the batch's
                    # agents, the average is the gradient of the whole batch's (per-agent) loss
                    weighted = loss
                    if dist_info.enabled:
                        weighted = loss * (dist_info.world_size * mine / whole)
                    finite = torch.isfinite(loss.detach()).to(torch.int32)
                    if dist_info.enabled:  # every rank skips together, or DDP's all-reduce hangs
                        torch.distributed.all_reduce(finite, op=torch.distributed.ReduceOp.MIN)
                    if not bool(finite):
                        # skip the update rather than poison the weights; give up if it persists
                        nonfinite += 1
                        tqdm.write(f"[{stage.name}] non-finite loss at step {step + 1}; "
                                   "update skipped")  # fmt: skip
                        if nonfinite > max(3, steps_per_epoch // 10):
                            raise TrajprefError(f"{stage.name}: {nonfinite} non-finite losses; "
                                                f"{stage.nonfinite_hint}")  # fmt: skip
                        continue
                    optimizer.zero_grad(set_to_none=True)
                    weighted.backward()
                    grad_norm = torch.nn.utils.clip_grad_norm_(params, optim_cfg.grad_clip)
                    optimizer.step()
                    budget["share"] = _budget_share(spent + clock() - c0, optim_cfg, dist_info,
                                                    device)  # fmt: skip
                    sched.step()
                    if average is not None:
                        average.update()
                    step += 1
                    logs = {"loss": float(loss.detach()), "grad_norm": float(grad_norm), **logs}
                    for key, value in logs.items():
                        sums[key] = sums.get(key, 0.0) + value * mine
                    agents += mine
                    post = {"loss": f"{logs['loss']:.4f}"}
                    if optim_cfg.max_minutes is not None:  # the share of the budget spent
                        used = (spent + clock() - c0) / (60 * optim_cfg.max_minutes)
                        post["budget"] = f"{min(1.0, used):.0%}"
                    bar.set_postfix(post, refresh=False)  # drawn at the bar's own pace
                    stop = _should_stop(step, max_steps, spent + clock() - c0,
                                        optim_cfg.max_minutes, dist_info, device)  # fmt: skip
                    if stop:
                        bar.refresh()  # the state it ended at (its budget's share) is drawn
                        break
                if stop:
                    break
        elapsed += time.perf_counter() - t0
        # the busiest rank's (a collective), as _should_stop's: the log, the resume state, the
        # budget's end and a resume's check (train.run._nothing_left) read this one number
        spent = largest(spent + (clock() - c0), dist_info, device)
        epoch_seconds = time.perf_counter() - t0
        if dist_info.enabled:  # the whole batches': every rank's agents and losses
            agents, sums = _summed(agents, sums, device)
        rate = agents / max(1e-9, epoch_seconds)
        record: dict[str, Any] = {
            "epoch": epoch + 1, "step": step, "lr": sched.get_last_lr()[0],
            "train_seconds": round(elapsed, 2),
            f"budget_{optim_cfg.budget_clock}_seconds": round(spent, 4),
            "samples_per_second": round(rate, 1), "processes": dist_info.world_size,
        }  # fmt: skip
        if optim_cfg.budget_schedule:  # how much of the time budget the schedule has used
            record["budget_share"] = round(budget["share"], 6)
        record.update({f"train_{k}": v / max(1, agents) for k, v in sums.items()})
        last = epoch + 1 == optim_cfg.epochs or stop
        if optim_cfg.eval_every_minutes is not None:
            due = spent - validated_at >= 60 * optim_cfg.eval_every_minutes
        else:
            due = (epoch + 1) % optim_cfg.eval_every == 0
        if main and (due or last):
            validated_at = spent
            v0 = time.perf_counter()
            # what each checkpoint written at this evaluation records beside its validation
            at = {"epoch": epoch + 1, "step": step, "train_seconds": round(elapsed, 2),
                  "dataset": train.info.name, "machine": trained_on,
                  "processes": dist_info.world_size, **(run_meta or {})}  # fmt: skip
            stage.objective.eval()
            if average is not None:  # the raw weights too, for the comparison
                raw = stage.validate(progress=show)
                record.update({f"val_raw_{k}": v for k, v in raw.items()})
                if raw["score"] < best_raw["score"]:
                    best_raw = {**raw, "epoch": epoch + 1}
                    meta = {**at, "val": raw, "weights": "raw (this run's best averaged "
                            f"weights are {stage.name}{ckpt.SUFFIX})"}  # fmt: skip
                    ckpt.save(out_dir / f"{stage.name}_raw{ckpt.SUFFIX}", stage.payload(meta))
            with _averaged(average):
                val = stage.validate(progress=show)
                record.update({f"val_{k}": v for k, v in val.items()})
                if val["score"] < best["score"]:
                    best = {**val, "epoch": epoch + 1}
                    meta = {**at, "val": val}
                    if average is not None:
                        meta["ema_epochs"] = optim_cfg.ema_epochs
                    ckpt.save(out_dir / f"{stage.name}{ckpt.SUFFIX}", stage.payload(meta))
                    record["best"] = True
                if optim_cfg.keep_checkpoints:  # what was validated: the average, if any
                    name = f"{stage.name}_epoch{epoch + 1:03d}{ckpt.SUFFIX}"
                    ckpt.save(out_dir / name, stage.payload({**at, "val": val}))
            stage.objective.train()
            # 4 decimals: at 0.01 s a small validation pass on a fast host was logged as 0
            record["val_seconds"] = round(time.perf_counter() - v0, 4)
        # every rank's random generators (a collective): each resumes its own draws
        generators = gather_generators({"noise_gen": noise_gen, "aug_gen": aug_gen,
                                        **torch_generators(device)}, dist_info)  # fmt: skip
        if main:
            log.write(record)
            save_resume_state(out_dir / f"{stage.name}_last.pt", {
                "stage": stage.name, "trainable": stage.trainable.state_dict(),
                "optimizer": optimizer.state_dict(), "scheduler": sched.state_dict(),
                "noise_gen": noise_gen.get_state(), "aug_gen": aug_gen.get_state(),
                "rank_generators": generators, "world_size": dist_info.world_size,
                "epoch": epoch, "step": step, "best": best, "elapsed": elapsed, "spent": spent,
                "validated_at": validated_at,
                **({"identity": identity} if identity is not None else {}),
                **({"start_val": start_val} if start_val is not None else {}),
                **({"ema": average.state_dict(), "best_raw": best_raw}
                   if average is not None else {}),
            })  # fmt: skip
            # 4 significant digits: a small learning rate (1e-5) must not print as 0.0
            summary = {k: (float(f"{v:.4g}") if isinstance(v, float) else v)
                       for k, v in record.items()}  # fmt: skip
            tqdm.write(f"[{stage.name}] " + " ".join(f"{k}={v}" for k, v in summary.items()))
        _stop_if_interrupted()  # after the epoch's state is saved: a resume continues it
        if stop:
            break
    budget_reached = (optim_cfg.max_minutes is not None and step < total
                      and spent >= 60 * optim_cfg.max_minutes)  # fmt: skip
    if budget_reached and main:
        if equal_budget is not None:  # the protocol's budget ends every run, by design
            tqdm.write(f"[{stage.name}] the equal budget (--equal-budget {equal_budget:g}: "
                       f"{optim_cfg.max_minutes:g} min of {optim_cfg.budget_clock} time on "
                       f"training steps) ended the stage after {step} step"
                       f"{'s' * (step != 1)}, as the protocol "
                       "does; to train longer, resume with a larger --equal-budget (and give "
                       "every method you compare the same)")  # fmt: skip
        else:
            how = ("annealed to it (budget_schedule)" if optim_cfg.budget_schedule
                   else "cut mid-schedule (budget_schedule is off)")  # fmt: skip
            unset = (f"--set {stage.name}.max_minutes=null --set "
                     f"{stage.name}.budget_schedule=false")  # fmt: skip
            more = spent / max(1, step) * (total - step) / 60  # minutes at this pace
            tqdm.write(f"[{stage.name}] the time budget of {optim_cfg.max_minutes:g} min "
                       f"({optim_cfg.budget_clock} clock) ended the stage after {step} of its "
                       f"{total} steps, {how}; to train every step (about {_duration(more)} "
                       f"more at this pace): {unset}")  # fmt: skip
    if start_val is not None and "epoch" in best and main:
        tqdm.write(f"[{stage.name}] kept epoch {best['epoch']} against its start (epoch 0, the "
                   f"same validation scenes): {against_start(best, start_val)}")  # fmt: skip
    return {"best": best, "train_seconds": elapsed, "budget_seconds": spent, "steps": step,
            "budget_reached": budget_reached, "start": start_val,
            "samples_per_second": rate}  # fmt: skip


def against_start(best: dict[str, float], start: dict[str, float]) -> str:
    """The kept validation set against the start's: ``min_ade 0.1691 -> 0.1650 (-2.4 %)`` for
    minADE and minFDE (the score alone for a stage without them)."""
    keys = [k for k in ("min_ade", "min_fde") if k in start and k in best] or ["score"]
    return ", ".join(f"{k} {start[k]:.4f} -> {best[k]:.4f} "
                     f"({100 * (best[k] / start[k] - 1):+.1f} %)" if start[k] else
                     f"{k} {start[k]:.4f} -> {best[k]:.4f}" for k in keys)  # fmt: skip
