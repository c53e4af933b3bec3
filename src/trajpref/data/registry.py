"""One entry point for every dataset: ``load_dataset(name, split, root)``.

Names: ``NAMES`` (``config.BUILTIN_DATASETS``: ``eth hotel univ zara1 zara2 sdd nba robo
robo-sim robo-mix``), or a path to a folder of
``frame agent x y`` text files or TrajNet++ ``.ndjson`` scene files (with ``train/val/test``
sub-folders when present), or to one ``.ndjson`` file. Formats: ``docs/data_format.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import numbers
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from trajpref.config import BUILTIN_DATASETS
from trajpref.data import arrays, text, trajnet
from trajpref.data.robo_sim import simulate
from trajpref.data.stats import METRES_PER_UNIT
from trajpref.errors import (
    ConfigError,
    DataError,
    DataNotFound,
    DataWarning,
    FrameRateWarning,
    IgnoredWarning,
    TrajprefError,
)
from trajpref.types import WINDOW, DatasetInfo, Scene, TrajectoryDataset

if TYPE_CHECKING:
    from trajpref.config import DataConfig

ETH_UCY = ("eth", "hotel", "univ", "zara1", "zara2")
"""The five ETH/UCY leave-one-out folds."""
NAMES = BUILTIN_DATASETS
"""Built-in dataset names."""
BRANCHES = (*ETH_UCY, "sdd", "nba", "robo", "robo-sim", "robo-mix")
"""The names ``_built_in`` has a branch for (a test checks that they, ``NAMES`` and ``SPECS``
agree)."""
SPLITS = ("train", "val", "test")
USER_TEXT = ("*.txt", "*.csv", "*.tsv")
"""Track files of a user folder (Social-GAN text format; docs/data_format.md), matched
ignoring case (``a.TXT``, ``b.Csv``). All are read alike, the separator sniffed from the
first data line: a ``.tsv`` file's tabs are whitespace, as in the ETH/UCY ``.txt`` files."""
DEFAULT_FRAME_INTERVAL = 0.4
"""Seconds between frames of a user folder when none is given (and, for TrajNet++ files,
none is declared; for text files, their frame column is not named as seconds)."""
SECONDS_STEPS = (1e-3, 10.0)
"""The frame steps of a ``time``/``timestamp`` column (``text.SECONDS_COLUMNS``; a
``time_ms``/``timestamp_ms`` one's, ``text.MILLISECONDS_COLUMNS``, divided by 1000) that are read
as seconds; a step outside (milliseconds, nanoseconds) leaves ``DEFAULT_FRAME_INTERVAL`` with
a ``FrameRateWarning``. The ceiling is 10 s, not more: a log in milliseconds at 17-100 Hz
steps 10-60, which a 60 s ceiling read as seconds (a 30 fps file at 33 s between frames, its
speeds a thousand times too low)."""

FEET_TO_METRES = 0.3048

PROTOCOLS = ("all", "sgan")
"""Which windows count (docs/data.md, "Evaluation protocols"): ``all`` keeps every window with
at least one fully observed agent; ``sgan`` keeps only windows with at least
``SGAN_MIN_AGENTS`` of them, as the Social-GAN loader does (its ``min_ped = 1`` and
``num_peds_considered > min_ped``)."""
SGAN_MIN_AGENTS = 2


@dataclass(frozen=True)
class SourceSpec:
    """Fixed facts about one data source (units, timing, how val is made)."""

    units: str
    """Coordinate units after loading."""
    frame_interval: float
    """Seconds between consecutive frames of a window."""
    t_hist: int = 8
    """Observed frames per window."""
    t_fut: int = 12
    """Future frames per window."""
    text_tracks: bool = False
    """Its splits are text track files that the reader cuts into windows (``frame agent x
    y``: ETH/UCY's, NBA's), not windows already cut (``.npz``) or simulated: its
    ``DatasetInfo.text_tracks`` (which the fold-overlap checks read), and it takes
    ``ReadOptions.time_step``."""
    folder_options: bool | None = None
    """Whether it takes what a folder of its text track files takes: ``data.partial_future``
    and ``--protocol sgan`` (``takes_folder_options``). None: as ``text_tracks``. NBA says
    False: its peers count every agent (no sgan), and it refused both before they were keyed
    on this."""

    @property
    def takes_folder_options(self) -> bool:
        """``folder_options``, or where it is None, ``text_tracks``."""
        return self.text_tracks if self.folder_options is None else self.folder_options


SPECS = {
    **{name: SourceSpec("m", 0.4, text_tracks=True) for name in ETH_UCY},
    "sdd": SourceSpec("px", 0.4),
    "nba": SourceSpec("m", 0.12, text_tracks=True, folder_options=False),
    "robo": SourceSpec("m", 0.5),
    "robo-sim": SourceSpec("m", 0.5),
    "robo-mix": SourceSpec("m", 0.5),
}

VAL_FRACTION = 0.1
"""SDD and NBA ship train/test only: this fraction of train (whole scenes for SDD, whole files
for NBA), drawn with ``VAL_SEED``, becomes the validation split."""
VAL_SEED = 0

ROBO_SIM_EPISODES = {"train": 10_000, "val": 1_000, "test": 1_000}
"""Episodes per robo-sim split; each split has its own seed (``ROBO_SIM_SEEDS``)."""
ROBO_SIM_SEEDS = {"train": 0, "val": 1, "test": 2}

ROBO_MIX_VAL_FRACTION = 0.2
"""robo-mix: this fraction of the official Robo val split's episodes (whole episodes, drawn with
``VAL_SEED``) is held out as robo-mix's validation split; the rest joins robo-sim's training
split. robo-mix's test split is the official Robo test split."""
ROBO_MIX_REAL_SHARE = 1 / 3
"""robo-mix: the share of training scenes that are real. The ~400 real training windows are
repeated (whole copies, rounded) until they make up about this share beside robo-sim's 10,000
episodes; without it they would be 4 % of what the model sees. One unsearched choice."""


def resolve_data_root(root: str | Path | None = None) -> Path:
    """The data root: the argument, else ``$TRAJPREF_DATA``. Raises if neither is usable."""
    value = root if root is not None else os.environ.get("TRAJPREF_DATA")
    if not value:
        raise ConfigError(
            "no data root: give it (the CLI's --data-root, or root= in Python, "
            "e.g. load_dataset(name, split, root=...)) or set TRAJPREF_DATA"
        )
    path = Path(value).expanduser()
    if not path.is_dir():
        if not path.exists():
            raise DataNotFound("data root is not a folder", path)
        raise DataError("data root is not a folder", path)
    return path


UNKNOWN = "unknown"
"""The units of a folder read without ``units`` (nothing said of them)."""
PIXEL_NAMES = frozenset({"px", "pixel", "pixels", "pix"})
"""The names of pixels (``models.timing.PIXEL_UNITS``, ``viz.plot.IMAGE_UNITS``: a test
checks that they agree)."""
KNOWN_UNITS = frozenset(METRES_PER_UNIT) | PIXEL_NAMES | {UNKNOWN}
"""Unit names the library reads something into (compared in any case): metres and their
fractions and feet (``data.stats.METRES_PER_UNIT``: the walking-speed note; metres alone set
the default collision radius), pixels (figures drawn y down), and ``unknown``. Another name is
kept as given, with a ``UserWarning`` (``check_units``)."""


def check_frame_interval(frame_interval: float | None,
                         what: str = "seconds between an agent's consecutive rows",
                         ) -> float | None:  # fmt: skip
    """``frame_interval`` (``what``: seconds between an agent's consecutive rows, or the
    history's positions for ``models.timing.check_pace``) as a float, None staying None;
    ``ConfigError`` unless it is a real, finite number > 0 (a string such as ``'0.4'``
    included)."""
    if frame_interval is None:
        return None
    if (isinstance(frame_interval, bool) or not isinstance(frame_interval, numbers.Real)
            or not math.isfinite(frame_interval) or frame_interval <= 0):  # fmt: skip
        raise ConfigError(f"frame_interval: {what}, a number > 0, got {frame_interval!r}")
    return float(frame_interval)


def check_units(units: str | None) -> str:
    """``units`` as a dataset's unit name: None is ``unknown`` (as ``DataConfig.units``
    None); ``ConfigError`` for anything but a non-empty string; a ``UserWarning`` for a name
    outside ``KNOWN_UNITS``, which is kept as given but means nothing to the library (as
    ``--units``: the CLI reads data through ``load_dataset``)."""
    if units is None:
        return UNKNOWN
    if not isinstance(units, str) or not units.strip():
        raise ConfigError(f"units: a unit name such as 'm' or 'px', or 'unknown' (the "
                          f"default), got {units!r}")  # fmt: skip
    if units.strip().lower() not in KNOWN_UNITS:
        known = ", ".join(sorted(KNOWN_UNITS - {UNKNOWN}))
        warnings.warn(f"units {units!r} is none of the names trajpref knows ({known}, or "
                      f"{UNKNOWN}): kept as given, but no speed is read in metres, collision "
                      "metrics need a radius in these units, and a model's units are compared "
                      "by name", DataWarning, stacklevel=3)  # fmt: skip
    return units


def _check_split(split: str) -> None:
    if split not in SPLITS:
        raise ConfigError(f"unknown split {split!r}; choose one of {', '.join(SPLITS)}")


def load_dataset(
    name: str,
    split: str = "test",
    root: str | Path | None = None,
    frame_interval: float | None = None,
    units: str | None = "unknown",
    options: text.ReadOptions | None = None,
    protocol: str = "all",
) -> TrajectoryDataset:
    """Load one split of a dataset as a list of scenes in absolute coordinates.

    ``frame_interval`` and ``units`` describe user folders (a path ``name``) only; built-in
    datasets know their own, and given for one they are ignored with a ``UserWarning`` (as
    the CLI's ``--frame-interval`` and ``--units``). ``frame_interval`` is a number of seconds
    > 0 (``check_frame_interval``) and ``units`` a unit name (``check_units``: None is
    ``unknown``; a name outside ``KNOWN_UNITS`` warns): anything else is a ``ConfigError``,
    before any file is read. ``frame_interval`` None: for text files the step of their frame
    column when its header names it as seconds (``time``, ``timestamp``: ``text_interval``),
    else ``DEFAULT_FRAME_INTERVAL`` (0.4 s); the declared ``fps`` of TrajNet++ files
    (``trajnet_interval``; a value given that differs from it is ignored with a
    ``FrameRateWarning``). ``info.interval_from`` says which; ``info.frame_interval`` is that
    interval times ``options.time_step``, the seconds between a window's steps. ``options``
    (delimiter, ``max_gap``, ``max_coord``) apply to every reader that they make sense for (the
    bound to all of them). ``protocol`` is one of ``PROTOCOLS`` (``apply_protocol``).
    """
    _check_split(split)
    check_protocol(protocol)
    frame_interval = check_frame_interval(frame_interval)
    units = check_units(units)
    given = [f"frame_interval={frame_interval:g}"] if frame_interval is not None else []
    given += [f"units={units!r}"] if units != UNKNOWN else []
    if name in NAMES and given:  # as the CLI's --frame-interval and --units
        ignored = f"{' and '.join(given)} {'is' if len(given) == 1 else 'are'} ignored"
        warnings.warn(own_reading_note(name, "frame_interval and units", ignored),
                      IgnoredWarning, stacklevel=2)  # fmt: skip
    data = _load(name, split, root, frame_interval, units, options)
    step = options.time_step if options is not None else 1.0
    if step != 1.0:  # read every ``step`` frame steps: each window step spans that much more
        info = dataclasses.replace(data.info, frame_interval=data.info.frame_interval * step,
                                   time_step=step)  # fmt: skip
        data = TrajectoryDataset(data.scenes, info)
    return apply_protocol(data, protocol)


def own_reading_note(name: str, options: str, ignored: str) -> str:
    """The warning for a built-in dataset ``name`` given a folder's description (``options``:
    how the caller names its frame interval and units; ``ignored``: what is ignored): it
    knows its own (``SPECS``). ``load_dataset`` and the CLI's data options say it alike."""
    spec = SPECS.get(name)
    own = f" ({spec.units}, {spec.frame_interval:g} s)" if spec is not None else ""
    return f"{options} describe a folder dataset; {name} knows its own{own}, so {ignored}"


def check_protocol(protocol: str) -> None:
    """Raise a clear error unless ``protocol`` is one of ``PROTOCOLS``."""
    if protocol not in PROTOCOLS:
        raise ConfigError(f"unknown protocol {protocol!r}; choose one of {', '.join(PROTOCOLS)}")


def _takes_folder_options(name: str) -> bool:
    """Whether the built-in ``name`` takes a text-track folder's options (``SourceSpec.
    takes_folder_options``); a name without a ``SPECS`` entry does not (reading it is an
    error of its own)."""
    spec = SPECS.get(name)
    return spec is not None and spec.takes_folder_options


def _has_text_tracks(name: str) -> bool:
    """Whether the built-in ``name``'s splits are text track files (``SourceSpec.text_tracks``)."""
    spec = SPECS.get(name)
    return spec is not None and spec.text_tracks


def check_protocol_for(name: str, protocol: str) -> None:
    """Raise a ``ConfigError`` when ``protocol`` does not apply to the dataset ``name``:
    ``sgan`` is the counting of Social-GAN's ETH/UCY loader, so it is refused for the other
    built-in datasets (on SDD it would silently drop the windows of lone agents, about half
    the test agents, and the SDD and NBA peers count every agent; on NBA and Robo it changes
    nothing). A folder of one's own data may use either protocol, and so may a built-in
    dataset of text tracks whose ``SPECS`` entry takes a folder's options (the ETH/UCY folds;
    ``SourceSpec.takes_folder_options``)."""
    check_protocol(protocol)
    if protocol != "sgan" or name not in NAMES or _takes_folder_options(name):
        return
    others = [n for n in NAMES if n not in ETH_UCY and _takes_folder_options(n)]
    also = f" and {', '.join(others)}" if others else ""  # text-track datasets added since
    raise ConfigError(
        f"--protocol sgan is Social-GAN's ETH/UCY counting (windows with at least "
        f"{SGAN_MIN_AGENTS} agents), for the ETH/UCY folds ({', '.join(ETH_UCY)}){also} only; the "
        "SDD and NBA peers count every agent (on sdd, sgan would drop the lone agents' "
        "windows, about half of the test agents): use --protocol all (the default) for "
        f"{name} (docs/data.md, 'Evaluation protocols')"
    )


def apply_protocol(dataset: TrajectoryDataset, protocol: str) -> TrajectoryDataset:
    """The scenes of ``dataset`` that count under ``protocol``, with ``info.protocol`` set.

    ``sgan`` drops the scenes with fewer than ``SGAN_MIN_AGENTS`` agents: every metric is then
    over the agents of the remaining scenes. Raises ``DataError`` when nothing is left."""
    check_protocol(protocol)
    scenes = dataset.scenes
    if protocol == "sgan":
        scenes = [s for s in scenes if s.num_agents >= SGAN_MIN_AGENTS]
        if not scenes:
            raise DataError(
                f"no scene has {SGAN_MIN_AGENTS} or more agents, so the sgan protocol "
                "leaves nothing to evaluate",
                dataset.info.source,
            )
    info = dataclasses.replace(dataset.info, protocol=protocol)
    return TrajectoryDataset(scenes, info)


def scene_file(scene: Scene) -> str:
    """The file a window comes from (its ``scene_id`` before ``@``)."""
    return scene.scene_id.split("@", 1)[0]


def hold_out_scene(
    train: TrajectoryDataset, val: TrajectoryDataset, prefix: str
) -> tuple[TrajectoryDataset, TrajectoryDataset]:
    """Model selection on a scene the model has not trained on: the training windows of the
    files whose name starts with ``prefix`` (one of a fold's training scenes, e.g.
    ``biwi_hotel`` or ``students``) leave the training split, and that scene's windows of both
    splits become the validation split (the other scenes' validation windows are dropped; when
    both splits read the same files, a folder without split sub-folders, its windows once).
    An ETH/UCY fold's usual validation split holds files of the very scenes it trains on; this
    one asks what the fold's test asks, how a model does on a new scene."""
    if not prefix:
        raise ConfigError("hold_out_scene needs a file-name prefix")
    held = [s for s in train.scenes if scene_file(s).startswith(prefix)]
    kept = [s for s in train.scenes if not scene_file(s).startswith(prefix)]
    files = sorted({scene_file(s) for s in train.scenes})
    if not held:
        raise ConfigError(
            f"no training file of {train.info.name} starts with {prefix!r}; its files: "
            + ", ".join(files)
        )
    if not kept:
        raise ConfigError(f"holding out {prefix!r} leaves {train.info.name} no training file")
    if val.info.source != train.info.source:  # a folder without split sub-folders: the same
        held += [s for s in val.scenes if scene_file(s).startswith(prefix)]  # windows again
    note = f" (held-out scene {prefix})"
    train_info = dataclasses.replace(train.info, source=train.info.source + f" minus {prefix}*")
    val_info = dataclasses.replace(val.info, source=train.info.source + note)
    return TrajectoryDataset(kept, train_info), TrajectoryDataset(held, val_info)


def with_paced_copy(
    train: TrajectoryDataset, paced: TrajectoryDataset, exclude: str = ""
) -> TrajectoryDataset:
    """``train`` plus ``paced``, the same files read at another time step
    (``ReadOptions.time_step``): a training split at two paces (``DataConfig.extra_time_step``).
    Windows of files whose name starts with ``exclude`` (a held-out scene) are left out of the
    copy, as they are out of ``train``."""
    if paced.info.name != train.info.name or paced.info.split != train.info.split:
        raise ConfigError(f"a paced copy of {train.info.name}/{train.info.split} cannot come "
                          f"from {paced.info.name}/{paced.info.split}")  # fmt: skip
    ours, its = (train.info.t_hist, train.info.t_fut), (paced.info.t_hist, paced.info.t_fut)
    if its != ours:
        raise ConfigError(f"a paced copy of {train.info.name}/{train.info.split} must be cut "
                          f"into its windows of {ours[0]} + {ours[1]} frames, not "
                          f"{its[0]} + {its[1]}: read it with the same ReadOptions t_hist and "
                          "t_fut")  # fmt: skip
    extra = [s for s in paced.scenes if not (exclude and scene_file(s).startswith(exclude))]
    if not extra:
        raise ConfigError(f"{train.info.name}'s training files give no window at the extra "
                          "time step: no agent is seen long enough")  # fmt: skip
    pace = paced.info.frame_interval / train.info.frame_interval
    note = f" plus its files read at {pace:g}x its step ({len(extra)} windows)"
    info = dataclasses.replace(train.info, source=train.info.source + note)
    return TrajectoryDataset(list(train.scenes) + extra, info)


def add_paced_copy(
    train: TrajectoryDataset,
    step: float,
    root: str | Path | None = None,
    options: text.ReadOptions | None = None,
    exclude: str = "",
) -> TrajectoryDataset:
    """``train`` with its own files read again every ``step`` frame steps joined to it
    (``with_paced_copy``; the other reading options as ``options``): how a run with
    ``DataConfig.extra_time_step`` builds its training split."""
    paced = dataclasses.replace(options or text.ReadOptions(), time_step=step)
    copy = load_dataset(train.info.name, train.info.split, root, options=paced)
    return with_paced_copy(train, copy, exclude)


def _start_frame(scene: Scene) -> int:
    """The first frame of a text-track window (its ``scene_id`` ends ``@frame=N``)."""
    _, _, tail = scene.scene_id.partition("@frame=")
    if not tail.lstrip("-").isdigit():
        raise ConfigError(f"{scene.scene_id}: splitting validation in time needs windows "
                          "cut from text track files (scene ids ending '@frame=N')")  # fmt: skip
    return int(tail)


def split_validation_in_time(
    train: TrajectoryDataset, val: TrajectoryDataset, share: float, to_train: bool
) -> tuple[TrajectoryDataset, TrajectoryDataset]:
    """Cut each validation file in time: its earliest ``share`` of windows leave the
    validation split, and so do the windows after them that would share a frame with them
    (a gap of one window's length); what is left is the validation split. With ``to_train``
    the early windows join the training split, otherwise they are dropped, so that a run
    with more training data and its control validate on the very same windows."""
    if not 0.0 < share < 1.0:
        raise ConfigError(f"the validation share to cut must be in (0, 1), got {share}")
    files: dict[str, list[Scene]] = {}
    for scene in val.scenes:
        files.setdefault(scene_file(scene), []).append(scene)
    early: list[Scene] = []
    late: list[Scene] = []
    for name in sorted(files):
        timed = sorted(((_start_frame(s), s) for s in files[name]), key=lambda fs: fs[0])
        starts = [f for f, _ in timed]  # windows in time order
        scenes = [s for _, s in timed]
        cut = round(share * len(scenes))
        if cut == 0:
            late += scenes
            continue
        steps = [b - a for a, b in zip(starts[:-1], starts[1:], strict=True) if b > a]
        step = min(steps) if steps else 1  # the file's frame spacing between windows
        length = scenes[0].history.shape[1] + scenes[0].future.shape[1]  # T_h + T_f
        last_shared = starts[cut - 1] + (length - 1) * step  # the last early window's end
        early += scenes[:cut]
        late += [s for s, f in zip(scenes[cut:], starts[cut:], strict=True) if f > last_shared]
    if not late:
        raise ConfigError(f"cutting {share:.0%} of {val.info.name}'s validation windows "
                          "leaves none to validate on")  # fmt: skip
    tag = f" (validation after its first {share:.0%} in time)"
    val_info = dataclasses.replace(val.info, source=val.info.source + tag)
    if to_train:
        note = f" plus the first {share:.0%} of {val.info.source}"
        train_info = dataclasses.replace(train.info, source=train.info.source + note)
        train = TrajectoryDataset(list(train.scenes) + early, train_info)
    return train, TrajectoryDataset(late, val_info)


def split_sources(name: str, split: str) -> frozenset[tuple[str, str]]:
    """The built-in (dataset, split) pairs whose windows the built-in ``name``'s ``split``
    holds: itself, but for robo-mix, whose training split is robo-sim's plus most of the
    official Robo val split's episodes, its validation split the rest of them, and its test
    split Robo's (``_robo_mix``). What a model trained or validated on, beside what it is
    evaluated on, tells an overlap across names (``cli._shared_split``)."""
    if name == "robo-mix":
        mix = {"train": {("robo-sim", "train"), ("robo", "val")}, "val": {("robo", "val")},
               "test": {("robo", "test")}}  # fmt: skip
        return frozenset(mix.get(split, {(name, split)}))
    return frozenset({(name, split)})


def run_splits(
    data: DataConfig, root: str | Path | None = None, windows: tuple[int, int] = WINDOW
) -> tuple[TrajectoryDataset, TrajectoryDataset]:
    """A run's training and validation splits as its data config builds them: both read with
    its reading options in windows of ``windows`` = (T_h, T_f) frames (the run's
    ``model.t_hist`` and ``model.t_fut``), then its held-out scene, its validation cut in time,
    and last its paced copy (``extra_time_step``; after the hold-out, so the copy leaves that
    scene too). ``partial_future`` and ``reverse_context`` apply to the training split (and its
    paced copy) alone.
    The training loop reads its data this way, and so does anything that must see the windows a
    checkpoint trained on (``models.checkpoint.config_of(...)``: its ``data``, and its
    ``model.windows``)."""
    if data.partial_future and data.holdout_scene:  # here, not in DataConfig: checkpoints load
        raise ConfigError("data.partial_future and data.holdout_scene exclude each other: the "
                          "held-out scene's validation windows would come from the training "
                          "read, whose partial-future agents have no whole future to validate "
                          "on")  # fmt: skip
    options = text.ReadOptions(data.delimiter, data.max_gap, data.max_coord, data.time_step,
                               t_hist=windows[0], t_fut=windows[1])  # fmt: skip

    def described(name: str) -> dict:
        """A folder's frame interval and units (a built-in dataset knows its own: with a
        built-in training set and a folder for validation, they describe the folder)."""
        if name in NAMES:
            return {}
        return {"frame_interval": data.frame_interval, "units": data.units or UNKNOWN}

    val_name = data.val_dataset or data.dataset
    val = load_dataset(val_name, "val", root, options=options, **described(val_name))
    # agents that leave the view count as targets in training only (``partial_future``)
    options = dataclasses.replace(options, partial_future=data.partial_future,
                                  reverse_context=data.reverse_context)  # fmt: skip
    train = load_dataset(data.dataset, "train", root, options=options,
                         **described(data.dataset))  # fmt: skip
    if data.holdout_scene:
        train, val = hold_out_scene(train, val, data.holdout_scene)
    if data.val_cut:
        train, val = split_validation_in_time(train, val, data.val_cut, data.val_cut_to_train)
    if data.extra_time_step:
        train = add_paced_copy(train, data.extra_time_step, root, options, data.holdout_scene)
    # TrajNet++ test files hide the future: no loss or validation could be computed on them
    # (training's partial-future targets are NaN where unseen by design, so not checked then)
    trajnet.require_future(val, "training (its validation split)")
    if not data.partial_future:
        trajnet.require_future(train, "training")
    return train, val


def _load(
    name: str,
    split: str,
    root: str | Path | None,
    frame_interval: float | None,
    units: str,
    options: text.ReadOptions | None,
) -> TrajectoryDataset:
    options = options or text.ReadOptions()
    if options.partial_future and name in NAMES and not _takes_folder_options(name):
        why = ("is read as its peers read it, without a folder's options (its SPECS entry, "
               "SourceSpec.folder_options)" if _has_text_tracks(name)
               else "comes as windows already cut")  # fmt: skip
        raise ConfigError(f"partial_future cuts windows from text track files (ETH/UCY or "
                          f"a folder of them); {name} {why}")  # fmt: skip
    if options.time_step != 1.0 and name in SPECS and not SPECS[name].text_tracks:
        raise ConfigError(f"time_step resamples text track files; {name} comes as windows "
                          "already cut (or simulated)")  # fmt: skip
    windows = (options.t_hist, options.t_fut)
    if windows != WINDOW and name in SPECS and not SPECS[name].text_tracks:
        raise ConfigError(f"{name} comes as windows already cut (or simulated) at "
                          f"{SPECS[name].t_hist} observed + {SPECS[name].t_fut} future frames; "
                          f"windows of {windows[0]} + {windows[1]} (the lengths asked, or a "
                          "model's own) are cut from text track files alone (ETH/UCY, NBA, "
                          "TrajNet++ or a folder of your own)")  # fmt: skip
    if name in NAMES:
        data = _built_in(name, split, root, options)
        info = dataclasses.replace(data.info, interval_from="dataset",
                                   text_tracks=SPECS[name].text_tracks)  # fmt: skip
        return TrajectoryDataset(data.scenes, info)
    path = Path(name).expanduser()
    if path.exists() or path.is_symlink() or os.sep in name or name.startswith("."):
        return _user_folder(path, split, frame_interval, units, options)
    raise DataNotFound(
        f"unknown dataset {name!r}; choose one of {', '.join(NAMES)} or pass a folder path"
    )


def _built_in(name: str, split: str, root: str | Path | None,
              options: text.ReadOptions) -> TrajectoryDataset:  # fmt: skip
    """A built-in dataset read from the data root. Each name has its own branch (an ETH/UCY
    fold: ``ETH_UCY``); a name of ``NAMES`` without ``SPECS`` entry or branch is an error."""
    if name == "robo-sim":
        return _robo_sim(split)
    if name == "robo-mix":
        with _layout_on_missing(name, resolve_data_root(root)):
            return _robo_mix(split, root, options)
    spec = SPECS.get(name)
    if spec is None:
        raise TrajprefError(f"built-in dataset {name!r} (config.BUILTIN_DATASETS) has no entry in "
                            "data.registry.SPECS (its units and frame interval); the datasets "
                            f"with one: {', '.join(SPECS)} (docs/data.md, \"Adding a built-in "
                            "dataset\")")  # fmt: skip
    if name not in BRANCHES:
        raise TrajprefError(f"built-in dataset {name!r} has no branch in data.registry._built_in "
                            f"that reads it; the datasets it reads: {', '.join(BRANCHES)} "
                            "(docs/data.md, \"Adding a built-in dataset\")")  # fmt: skip
    base = resolve_data_root(root)
    with _layout_on_missing(name, base):
        if name in ETH_UCY:
            folder = base / "eth_ucy" / name / split
            scenes = text.read_folder(folder, options=options, units=spec.units)
            source = folder
        elif name == "sdd":
            scenes, source = _sdd(base, split, options)
        elif name == "nba":
            scenes, source = _nba(base, split, spec, options)
        elif name == "robo":
            scenes, source = _robo(base, split, options)
        else:  # a name added to BRANCHES without its branch here
            raise AssertionError(f"data.registry._built_in: {name!r} is in BRANCHES but has no "
                                 "branch")  # fmt: skip
    t_hist, t_fut = (
        (options.t_hist, options.t_fut) if spec.text_tracks else (spec.t_hist, spec.t_fut)
    )
    info = DatasetInfo(name, split, spec.units, spec.frame_interval, t_hist, t_fut, str(source))
    return TrajectoryDataset(scenes, info)


_LAYOUTS = {
    **{name: f"eth_ucy/{name}/{{train,val,test}}/*.txt" for name in ETH_UCY},
    "sdd": "sdd/{train,test}.npz",
    "nba": "nba/rebound/{train,test}/*.txt",
    "robo": "robo/{val,test}.npz",
    "robo-mix": "robo/{val,test}.npz",
}
"""Where each built-in dataset read from the data root lies under it, for the error on a
missing folder or file (the README's table, "Data: where each dataset comes from")."""


@contextlib.contextmanager
def _layout_on_missing(name: str, base: Path) -> Iterator[None]:
    """Re-raise a ``DataError`` for a missing folder or file under the data root ``base``
    (not a broken link, not a malformed file) with where ``name`` lies under it."""
    try:
        yield
    except DataError as exc:
        missing = exc.path is not None and exc.line is None
        if missing:
            path = Path(exc.path)
            missing = (not path.exists() and not path.is_symlink()
                       and path.is_relative_to(base) and name in _LAYOUTS)  # fmt: skip
        if not missing:
            raise
        said = str(exc).removeprefix(f"{exc.path}: ")
        raise DataNotFound(
            f"{said}; {name} is read from {_LAYOUTS[name]} under the data root "
            f'({base}; the README\'s "Data: where each dataset comes from" says '
            "where each dataset's files come from)",
            exc.path,
        ) from None


def _user_folder(
    path: Path, split: str, frame_interval: float | None, units: str, options: text.ReadOptions
) -> TrajectoryDataset:
    if path.suffix.lower() == ".ndjson" and not path.is_dir():
        text.check_file(path)  # a clear error for a missing file or a symlink loop
        return _trajnet([path], str(path), split, frame_interval, units, options, path)
    if not path.is_dir():
        if path.is_symlink():
            text.track_files(path)  # says "symlink loop" or "broken symlink"
        if path.is_file():
            raise DataError(f"a file, where a folder of track files is needed (with its own "
                            f"train/val/test sub-folders or not): pass {path.parent} or a "
                            "folder holding just this file", path)  # fmt: skip
        raise DataNotFound("no such folder", path)
    splits = split_folders(path)
    folder = splits.get(split, path)
    if splits and split not in splits:
        present = [f.name for f in splits.values()]
        remedy = ""
        if split == "val":  # what a run validates on; data.holdout_scene reads val/ too
            remedy = ("; add a val/ sub-folder (a few of the recordings moved out of "
                      "train/), or, to train or fine-tune, --set data.val_dataset=FOLDER (a "
                      "folder of validation track files); to evaluate, predict or plot "
                      "validation files, give their folder as --dataset")  # fmt: skip
        others = _other_folders(path, splits)
        if others:  # folders that may be the split under another name (validation/, testing/)
            renames = [f"{o}/ to {SPLIT_ALIASES[o.lower()]}/" for o in others
                       if SPLIT_ALIASES.get(o.lower()) not in (None, *splits)]  # fmt: skip
            present.append(
                f"and {', '.join(f'{o}/' for o in others)}, which are not split "
                f"folders: only train/, val/ and test/ are"
                + (f"; rename {' and '.join(renames)}" if renames else "")
            )
        raise DataNotFound(f"no {split}/ sub-folder (found {', '.join(present)}){remedy}", path)
    has_text = bool(text.matching_files(folder, USER_TEXT))
    if text.matching_files(folder, ("*.ndjson",)):
        if has_text:
            raise DataError(f"holds both text ({', '.join(USER_TEXT)}) and *.ndjson files: "
                            "keep one format per folder", folder)  # fmt: skip
        files = text.track_files(folder, "*.ndjson")
        return _trajnet(files, str(path), split, frame_interval, units, options, folder)
    steps: dict[Path, tuple[str | None, float]] = {}
    scenes = text.read_folder(folder, pattern=USER_TEXT, options=options, units=units,
                              steps=steps)  # fmt: skip
    interval, source = text_interval(steps, frame_interval, folder)
    info = DatasetInfo(str(path), split, units, interval, options.t_hist, options.t_fut,
                       str(folder), interval_from=source, text_tracks=True)  # fmt: skip
    return TrajectoryDataset(scenes, info)


def text_interval(steps: dict[Path, tuple[str | None, float]], given: float | None,
                  source: Path) -> tuple[float, str]:  # fmt: skip
    """Seconds between frames of a folder's text files, and where they come from
    (``DatasetInfo.interval_from``), from ``steps`` (each file's header name of its frame
    column and its frame step, ``text.read_files``) and ``given``, the interval the user
    passed (None: none). ``given`` wins. Else, when every file's frame column is named as a
    time (``text.column_seconds``: ``time``, ``timestamp`` in seconds, ``time_ms``,
    ``timestamp_ms`` in milliseconds) and they all step alike, by a step in ``SECONDS_STEPS``
    once in seconds: that step in seconds (``timestamps``). Else ``DEFAULT_FRAME_INTERVAL``
    (``default``), with a ``FrameRateWarning`` when time columns were there but gave no one
    interval in seconds."""
    if given is not None:
        return given, "given"
    stepped = {path: (name, step) for path, (name, step) in steps.items() if step > 0}
    timed: dict[Path, tuple[float, float, bool]] = {}  # seconds, as written, in milliseconds
    for path, (name, step) in stepped.items():
        per = text.column_seconds(name)
        if per is not None:
            timed[path] = (step * per, step, per != 1.0)
    if not timed:
        return DEFAULT_FRAME_INTERVAL, "default"
    why = None
    first, written, ms = next(iter(timed.values()))
    if len(timed) < len(stepped):
        untimed = next(path for path in stepped if path not in timed)
        unit = "milliseconds" if ms else "seconds"
        why = (f"{next(iter(timed)).name}'s frame column is a time in {unit}, "
               f"{untimed.name}'s is not")  # fmt: skip
    elif any(not math.isclose(step, first, rel_tol=1e-3) for step, _, _ in timed.values()):
        where = ", ".join(f"{raw:.6g} ms in {path.name}" if in_ms else f"{step:.6g} in {path.name}"
                          for path, (step, raw, in_ms) in timed.items())  # fmt: skip
        why = f"the files' time columns step differently ({where})"
    elif not SECONDS_STEPS[0] <= first <= SECONDS_STEPS[1]:
        if ms:
            why = (f"the files' time column, in milliseconds, steps {written:.6g} ms "
                   f"({first:.6g} s), which is no plausible number of seconds between "
                   "frames")  # fmt: skip
        else:
            why = (f"the files' time column steps {first:.6g}, which is no plausible number "
                   f"of seconds between frames (milliseconds? nanoseconds?")  # fmt: skip
            in_s = first / 1000
            why += (f" as milliseconds that is {in_s:.6g} s, --frame-interval {in_s:.6g})"
                    if SECONDS_STEPS[0] <= in_s <= SECONDS_STEPS[1] else ")")  # fmt: skip
    if why is not None:
        warnings.warn(f"{source}: {why}: {DEFAULT_FRAME_INTERVAL:g} s between frames is "
                      "assumed; pass the files' own with --frame-interval (data.frame_interval "
                      "in training)", FrameRateWarning, stacklevel=4)  # fmt: skip
        return DEFAULT_FRAME_INTERVAL, "default"
    return float(f"{first:.9g}"), "timestamps"


SPLIT_ALIASES = {"training": "train", "trn": "train", "validation": "val", "valid": "val",
                 "validate": "val", "dev": "val", "testing": "test", "tests": "test",
                 "tst": "test", "eval": "test"}  # fmt: skip
"""Other names of split folders, which the missing-split error suggests renaming."""


def _other_folders(path: Path, splits: dict[str, Path]) -> list[str]:
    """The sub-folders of ``path`` that are not its split folders, sorted (hidden ones left
    out); empty when it cannot be read."""
    try:
        entries = text.folder_entries(path)
    except (OSError, DataError):
        return []
    kept = {p.name for p in splits.values()}
    return sorted(e.name for e in entries
                  if e.is_dir() and e.name not in kept and not e.name.startswith("."))  # fmt: skip


def split_folders(path: Path) -> dict[str, Path]:
    """The ``train/ val/ test/`` sub-folders of a user folder, by split name, matched
    ignoring case (``Train/`` is ``train/``); empty when it has none. Two folders for one
    split (``train/`` and ``Train/``) are a ``DataError``: which one was meant is unknown."""
    found: dict[str, Path] = {}
    try:
        for entry in text.folder_entries(path):
            name = entry.name.lower()
            if name not in SPLITS or not entry.is_dir():
                continue
            if name in found:
                raise DataError(f"both {found[name].name}/ and {entry.name}/ are there, and "
                                "split folders are matched ignoring case: keep one",
                                path)  # fmt: skip
            found[name] = entry
    except OSError as exc:  # a sub-folder that cannot be looked at
        raise text.folder_error(path, exc) from None
    return found


SGAN_TEST_FILES = {"eth": ("biwi_eth",), "hotel": ("biwi_hotel",),
                   "univ": ("students001", "students003"), "zara1": ("crowds_zara01",),
                   "zara2": ("crowds_zara02",)}  # fmt: skip
"""Each ETH/UCY fold's test files in Social-GAN's release (``eth_ucy/<fold>/test/<name>.txt``):
the fold's own scenes, most of whose windows the other folds' leave-one-out training files
hold (``uni_examples`` and ``crowds_zara03`` are in every fold's training split, no test)."""


def sgan_folds(path: str | Path) -> tuple[str, ...]:
    """The ETH/UCY folds (``ETH_UCY`` order) whose Social-GAN test files (``SGAN_TEST_FILES``,
    matched by name ignoring case and suffix) a user folder holds, in itself or in its
    ``train/ val/ test/`` sub-folders: ``eth_ucy/zara1`` given as a path, or a copy of
    ``crowds_zara01.txt``, is the zara1 fold's data. Empty for anything else: a built-in name,
    a file, a folder that is not there or cannot be read (loading it says why)."""
    folder = Path(path).expanduser()
    try:
        if not folder.is_dir():
            return ()
        stems = set()
        for sub in (folder, *split_folders(folder).values()):
            stems |= {f.stem.lower() for f in text.matching_files(sub, USER_TEXT)}
    except (OSError, TrajprefError):
        return ()
    return tuple(fold for fold in ETH_UCY if stems & set(SGAN_TEST_FILES[fold]))


def _trajnet(
    files: list[Path],
    name: str,
    split: str,
    frame_interval: float | None,
    units: str,
    options: text.ReadOptions,
    source: Path,
) -> TrajectoryDataset:
    """TrajNet++ scene files: metres by the format's convention, the interval from their fps
    (``trajnet_interval``)."""
    if options.time_step != 1.0:
        raise ConfigError("time_step resamples text track files, not TrajNet++ scenes")
    if options.partial_future:
        raise ConfigError("partial_future cuts windows from text track files, not TrajNet++ "
                          "scenes")  # fmt: skip
    units = "m" if units == "unknown" else units
    scenes: list[Scene] = []
    rates: dict[float, str] = {}  # each declared fps -> the first file declaring it
    for path in files:
        read = trajnet.read_trajnet(path, options.t_hist, options.t_fut, options.max_coord, units)
        scenes.extend(read.scenes)
        for rate in sorted(read.fps):
            rates.setdefault(rate, path.name)
    if not scenes:
        raise DataError(f"no TrajNet++ scene has {options.t_hist + options.t_fut} frames of "
                        "its primary agent", source)  # fmt: skip
    interval, origin = trajnet_interval(rates, frame_interval, source)
    info = DatasetInfo(name, split, units, interval, options.t_hist, options.t_fut, str(source),
                       interval_from=origin)  # fmt: skip
    return TrajectoryDataset(scenes, info)


def trajnet_interval(rates: dict[float, str], given: float | None,
                     source: Path) -> tuple[float, str]:  # fmt: skip
    """Seconds between frames of TrajNet++ files whose scenes declare the frame rates
    ``rates`` (fps -> a file declaring it), with ``given`` the interval the user passed
    (None: none), and where they come from (``DatasetInfo.interval_from``, as
    ``text_interval``). One rate: ``1 / fps`` (``declared``), and a ``FrameRateWarning`` when
    ``given`` differs (the files' own rate is used). Several rates: ``given`` with a
    ``FrameRateWarning``, or a ``DataError`` without one, since one dataset's windows would
    step different times. No rate: ``given``, else ``DEFAULT_FRAME_INTERVAL`` (``default``)."""
    where = ", ".join(f"{rate:g} fps in {file}" for rate, file in sorted(rates.items()))
    if len(rates) > 1:
        if given is None:
            raise DataError(f"the TrajNet++ scenes declare different frame rates ({where}): "
                            "one dataset's windows would step different times; keep one rate "
                            "per folder, or pass --frame-interval to read all of them at that "
                            "interval", source)  # fmt: skip
        warnings.warn(f"{source}: the TrajNet++ scenes declare different frame rates "
                      f"({where}); all are read at the frame interval given, {given:g} s",
                      FrameRateWarning, stacklevel=3)  # fmt: skip
        return given, "given"
    if not rates:
        return (DEFAULT_FRAME_INTERVAL, "default") if given is None else (given, "given")
    (rate,) = rates
    own = 1.0 / rate
    if given is not None and not math.isclose(given, own, rel_tol=1e-6):
        warnings.warn(f"{source}: the TrajNet++ scenes declare {where} ({own:g} s between "
                      f"frames), which is used: the frame interval given ({given:g} s, "
                      "--frame-interval) is ignored", FrameRateWarning,
                      stacklevel=3)  # fmt: skip
    return own, "declared"


def _carve_val(n: int, fraction: float = VAL_FRACTION) -> np.ndarray:
    """Boolean [n] mask of the items (scenes, files, episodes) that form the validation split:
    ``fraction`` of them, at least one, drawn with ``VAL_SEED``."""
    rng = np.random.default_rng(VAL_SEED)
    n_val = max(1, round(fraction * n))
    mask = np.zeros(n, bool)
    mask[rng.permutation(n)[:n_val]] = True
    return mask


def _sdd(base: Path, split: str, options: text.ReadOptions) -> tuple[list[Scene], Path]:
    path = base / "sdd" / ("test.npz" if split == "test" else "train.npz")
    data = arrays.load_npz(path, ("traj", "seq_start_end"))
    traj = data["traj"]  # [N, 20, 2]
    if traj.ndim != 3 or traj.shape[1] != 20:
        raise DataError(f"traj must be [N, 20, 2], got {traj.shape}", path)
    scenes = arrays.scenes_from_arrays(
        traj[:, :8], traj[:, 8:], data["seq_start_end"], path,
        max_coord=options.max_coord, units=SPECS["sdd"].units,
    )  # fmt: skip
    if split != "test":
        is_val = _carve_val(len(scenes))
        scenes = [s for s, v in zip(scenes, is_val, strict=True) if v == (split == "val")]
    return scenes, path


def _nba(
    base: Path, split: str, spec: SourceSpec, options: text.ReadOptions
) -> tuple[list[Scene], Path]:
    folder = base / "nba" / "rebound" / ("test" if split == "test" else "train")
    files = text.track_files(folder)
    if split != "test":
        is_val = _carve_val(len(files))
        files = [f for f, v in zip(files, is_val, strict=True) if v == (split == "val")]
    scenes = text.read_files(files, scale=FEET_TO_METRES, with_type=True, options=options,
                             units=spec.units, where=folder)  # fmt: skip
    return scenes, folder


def _robo(base: Path, split: str, options: text.ReadOptions) -> tuple[list[Scene], Path]:
    if split == "train":
        raise ConfigError("the official Robo set has no public training split; train on 'robo-sim'")
    path = base / "robo" / f"{split}.npz"
    data = arrays.load_npz(path, ("obs_traj", "pred_traj", "seq_start_end"))
    scenes = arrays.scenes_from_arrays(
        data["obs_traj"], data["pred_traj"], data["seq_start_end"], path,
        max_coord=options.max_coord, units=SPECS["robo"].units,
    )  # fmt: skip
    return scenes, path


def _robo_sim(split: str) -> TrajectoryDataset:
    episodes, seed = ROBO_SIM_EPISODES[split], ROBO_SIM_SEEDS[split]
    history, future = simulate(episodes, seed=seed)  # [E, 3, 8, 2], [E, 3, 12, 2]
    scenes = [
        Scene(history[e], future[e], np.zeros(history.shape[1], np.int64), f"robo-sim#{seed}:{e}")
        for e in range(episodes)
    ]
    spec = SPECS["robo-sim"]
    info = DatasetInfo(
        "robo-sim",
        split,
        spec.units,
        spec.frame_interval,
        spec.t_hist,
        spec.t_fut,
        f"simulated: {episodes} episodes, seed {seed}",
    )
    return TrajectoryDataset(scenes, info)


def robo_episodes(scenes: list[Scene]) -> np.ndarray:
    """Episode id [S] of each window of an official Robo split, in file order.

    The files hold sliding windows of a few recordings, one frame apart: window i continues
    window i-1 when its 20 frames are those of i-1 shifted by one. Holding out whole episodes
    keeps overlapping windows from landing on both sides of a split."""
    ids = np.zeros(len(scenes), np.int64)
    for i in range(1, len(scenes)):
        prev, cur = scenes[i - 1], scenes[i]
        same = prev.num_agents == cur.num_agents
        if same:
            a = np.concatenate([prev.history, prev.future], axis=1)  # [P, 20, 2]
            b = np.concatenate([cur.history, cur.future], axis=1)  # [P, 20, 2]
            same = bool(np.allclose(a[:, 1:], b[:, :-1], atol=1e-3))
        ids[i] = ids[i - 1] + (0 if same else 1)
    return ids


def _robo_mix(split: str, root: str | Path | None, options: text.ReadOptions) -> TrajectoryDataset:
    base = resolve_data_root(root)
    spec = SPECS["robo-mix"]
    if split == "test":
        scenes, source = _robo(base, "test", options)
        where = str(source)
    else:
        real, source = _robo(base, "val", options)
        episode = robo_episodes(real)  # [S]
        n_ep = int(episode.max()) + 1
        held = _carve_val(n_ep, ROBO_MIX_VAL_FRACTION)  # [episodes]
        is_val = held[episode]  # [S]
        chosen = [s for s, v in zip(real, is_val, strict=True) if v == (split == "val")]
        if split == "val":
            scenes = chosen
            where = f"{source}: {int(held.sum())} of {n_ep} episodes held out"
        else:
            sim = _robo_sim("train").scenes
            copies = max(1, round(ROBO_MIX_REAL_SHARE / (1 - ROBO_MIX_REAL_SHARE)
                                  * len(sim) / len(chosen)))  # fmt: skip
            scenes = sim + chosen * copies
            where = (f"robo-sim train + {source}: {n_ep - int(held.sum())} of {n_ep} episodes "
                     f"({len(chosen)} windows x {copies})")  # fmt: skip
    info = DatasetInfo(
        "robo-mix", split, spec.units, spec.frame_interval, spec.t_hist, spec.t_fut, where
    )
    return TrajectoryDataset(scenes, info)


def stacked_arrays(
    name: str, split: str, root: str | Path | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """One split of a dataset whose scenes all have the same agent count (Robo, robo-sim),
    stacked as ``(history [S, P, T_h, 2], future [S, P, T_f, 2])``."""
    scenes = load_dataset(name, split, root).scenes
    if len({s.num_agents for s in scenes}) > 1:
        raise DataError(f"{name}/{split}: scenes differ in agent count; cannot stack them")
    return np.stack([s.history for s in scenes]), np.stack([s.future for s in scenes])
