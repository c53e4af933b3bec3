"""``trajpref survey build``: pick scenes (seeded, stratified by scene size), sample every
method, score the samples with one denoiser, and write a blinded study folder."""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from trajpref import __version__
from trajpref.data import ReadOptions, hold_out_scene, load_dataset
from trajpref.data.registry import SPECS, check_protocol
from trajpref.data.text import DEFAULT_MAX_COORD
from trajpref.device import resolve_device
from trajpref.errors import ConfigError, DataWarning, TrajprefError
from trajpref.io import bar_options
from trajpref.models import checkpoint as ckpt
from trajpref.models.registry import BUILTIN, load_predictor
from trajpref.models.timing import UNKNOWN_UNITS, model_timing
from trajpref.score.scorer import TrajectoryScorer
from trajpref.survey.manifest import GROUND_TRUTH, METHOD_RE, Study
from trajpref.survey.study import (
    GroundTruthMode,
    SceneData,
    ground_truth_panel,
    shown_predictions,
    write_study,
)
from trajpref.types import WINDOW, TrajectoryDataset, collate


@dataclass
class BuildConfig:
    """Everything ``survey build`` needs; checked on creation."""

    dataset: str
    """Dataset name (``zara1`` ...) or a folder of ``frame agent x y`` files."""
    models: dict[str, str]
    """Method name -> ``cv`` or a checkpoint path, in the order given."""
    split: str = "test"
    """Which split to draw scenes from."""
    data_root: str | None = None
    """Data folder (default ``$TRAJPREF_DATA``)."""
    frame_interval: float | None = None
    """Seconds between frames, for a folder dataset (None: 0.4 for text files, the declared
    fps of TrajNet++ files; ``load_dataset``)."""
    units: str = "unknown"
    """Coordinate units, for a folder dataset."""
    delimiter: str | None = None
    """Column separator of the text files (``ReadOptions.delimiter``; None: sniffed)."""
    max_gap: int | None = None
    """Missing frames a window may span (``ReadOptions.max_gap``; None: any, with a warning)."""
    max_coord: float = DEFAULT_MAX_COORD
    """Largest accepted |x| or |y| (``ReadOptions.max_coord``)."""
    time_step: float = 1.0
    """Read the text files every this many frame steps (``ReadOptions.time_step``: 4 shows
    10 Hz data at a 0.4 s model's step)."""
    t_hist: int | None = None
    """Observed frames per window (``ReadOptions.t_hist``); None: the models' own (8 for
    every published model). Given, it must be theirs."""
    t_fut: int | None = None
    """Future frames per window (``ReadOptions.t_fut``), as ``t_hist``."""
    protocol: str = "all"
    """Which windows count (``load_dataset``'s ``protocol``)."""
    holdout_scene: str | None = None
    """With ``split="val"``: the windows of the training scene whose file names start with
    this prefix (``hold_out_scene``)."""
    scorer: str | None = None
    """The denoiser (or generator) checkpoint whose diffusion score rates every method's
    samples; default: the first checkpoint among ``models``. One scorer for all methods, so
    that their ATS/FTS are comparable."""
    scenes: int = 12
    """Scenes in the study (the paper: 12)."""
    samples: int = 20
    """K, samples per agent drawn from each method before the top ones are picked."""
    top: int = 2
    """Futures shown per agent: its ``top`` samples by the agent's ATS (the paper: 2)."""
    seed: int = 0
    """Seeds the scene draw, the sampling and the shuffling of the panels."""
    min_agents: int = 1
    """Smallest scene drawn."""
    max_agents: int = 8
    """Largest scene drawn (crowded scenes are hard to read at a glance)."""
    min_gap: int | None = None
    """Two drawn scenes are at least this many positions apart in the split, so that no two
    share a window; None: a window's frames, ``t_hist + t_fut`` (20 for the published models,
    whose ETH/UCY windows overlap by up to 19 frames); 0 allows neighbours."""
    strata: int = 3
    """Size strata: the eligible scenes are cut by agent count into this many groups of
    about equal share, and the scenes are drawn equally from each group."""
    ground_truth: GroundTruthMode = "rated"
    """``rated``: the real futures are one more blinded panel to rate (a calibration of the
    scale); ``reference``: they are shown beside every panel and not rated."""
    title: str = "Which predicted paths look human?"
    """Shown at the top of the page."""
    consent: str = ""
    """A consent text (``--consent FILE``'s contents) that every rater agrees to before the
    first picture; empty: none."""
    fixed_order: bool = False
    """``--fixed-order``: every rater sees the scenes and panels in one order (the manifest's,
    shuffled once with ``seed``), as studies built before 2026-12-06 did; default: each
    rater sees an order of their own (``Study.rater_order``), so that a position effect is
    spread over the methods."""
    device: str = "auto"
    """auto, cpu or cuda."""

    def __post_init__(self) -> None:
        if not self.models:
            raise ConfigError("--models: give at least one NAME=MODEL")
        for name in self.models:
            if name == GROUND_TRUTH or not METHOD_RE.fullmatch(name):
                raise ConfigError(
                    f"--models: bad method name {name!r} (letters, digits and ' _.+-', at "
                    f"most 40; {GROUND_TRUTH!r} is reserved)"
                )
        for key in ("scenes", "samples", "top", "strata", "min_agents"):
            if getattr(self, key) < 1:
                raise ConfigError(f"--{key.replace('_', '-')} must be >= 1")
        if self.top > self.samples:
            raise ConfigError(f"--top {self.top} exceeds --samples {self.samples}")
        if self.max_agents < self.min_agents:
            raise ConfigError("--max-agents must be >= --min-agents")
        if self.min_gap is not None and self.min_gap < 0:
            raise ConfigError("--min-gap must be >= 0")
        if self.frame_interval is not None and not (
            math.isfinite(self.frame_interval) and self.frame_interval > 0
        ):
            raise ConfigError(f"--frame-interval must be a number of seconds > 0, "
                              f"got {self.frame_interval}")  # fmt: skip
        if not isinstance(self.consent, str):
            raise ConfigError("the consent text must be a string")
        self.consent = self.consent.strip()
        if self.ground_truth not in ("rated", "reference"):
            raise ConfigError("--ground-truth must be 'rated' or 'reference'")
        given = (self.t_hist, self.t_fut)
        self.read_options(tuple(w if v is None else v for v, w in zip(given, WINDOW, strict=True)))
        # (a ConfigError for a bad delimiter, gap, bound, step or window length)
        check_protocol(self.protocol)
        if self.holdout_scene is not None and self.split != "val":
            raise ConfigError(f"--holdout-scene selects a validation split: use it with "
                              f"--split val, not --split {self.split}")  # fmt: skip

    def read_options(self, windows: tuple[int, int] = WINDOW) -> ReadOptions:
        """How the dataset's text files are read, in windows of ``windows`` = (T_h, T_f)
        frames (the models' own: ``study_windows``)."""
        return ReadOptions(delimiter=self.delimiter, max_gap=self.max_gap,
                           max_coord=self.max_coord, time_step=self.time_step,
                           t_hist=windows[0], t_fut=windows[1])  # fmt: skip


def read_data(cfg: BuildConfig, windows: tuple[int, int] = WINDOW) -> TrajectoryDataset:
    """The split the scenes are drawn from, read as ``trajpref evaluate`` reads it, in windows
    of ``windows`` frames: the frame interval and units go to a folder dataset only (a
    built-in has its own; the CLI has warned once of options it ignores, and
    ``load_dataset`` would warn again for every split)."""
    folder = cfg.dataset not in SPECS

    def split(name: str) -> TrajectoryDataset:
        return load_dataset(cfg.dataset, name, cfg.data_root,
                            cfg.frame_interval if folder else None, cfg.units if folder else None,
                            options=cfg.read_options(windows), protocol=cfg.protocol)  # fmt: skip

    if cfg.holdout_scene:  # the held-out scene's windows of both splits
        return hold_out_scene(split("train"), split("val"), cfg.holdout_scene)[1]
    return split(cfg.split)


def select_scenes(
    sizes: np.ndarray, n: int, seed: int = 0, strata: int = 3, min_agents: int = 1,
    max_agents: int = 8, min_gap: int = 0,
) -> list[tuple[int, int]]:  # fmt: skip
    """Draw ``n`` scene indices, stratified by scene size: ``[(index, stratum), ...]``.

    sizes [B] agents per scene. Scenes with ``min_agents..max_agents`` agents are eligible;
    their distinct sizes are cut into at most ``strata`` groups holding about equal shares
    of the scenes (a size is never split), ``n`` is shared equally between the groups (the
    remainder to random ones), and each group is drawn without replacement. No two picks are
    closer than ``min_gap`` positions; a group that runs short passes its share on to the
    others. Deterministic for a given seed.
    """
    sizes = np.asarray(sizes)
    eligible = np.flatnonzero((sizes >= min_agents) & (sizes <= max_agents))  # [E]
    if len(eligible) < n:
        raise ConfigError(f"only {len(eligible)} scenes have {min_agents}..{max_agents} agents; "
                          f"{n} were asked for (lower --scenes or widen --max-agents)")  # fmt: skip
    values, counts = np.unique(sizes[eligible], return_counts=True)  # [V]
    middle = (np.cumsum(counts) - counts / 2) / counts.sum()  # [V] centre of each size's share
    group = np.minimum((middle * strata).astype(int), strata - 1)  # [V]
    _, group = np.unique(group, return_inverse=True)  # renumber the non-empty groups 0..S-1
    stratum = group[np.searchsorted(values, sizes[eligible])]  # [E]
    s = int(group.max()) + 1
    rng = np.random.default_rng(seed)
    quota = np.full(s, n // s)
    quota[rng.permutation(s)[: n % s]] += 1
    pools = [rng.permutation(eligible[stratum == g]) for g in range(s)]
    gap = max(1, min_gap)
    picked: list[tuple[int, int]] = []
    taken = np.zeros(len(sizes), bool)

    def take(g: int, want: int) -> int:
        got = 0
        for i in pools[g]:
            if got == want:
                break
            if not taken[i] and all(abs(int(i) - j) >= gap for j, _ in picked):
                picked.append((int(i), g))
                taken[i] = True
                got += 1
        return got

    short = sum(int(quota[g]) - take(g, int(quota[g])) for g in range(s))
    for g in rng.permutation(s):
        if short == 0:
            break
        short -= take(int(g), short)
    if short:
        raise ConfigError(f"only {len(picked)} of the {len(eligible)} eligible scenes are "
                          f"--min-gap {min_gap} apart; lower --scenes or --min-gap")  # fmt: skip
    return picked


def _header(spec: str) -> dict | None:
    """Checkpoint ``spec``'s header (a path or a published name), its weights unread (a legacy
    ``.pt`` file is loaded without them); None for a built-in method or a file it cannot read
    (loading the model says what is wrong)."""
    if spec in BUILTIN:
        return None
    try:
        return ckpt.header_of(spec)
    except (TrajprefError, OSError, KeyError, TypeError, ValueError, AttributeError):
        return None


def checkpoint_hashes(spec: str, scorer: bool = False) -> dict[str, str | None]:
    """``weights_hash`` (the weights' content hash; a scorer's: its denoiser's) and
    ``model_hash`` (``models.checkpoint.header_model_hash``: what it predicts with, as
    ``evaluate --out`` records it; a scorer's: its denoiser and data scale) of checkpoint
    ``spec``; both None for cv or a header without them."""
    header = _header(spec)
    out: dict[str, str | None] = {"weights_hash": None, "model_hash": None}
    if header is None:
        return out
    try:
        denoiser = header.get("kind") == "denoiser"
        sampler = "full" if scorer or denoiser else "leapfrog"
        out["model_hash"] = ckpt.header_model_hash(header, sampler)
        den = header.get("denoiser_ref") or header.get("denoiser") or {}
        out["weights_hash"] = header.get("hash") if denoiser or not scorer else den.get("hash")
    except (TrajprefError, AttributeError):
        pass
    return out


def recorded_units(specs: list[str]) -> dict[str, str]:
    """spec -> the units its checkpoint recorded of its training data (``model_timing``), for
    each checkpoint among ``specs`` that recorded known units."""
    out = {}
    for spec in dict.fromkeys(specs):
        header = _header(spec)
        try:
            units = model_timing(header)["units"] if header else None
        except (KeyError, TypeError, ValueError, AttributeError):
            units = None
        if units and units not in UNKNOWN_UNITS:
            out[spec] = units
    return out


def units_warning(dataset: str, models: dict[str, str]) -> str:
    """The warning for a study built on data of unknown units: what raters and the analysis
    then miss, and the units the models (``recorded_units``: spec -> units) recorded."""
    text = (
        f"{dataset}: the data's units are unknown (no --units): the raters' pictures "
        "show axes without a unit and the analysis gives ADE/FDE in unknown units"
    )
    found = sorted(set(models.values()))
    if len(found) == 1:
        names = ", ".join(models)
        return f"{text}; the models recorded units {found[0]} ({names}): pass --units {found[0]}"
    if found:
        each = ", ".join(f"{k}: {v}" for k, v in models.items())
        return f"{text}; the models recorded different units ({each}): pass --units UNITS"
    return f"{text}; pass --units UNITS (m, px, ...)"


def _scorer_path(cfg: BuildConfig) -> str:
    if cfg.scorer:
        return cfg.scorer
    for spec in cfg.models.values():
        if spec not in BUILTIN:
            return spec
    raise ConfigError("every method is built in (e.g. cv): pass --scorer DENOISER.safetensors "
                      "to compute ATS/FTS")  # fmt: skip


@torch.no_grad()
def build_study(cfg: BuildConfig, out: str | Path, progress: bool = True,
                on_data: Callable[[TrajectoryDataset], None] | None = None) -> Study:  # fmt: skip
    """Draw the scenes, sample and score every method, render and write the study folder.
    ``on_data`` is called with the dataset once it is read, before any sampling (the CLI
    warns there when a model was trained on data in other units or at another step)."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ConfigError(f"{out}: already exists; a study folder is never overwritten "
                          "(its answers would no longer match): choose a new --out")  # fmt: skip
    device = resolve_device(cfg.device)
    predictors = {name: load_predictor(spec, device=device) for name, spec in cfg.models.items()}
    scorer = TrajectoryScorer.from_checkpoint(_scorer_path(cfg), device)
    readers = {f"method {name}": (m.t_hist, m.t_fut) if getattr(m, "t_hist", None) else None
               for name, m in predictors.items()}  # fmt: skip
    readers["the scorer"] = (scorer.t_hist, scorer.t_fut)
    windows = ckpt.agreed_windows(readers, (cfg.t_hist, cfg.t_fut))
    ds = read_data(cfg, windows)
    if on_data is not None:
        on_data(ds)
    if ds.info.units in UNKNOWN_UNITS:
        units = recorded_units([*cfg.models.values(), _scorer_path(cfg)])
        warnings.warn(units_warning(ds.info.name, units), DataWarning, stacklevel=2)
    sizes = np.array([s.num_agents for s in ds.scenes])  # [B]
    gap = sum(windows) if cfg.min_gap is None else cfg.min_gap  # no shared frames by default
    try:
        picks = select_scenes(sizes, cfg.scenes, cfg.seed, cfg.strata, cfg.min_agents,
                              cfg.max_agents, gap)  # fmt: skip
    except ConfigError as exc:
        if cfg.min_gap is not None:
            raise
        raise ConfigError(
            f"{exc} (--min-gap {gap} by default: a window's {windows[0]} + "
            f"{windows[1]} frames, so that no two scenes share one)"
        ) from None
    order = np.random.default_rng(cfg.seed + 1).permutation(len(picks))  # presentation order
    scenes = []
    for j in tqdm(order, desc="survey build", unit="scene", leave=False, **bar_options(progress)):
        index, stratum = picks[int(j)]
        scene = ds[index]
        batch = collate([scene]).to(device)
        panels = {}
        for name, model in predictors.items():
            gen = torch.Generator().manual_seed(cfg.seed * 1_000_003 + index)
            pred = model.predict(batch, cfg.samples, gen)  # [K, P, T_f, 2]
            res = scorer.score(batch, pred)
            panels[name] = shown_predictions(
                pred.cpu().double().numpy(),
                res.d_pred.cpu().double().numpy(),  # [K, P, T_f]
                res.d_gt.cpu().double().numpy(),  # [P, T_f]
                scene.future.astype(np.float64),
                cfg.top,
            )
        if cfg.ground_truth == "rated":
            panels[GROUND_TRUTH] = ground_truth_panel(scene.future.astype(np.float64))
        scenes.append(SceneData(scene.history, scene.future, panels, scene.scene_id, index,
                                stratum))  # fmt: skip
    methods = ([GROUND_TRUTH] if cfg.ground_truth == "rated" else []) + list(cfg.models)
    record = dataclasses.asdict(cfg)
    record.pop("consent")  # in the manifest's own ``consent``
    record["scorer"] = _scorer_path(cfg)
    record.update(min_gap=gap, t_hist=windows[0], t_fut=windows[1])  # as used, not as given
    record["trajpref_version"] = __version__
    record["torch_version"] = torch.__version__
    record["hashes"] = {
        "methods": {name: checkpoint_hashes(spec) for name, spec in cfg.models.items()},
        "scorer": checkpoint_hashes(_scorer_path(cfg), scorer=True),
    }
    return write_study(
        out, scenes, methods, seed=cfg.seed, title=cfg.title, ground_truth=cfg.ground_truth,
        units=None if ds.info.units in UNKNOWN_UNITS else ds.info.units,  # axes: no unit
        dataset={"name": ds.info.name, "split": ds.info.split, "units": ds.info.units,
                 "frame_interval": ds.info.frame_interval, "t_hist": ds.info.t_hist,
                 "t_fut": ds.info.t_fut, "scenes_in_split": len(ds)},
        build=record, consent=cfg.consent, order="fixed" if cfg.fixed_order else "rater",
    )  # fmt: skip
