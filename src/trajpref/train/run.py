"""``trajpref train diffusion|generator`` and ``trajpref finetune``: datasets + stage + the
shared loop, DDP-aware."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import shlex
import shutil
import socket
import sys
import time
import typing
import warnings
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from trajpref.config import DataConfig, ExperimentConfig, OptimConfig, save_config, to_dict
from trajpref.data import mean_speed, run_splits, speed_note, text
from trajpref.data.loader import SceneLoader
from trajpref.data.registry import NAMES, SECONDS_STEPS, USER_TEXT
from trajpref.device import resolve_device
from trajpref.errors import (
    ConfigError,
    DataWarning,
    EveryRankError,
    NothingLeftToTrain,
    OverlapWarning,
    TrajprefError,
    TrajprefWarning,
)
from trajpref.io import (
    atomic_path,
    check_output_dir,
    dotted,
    read_checkpoint_header,
    write_json,
)
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.models.timing import (
    UNKNOWN_UNITS,
    model_timing,
    same_content_note,
    timing_problems,
    trained_otherwise,
)
from trajpref.results import command_line, machine
from trajpref.rl.presets import own_reward_data
from trajpref.train.distributed import (
    DistInfo,
    barrier,
    cleanup,
    env_info,
    gather_objects,
    init_from_env,
    launcher_command,
)
from trajpref.train.loop import (
    RUN_STATE,
    check_resume_matches,
    fit,
    load_resume_state,
    set_aside,
)
from trajpref.train.stages import (
    build_denoiser_stage,
    build_finetune_stage,
    build_generator_stage,
    data_scale,
)
from trajpref.types import TrajectoryDataset

Pretraining = Literal["diffusion", "generator"]
STAGES: tuple[str, ...] = typing.get_args(Pretraining)
STAGE_NAMES = {"diffusion": "denoiser", "generator": "generator", "finetune": "finetune"}
"""CLI stage -> the name its files carry (``<name>.safetensors``, ``<name>_last.pt``)."""


def finetune_run_config(cfg: ExperimentConfig) -> tuple[ExperimentConfig, str | None]:
    """-> (the config a fine-tuning run of ``cfg`` trains with and writes beside its
    checkpoints, ``<out>/finetune_config.yaml``; ``own_reward_data``'s note or None): its
    folders made absolute (``with_absolute_folders``), and a registered reward's or ``sda``'s
    scenes without the augmentations it must not see (``rl.presets.own_reward_data``). A
    script that reuses run folders compares a folder's file with this."""
    return own_reward_data(with_absolute_folders(cfg))  # a registered reward: unaugmented


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


def run_identity(cfg: ExperimentConfig, name: str, start: str | None = None,
                 data: dict[str, dict[str, str]] | None = None) -> str:  # fmt: skip
    """What a stage's resume state records of its run (JSON text): the config sections that
    shape stage ``name`` (data, model, diffusion, seed, its own section less ``RESUME_FREE``),
    ``start``, the hash of the checkpoint it starts from (the generator stage's denoiser,
    fine-tuning's generator), and with ``data`` the fingerprint of what it reads
    (``data_fingerprint``, under the key ``data_files``). ``check_resume`` compares a key that
    an older state lacks with its value in ``identity_defaults`` (the field's dataclass default,
    or the old one where ``LEGACY_DEFAULTS`` records a change): a field added since whose
    default reproduces the old behaviour (``data.frame_interval``, ``data.units``) leaves such a
    state resumable."""
    full = to_dict(cfg)
    own = {k: v for k, v in full[name].items() if k not in RESUME_FREE}
    keep = {k: full[k] for k in ("data", "model", "diffusion", "seed")}
    files = {"data_files": data} if data is not None else {}
    return json.dumps({**keep, name: own, "start": start, **files}, sort_keys=True, default=str)


def data_fingerprint(train: TrajectoryDataset, val: TrajectoryDataset) -> dict[str, dict[str, str]]:
    """What a run reads, as ``{split: {file: "<N> windows, <digest>"}}`` for its training and
    validation splits: per source file (a window's ``scene_id`` before ``@`` or ``#``), the
    number of windows and a 16-digit BLAKE2 digest of their ids and values (positions, agent
    types, context agents). A digest of the windows rather than of the files' bytes or times:
    a copied or touched file is the same data, while changed lines, a changed reader or
    another folder behind the same path are not. Cheap: one pass over arrays in memory (zara1:
    a few milliseconds)."""
    out: dict[str, dict[str, str]] = {}
    for split, dataset in (("train", train), ("val", val)):
        digests: dict[str, Any] = {}
        counts: dict[str, int] = {}
        for scene in dataset.scenes:
            source = scene.scene_id.split("@", 1)[0].split("#", 1)[0]
            h = digests.setdefault(source, hashlib.blake2b(digest_size=8))
            counts[source] = counts.get(source, 0) + 1
            h.update(scene.scene_id.encode())
            for values in (scene.history, scene.future, scene.agent_type, scene.context,
                           scene.context_reverse):  # fmt: skip
                if values is not None:
                    h.update(str(values.shape).encode())
                    h.update(np.ascontiguousarray(values).tobytes())
        out[split] = {f: f"{counts[f]} windows, {digests[f].hexdigest()}" for f in sorted(counts)}
    return out


def data_timing(train: TrajectoryDataset) -> dict[str, Any]:
    """What a checkpoint records of the pace and units of the data it trained on (its meta's
    ``data_timing``): ``frame_interval``, the seconds between a window's steps (the files'
    interval times ``time_step``), ``interval_from`` (``DatasetInfo.interval_from``: whether
    those seconds are known or the 0.4 s default assumed), ``time_step`` and ``units``.
    ``evaluate``, ``predict`` and ``plot`` compare it with the data they are given. Also
    ``agent_types``: the sorted agent-type flags the training windows hold (``[0]`` persons
    only, ``[0, 1]`` with NBA's ball or a folder's BALL column), so that a model that learned
    from flags can say so when it is given none (``score.scorer.reads_agent_types``)."""
    info = train.info
    types = sorted({int(t) for s in train.scenes for t in np.unique(s.agent_type)})
    return {"frame_interval": info.frame_interval, "interval_from": info.interval_from,
            "time_step": info.time_step, "units": info.units,
            "agent_types": types}  # fmt: skip


INTERVAL_NOTES = {"dataset": "", "given": "given", "declared": "declared by the TrajNet++ scenes",
                  "timestamps": "the step of the files' time column",
                  "default": "assumed: none given (--frame-interval)"}  # fmt: skip
"""How ``data stats`` and a training run's split lines say where a frame interval comes from
(``DatasetInfo.interval_from``)."""


def interval_note(info: Any) -> str:
    """`` (0.1 s between frames: the step of the files' time column; read every 4)`` after
    the step ``data stats`` prints (a time column's step is in seconds, a ``time_ms`` or
    ``timestamp_ms`` one's divided by 1000); empty for a built-in dataset read as recorded."""
    source = INTERVAL_NOTES.get(info.interval_from, info.interval_from)
    if info.time_step == 1.0:
        return f" ({source})" if source else ""
    frame = f"{info.frame_interval / info.time_step:g} s between frames"
    return f" ({frame}{f': {source}' if source else ''}; read every {info.time_step:g})"


def split_line(dataset: TrajectoryDataset, role: str) -> str:
    """The line a training run prints of one split it read (``role``: train or val): its
    dataset and split, scenes (windows) and agents, the seconds per step and where they come
    from (``interval_note``, as ``data stats`` says it) and the units."""
    info = dataset.info
    return (f"{role}: {info.name} ({info.split} split): {len(dataset)} scenes, "
            f"{dataset.num_agents} agents, {info.frame_interval:g} s per step"
            f"{interval_note(info)}, units {info.units}")  # fmt: skip


SMALL_VALIDATION = 20
"""Validation scenes (windows) under which a run warns that its choice of epoch is noise."""


def _time_column(info: Any, options: text.ReadOptions) -> tuple[str, str, float] | None:
    """The first track file of a text folder split whose frame column is a time
    (``text.column_seconds``): its name, the column's name and its step in seconds; None when
    there is none (frame numbers, no header, not a text folder, unreadable)."""
    try:
        files = text.track_files(info.source, USER_TEXT)
    except (TrajprefError, OSError):
        return None
    for path in files[:1]:  # one file: the reader already read them all alike
        try:
            tracks = text.read_tracks(path, options=options)
        except (TrajprefError, OSError):
            return None
        per = text.column_seconds(tracks.frame_name)
        step = text.frame_step(tracks.frames)
        if per is not None and step > 0:
            return path.name, str(tracks.frame_name), step * per
    return None


def data_warnings(train: TrajectoryDataset, val: TrajectoryDataset,
                  data: DataConfig) -> list[str]:  # fmt: skip
    """What a training run warns of the splits it read: a mean speed that is no walking pace
    (``speed_note``, as ``data stats`` says it), a frame interval only assumed while
    ``data.time_step`` reads every n-th row (the step recorded is n times an assumed 0.4 s), a
    given interval that overrides the files' time column with another step, and a validation
    split too small to choose an epoch on."""
    out = []
    for ds in (train, val) if val.info.name != train.info.name else (train,):
        info = ds.info
        note = speed_note(mean_speed(ds), info.units, info.frame_interval, info.interval_from,
                          info.time_step)  # fmt: skip
        if note is not None:
            out.append(f"{info.name}: {note}")
    info = train.info
    rows = info.frame_interval / info.time_step
    if info.interval_from == "default" and info.time_step != 1.0:
        out.append(
            f"{info.name}: data.time_step {info.time_step:g} reads every "
            f"{info.time_step:g} rows, but the seconds between rows are assumed "
            f"({rows:g} s: no --frame-interval and no time column), so the model "
            f"records {info.frame_interval:g} s per step, which evaluate and predict "
            "trust: give the files' own with --frame-interval (data.frame_interval)"
        )
    if info.interval_from == "given" and info.text_tracks:
        options = text.ReadOptions(data.delimiter, data.max_gap, data.max_coord)
        found = _time_column(info, options)
        plausible = found is not None and SECONDS_STEPS[0] <= found[2] <= SECONDS_STEPS[1]
        if plausible and not np.isclose(found[2], rows, rtol=0.01):  # else data stats' advice
            name, column, seconds = found
            out.append(f"{info.name}: --frame-interval {rows:g} (data.frame_interval) overrides "
                       f"the files' time column ({name}'s {column} column steps {seconds:g} s "
                       f"between rows): the model records {info.frame_interval:g} s per step "
                       f"where the files say {seconds * info.time_step:g} s; leave "
                       "--frame-interval out to read the time column (in seconds), or check "
                       "the column")  # fmt: skip
    if len(val) < SMALL_VALIDATION:
        out.append(
            f"validation has {len(val)} scenes (windows) of {val.info.name}: the epoch "
            f"it keeps is chosen on so few that the choice is mostly noise; give "
            f"validation more recordings (at least {SMALL_VALIDATION} windows)"
        )
    return out


def report_data(name: str, train: TrajectoryDataset, val: TrajectoryDataset,
                data: DataConfig) -> None:  # fmt: skip
    """Say what a run read (``split_line`` for each split, on stderr) and warn
    (``data_warnings``): on the first process alone."""
    for ds, role in ((train, "train"), (val, "val")):
        print(f"[{name}] {split_line(ds, role)}", file=sys.stderr)
    for message in data_warnings(train, val, data):
        warnings.warn(message, category=DataWarning, stacklevel=3)


def data_digest(data: dict[str, dict[str, str]]) -> str:
    """A 12-digit digest of a ``data_fingerprint``: recorded in each checkpoint's meta
    (``data_hash``), so that a result can be tied to the data it was trained and validated on."""
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:12]


def identity_defaults(name: str) -> dict[str, Any]:
    """What ``run_identity`` records for stage ``name`` at every field's default (``start``
    null, no ``data_files``): the value ``check_resume`` gives a key that a state written
    before the field existed lacks. The dataclass default, except where the default has
    changed since (``models.checkpoint.LEGACY_DEFAULTS``: such a state ran with the old one)."""
    out = json.loads(run_identity(ExperimentConfig(), name))
    for (section, key), value in ckpt.LEGACY_DEFAULTS.items():
        if isinstance(out.get(section), dict) and key in out[section]:
            out[section][key] = value
    return out


_ABSENT = object()
"""A key one side of ``_differences`` lacks."""


def _differences(saved: Any, now: Any, defaults: Any = None, prefix: str = "") -> list[str]:
    """``key: saved -> now`` for each leaf that differs between two nested dicts. A key that
    ``saved`` lacks is compared with its value in ``defaults`` (``identity_defaults``: the
    state was written before the field existed) and shown as ``absent (default ...)``; a
    key that ``now`` lacks was written by a newer trajpref, which this one cannot honour."""
    if isinstance(saved, dict) and isinstance(now, dict):
        defaults = defaults if isinstance(defaults, dict) else {}
        lines = []
        for k in sorted(set(saved) | set(now), key=str):
            old, new, key = saved.get(k, _ABSENT), now.get(k, _ABSENT), f"{prefix}{k}"
            if old is _ABSENT and k in defaults:
                if defaults[k] != new:
                    lines.append(f"{key}: absent (default {defaults[k]!r}) -> {new!r}")
            elif new is _ABSENT:
                lines.append(f"{key}: {old!r} -> not a key of this trajpref (a newer version "
                             "wrote the state?)")  # fmt: skip
            else:
                lines += _differences(None if old is _ABSENT else old, new, defaults.get(k),
                                      f"{key}.")  # fmt: skip
        return lines
    return [] if saved == now else [f"{prefix.rstrip('.')}: {saved!r} -> {now!r}"]


def _shown(changes: list[str]) -> str:
    return "; ".join(changes[:3]) + (f" (and {len(changes) - 3} more)" if len(changes) > 3 else "")


def _same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file (False when either is missing)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def program_launcher(program: str | None = None, python: str | None = None) -> list[str]:
    """How the resume advice starts trajpref again, as this process was started (``program``:
    ``sys.argv[0]``, ``python``: ``sys.executable``, by default): the ``trajpref`` script as
    ``trajpref`` when it is the one ``PATH`` finds, else by its path as it was given (an
    un-activated ``/path/.venv/bin/trajpref``, on which ``trajpref`` fails); ``python -m
    trajpref`` (``-m trajpref.cli`` for ``cli.py``) when it ran as a module, with ``python``'s
    path unless it is the one ``PATH`` finds by its name; ``trajpref`` for anything else
    (``cli.main`` called from Python, a test)."""
    program = sys.argv[0] if program is None else program
    python = sys.executable if python is None else python
    path = Path(program)
    if path.name in ("trajpref", "trajpref.exe"):
        found = shutil.which("trajpref")
        return ["trajpref"] if found is not None and _same_file(found, program) else [program]
    if path.parent.name == "trajpref" and path.name in ("__main__.py", "cli.py"):
        module = "trajpref" if path.name == "__main__.py" else "trajpref.cli"
        shown = Path(python).name
        if shutil.which(shown) != python and python != shown:  # not the one PATH finds
            shown = python
        return [shown or "python", "-m", module]
    return ["trajpref"]


def cli_resume_command(argv: list[str], resume: str | Path, world_size: int = 1,
                       seed: int | None = None,
                       launcher: list[str] | None = None) -> str:  # fmt: skip
    """The ``trajpref`` command ``argv`` (its arguments after the program name) made to resume
    from ``resume``: its ``--resume`` replaced, started by ``launcher`` when given (the
    torchrun command line before ``argv``, as the run was launched:
    ``train.distributed.launcher_command``), else by ``torchrun`` with ``world_size``
    processes when ``world_size`` > 1, else as this process was started
    (``program_launcher``: ``trajpref``, the script's path, or ``python -m trajpref``), and
    with ``--seed seed`` added when ``argv`` gives none (a run without ``--seed`` records the
    seed it ran with, which another default would not restore). The same process count
    repeats the run's random draws; another continues the same schedule with other draws
    (``train.loop.fit``)."""
    rest, skip = [], False
    for arg in argv:  # the same options, --resume replaced
        if skip:
            skip = False
        elif arg == "--resume":
            skip = True
        elif not arg.startswith("--resume="):
            rest.append(arg)
    if seed is not None and not any(a == "--seed" or a.startswith("--seed=") for a in rest):
        rest += ["--seed", str(seed)]
    if launcher is None:
        launcher = (["torchrun", f"--nproc_per_node={world_size}", "-m", "trajpref.cli"]
                    if world_size > 1 else program_launcher())  # fmt: skip
    return shlex.join([*launcher, *rest, "--resume", str(resume)])


def resume_command(out_dir: str | Path, name: str, resume: str | Path) -> str | None:
    """The command that started the run's last session, as ``<name>_run.json`` records it,
    made to resume from ``resume`` (``cli_resume_command``, with the session's launcher, or
    its process count, and seed) when it ran the ``trajpref`` command (``python
    .../bin/trajpref``, or ``.../trajpref/cli.py`` under ``torchrun`` or ``python -m
    trajpref.cli``, or ``.../trajpref/__main__.py``: ``python -m trajpref``); one process is
    started again as it was (``program_launcher`` of the recorded program: ``trajpref`` where
    ``PATH`` finds that script, else its path). Another command (a script that resumes by
    itself) is given as it was. None without a record."""
    try:
        session = json.loads(run_record_path(out_dir, name).read_text())[-1]
        command = session["command"]
        args = shlex.split(command)
    except (OSError, ValueError, LookupError, TypeError, AttributeError):
        return None
    program = Path(args[1]) if len(args) > 1 else None
    if program is None or not (program.name == "trajpref" or (
            program.name in ("cli.py", "__main__.py")
            and program.parent.name == "trajpref")):  # fmt: skip
        return command
    world = session.get("world_size", 1)
    world = world if isinstance(world, int) else 1
    seed = session.get("seed")
    launcher = session.get("launcher")
    if isinstance(launcher, str):
        started = shlex.split(launcher)
    else:  # one process: as it was started (several: cli_resume_command's torchrun)
        # the record says "python" (results.command_line): this interpreter's path instead,
        # so that an un-activated .venv's python -m trajpref is advised by its path
        python = sys.executable if args[0] == "python" else args[0]
        started = program_launcher(args[1], python) if world <= 1 else None
    command = cli_resume_command(args[2:], resume, world, seed if isinstance(seed, int) else None,
                                 started)  # fmt: skip
    nodes = session.get("nodes", 1)
    if isinstance(nodes, int) and nodes > 1:
        command += (f" (on each of the {nodes} machines, with the launcher options it was "
                    "started with there)")  # fmt: skip
    return command


def check_resume(state: dict[str, Any], identity: str, epochs: int, out_dir: Path,
                 resume: str | Path, name: str, max_minutes: float | None = None,
                 equal_budget: float | None = None) -> None:  # fmt: skip
    """A resume state belongs to this run folder, was written by a run of the same config and
    start (``run_identity``; states older than the record are not checked; the data are
    checked apart, ``check_resume_data``) and has something left to train: epochs, and with
    ``max_minutes`` time in its budget; else a one-line ``ConfigError`` before anything is
    written (``equal_budget``: the ``--equal-budget`` minutes that set ``max_minutes``, which a
    spent budget's advice names). A changed config is refused with the command that started
    the run (its run
    record), which restores every option; the pretraining stages also name their
    ``<name>_config.yaml``, which their ``--config`` reads whole (fine-tuning's ``--config``
    reads only the finetune section)."""
    resume = Path(resume)
    if resume.resolve().parent != out_dir.resolve():
        raise ConfigError(f"--resume {resume}: a run resumes in its own folder (--out "
                          f"{resume.parent}), not in {out_dir}")  # fmt: skip
    saved = state.get("identity")
    if saved is not None:
        saved_run, now_run = json.loads(saved), json.loads(identity)
        saved_run.pop("data_files", None)  # the data are compared once read
        now_run.pop("data_files", None)
        changed = _differences(saved_run, now_run, identity_defaults(name))
        if changed:
            start = changed[0].startswith("start")
            which = "the checkpoint it starts from" if start else "its config"
            found = start_file(out_dir, saved_run.get("start")) if start else None
            if found is not None and name in START_FLAGS:
                aside = ("the earlier one, set aside when a new one was trained in the folder"
                         if ".replaced-" in found.name else "in the run's folder")  # fmt: skip
                raise ConfigError(f"--resume {resume}: the state was trained from another "
                                  f"checkpoint than this run's ({_shown(changed)}); {found} "
                                  f"is that checkpoint ({aside}): resume with "
                                  f"{START_FLAGS[name]} {found}")  # fmt: skip
            command = resume_command(out_dir, name, resume)
            config = out_dir / f"{name}_config.yaml"
            if name != "finetune" and not start:  # train --config reads the whole file
                how = f"its config as it was (--config {config})" + (
                    f" or as the command that started it did: {command}" if command else ""
                )
            elif command:
                how = f"{which} as it was, as the command that started it did: {command}"
            else:  # finetune --config reads its finetune section only
                how = (f"{which} as it was (the options it was started with; {config} holds "
                       "its resolved config)")  # fmt: skip
            raise ConfigError(f"--resume {resume}: this run differs from the one that wrote the "
                              f"state ({_shown(changed)}); resume with {how}; only {name}."
                              f"{{{','.join(RESUME_FREE)}}} may change")  # fmt: skip
    why = _nothing_left(state, epochs, max_minutes, name, equal_budget)
    if why is not None:
        raise NothingLeftToTrain(f"--resume {resume}: {why}")


START_FLAGS = {"generator": "--denoiser", "finetune": "--from"}
"""The option that names the checkpoint a stage starts from (``run_identity``'s ``start``)."""


def start_file(out_dir: Path, digest: Any) -> Path | None:
    """The checkpoint in ``out_dir`` whose weights' hash is ``digest`` (a resume state's
    start), the folder's own first, then those set aside (``*.replaced-<k>.safetensors``), or
    None: a denoiser replaced by a new run in the folder is found there."""
    if not isinstance(digest, str) or not out_dir.is_dir():
        return None
    files = sorted(out_dir.glob(f"*{ckpt.SUFFIX}"), key=lambda p: (".replaced-" in p.name, p.name))
    for path in files:
        try:
            if read_checkpoint_header(path).get("hash") == digest:
                return path
        except (TrajprefError, OSError):
            continue
    return None


def _nothing_left(state: dict[str, Any], epochs: int, max_minutes: float | None,
                  name: str, equal_budget: float | None = None) -> str | None:  # fmt: skip
    """Why a resume state of stage ``name`` has nothing left to train under ``epochs`` and
    ``max_minutes`` (its epochs done, or its budget spent), or None when it has. A budget set
    by ``finetune --equal-budget`` (``equal_budget``) is raised with that option, which refuses
    a ``--set`` of ``max_minutes`` beside it."""
    done = int(state["epoch"]) + 1
    if done >= epochs:
        return (f"the state has finished {done} epochs and this run has {epochs}: nothing left "
                f"to train (raise {name}.epochs to train longer)")  # fmt: skip
    spent = float(state.get("spent", state.get("elapsed", 0.0)))  # the budget clock's seconds
    if max_minutes is not None and spent >= 60 * max_minutes:
        how = (f"raise {name}.max_minutes to train longer" if equal_budget is None else
               f"resume with --equal-budget above {equal_budget:g} to train longer: it sets "
               f"{name}.max_minutes")  # fmt: skip
        return (f"the budget of {max_minutes:g} min is spent (the state has trained "
                f"{spent / 60:.3g} min): nothing left to train ({how})")  # fmt: skip
    return None


def check_resume_data(state: dict[str, Any], data: dict[str, dict[str, str]],
                      resume: str | Path) -> None:  # fmt: skip
    """The data a resumed run reads are those its state was trained on (``data_fingerprint``,
    in the state's identity; a state written before the fingerprint is not checked), or a
    one-line ``ConfigError`` naming each changed file, before anything is written."""
    saved = json.loads(state.get("identity") or "{}").get("data_files")
    if saved is None:
        return
    changed = [f"{split} {f}: {saved.get(split, {}).get(f, 'absent')} -> "
               f"{data.get(split, {}).get(f, 'absent')}"
               for split in sorted(set(saved) | set(data))
               for f in sorted(set(saved.get(split, {})) | set(data.get(split, {})))
               if saved.get(split, {}).get(f) != data.get(split, {}).get(f)]  # fmt: skip
    if changed:
        raise ConfigError(f"--resume {resume}: the data differ from those the state was trained "
                          f"on ({_shown(changed)}); a run resumes on its own data: put them back "
                          "as they were, or start a new run (without --resume)")  # fmt: skip


def _matches_before_exact_labels(state: dict[str, Any], cfg: ExperimentConfig,
                                 root: str | None) -> bool:  # fmt: skip
    """Whether a resume state's data are the run's data with the scene ids of before
    2026-12-06, when frames that ``time_step`` resampled kept their float noise in their ids
    (``227.70000000000002``, now ``227.7``: ``text.frame_labels``): such a state resumes.
    Read again only when the fingerprints differ."""
    with text.exact_frame_labels():
        before = data_fingerprint(*run_splits(cfg.data, root, cfg.model.windows))
    try:
        check_resume_data(state, before, "")
    except ConfigError:
        return False
    return True


def finished(path: str | Path, optim: OptimConfig) -> bool:
    """Whether the resume state at ``path`` has nothing left to train under ``optim`` (its
    epochs done, or its ``max_minutes`` spent), which a resume refuses: a script that trains
    or resumes skips such a stage. False when there is no such file."""
    path = Path(path)
    if not path.is_file():
        return False
    state = load_resume_state(path)
    return _nothing_left(state, optim.epochs, optim.max_minutes, "stage") is not None


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
                   world_size: int, resumed: bool,
                   info: DistInfo | None = None) -> dict[str, Any]:  # fmt: skip
    """Append this session's conditions to ``<name>_run.json`` (a JSON list, one entry per
    start or resume) and return the entry.

    A seed repeats a run bit for bit only under the same conditions: on the CPU the thread
    count changes the order of floating-point reductions, and a Robo generator trained with
    seed 1 kept validation minFDE20 0.2958 on one thread (twice, to the fourth digit) but
    0.3083 on two (docs/pretraining.md, "Robo with roles and dropout 0.2 published"). So each
    session writes the threads (each process's), the device, the number of processes, the
    machine, torch's version and the command beside the config; under torchrun (``info``)
    also the machines and the launcher's command line, when it can be read
    (``distributed.launcher_command``), which the resume advice repeats."""
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
            warnings.warn(
                f"{path}: not a list of sessions; starting it again",
                category=TrajprefWarning,
                stacklevel=2,
            )
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
    if info is not None and info.enabled:
        entry["nodes"] = info.nodes
        launcher = launcher_command()
        if launcher is not None:
            entry["launcher"] = shlex.join(launcher)
    write_json(path, [*sessions, entry])
    return entry


def set_threads(info: DistInfo) -> None:
    """Each process's threads under torchrun. An ``OMP_NUM_THREADS`` in the environment is a
    per-process count (torchrun sets 1 where it is unset, and says so) and is kept; without
    one (another launcher), the threads torch would take are shared among the machine's
    processes. Warns (once per machine) when the processes' threads exceed its cores."""
    if not info.enabled:
        return
    if not os.environ.get("OMP_NUM_THREADS"):
        torch.set_num_threads(max(1, torch.get_num_threads() // info.local_world_size))
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    threads = torch.get_num_threads()
    if info.local_rank == 0 and info.local_world_size * threads > cores:
        per = cores // info.local_world_size  # threads each process may have: 0, 1, ...
        how = (f"start at most {cores} processes here (--nproc_per_node)" if per < 1 else
               f"set OMP_NUM_THREADS={per}, or start fewer processes")  # fmt: skip
        warnings.warn(f"{info.local_world_size} processes of {threads} thread(s) each on this "
                      f"machine's {cores} cores: they wait on each other ({how})",
                      category=TrajprefWarning, stacklevel=2)  # fmt: skip


def _note_processes(path: Path, info: DistInfo) -> None:
    """Say at the head of a run's config file that the run trained on several processes."""
    text = path.read_text()
    with atomic_path(path) as tmp:
        tmp.write_text(f"# trained on {info.world_size} processes ({info.nodes} machine(s)) "
                       "under torchrun; data.max_agents is each step's batch over all of them, "
                       "as on one process\n" + text)  # fmt: skip


def check_resume_processes(state: dict[str, Any], out_dir: Path, name: str,
                           resume: str | Path) -> None:  # fmt: skip
    """A resume state written on several processes before the processes shared each batch
    (each took whole batches: 1/N of one process's steps at N times its batch, under the
    same step-counted schedule) cannot continue under the current rule: a one-line
    ``ConfigError``. Such a state records no ``world_size``; its run record says how many
    processes wrote it. A state that records its count may resume on another (a note is
    printed: same schedule, other random draws)."""
    if "world_size" in state:
        return
    try:
        sessions = json.loads(run_record_path(out_dir, name).read_text())
        worlds = [int(s.get("world_size", 1)) for s in sessions]
    except (OSError, ValueError, TypeError, AttributeError):
        worlds = []
    if any(w > 1 for w in worlds):
        raise ConfigError(
            f"--resume {resume}: the state was written on {max(worlds)} processes by an "
            "earlier trajpref, under which each process took whole batches (1/N of one "
            "process's steps); the processes now share each batch, so it cannot continue: "
            "start the run again without --resume"
        )


FOLDER_KEYS = ("dataset", "val_dataset")
"""``data`` keys that may name a folder, whose path may differ between machines holding the
same files: ``run_facts`` compares what the ranks read (``data_fingerprint``) instead."""


def run_facts(cfg: ExperimentConfig, name: str, start: str | None,
              data: dict[str, dict[str, str]], train: TrajectoryDataset,
              state: dict[str, Any] | None, max_steps: int | None = None,
              equal_budget: float | None = None) -> dict[str, Any]:  # fmt: skip
    """What each process of a torchrun launch must hold alike to train one run of stage
    ``name`` (``check_same_run``): the config sections that shape it (seed, data less its
    folders' paths, model, diffusion, the stage's own, its length and budget included), the
    hash of the checkpoint it starts from, the data it reads (``data_fingerprint``), its
    batches per epoch, the resume state's epoch and step, and the limits given besides."""
    full = to_dict(cfg)
    shape = {k: full[k] for k in ("seed", "model", "diffusion", name)}
    shape["data"] = {k: v for k, v in full["data"].items() if k not in FOLDER_KEYS}
    batches = len(SceneLoader(train, max_agents=cfg.data.max_agents, shuffle=True,
                              seed=cfg.seed))  # fmt: skip
    resumed = None if state is None else f"epoch {int(state['epoch']) + 1}, step {state['step']}"
    return {"config": shape, "start": start, "data_files": data, "batches_per_epoch": batches,
            "resumed_after": resumed, "max_steps": max_steps,
            "equal_budget": equal_budget}  # fmt: skip


def check_same_run(info: DistInfo, facts: dict[str, Any]) -> None:
    """Every rank's ``facts`` (``run_facts``) are rank 0's, or an ``EveryRankError`` raised on
    every rank that names the first rank that differs and how: a collective, taken right
    after the data are read and before anything is trained or written. Without it a rank
    given other data, another config or its own ``--seed`` either trained another shuffle of
    the batches without a word (scenes trained twice, others never) or took another number of
    steps and left the others waiting in a collective until the timeout (60 min)."""
    if not info.enabled:
        return
    every = [dotted(f) for f in gather_objects(facts, info)]  # each rank's facts, dotted keys
    differ = []
    for rank, own in enumerate(every[1:], 1):
        keys = sorted(set(every[0]) | set(own))
        changes = [f"{k}: {every[0].get(k, 'absent')!r} -> {own.get(k, 'absent')!r}"
                   for k in keys if every[0].get(k, _ABSENT) != own.get(k, _ABSENT)]  # fmt: skip
        if changes:
            differ.append((rank, changes))
    if not differ:
        return
    rank, changes = differ[0]
    more = [str(r) for r, _ in differ[1:]]
    also = f"; so do rank(s) {', '.join(more)}" if more else ""
    raise EveryRankError(
        f"the {info.world_size} processes of this launch do not train one run: rank {rank} "
        f"differs from rank 0 (rank 0's -> rank {rank}'s: {_shown(changes)}){also}. Nothing "
        "was trained or written: start every process with the same options and config (--seed "
        "is the run's, not each process's), the same data and the same files to start or "
        "resume from (on several machines: a shared --out)"
    )


def cpu_budget_note(name: str, section: OptimConfig, info: DistInfo) -> str | None:
    """The line a stage with a CPU-time budget (``budget_clock`` cpu, ``max_minutes``) prints
    on several processes (None otherwise): the clock is each process's own."""
    if not info.enabled or section.max_minutes is None or section.budget_clock != "cpu":
        return None
    n = info.world_size
    return (f"[{name}] {name}.budget_clock=cpu on {n} processes: the budget of "
            f"{section.max_minutes:g} min counts each process's own CPU time (the stage ends "
            f"when the busiest has spent it), so the {n} processes together spend up to {n} "
            "times it, and the steps it buys are not one process's on the same budget "
            f"(budget_clock=wall counts the launch's elapsed time)")  # fmt: skip


def lock_path(out_dir: str | Path, name: str) -> Path:
    """The file by which a run of stage ``name`` holds its folder: ``<out>/.<name>.lock``."""
    return Path(out_dir) / f".{name}.lock"


@dataclasses.dataclass
class StageLock:
    """An exclusive ``flock`` on ``path`` (``take_stage_lock``), held through ``fd``."""

    path: Path
    fd: int


def _lock_holder(fd: int) -> str:
    """What the lock file open as ``fd`` says of the run that holds it, for the refusal."""
    try:
        size = os.fstat(fd).st_size  # the record ends with the command, however long
        held = json.loads(os.pread(fd, size, 0).decode("utf-8", "replace"))
        who = f"pid {int(held['pid'])} on host {held['host']}"
        return who + (f", started {held['started']}" if held.get("started") else "")
    except (OSError, ValueError, TypeError, KeyError):  # being written, or not ours
        return "a process that has not said which yet"


def _held(out_dir: str | Path, name: str, path: Path, holder: str) -> TrajprefError:
    """The refusal of a run whose folder another run holds (``holder``: ``_lock_holder``)."""
    return TrajprefError(
        f"--out {out_dir}: another run is training {name} there ({holder}; it holds "
        f"{path.name}): two runs in one folder would mix their logs, checkpoints and "
        "resume states; wait for it to end, or give this run another --out"
    )


def _flock_or_refuse(fd: int, mode: int, out_dir: str | Path, name: str, path: Path) -> None:
    """``flock`` ``fd`` in ``mode`` (shared or exclusive) without waiting; where a run holds
    it, ``fd`` is closed and the run refused (``_held``). Another ``OSError`` (a file system
    without locks) is the caller's."""
    import fcntl

    try:
        fcntl.flock(fd, mode | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _lock_holder(fd)
        os.close(fd)
        raise _held(out_dir, name, path, holder) from None


def _remove_stale_lock(path: Path, out_dir: str | Path, name: str) -> None:
    """A lock file this process may not write (another user's, left by a run of theirs):
    refused as ``take_stage_lock`` refuses when a run holds it, else removed, so that a
    killed run's file blocks nothing in a shared folder either."""
    import fcntl

    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:  # let go meanwhile
        return
    except OSError as exc:
        raise TrajprefError(f"{path}: cannot read ({exc.strerror or exc})") from None
    try:
        _flock_or_refuse(fd, fcntl.LOCK_SH, out_dir, name, path)
    except OSError:
        pass  # no locks here: the file is as stale as any
    os.close(fd)
    try:
        path.unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise TrajprefError(f"{path}: a lock file left by another user's run, which this "
                            f"user cannot remove ({exc.strerror or exc})") from None  # fmt: skip


def take_stage_lock(out_dir: str | Path, name: str) -> StageLock | None:
    """Hold stage ``name``'s run folder ``out_dir`` (created if need be) for this process:
    an exclusive, non-blocking ``flock`` on ``lock_path`` (the kernel releases it when the
    process ends, however it ends: a file left by a killed run blocks nothing), into which
    this process writes its pid, host, start and command. A run that holds it already is
    refused with a one-line ``TrajprefError`` naming its pid and host: two jobs given one
    ``--out`` wrote one metrics log between them, and each moved the other's files aside.
    None where there are no such locks (Windows; a file system that refuses ``flock``, with a
    warning): the run goes on unguarded. ``release_stage_lock`` lets it go."""
    try:
        import fcntl
    except ImportError:  # Windows
        return None
    path = lock_path(out_dir, name)
    try:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TrajprefError(f"{out_dir}: cannot create ({exc.strerror or exc})") from None
    for _ in range(20):  # a run that lets the lock go removes its file: take the new one
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except PermissionError:  # another user's file (0644): held by a run, or left behind
            fd = None
        except OSError as exc:
            raise TrajprefError(f"{path}: cannot write ({exc.strerror or exc})") from None
        if fd is None:
            _remove_stale_lock(path, out_dir, name)  # or refused, when its run holds it
            continue
        try:
            _flock_or_refuse(fd, fcntl.LOCK_EX, out_dir, name, path)
        except OSError as exc:  # some NFS or Lustre mounts, a FUSE file system
            os.close(fd)
            warnings.warn(f"{path}: cannot lock the run folder ({exc.strerror or exc}): a "
                          f"second run given --out {out_dir} would not be refused",
                          category=TrajprefWarning, stacklevel=3)  # fmt: skip
            return None
        try:
            mine, held = os.stat(path), os.fstat(fd)
            if (mine.st_dev, mine.st_ino) == (held.st_dev, held.st_ino):
                break
        except FileNotFoundError:
            pass
        os.close(fd)  # removed (or replaced) while this process opened it: again
    else:
        raise TrajprefError(f"{path}: could not take the run folder's lock")
    record = {"pid": os.getpid(), "host": socket.gethostname(),
              "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "command": command_line()}  # fmt: skip
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)
    except OSError:  # a full disk: the lock holds; a refused run names no pid
        pass
    return StageLock(path, fd)


def release_stage_lock(lock: StageLock | None) -> None:
    """Let a ``take_stage_lock`` lock go: its file removed (while it is still held, and only
    if it is still this lock's), then closed."""
    if lock is None:
        return
    try:
        mine, held = os.stat(lock.path), os.fstat(lock.fd)
        if (mine.st_dev, mine.st_ino) == (held.st_dev, held.st_ino):
            os.unlink(lock.path)
    except OSError:
        pass
    finally:
        os.close(lock.fd)


def hold_stage(out_dir: Path, name: str, info: DistInfo) -> StageLock | None:
    """``take_stage_lock`` on the first process; under torchrun its refusal is every rank's
    (a collective: an ``EveryRankError`` on each, rather than ranks left waiting)."""
    lock, refusal = None, None
    if info.is_main:
        try:
            lock = take_stage_lock(out_dir, name)
        except TrajprefError as exc:
            refusal = str(exc)
    if info.enabled:
        refusal = gather_objects(refusal, info)[0]
        if refusal is not None:
            raise EveryRankError(refusal)
    if refusal is not None:
        raise TrajprefError(refusal)
    return lock


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
    equal_budget: float | None = None,
    notes: Callable[[TrajectoryDataset], list[str]] | None = None,
) -> dict[str, Any]:
    """What every stage shares: devices and DDP, the datasets, the run folder's config, the
    loop. ``build(train, val, device) -> (Stage, OptimConfig)`` supplies the stage ``name``;
    ``start`` is the hash of the checkpoint it starts from, when it has one (the generator's
    denoiser, fine-tuning's generator).

    The run folder and the resume state are checked before any data is read, the data the
    state was trained on once they are read, and all before anything is written (a failed
    check leaves nothing behind). Then the first process holds the folder for stage ``name``
    until the run ends (``hold_stage``): a second run there is refused. A new run in a folder
    that holds another's moves that run's metrics log, run record, resume state and
    checkpoints of stage ``name`` aside (``loop.set_aside``). ``equal_budget``: the minutes
    of ``finetune --equal-budget``, for its advice (``fit``) and a note when the process has
    more than one thread.

    Under torchrun every rank compares what it is about to train with rank 0's once the data
    are read (``check_same_run``, before anything is written), and a CPU-time budget says that
    its clock is each process's own (``cpu_budget_note``). Once every check has passed, the
    first process says what the run read (``report_data``) and warns of ``notes(train)``."""
    check_output_dir(out_dir)
    out_dir = Path(out_dir)
    section = getattr(cfg, name)
    state = None
    lock = None
    if resume is not None:
        state = load_resume_state(resume, name)
        check_resume(state, run_identity(cfg, name, start), section.epochs, out_dir, resume,
                     name, section.max_minutes, equal_budget)  # fmt: skip
        check_resume_processes(state, out_dir, name, resume)
    dev = resolve_device(device)
    info, dev = init_from_env(dev)
    set_threads(info)
    if equal_budget is not None and info.is_main and torch.get_num_threads() > 1:
        print(equal_budget_threads_note(torch.get_num_threads()), file=sys.stderr)
    note = cpu_budget_note(name, section, info)
    if note is not None and info.is_main:
        print(note, file=sys.stderr)
    try:
        train, val = run_splits(cfg.data, data_root, cfg.model.windows)
        data = data_fingerprint(train, val)
        if info.is_main and (same := same_content_note(train, val)) is not None:
            warnings.warn(
                same, category=OverlapWarning, stacklevel=2
            )  # the epoch would be chosen on training windows
        if state is not None:
            try:
                check_resume_data(state, data, resume)
            except ConfigError:
                if not _matches_before_exact_labels(state, cfg, data_root):
                    raise
        built, optim = build(train, val, dev)
        if state is not None:
            check_resume_matches(state, built.trainable, resume, optim.ema_epochs > 0)
        # every rank trains the run rank 0 does (a collective): before anything is written
        check_same_run(info, run_facts(cfg, name, start, data, train, state, max_steps,
                                       equal_budget))  # fmt: skip
        # one run of a stage in a folder at a time: held until the run ends, before any write
        lock = hold_stage(out_dir, name, info)
        if info.is_main:  # once every check that refuses the run has passed
            report_data(name, train, val, cfg.data)
            for note in notes(train) if notes is not None else ():
                warnings.warn(note, category=TrajprefWarning, stacklevel=3)
        if info.is_main:
            out_dir.mkdir(parents=True, exist_ok=True)
            if state is None:  # another run's log, record, state and checkpoints: not this run's
                set_aside(out_dir, name, RUN_STATE, checkpoints=True)
            for path in (out_dir / "config.yaml", out_dir / f"{name}_config.yaml"):
                save_config(cfg, path)  # the run's last stage's; this stage's, kept
                if info.enabled:
                    _note_processes(path, info)
            record_session(out_dir, name, cfg.seed, dev, info.world_size, state is not None,
                           info)  # fmt: skip
            if state is not None and state.get("world_size", 1) != info.world_size:
                print(f"[{name}] resumed on {info.world_size} process(es) from a state "
                      f"written on {state.get('world_size', 1)}: the batches, steps and "
                      "learning rates continue as they were; the random draws (noise, "
                      "augmentation, dropout) are not those an uninterrupted run would take",
                      file=sys.stderr)  # fmt: skip
        barrier(info)
        start_time = time.perf_counter()
        summary = fit(built, train, cfg.data, optim, out_dir, dev, cfg.seed, state, info,
                      progress, max_steps, run_identity(cfg, name, start, data),
                      {"data_hash": data_digest(data), "data_timing": data_timing(train)},
                      equal_budget)  # fmt: skip
        summary["wall_seconds"] = time.perf_counter() - start_time
        barrier(info)  # every rank done (rank 0 may still have been writing) before teardown
        summary["train_agents"] = train.num_agents
        summary["rank"] = info.rank  # only rank 0 validates: other ranks' "best" is empty
        return summary
    finally:
        release_stage_lock(lock)
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
            example = f"{cfg.data.dataset}/denoiser"
            if example not in zoo.published():  # a folder's run: any published one as a form
                example = "zara1/denoiser"
            raise ConfigError(
                f"{path}: the generator trains through a denoiser and there is none in "
                f"{out_dir}: train it there first (trajpref train diffusion ... --out "
                f"{out_dir}) or pass --denoiser FILE (or a published denoiser's name, e.g. "
                f"{example}: `trajpref models` lists them)"
            )
        payload = ckpt.load(path)
        if payload["kind"] != "denoiser":
            raise ConfigError(f"{path}: expected a denoiser checkpoint, got a {payload['kind']}")

    def build(train, val, dev):
        if payload is None:
            return build_denoiser_stage(cfg, train, val, dev)[0], cfg.denoiser
        return build_generator_stage(cfg, payload, val, dev, train), cfg.generator

    def notes(train: TrajectoryDataset) -> list[str]:
        if payload is None:
            return []
        note = denoiser_data_note(payload, str(denoiser or path), train)
        return [] if note is None else [note]

    start = payload.get("hash") if payload is not None else None  # the generator's denoiser
    return _run(cfg, out_dir, data_root, device, resume, progress, max_steps, build,
                STAGE_NAMES[stage], start, notes=notes)  # fmt: skip


def _denoiser_step_hint(model: dict[str, Any]) -> str:
    """``timing_problems``' advice for a denoiser of another step than the generator's data."""
    return (f"the generator would learn {model['step']:g} s steps' motion through it from "
            "data that step otherwise")  # fmt: skip


SCALE_TOLERANCE = 1.25
"""How far (as a ratio either way) the generator's data scale may be from the denoiser's
before ``denoiser_data_note`` names the difference."""


def denoiser_data_note(payload: dict[str, Any], name: str,
                       train: TrajectoryDataset) -> str | None:  # fmt: skip
    """The warning for a generator run whose denoiser (``payload``, shown as ``name``) was
    trained on data of other units or another step than ``train`` (``models.timing``'s
    ``timing_problems``, as evaluate compares a model with its data), or whose data scale is
    not this data's (``SCALE_TOLERANCE``): the generator takes the denoiser's scale, so it
    reads this data divided by another data's spread. None when nothing known differs."""
    try:
        timing = model_timing(payload)
    except (KeyError, TypeError, ValueError, AttributeError):
        return None
    info = train.info
    units = None if info.units in UNKNOWN_UNITS else info.units
    step = info.frame_interval if info.interval_from != "default" or timing["known"] else None
    problems = timing_problems(timing, step, units, _denoiser_step_hint)
    scale, own = float(payload["scale"]), data_scale(train)
    off = not 1 / SCALE_TOLERANCE <= own / scale <= SCALE_TOLERANCE
    if not problems and not off:
        return None
    shown = "" if timing["units"] in UNKNOWN_UNITS else f" {timing['units']}"
    here = "" if units is None else f" {units}"
    consequence = (f"the generator takes the denoiser's data scale ({scale:.3g}{shown}) for this "
                   f"data, whose own is {own:.3g}{here}, so these tracks reach the networks at "
                   f"{own / scale:.3g} times the size the denoiser learned, and it scores "
                   "samples of data it never saw")  # fmt: skip
    head = trained_otherwise(f"--denoiser {name}", timing, problems) if problems else (
        f"--denoiser {name} was trained on {timing['trained_on']}")  # fmt: skip
    return (
        f"{head}; {consequence}: train a denoiser on this data first (trajpref train "
        "diffusion with this run's config and --out), then the generator through it"
    )


def check_config_of_start(cfg: ExperimentConfig, payload: dict[str, Any],
                          start: str | Path) -> None:  # fmt: skip
    """``cfg``'s network and noise schedule (its ``model`` and ``diffusion`` sections) are
    those of the start checkpoint ``payload`` (as ``rl.presets.finetune_config`` resolves
    them), or a one-line ``ConfigError``: a config resolved from another start would mix that
    start's settings (a speed clamp, a width) into this one's weights. The data may differ
    (``data.dataset=FOLDER`` fine-tunes on other data)."""
    own = to_dict(ckpt.config_of(payload))
    now = to_dict(cfg)
    for section in ("model", "diffusion"):
        for key in sorted(set(own[section]) | set(now[section])):
            if own[section].get(key) != now[section].get(key):
                raise ConfigError(
                    f"{start}: the config was not resolved from this start ({section}.{key} = "
                    f"{own[section].get(key)!r} in the start, {now[section].get(key)!r} in the "
                    f"config); build it with rl.presets.finetune_config({str(start)!r}, ...)"
                )


def equal_budget_threads_note(threads: int) -> str:
    """The line that ``finetune --equal-budget`` prints on more than one thread."""
    return (f"[finetune] --equal-budget on {threads} threads: the budget counts this process's "
            "CPU time on all of them, so the steps it buys depend on how well each method's "
            "steps use the threads, and the runs do not compare with the equal-budget table's "
            "(one thread each); run each method on one thread (OMP_NUM_THREADS=1)")  # fmt: skip


OWN_OUTPUT = re.compile(rf"finetune(_raw|_epoch\d+)?{re.escape(ckpt.SUFFIX)}")
"""The names of the checkpoints a fine-tuning run writes in its folder (``loop.fit``)."""


def _check_start_not_output(start: str | Path, out_dir: str | Path) -> None:
    """A start that is one of the fine-tuning checkpoints in ``out_dir`` (a run fine-tuned
    again in its own folder) is refused: the new run moves it aside (a resumed one writes over
    it), and its record would name a file that no longer holds the start."""
    path = ckpt.resolve_path(start)
    if path.resolve().parent == Path(out_dir).resolve() and OWN_OUTPUT.fullmatch(path.name):
        raise ConfigError(f"--from {start}: a checkpoint of the fine-tuning run in {out_dir}, "
                          "which this run there replaces (it moves the folder's finetune "
                          "checkpoints aside, or writes over them when it resumes): copy it "
                          "out of the folder first, or choose another --out")  # fmt: skip


def finetune(
    cfg: ExperimentConfig,
    start: str | Path,
    out_dir: str | Path,
    data_root: str | None = None,
    device: str = "auto",
    resume: str | None = None,
    progress: bool = True,
    max_steps: int | None = None,
    equal_budget: float | None = None,
) -> dict[str, Any]:
    """RLHF / RLHF-ReS fine-tuning from the generator checkpoint ``start`` (DDP-aware);
    ``cfg`` comes from ``rl.presets.finetune_config`` with the same ``start``: its network
    and noise schedule (``model``, ``diffusion``) must be the start's, or a ``ConfigError``
    names the first difference before anything is written. ``equal_budget``: the minutes
    ``cfg`` was resolved with (``finetune_config(equal_budget=...)``, ``--equal-budget``): a
    run its budget ended, or a resume with the budget spent, then names that option rather
    than the ``--set finetune.max_minutes`` it refuses, and a process of more than one thread
    says that the protocol's runs take one; under torchrun (several processes) it is refused
    (an ``EveryRankError``): the protocol's budget is one process's CPU time."""
    launch = env_info()
    if equal_budget is not None and launch.enabled:  # every rank alike: rank 0 says it
        raise EveryRankError(
            f"--equal-budget under torchrun ({launch.world_size} processes): the equal-budget "
            "protocol is one process on one thread (its budget is that process's CPU time, so "
            f"{launch.world_size} processes would spend {launch.world_size} times it, and the "
            "runs would not compare with its table's): run it without torchrun, with "
            "OMP_NUM_THREADS=1"
        )
    _check_start_not_output(start, out_dir)
    payload = ckpt.load(start)
    if payload["kind"] != "generator":
        raise ConfigError(f"{start}: fine-tuning starts from a generator checkpoint")
    check_config_of_start(with_absolute_folders(cfg), payload, start)
    cfg, note = finetune_run_config(cfg)
    if note is not None and os.environ.get("RANK", "0") == "0":
        print(note, file=sys.stderr)

    def build(train, val, dev):
        return build_finetune_stage(cfg, payload, val, dev, train), cfg.finetune

    return _run(cfg, out_dir, data_root, device, resume, progress, max_steps, build,
                STAGE_NAMES["finetune"], payload.get("hash"), equal_budget)  # fmt: skip
