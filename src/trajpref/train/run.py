"""``trajpref train diffusion|generator`` and ``trajpref finetune``: datasets + stage + the
shared loop, DDP-aware."""

from __future__ import annotations

import dataclasses
import json
import time
import typing
import warnings
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Literal

import torch

from trajpref.config import ExperimentConfig, save_config, to_dict
from trajpref.data import run_splits
from trajpref.data.registry import NAMES
from trajpref.device import resolve_device
from trajpref.errors import ConfigError
from trajpref.io import check_output_dir, write_json
from trajpref.models import checkpoint as ckpt
from trajpref.results import command_line, machine
from trajpref.train.distributed import barrier, cleanup, init_from_env
from trajpref.train.loop import check_resume_matches, fit, load_resume_state
from trajpref.train.stages import (
    build_denoiser_stage,
    build_finetune_stage,
    build_generator_stage,
)

Pretraining = Literal["diffusion", "generator"]
STAGES: tuple[str, ...] = typing.get_args(Pretraining)
STAGE_NAMES = {"diffusion": "denoiser", "generator": "generator", "finetune": "finetune"}
"""CLI stage -> the name its files carry (``<name>.safetensors``, ``<name>_last.pt``)."""


def with_absolute_folders(cfg: ExperimentConfig) -> ExperimentConfig:
    """``cfg`` with a dataset (or validation dataset) given as a relative folder path made
    absolute, so that the run's config and checkpoints find it from any working directory;
    built-in names and absolute paths stay as they are."""
    changes = {}
    for key in ("dataset", "val_dataset"):
        value = getattr(cfg.data, key)
        if value and value not in NAMES and not Path(value).expanduser().is_absolute():
            folder = Path(value).expanduser()
            if folder.exists():
                changes[key] = str(folder.resolve())
    if not changes:
        return cfg
    return dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, **changes))


RESUME_FREE = ("epochs", "eval_every", "eval_every_minutes", "max_minutes", "budget_clock",
               "precision", "compile", "fused", "keep_checkpoints")  # fmt: skip
"""Fields of the resumed stage's own section that a resume may change: its length, budget,
validation interval, arithmetic and checkpoints kept. Everything else that shapes the stage
(data, model, noise schedule, seed, the rest of its section, its start) must be as it was."""


def run_identity(cfg: ExperimentConfig, name: str, start: str | None = None) -> str:
    """What a stage's resume state records of its run (JSON text): the config sections that
    shape stage ``name`` (data, model, diffusion, seed, its own section less ``RESUME_FREE``)
    and ``start``, the hash of the checkpoint it starts from (the generator stage's denoiser,
    fine-tuning's generator)."""
    full = to_dict(cfg)
    own = {k: v for k, v in full[name].items() if k not in RESUME_FREE}
    keep = {k: full[k] for k in ("data", "model", "diffusion", "seed")}
    return json.dumps({**keep, name: own, "start": start}, sort_keys=True, default=str)


def _differences(saved: Any, now: Any, prefix: str = "") -> list[str]:
    """``key: saved -> now`` for each leaf that differs between two nested dicts."""
    if isinstance(saved, dict) and isinstance(now, dict):
        return [line for k in sorted(set(saved) | set(now), key=str)
                for line in _differences(saved.get(k), now.get(k), f"{prefix}{k}.")]  # fmt: skip
    return [] if saved == now else [f"{prefix.rstrip('.')}: {saved!r} -> {now!r}"]


def check_resume(state: dict[str, Any], identity: str, epochs: int, out_dir: Path,
                 resume: str | Path, name: str) -> None:  # fmt: skip
    """A resume state belongs to this run folder, was written by a run of the same config and
    start (``run_identity``; states older than the record are not checked) and has epochs left
    to train; else a one-line ``ConfigError`` before anything is written."""
    resume = Path(resume)
    if resume.resolve().parent != out_dir.resolve():
        raise ConfigError(f"--resume {resume}: a run resumes in its own folder (--out "
                          f"{resume.parent}), not in {out_dir}")  # fmt: skip
    saved = state.get("identity")
    if saved is not None:
        changed = _differences(json.loads(saved), json.loads(identity))
        if changed:
            shown = "; ".join(changed[:3]) + (f" (and {len(changed) - 3} more)"
                                              if len(changed) > 3 else "")  # fmt: skip
            which = (
                "the checkpoint it starts from" if changed[0].startswith("start") else "its config"
            )
            raise ConfigError(f"--resume {resume}: this run differs from the one that wrote the "
                              f"state ({shown}); resume with {which} as it was (--config "
                              f"{out_dir / f'{name}_config.yaml'}); only {name}."
                              f"{{{','.join(RESUME_FREE)}}} may change")  # fmt: skip
    done = int(state["epoch"]) + 1
    if done >= epochs:
        raise ConfigError(f"--resume {resume}: the state has finished {done} epochs and this run "
                          f"has {epochs}: nothing left to train (raise {name}.epochs to train "
                          "longer)")  # fmt: skip


def epochs_done(path: str | Path) -> int:
    """The epochs a resume state has finished (0 when there is no such file): a script that
    trains or resumes skips a stage whose state has done its config's epochs, which a resume
    refuses."""
    path = Path(path)
    return int(load_resume_state(path)["epoch"]) + 1 if path.is_file() else 0


def last_state_path(out_dir: str | Path, stage: str) -> Path:
    """The resume state a stage (``diffusion``, ``generator``, ``finetune``) writes."""
    return Path(out_dir) / f"{STAGE_NAMES[stage]}_last.pt"


def run_record_path(out_dir: str | Path, name: str) -> Path:
    """The file in which a stage's run folder records where and how each of its sessions ran:
    ``<name>_run.json`` (``denoiser``, ``generator``, ``finetune``)."""
    return Path(out_dir) / f"{name}_run.json"


def record_session(out_dir: str | Path, name: str, seed: int, device: torch.device,
                   world_size: int, resumed: bool) -> dict[str, Any]:  # fmt: skip
    """Append this session's conditions to ``<name>_run.json`` (a JSON list, one entry per
    start or resume) and return the entry.

    A seed repeats a run bit for bit only under the same conditions: on the CPU the thread
    count changes the order of floating-point reductions, and a Robo generator trained with
    seed 1 kept validation minFDE20 0.2958 on one thread (twice, to the fourth digit) but
    0.3083 on two (docs/pretraining.md, "Robo with roles and dropout 0.2 published"). So each
    session writes the threads, the device, the number of processes, the machine, torch's
    version and the command beside the config."""
    path = run_record_path(out_dir, name)
    sessions: list[dict[str, Any]] = []
    if path.is_file():
        try:
            loaded = json.loads(path.read_text())
        except (OSError, ValueError):
            loaded = None
        if isinstance(loaded, list):
            sessions = loaded
        else:  # never stop a run over its log, but say that the earlier entries are gone
            warnings.warn(f"{path}: not a list of sessions; starting it again", stacklevel=2)
    entry = {
        "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "resumed": resumed,
        "seed": seed,
        "threads": torch.get_num_threads(),
        "device": str(device),
        "world_size": world_size,
        "torch": torch.__version__,
        "machine": machine(),
        "command": command_line(),
    }
    write_json(path, [*sessions, entry])
    return entry


def _run(
    cfg: ExperimentConfig,
    out_dir: str | Path,
    data_root: str | None,
    device: str,
    resume: str | None,
    progress: bool,
    max_steps: int | None,
    build,
    name: str,
    start: str | None = None,
) -> dict[str, Any]:
    """What every stage shares: devices and DDP, the datasets, the run folder's config, the
    loop. ``build(train, val, device) -> (Stage, OptimConfig)`` supplies the stage ``name``;
    ``start`` is the hash of the checkpoint it starts from, when it has one (the generator's
    denoiser, fine-tuning's generator).

    The run folder and the resume state are checked before any data is read and before
    anything is written (a failed check leaves nothing behind)."""
    check_output_dir(out_dir)
    out_dir = Path(out_dir)
    identity = run_identity(cfg, name, start)
    state = None
    if resume is not None:
        state = load_resume_state(resume, name)
        check_resume(state, identity, getattr(cfg, name).epochs, out_dir, resume, name)
    dev = resolve_device(device)
    info, dev = init_from_env(dev)
    torch.set_num_threads(max(1, torch.get_num_threads() // max(1, info.world_size)))
    try:
        train, val = run_splits(cfg.data, data_root)
        built, optim = build(train, val, dev)
        if state is not None:
            check_resume_matches(state, built.trainable, resume, optim.ema_epochs > 0)
        if info.is_main:
            out_dir.mkdir(parents=True, exist_ok=True)
            save_config(cfg, out_dir / "config.yaml")  # the run's last stage
            save_config(cfg, out_dir / f"{name}_config.yaml")  # this stage's, kept
            record_session(out_dir, name, cfg.seed, dev, info.world_size, state is not None)
        barrier(info)
        start = time.perf_counter()
        summary = fit(built, train, cfg.data, optim, out_dir, dev, cfg.seed, state, info,
                      progress, max_steps, identity)  # fmt: skip
        summary["wall_seconds"] = time.perf_counter() - start
        barrier(info)  # every rank done (rank 0 may still have been writing) before teardown
        summary["train_agents"] = train.num_agents
        summary["rank"] = info.rank  # only rank 0 validates: other ranks' "best" is empty
        return summary
    finally:
        cleanup(info)


def train_stage(
    stage: Pretraining,
    cfg: ExperimentConfig,
    out_dir: str | Path,
    data_root: str | None = None,
    device: str = "auto",
    resume: str | None = None,
    denoiser: str | None = None,
    progress: bool = True,
    max_steps: int | None = None,
) -> dict[str, Any]:
    """Train one pretraining stage; returns the loop's summary (best validation metrics,
    seconds). The denoiser stage trains on ``cfg.data.denoiser_part()``: complete futures
    only, whatever the generator's ``data.partial_future`` (its run folder's config says so)."""
    if stage not in STAGES:
        raise ConfigError(f"unknown stage {stage!r}; choose {' or '.join(STAGES)}")
    cfg = with_absolute_folders(cfg)
    payload = None
    if stage == "diffusion":  # generator-only data settings (partial futures) left out
        cfg = dataclasses.replace(cfg, data=cfg.data.denoiser_part())
    if stage == "generator":  # read before any compute: a wrong file fails at once
        path = Path(denoiser) if denoiser else Path(out_dir) / f"denoiser{ckpt.SUFFIX}"
        if not denoiser and not path.is_file():
            raise ConfigError(
                f"{path}: the generator trains through a denoiser and there is none in "
                f"{out_dir}: train it there first (trajpref train diffusion ... --out "
                f"{out_dir}) or pass --denoiser FILE (e.g. a published one: "
                "models/zara1/denoiser.safetensors)"
            )
        payload = ckpt.load(path)
        if payload["kind"] != "denoiser":
            raise ConfigError(f"{path}: expected a denoiser checkpoint, got a {payload['kind']}")

    def build(train, val, dev):
        if payload is None:
            return build_denoiser_stage(cfg, train, val, dev)[0], cfg.denoiser
        return build_generator_stage(cfg, payload, val, dev), cfg.generator

    start = payload.get("hash") if payload is not None else None  # the generator's denoiser
    return _run(cfg, out_dir, data_root, device, resume, progress, max_steps, build,
                STAGE_NAMES[stage], start)  # fmt: skip


def finetune(
    cfg: ExperimentConfig,
    start: str | Path,
    out_dir: str | Path,
    data_root: str | None = None,
    device: str = "auto",
    resume: str | None = None,
    progress: bool = True,
    max_steps: int | None = None,
) -> dict[str, Any]:
    """RLHF / RLHF-ReS fine-tuning from the generator checkpoint ``start`` (DDP-aware);
    ``cfg`` comes from ``rl.presets.finetune_config``."""
    cfg = with_absolute_folders(cfg)
    payload = ckpt.load(start)
    if payload["kind"] != "generator":
        raise ConfigError(f"{start}: fine-tuning starts from a generator checkpoint")

    def build(train, val, dev):
        return build_finetune_stage(cfg, payload, val, dev), cfg.finetune

    return _run(cfg, out_dir, data_root, device, resume, progress, max_steps, build,
                STAGE_NAMES["finetune"], payload.get("hash"))  # fmt: skip
