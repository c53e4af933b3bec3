"""Experiment configuration: dataclasses with a docstring per field, checked on creation,
read from and written to YAML. A run writes its resolved config next to its checkpoints."""

from __future__ import annotations

import ast
import copy
import dataclasses
import difflib
import inspect
import math
import os
import textwrap
import typing
import warnings
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Literal

import yaml

from trajpref.errors import ConfigError, ConfigNotFound, TrajprefDeprecationWarning
from trajpref.io import atomic_path


def _positive(obj: Any, *names: str) -> None:
    for name in names:
        if not getattr(obj, name) > 0:
            raise ConfigError(f"{type(obj).__name__}.{name} must be > 0, got {getattr(obj, name)}")


def check_choices(obj: Any) -> None:
    """Every ``Literal[...]`` field of dataclass ``obj`` holds one of its choices."""
    hints = typing.get_type_hints(type(obj))
    for f in fields(obj):
        hint = hints[f.name]
        choices = typing.get_args(hint) if typing.get_origin(hint) is Literal else ()
        value = getattr(obj, f.name)
        if choices and value not in choices:
            options = " or ".join(repr(c) for c in choices)
            raise ConfigError(f"{type(obj).__name__}.{f.name} must be {options}, got {value!r}")


DATA_GENERATOR_ONLY = ("partial_future",)
"""``DataConfig`` fields that only the generator stage reads: the denoiser stage trains with
them at their defaults (``DataConfig.denoiser_part``)."""


BUILTIN_DATASETS = ("eth", "hotel", "univ", "zara1", "zara2", "sdd", "nba", "robo", "robo-sim",
                    "robo-mix")  # fmt: skip
"""The datasets ``data.registry`` reads by name (``data.registry.NAMES``); any other
``DataConfig.dataset`` is a folder or file path. A new one also needs its entry in
``data.registry.SPECS``, its branch there and a line in ``DataConfig.dataset``'s docstring
(docs/data.md, "Adding a built-in dataset")."""


@dataclass
class DataConfig:
    """Which data to train on and how to batch and augment it."""

    dataset: str = "zara1"
    """Dataset name (``BUILTIN_DATASETS``: ``eth hotel univ zara1 zara2 sdd nba robo robo-sim
    robo-mix``) or a folder path."""
    val_dataset: str | None = None
    """Dataset for validation when it differs (Robo: train on robo-sim, validate on robo)."""
    max_agents: int = 512
    """Agents per training batch (whole scenes are packed up to this budget); with several
    processes (torchrun) the batch over all of them, each rank taking a share."""
    rotate: bool = True
    """Randomly rotate each training scene."""
    flip: bool = False
    """Randomly mirror training scenes."""
    reverse: bool = False
    """Randomly play training scenes backwards in time (probability 1/2 per scene, all its
    agents together: the window's last T_h positions, reversed, become the history and the
    rest, reversed, the future; docs/pretraining.md, "Scenes played backwards")."""
    reverse_context: bool = False
    """A scene played backwards keeps context-only neighbours: those of the reversed window
    (``Scene.context_reverse``: the other agents seen at the first of the window's last T_h
    frames, their positions there reversed) instead of none (False: the published eth, univ
    and zara2 generators' training). Only with ``reverse`` and a generator built with
    ``model.context_agents``; docs/pretraining.md, "Reversed scenes keep their neighbours"."""
    history_noise: float = 0.0
    """Std of Gaussian noise added to each training window's observed positions except the
    last, in the dataset's units (0: off): the inputs jitter, the targets (futures relative to
    the last observed position) stay exact. Against fitting the training histories exactly
    (docs/pretraining.md, "Jittered histories")."""
    drop_agents: float = 0.0
    """Rate at which agents are left out of each training batch, as targets and as
    neighbours, after the other augmentations (0: off; every scene keeps at least one agent).
    Shows each window with a random subset of its neighbours (docs/pretraining.md, "Fewer
    neighbours")."""
    scale_min: float = 1.0
    """Lower bound of the random per-scene scale factor (1.0 with scale_max = 1.0: off)."""
    scale_max: float = 1.0
    """Upper bound of the random per-scene scale factor."""
    delimiter: str | None = None
    """Column separator of text track files (None: sniffed; ``, ; | tab whitespace``), as
    ``--delimiter`` (docs/data_format.md)."""
    max_gap: int | None = None
    """Missing frames a window may span (None: the Social-GAN rule with a warning; 0: none),
    as ``--max-gap``."""
    max_coord: float = 1e6
    """Largest accepted |x| or |y| in the dataset's units, as ``--max-coord``."""
    time_step: float = 1.0
    """Read text track files every this many frame steps, positions interpolated in time
    (1: as recorded), as ``--time-step``; both splits are read alike."""
    frame_interval: float | None = None
    """Seconds between consecutive frames of a folder dataset's files (``dataset`` or
    ``val_dataset`` given as a path), as ``--frame-interval`` (None: what the files say: the
    step of a frame column headed ``time`` or ``timestamp``, read as seconds, or the fps that
    TrajNet++ scenes declare, which wins over a value given; else 0.4 s, assumed). Built-in
    datasets know their own and refuse it. A model records the interval it trained at (this
    times ``time_step``), so that ``evaluate``, ``predict`` and ``plot`` warn about data at
    another step (docs/data_format.md)."""
    units: str | None = None
    """Coordinate units of a folder dataset, as ``--units`` (None: unknown; TrajNet++ files:
    m). Recorded in the model, so that data in other units is warned about; built-in datasets
    know their own and refuse it."""
    extra_time_step: float = 0.0
    """A second copy of the training split's text track files, read every this many frame
    steps (positions interpolated in time, as ``time_step`` reads them), joins the training
    split (0: off): training on two paces, for a test file whose steps span more time than
    their label says (eth's: about 5/3; docs/data.md). The validation split is untouched."""
    partial_future: int = 0
    """Training split only: also train on the agents seen in every history frame and in at
    least this many first future frames but not in all of them (agents that leave the view
    before a window ends), as targets whose loss reads only the frames they were seen in (0:
    off; the validation and test splits keep the benchmarks' complete windows). Text track
    files only (ETH/UCY or a folder of them); not with ``reverse`` (a future with missing
    frames cannot be played backwards). The generator stage only: the denoiser stage trains on
    complete futures whatever this says (``denoiser_part``; docs/pretraining.md, "Agents that
    leave the view")."""
    holdout_scene: str = ""
    """Validate on a scene the model does not train on ("" : the dataset's own val split):
    the training files whose name starts with this prefix (e.g. ``biwi_hotel``, ``students``,
    ``crowds_zara02``) leave training, and that scene's windows of both splits are the
    validation split (``data.hold_out_scene``). For choosing between settings on ETH/UCY,
    whose val files come from the training scenes; the published model then trains on all."""
    val_cut: float = 0.0
    """Share of each validation file's earliest windows (in time) taken out of the validation
    split, with the windows that would share a frame with them (0: none); what is left is the
    validation split. Text-track datasets only (``data.split_validation_in_time``)."""
    val_cut_to_train: bool = False
    """The windows cut by ``val_cut`` join the training split (otherwise they are dropped, so
    that a control validates on the same windows without training on more)."""

    def __post_init__(self) -> None:
        if self.reverse_context and not self.reverse:
            raise ConfigError("DataConfig.reverse_context needs data.reverse: it says which "
                              "neighbours a scene played backwards keeps")  # fmt: skip
        if self.holdout_scene and self.val_dataset:
            raise ConfigError("DataConfig.holdout_scene and val_dataset exclude each other: "
                              "the held-out scene is the validation split")  # fmt: skip
        if not 0.0 <= self.val_cut < 1.0:
            raise ConfigError(f"DataConfig.val_cut must be in [0, 1), got {self.val_cut}")
        if self.val_cut_to_train and not self.val_cut:
            raise ConfigError("DataConfig.val_cut_to_train needs val_cut > 0")
        if self.val_cut and self.holdout_scene:
            raise ConfigError("DataConfig.val_cut and holdout_scene exclude each other: the "
                              "held-out scene is the validation split")  # fmt: skip
        _positive(self, "max_agents", "scale_min", "scale_max", "max_coord", "time_step")
        interval = self.frame_interval
        number = isinstance(interval, (int, float)) and not isinstance(interval, bool)
        if interval is not None and not (number and math.isfinite(interval) and interval > 0):
            raise ConfigError(f"DataConfig.frame_interval must be a number of seconds > 0 or "
                              f"null (what the files say), got {interval!r}")  # fmt: skip
        if self.units is not None and not (isinstance(self.units, str) and self.units.strip()):
            raise ConfigError(f"DataConfig.units must be a unit name (e.g. m) or null (unknown), "
                              f"got {self.units!r}")  # fmt: skip
        self._check_folder_description()
        if self.extra_time_step < 0 or self.extra_time_step == self.time_step:
            raise ConfigError(f"DataConfig.extra_time_step must be 0 (off) or a positive step "
                              f"other than time_step ({self.time_step:g}), "
                              f"got {self.extra_time_step:g}")  # fmt: skip
        if isinstance(self.partial_future, bool) or self.partial_future < 0:
            raise ConfigError(f"DataConfig.partial_future must be an integer >= 0 (0: off), "
                              f"got {self.partial_future!r}")  # fmt: skip
        if self.partial_future and self.reverse:
            raise ConfigError("DataConfig.partial_future and reverse exclude each other: a "
                              "future with missing frames cannot be played backwards")  # fmt: skip
        if self.history_noise < 0:
            raise ConfigError(f"DataConfig.history_noise must be >= 0 (0: off), "
                              f"got {self.history_noise}")  # fmt: skip
        if not 0.0 <= self.drop_agents < 1.0:
            raise ConfigError(f"DataConfig.drop_agents must be in [0, 1) (0: off), "
                              f"got {self.drop_agents}")  # fmt: skip
        if self.scale_min > self.scale_max:
            raise ConfigError("DataConfig.scale_min must be <= scale_max")
        if self.max_gap is not None and self.max_gap < 0:
            raise ConfigError("DataConfig.max_gap must be >= 0 or null")

    def _check_folder_description(self) -> None:
        """``frame_interval`` and ``units`` describe a folder: refused when every dataset the
        config reads is a built-in one (``BUILTIN_DATASETS``), which knows its own."""
        if self.frame_interval is None and self.units is None:
            return
        read = [d for d in (self.dataset, self.val_dataset) if d]
        if all(d in BUILTIN_DATASETS for d in read):
            given = [k for k in ("frame_interval", "units") if getattr(self, k) is not None]
            one = len(given) == 1
            raise ConfigError(f"DataConfig.{' and '.join(given)} describe{'s' if one else ''} a "
                              f"folder dataset; {self.dataset} is a built-in one and knows its "
                              f"own units and frame interval: leave {'it' if one else 'them'} "
                              "unset")  # fmt: skip

    def denoiser_part(self) -> DataConfig:
        """This data config as the denoiser stage trains on it: the generator-only settings
        (``DATA_GENERATOR_ONLY``) at their defaults; itself when none is set."""
        defaults = {k: getattr(DataConfig, k) for k in DATA_GENERATOR_ONLY}  # as ModelConfig's
        changes = {k: v for k, v in defaults.items() if getattr(self, k) != v}
        return dataclasses.replace(self, **changes) if changes else self

    @property
    def scale_range(self) -> tuple[float, float] | None:
        """The per-scene scale augmentation's range, None when it is off (both bounds 1)."""
        bounds = (self.scale_min, self.scale_max)
        return None if bounds == (1.0, 1.0) else bounds


@dataclass
class DiffusionConfig:
    """The DDPM schedule (the paper: 100 steps, beta linear from 1e-4 to 5e-2)."""

    num_steps: int = 100
    """S, diffusion steps."""
    beta_start: float = 1e-4
    """beta at the first step."""
    beta_end: float = 5e-2
    """beta at the last step."""

    def __post_init__(self) -> None:
        _positive(self, "num_steps", "beta_start", "beta_end")
        if not self.beta_start <= self.beta_end < 1:
            raise ConfigError("DiffusionConfig needs beta_start <= beta_end < 1")


@dataclass
class ModelConfig:
    """Network sizes (a CPU-sized default)."""

    hidden: int = 128
    """Width of the social context encoders."""
    encoder_layers: int = 2
    """Social attention layers in each encoder."""
    heads: int = 4
    """Attention heads."""
    denoiser_width: int = 256
    """Width of the denoiser's residual MLP."""
    denoiser_blocks: int = 4
    """Residual blocks in the denoiser."""
    generator_width: int = 256
    """Width of the generator's heads."""
    generator_hidden: int = 0
    """Width of the generator's own social encoder (0: ``hidden``, the denoiser's width). The
    generator's encoder is its own network, so it may be wider than the frozen denoiser's
    (LED's initializer uses 256)."""
    generator_layers: int = 0
    """Social attention layers in the generator's own encoder (0: ``encoder_layers``, the
    denoiser's depth). Like ``generator_hidden``, it sizes the generator alone."""
    t_hist: int = 8
    """Observed frames (T_h), at least 2. It sizes the networks and cuts the data: training,
    and every command given the model, reads its windows in ``t_hist + t_fut`` frames. Any
    lengths can be cut from text track files (a folder of your own, ETH/UCY, NBA, TrajNet++
    files); SDD's and Robo's windows come already cut at 8 + 12, the published models'
    lengths (docs/data_format.md, "Window lengths")."""
    t_fut: int = 12
    """Future frames (T_f), the horizon the model predicts; as ``t_hist``, it cuts the data."""
    samples: int = 20
    """K, the samples the generator emits per agent (its heads' output size)."""
    tau: int = 5
    """Denoising steps the leapfrog sampler applies to the generator's output Y^tau; 0 makes
    the generator's samples the prediction itself, with no pass of the denoiser (which the
    diffusion score still uses)."""
    stochastic_steps: bool = False
    """Add the ancestral DDPM noise in the tau denoising steps (true), or make each step the
    posterior mean, deterministic given Y^tau (false, the default since 2026-11-24: better on
    validation for all 12 published generators' minADE20 and 11 of 12 minFDE20;
    benchmarks/deterministic_steps.py, docs/pretraining.md)."""
    agent_frame: Literal["scene", "heading"] = "scene"
    """The frame the generator sees and predicts in: ``scene`` (each agent's history relative
    to its last position, axes of the scene; rotation augmentation teaches it every
    orientation) or ``heading`` (the same, rotated per agent so that its observed displacement
    points along +x, with its neighbours rotated alike; predictions are rotated back). The
    denoiser always works in the scene frame, so a published denoiser serves both."""
    history_encoder: Literal["mlp", "temporal"] = "mlp"
    """How the generator's encoder reads each agent's history: ``mlp`` (the flattened T_h
    steps through an MLP, as the denoiser's does) or ``temporal`` (that MLP plus a GRU run
    over the steps, whose last state is added to the embedding: LED's initializer reads the
    past with a recurrent encoder as well). The denoiser always uses ``mlp``."""
    max_speed: float = 0.0
    """Speed clamp of the generator's inputs, in model units per observed step (0: off). An
    agent whose observed displacement per step (first to last observed position) exceeds it
    is seen at this speed: its history and its neighbours' relative positions and velocities
    are divided by c = speed / max_speed, and its mean and spread are multiplied by c. Model
    units divide by the data scale, so one value serves metres and pixels; a fold's training
    split puts its 99th percentile at 0.43-0.45 on ETH/UCY (docs/pretraining.md). Agents
    faster than anything in training are then predicted as scaled-up copies of the fastest
    ones instead of by extrapolation."""
    generator_social: bool = True
    """Whether the generator's encoder attends across each scene's agents (its
    ``encoder_layers`` attention layers). False: each agent's initial samples come from its own
    history alone, as in LED's and MoFlow's single-agent ETH/UCY windows; the frozen denoiser
    the tau steps run still attends across agents (docs/pretraining.md, "A generator without
    attention across agents")."""
    generator_dropout: float = 0.0
    """Dropout probability in the generator during training: on its encoder's output before
    the heads, and after each hidden layer of the mean, sigma and shift heads (with
    ``query_layers`` > 0: on the tokens' shared projection instead of inside the query layers;
    0: none; LED's transformer layers drop 0.1). Evaluation and sampling never drop."""
    encoder_dropout: float = 0.0
    """Dropout probability inside the generator's own social encoder during training: on each
    agent's history embedding before the attention layers, and on those layers' residual
    updates (a transformer's residual dropout, LED's 0.1 in its layers; 0: none). It adds no
    parameters, so a file trained with it loads into a generator without it and the other
    way round; ``generator_dropout`` acts after the encoder. Evaluation never drops
    (docs/pretraining.md, "Dropout inside the generator's encoder")."""
    context_agents: bool = False
    """The generator's social encoder also attends to the context-only agents of each window
    (``Scene.context``: observed over the whole history, gone before the window ends), as
    further neighbours. They get no prediction and no loss, and nothing marks them apart from
    the predicted agents (a mark would tell the encoder who stays in view). Data without them
    (the ``.npz`` splits: SDD, Robo) runs as without the flag; the denoiser and the score never
    read them (docs/pretraining.md, "Context-only neighbours")."""
    context_frames: int = 0
    """With ``context_agents``: how many of the last history frames a context-only agent must
    have been seen in without a break to be read (2..T_h; its earlier frames hold its first
    position of that run, ``data.transforms.observed_context``). 0: all T_h frames, the
    setting of the first context-reading models."""
    mean_prior: Literal["none", "velocity"] = "none"
    """What the generator's mean head predicts: ``none``, the mean path itself (LED's head);
    ``velocity``, the path's departure from a constant-velocity extrapolation of the agent's
    last observed step (v t for the future steps t = 1..T_f, with v the backward difference of
    the last two observed positions, in the frame and at the speed the encoder sees the agent,
    so the heading frame and the speed clamp stay equivariant). It adds no parameters; with the
    head's output at zero the mean is the constant-velocity baseline's path
    (docs/pretraining.md, "A constant-velocity prior under the generator's mean")."""
    future_rank: int = 0
    """Rank of the generator's outputs in time (0: free, T_f numbers per coordinate). r > 0
    projects the mean and each of the K shifts, per coordinate, onto the polynomials
    t, t^2, ..., t^r of the future step t = 1..T_f (orthonormalised): smooth paths that
    start at the last observed position, r numbers per coordinate instead of T_f. A linear
    map in time commutes with rotations and scalings of the plane, so the heading frame and
    the speed clamp are unaffected. Validation futures of zara1, hotel and eth lie within
    0.012 m ADE / 0.005 m FDE of that span at r = 5 (benchmarks/future_span.py;
    docs/pretraining.md, "Smooth outputs")."""
    pair_distance: bool = False
    """Whether the generator's attention across agents also reads, for each pair, their
    distance and closing speed (the rate at which that distance changes at the last observed
    step; negative when approaching), beside j's position and velocity relative to i. The
    raw relative coordinates hold the same information, but a distance is a norm that a small
    MLP of them only approximates; social models weigh neighbours by it
    (docs/pretraining.md, "Pair distance and closing speed")."""
    scene_position: bool = False
    """Whether the generator also sees where each agent is and which way it heads in the
    scene's own coordinates (its last observed position, divided by the data scale, and the
    unit vector of its observed displacement), as LED's and MoFlow's ETH/UCY inputs include
    absolute positions. It can learn a location's layout (doors, sidewalks) only where the
    test location shares its coordinates with training files (the zara files with each other,
    the students files with uni_examples); it ties the model to those coordinates, and training
    requires ``data.rotate``, ``data.flip`` and ``data.reverse`` off, which would move the
    scene or its motion away from its place (docs/pretraining.md, "Where the agents are")."""
    agent_roles: int = 0
    """Number of fixed agent roles (0: off). When R > 0 the generator's encoder adds a learned
    embedding of each agent's slot in its scene (its index in the scene's agent list), for
    datasets whose every scene lists the same R roles in the same order: Robo's leader,
    follower and approacher (docs/robo_sim.md). A scene with more than R agents is an error
    at prediction time, and training refuses ``data.drop_agents``, which would shift the
    slots (docs/pretraining.md, "Robo: which robot is which")."""
    denoiser_roles: int = 0
    """``agent_roles`` for the denoiser (0: off): its encoder adds a learned embedding of each
    agent's slot, so that the diffusion score can judge each robot by its own role's motion.
    A denoiser field: a generator trained from a denoiser must state the same value."""
    query_layers: int = 0
    """How the generator proposes its K shifts: 0 (the default) maps each agent's encoding and
    mean to all K x T_f x 2 numbers with one MLP (LED's head); L > 0 makes K tokens instead
    (a projection of [encoding, mean] plus one learned embedding per sample), runs L pre-norm
    transformer layers over each agent's K tokens, and reads each token out with one shared
    layer as its shift and its log sigma (MoFlow's decoder proposes its K futures as queries
    that attend to each other; docs/pretraining.md, "K query tokens")."""
    query_width: int = 64
    """Width of the K query tokens when ``query_layers`` > 0 (then a positive multiple of
    ``heads``; unused and unchecked otherwise)."""
    spread_scale: float = 1.0
    """A sampling setting: multiplies each agent's sigma, the spread of its K initial samples
    about their mean (Y^tau = mu + spread_scale * sigma * S), before the tau denoising steps.
    1 changes nothing; it may be set on published weights without retraining
    (docs/pretraining.md, "The samples' spread at prediction time")."""

    max_log_sigma: float | None = None
    """A sampling setting: the most log sigma (model units) any of the K samples may take, as
    the generator's head emits it (before the speed clamp scales an agent back up and before
    ``spread_scale``); None: no cap. Best-of-K training only trains the sample that wins, and
    on agents unlike its training ones the sigma head extrapolates: SDD's generator of
    2026-11-29 put 4 % of its samples more than 5 units (300 px) from their mean, where they
    predict nothing and where a tiny change of weights moves them far, which made RL
    fine-tuning on SDD diverge. It may be set on published weights without retraining
    (docs/pretraining.md, "A cap on the samples' sigma"). Set in a training config, it also
    caps the spread while the generator trains (the clamp passes no gradient above the cap):
    a loose cap such as 3 keeps an outlier agent's samples from overflowing the loss
    (docs/pretraining.md, "(sh3)")."""

    neighbour_radius: float | None = None
    """A sampling setting: agents whose last observed positions are farther apart than this,
    in the data's own units (metres or pixels: the units the model was trained on, not model
    units), do not attend to each other in the encoders' attention across agents, the
    generator's and the denoiser's alike (so the diffusion score too); each agent still
    attends to itself. The distance is measured before the heading frame and the speed clamp
    (``max_speed``) change the features. None: every pair of a scene, the published models'
    behaviour. The published ETH/UCY models never saw two agents of a scene more than about
    16 m apart, and agents far beyond that (a robot's tracker sees pedestrians 20-50 m away)
    move every agent's futures; it may be set on published weights without retraining
    (``model.neighbour_radius = 12.0`` in Python), and training does not apply it."""

    def __post_init__(self) -> None:
        if self.neighbour_radius is not None and (
            isinstance(self.neighbour_radius, bool)
            or not isinstance(self.neighbour_radius, (int, float))
            or not math.isfinite(self.neighbour_radius)
            or not self.neighbour_radius > 0
        ):
            raise ConfigError(
                f"ModelConfig.neighbour_radius must be null (every pair attends) or a finite "
                f"distance > 0 in the data's units, got {self.neighbour_radius!r}"
            )
        if self.max_log_sigma is not None and not math.isfinite(self.max_log_sigma):
            raise ConfigError(
                f"ModelConfig.max_log_sigma must be a finite number or null, got "
                f"{self.max_log_sigma}"
            )
        if self.max_speed < 0:
            raise ConfigError("ModelConfig.max_speed must be >= 0 (0 switches the clamp off)")
        if not 0 <= self.generator_dropout < 1:
            raise ConfigError(
                f"ModelConfig.generator_dropout must lie in [0, 1), got {self.generator_dropout}"
            )
        if not 0 <= self.encoder_dropout < 1:
            raise ConfigError(
                f"ModelConfig.encoder_dropout must lie in [0, 1), got {self.encoder_dropout}"
            )
        if self.context_agents and not self.generator_social:
            raise ConfigError("ModelConfig.context_agents adds neighbours to the generator's "
                              "social attention: it needs generator_social true")  # fmt: skip
        if self.context_frames and not 2 <= self.context_frames <= self.t_hist:
            raise ConfigError(f"ModelConfig.context_frames must be 0 (the whole history) or "
                              f"lie in 2..t_hist ({self.t_hist}), got "
                              f"{self.context_frames}")  # fmt: skip
        if self.context_agents and self.agent_roles:
            raise ConfigError("ModelConfig.context_agents and agent_roles do not combine: "
                              "roles read each agent's slot, and context-only agents have "
                              "none of their own")  # fmt: skip
        if not self.spread_scale > 0:
            raise ConfigError(
                f"ModelConfig.spread_scale must be > 0 (1: the trained spread), "
                f"got {self.spread_scale}"
            )
        _positive(self, "hidden", "encoder_layers", "heads", "denoiser_width", "denoiser_blocks",
                  "generator_width", "t_hist", "t_fut", "samples")  # fmt: skip
        if self.tau < 0:
            raise ConfigError(f"ModelConfig.tau must be >= 0 (0: no denoising steps), "
                              f"got {self.tau}")  # fmt: skip
        if self.hidden % self.heads:
            raise ConfigError(f"ModelConfig.hidden must be divisible by heads, got hidden "
                              f"{self.hidden} and heads {self.heads}")  # fmt: skip
        if self.generator_hidden < 0 or self.generator_hidden % self.heads:
            raise ConfigError("ModelConfig.generator_hidden must be 0 (the denoiser's width) or "
                              "a positive multiple of heads")  # fmt: skip
        if self.generator_layers < 0:
            raise ConfigError(f"ModelConfig.generator_layers must be >= 0 (0: encoder_layers), "
                              f"got {self.generator_layers}")  # fmt: skip
        if self.hidden % 2:
            raise ConfigError("ModelConfig.hidden must be even (the sinusoidal step embedding)")
        if self.t_hist < 2:
            raise ConfigError("ModelConfig.t_hist must be >= 2 (velocities need two frames)")
        if self.denoiser_roles < 0:
            raise ConfigError(f"ModelConfig.denoiser_roles must be >= 0 (0: off), "
                              f"got {self.denoiser_roles}")  # fmt: skip
        if self.agent_roles < 0:
            raise ConfigError(f"ModelConfig.agent_roles must be >= 0 (0: off), "
                              f"got {self.agent_roles}")  # fmt: skip
        if self.query_layers < 0:
            raise ConfigError(f"ModelConfig.query_layers must be >= 0 (0: the MLP head), "
                              f"got {self.query_layers}")  # fmt: skip
        if self.query_layers and (self.query_width <= 0 or self.query_width % self.heads):
            raise ConfigError(f"ModelConfig.query_width must be a positive multiple of heads "
                              f"({self.heads}), got {self.query_width}")  # fmt: skip
        if not 0 <= self.future_rank <= self.t_fut:
            raise ConfigError(f"ModelConfig.future_rank must lie in [0, t_fut={self.t_fut}] "
                              f"(0: free outputs), got {self.future_rank}")  # fmt: skip
        check_choices(self)

    def denoiser_part(self) -> ModelConfig:
        """This config with the generator-only fields at their defaults: two configs whose
        ``denoiser_part`` agree describe the same denoiser."""
        return dataclasses.replace(self, **{k: getattr(ModelConfig, k) for k in GENERATOR_ONLY})

    @property
    def generator_encoder_width(self) -> int:
        """H of the generator's social encoding (``generator_hidden``, else ``hidden``)."""
        return self.generator_hidden or self.hidden

    @property
    def generator_encoder_layers(self) -> int:
        """Social attention layers of the generator's encoder (``generator_layers``, else
        ``encoder_layers``)."""
        return self.generator_layers or self.encoder_layers

    @property
    def windows(self) -> tuple[int, int]:
        """(T_h, T_f): the observed and future frames of the windows this model reads."""
        return (self.t_hist, self.t_fut)


GENERATOR_ONLY = (
    "generator_width",
    "generator_hidden",
    "generator_layers",
    "samples",
    "tau",
    "stochastic_steps",
    "agent_frame",
    "history_encoder",
    "generator_social",
    "generator_dropout",
    "encoder_dropout",
    "context_agents",
    "context_frames",
    "max_speed",
    "spread_scale",
    "max_log_sigma",
    "neighbour_radius",
    "future_rank",
    "mean_prior",
    "pair_distance",
    "scene_position",
    "agent_roles",
    "query_layers",
    "query_width",
)
"""``ModelConfig`` fields that concern the generator and its sampler, not the denoiser."""


@dataclass
class OptimConfig:
    """One training stage's optimisation."""

    epochs: int = 60
    """Passes over the training split."""
    lr: float = 1e-3
    """Peak learning rate (AdamW, cosine decay after a short warm-up)."""
    weight_decay: float = 1e-4
    """AdamW weight decay."""
    warmup_steps: int = 200
    """Linear warm-up steps."""
    final_lr: float = 0.1
    """Where the cosine decay ends, as a fraction of ``lr``: the rate falls from ``lr`` to
    ``final_lr * lr`` over the schedule (0.1 in every published config; 0 anneals to zero)."""
    grad_clip: float = 1.0
    """Gradient-norm clip."""
    eval_every: int = 5
    """Validate every this many epochs (and after the last)."""
    eval_every_minutes: float | None = None
    """Instead of ``eval_every``: validate at the end of the first epoch after which this many
    minutes of the ``budget_clock`` have passed since the last validation (and after the
    last epoch); None: by epochs. In an equal-budget table it gives methods whose epochs cost
    differently (a supervised control and the RL methods) equally many validations, so
    equally many checkpoints to choose from."""
    eval_max_scenes: int | None = None
    """Validate on at most this many scenes (None: the whole split)."""
    steps_per_epoch: int | None = None
    """Cap on optimiser steps per epoch (None: a full pass). Each epoch then sees a fresh
    random subset of the shuffled batches; for stages too costly for full passes."""
    max_minutes: float | None = None
    """Wall-clock budget of the training steps (validation excluded): the stage stops after
    the step that crosses it and validates once more (None: no budget). For equal-budget
    comparisons between methods."""
    budget_clock: Literal["wall", "cpu"] = "wall"
    """What ``max_minutes`` counts: ``wall`` (elapsed time) or ``cpu`` (this process's CPU
    time, all its threads). ``cpu`` keeps a budget fair when other jobs share the machine."""
    budget_schedule: bool = False
    """With ``max_minutes``: the learning rate's cosine decay (and an annealed best-of-K
    temperature) advances by the larger of the share of the steps done and the share of the
    budget spent, so a stage that meets its budget before its last epoch ends annealed at
    ``final_lr`` instead of being cut mid-decay. Where every epoch fits in the budget the
    steps' share is always the larger, and the run is the same as without it (same weights).
    Off: ``max_minutes`` only stops the stage (equal-budget comparisons)."""
    precision: Literal["fp32", "bf16"] = "fp32"
    """Arithmetic of the training steps' forward passes: ``fp32``, or ``bf16`` (autocast to
    bfloat16 on the stage's device; weights, optimiser state and validation stay float32).
    bf16 is fast where the CPU has bfloat16 instructions (AVX512-BF16, AMX) or on a GPU of
    compute capability 8 or more (Ampere and later); elsewhere it can be slower
    (docs/pretraining.md, "bfloat16 training steps")."""
    compile: bool = False
    """Compile the stage's networks with ``torch.compile`` (dynamic shapes) before its first
    step, at a one-off cost of minutes on a CPU; without a C++ compiler the stage trains
    eagerly, with a warning. Weights, checkpoints and resume states are the same as without it
    (``Stage.networks``). On the 2-core CPU its speed-up was not separable from the machine's
    drift (docs/pretraining.md, "Compiled training steps"), so every config leaves it off."""
    fused: bool = False
    """AdamW's fused implementation (one kernel per step instead of PyTorch's default, a loop
    over the parameters on the CPU and ``foreach`` on a GPU): the same arithmetic, the weights
    equal up to float rounding, a cheaper optimiser step (docs/pretraining.md, "Fused AdamW
    steps"). A resumed run follows this setting, whatever its saved state used."""
    ema_epochs: float = 0.0
    """Time constant, in epochs, of an exponential moving average of the trained weights
    (0: off). When on, validation and the best checkpoint use the average, the raw weights
    are validated too (logged as ``val_raw_*``, one more validation pass; their best is kept
    as ``<stage>_raw.safetensors``, the run's own control), and the decay per
    step is ``exp(-1 / (ema_epochs * steps_per_epoch))``, warmed up over the first steps
    (``train/ema.py``; docs/pretraining.md, "A moving average of the weights")."""
    keep_checkpoints: bool = False
    """Also save the weights of every validated epoch as ``<stage>_epoch<E>.safetensors``
    (E zero-padded to three digits; the averaged weights when ``ema_epochs > 0``), beside the
    best one: for studies of how the choice of epoch matters (``benchmarks/
    checkpoint_choice.py``). Off by default: each file is a full checkpoint."""

    def __post_init__(self) -> None:
        _positive(self, "epochs", "lr", "grad_clip", "eval_every")
        if not (self.ema_epochs >= 0 and math.isfinite(self.ema_epochs)):
            raise ConfigError(f"ema_epochs must be >= 0 (0: off), got {self.ema_epochs}")
        if self.steps_per_epoch is not None and self.steps_per_epoch < 1:
            raise ConfigError("steps_per_epoch must be >= 1 or null")
        if self.max_minutes is not None and self.max_minutes <= 0:
            raise ConfigError("max_minutes must be > 0 or null")
        if self.budget_schedule and self.max_minutes is None:
            raise ConfigError("budget_schedule anneals the schedule by the time budget: "
                              "it needs the same stage's max_minutes (e.g. 30)")  # fmt: skip
        if self.eval_every_minutes is not None and not (
            self.eval_every_minutes > 0 and math.isfinite(self.eval_every_minutes)
        ):
            raise ConfigError(
                f"eval_every_minutes must be > 0 or null, got {self.eval_every_minutes}"
            )
        if self.weight_decay < 0 or self.warmup_steps < 0:
            raise ConfigError("OptimConfig.weight_decay and warmup_steps must be >= 0")
        if not 0.0 <= self.final_lr <= 1.0:
            raise ConfigError(f"OptimConfig.final_lr is a fraction of lr in [0, 1], "
                              f"got {self.final_lr}")  # fmt: skip
        check_choices(self)


@dataclass
class DenoiserTrainConfig(OptimConfig):
    """Training of the denoiser by Eq. 2."""

    noise_draws: int = 4
    """Noise draws (and steps s) per agent per batch: more signal per context encoding."""

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive(self, "noise_draws")


@dataclass
class GeneratorTrainConfig(OptimConfig):
    """Training of the leapfrog generator through the frozen denoiser (Eq. 4)."""

    epochs: int = 20
    """Passes over the training split."""
    best_of_k_weight: float = 1.0
    """Weight of min_k (ADE_k + fde_weight FDE_k), the best-of-K distance through the
    denoiser."""
    fde_weight: float = 1.0
    """Weight of the endpoint error inside the best-of-K term (1: ADE + FDE)."""
    time_weights: Literal["uniform", "decreasing"] = "uniform"
    """How the best-of-K term averages a sample's error over the T_f steps: ``uniform`` (the
    ADE), or ``decreasing`` (step t of T_f weighted T_f + 1 - t, normalised to mean 1, as
    LED's initializer loss weights its steps: the near future counts most)."""
    winner: Literal["joint", "separate"] = "joint"
    """Which samples the best-of-K term trains: ``joint`` (per agent the one sample with the
    lowest ADE_k + fde_weight FDE_k), or ``separate`` (min_k ADE_k + fde_weight min_k FDE_k:
    the sample closest on average learns the path and the sample closest at the end learns the
    endpoint, as minADE_K and minFDE_K choose their samples independently)."""
    mean_weight: float = 0.5
    """Weight of the ADE of the generator's mean mu (keeps mu meaningful for RL)."""
    uncertainty_weight: float = 0.1
    """Weight of the term tying log sigma to the mean's error (LED's uncertainty loss)."""
    reg_weight: float = 0.0
    """Weight of Eq. 4 as written (mean over K of squared error; collapses diversity)."""
    wta_temperature: float = 0.0
    """Starting temperature of an annealed best-of-K term (annealed winner-takes-all), in the
    networks' units of ADE_k + fde_weight FDE_k: each sample's distance is weighted by the
    softmin of the K distances at this temperature (weights without gradient), so samples
    that seldom win still learn early on. 0 (the default): the hard minimum throughout."""
    wta_anneal: float = 0.5
    """Fraction of the run's optimiser steps over which ``wta_temperature`` decays
    geometrically to a thousandth of itself; the hard minimum after that."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 < self.wta_anneal <= 1.0:
            raise ConfigError(
                f"GeneratorTrainConfig.wta_anneal must lie in (0, 1], got {self.wta_anneal}"
            )
        for name in (
            "wta_temperature",
            "best_of_k_weight",
            "fde_weight",
            "mean_weight",
            "uncertainty_weight",
            "reg_weight",
        ):
            if getattr(self, name) < 0:
                raise ConfigError(f"GeneratorTrainConfig.{name} must be >= 0")


FinetuneMethod = Literal["rlhf", "rlhf-res", "control"]
"""The fine-tuning methods (``FinetuneConfig.method``): the one list of their names."""
FINETUNE_METHODS: tuple[str, ...] = typing.get_args(FinetuneMethod)
"""``FinetuneMethod``'s names, in order: the CLI's ``--method`` choices."""
USES_RL = {"rlhf": True, "rlhf-res": True, "control": False}
"""Whether each fine-tuning method is an RL method (a reward, a critic, PPO epochs) or the
supervised control; written out per method. The code asks ``uses_rl`` (an unknown name is
an error); a method's other facts have their own tables, each refusing a name it lacks
(docs/rlhf.md, "Adding a fine-tuning method")."""
if set(USES_RL) != set(FINETUNE_METHODS):
    raise AssertionError("config: USES_RL must name every method of FinetuneMethod")


def uses_rl(method: str) -> bool:
    """Whether fine-tuning ``method`` is an RL method (``USES_RL``); a name without an entry
    there is a ``ConfigError``, never taken for one of the others."""
    if method not in USES_RL:
        raise ConfigError(f"unknown fine-tuning method {method!r}: USES_RL has no entry for it "
                          f"(known: {', '.join(USES_RL)})")  # fmt: skip
    return USES_RL[method]


@dataclass
class FinetuneConfig(OptimConfig):
    """RLHF / RLHF-ReS fine-tuning of the generator (the paper's Sec. 5-6). The ``paper``
    preset (``rl.presets.PRESETS``) sets these to the equations as written."""

    epochs: int = 3
    """Passes over the training split (each capped by ``steps_per_epoch``)."""
    lr: float = 3e-4
    """Peak learning rate (fine-tuning: lower than pretraining)."""
    warmup_steps: int = 20
    """Linear warm-up steps."""
    eval_every: int = 1
    """Validate every this many epochs."""
    eval_max_scenes: int | None = 400
    """Validate on at most this many scenes (None: the whole split)."""
    steps_per_epoch: int | None = 12
    """Cap on optimiser steps per epoch (None: a full pass); the default 3 x 12 steps is the
    budget measured in docs/rlhf.md."""
    method: FinetuneMethod = "rlhf-res"
    """``rlhf`` (policy and value losses on all K samples), ``rlhf-res`` (on k* only), or
    ``control``: the supervised generator loss alone on clean rollouts, no score and no
    reward (the equal-budget control that any RL gain is measured against)."""
    policy_weight: float = 0.3
    """alpha_p (RLHF, paper 1.0) or beta_p (RLHF-ReS, paper 0.3): weight of Eq. 15 / 18."""
    value_weight: float = 1.5
    """alpha_v (RLHF, paper 5.0) or beta_v (RLHF-ReS, paper 1.5): weight of Eq. 16 / 19."""
    reg_weight: float = 1.0
    """Weight of L_reg, the pretraining loss on the denoised samples (Eq. 17 / 20: 1)."""
    clip: float = 0.2
    """epsilon of the clipped policy ratio (Eq. 15)."""
    value_clip: float = 0.2
    """epsilon of the clipped value (Eq. 16)."""
    kl_coef: float = 0.1
    """beta of Eq. 13 (the paper gives no value)."""
    kl_form: Literal["paper", "logratio"] = "logratio"
    """``paper`` (beta p_0 (log p_0 - log p_theta), as printed) or ``logratio`` (beta (log
    p_theta - log p_0), the usual per-sample KL estimate)."""
    gamma: float = 0.99
    """Discount over future steps (Eq. 14)."""
    gae_lambda: float = 0.0
    """GAE lambda; 0 is the paper's one-step advantage (Eq. 14)."""
    value_target: Literal["reward", "return"] = "return"
    """``reward`` (Eq. 16 regresses V on R) or ``return`` (the GAE return)."""
    adv_norm: Literal["none", "scene"] = "scene"
    """``none`` or ``scene``: whiten advantages within each scene."""
    reward_clip: float | None = 5.0
    """Clip the per-step score r (or the ``sda`` reward) to [-c, c] (None: unclipped, as the
    paper)."""
    score_every: int = 9
    """The reward's score timesteps: every this many of the S steps (the paper: 3; 9 gives 12
    steps, whose ranking recall matches 34 steps in docs/score_study_zara1.md, at a third of
    the cost)."""
    detach_critic: bool = True
    """Stop the value loss's gradient at the shared social encoder."""
    likelihood: Literal["mean", "sample"] = "sample"
    """Eq. 12's density: ``mean`` = N(Y; mu, sigma_k) at the denoised sample, as printed (the
    K samples are deterministic functions of X, so this is a surrogate); ``sample`` = each
    initial sample Y^tau_k is perturbed by explore_std noise before denoising and the density
    is N(perturbed; Y^tau_k, explore_std) - a proper stochastic policy per sample."""
    explore_std: float = 0.05
    """Exploration noise of the ``sample`` likelihood, in normalised units (its RMS per step
    and coordinate, for either ``explore``)."""
    explore: Literal["white", "smooth"] = "white"
    """The exploration noise's shape: ``white`` (independent per step and coordinate: 24
    numbers per sample) or ``smooth`` (a random velocity and acceleration offset per sample
    and coordinate: noise in the span of t and t^2 over the future, 4 numbers per sample),
    so that exploration moves a sample's speed, heading and curvature rather than jittering
    it. The density is Gaussian on those coefficients (rl/ppo.py, smooth_basis)."""
    ratio_against: Literal["reference", "rollout"] = "rollout"
    """Eq. 15's ratio p_theta / p_0 against the frozen ``reference`` (as printed; a trust
    region around G_0), or against the ``rollout`` policy (standard PPO: p_theta / p_old)."""

    reward: str = "score"
    """``score``: each sample's per-step diffusion score r (Eq. 6); ``set``: each sample's
    marginal gain in a score-weighted DPP over its K samples' endpoints (rl/set_reward.py),
    which rewards plausible samples that cover what the others do not; ``sda``: the paper's
    hand-crafted baseline reward (Sec. 8.1), keeping social groups found in the observed
    motion at their observed distances (rl/sda.py, docs/sda.md; no diffusion score); or the
    name of a reward registered from Python (``trajpref.rl.register_reward``, docs/rlhf.md:
    fine-tuning refuses a name that is not registered in its process)."""
    set_bandwidth: float = 0.5
    """``set`` reward: endpoint similarity bandwidth, in units of the median squared distance."""
    set_alpha: float = 1.0
    """``set`` reward: weight of the standardised score in the samples' quality."""
    sda_radius: float = 1.5
    """``sda`` reward: two persons of a scene can be one group only if they stay within this
    distance of each other at every observed step (the data's units: metres, SDD pixels)."""
    sda_drift: float = 0.5
    """``sda`` reward: two persons can be one group only if the offset between them moves by
    at most this much over the observed steps (their velocities agree: 0.5 m over ETH/UCY's
    2.8 s history is a mean relative speed of 0.18 m/s). Groups are the connected components
    of the pairs that pass both tests."""
    sda_tolerance: float = 0.2
    """``sda`` reward: the per-step reward is 1 - e / tolerance, e the mean error of a
    sample's distances to its group mates against their observed mean distances (the data's
    units); 0.2 m is about the ground truth's own error on ETH/UCY (docs/sda.md)."""
    ppo_epochs: int = 1
    """Update epochs on each collected rollout (TRL's ``ppo_epochs``). With 1, the update
    reuses the rollout's own graph and a ``rollout`` ratio is identically 1 (REINFORCE with
    a baseline); with more, the rollout is collected without gradients and re-evaluated, so
    the ratio and its clip act."""
    reg_on: Literal["explored", "clean"] = "clean"
    """L_reg on a ``clean`` rollout of the policy (no exploration noise), or on the
    ``explored`` rollout the reward scored (before 2026-11-23 the only behaviour; needs
    ppo_epochs = 1)."""
    baseline: Literal["critic", "antithetic"] = "critic"
    """What the policy gradient's advantage subtracts from the reward: ``critic`` (Eq. 14,
    R + gamma V' - V) or ``antithetic`` (``sample`` likelihood only): each sample is also
    rolled out with -xi under the same denoising noise and A(+-xi) = +-(R(+xi) - R(-xi)) / 2,
    which cancels the between-sample part of the reward's variance (measured in
    docs/rlhf.md); the critic is still trained. Costs a second rollout and score per step."""

    @staticmethod
    def is_reward_name(name: object) -> bool:
        """Whether ``name`` can name a reward (``reward``, ``rl.register_reward``): an ASCII
        letter, then ASCII letters, digits, ``_`` or ``-``. Whether a reward of that name
        exists is decided where rewards are looked up (``rl.rewards``), not here."""
        return (isinstance(name, str) and name[:1].isascii() and name[:1].isalpha()
                and all(c.isascii() and (c.isalnum() or c in "_-") for c in name))  # fmt: skip

    def __post_init__(self) -> None:
        super().__post_init__()  # OptimConfig checks every Literal field, these included
        if not self.is_reward_name(self.reward):
            raise ConfigError(
                "finetune.reward must be a reward's name (score, set, sda, or one registered "
                "from Python with trajpref.rl.register_reward: an ASCII letter, then letters, "
                f"digits, '_' or '-'), got {self.reward!r}"
            )
        if self.baseline == "antithetic" and self.likelihood != "sample":
            raise ConfigError("finetune.baseline=antithetic needs finetune.likelihood=sample")
        _positive(self, "explore_std", "ppo_epochs", "set_bandwidth")
        _positive(self, "sda_radius", "sda_drift", "sda_tolerance")
        if self.reg_on == "explored" and self.ppo_epochs > 1:
            raise ConfigError("finetune.reg_on=explored needs finetune.ppo_epochs=1")
        if not 0 <= self.gamma <= 1 or not 0 <= self.gae_lambda <= 1:
            raise ConfigError("finetune.gamma and gae_lambda must lie in [0, 1]")
        if self.reward_clip is not None and self.reward_clip <= 0:
            raise ConfigError("finetune.reward_clip must be > 0 or null")
        for name in ("policy_weight", "value_weight", "reg_weight", "kl_coef"):
            if getattr(self, name) < 0:
                raise ConfigError(f"finetune.{name} must be >= 0")
        _positive(self, "clip", "value_clip", "score_every")


@dataclass
class ExperimentConfig:
    """Everything one dataset's pipeline needs. One YAML file per dataset under configs/."""

    data: DataConfig = field(default_factory=DataConfig)
    """Data, batching, augmentation."""
    model: ModelConfig = field(default_factory=ModelConfig)
    """Network sizes."""
    diffusion: DiffusionConfig = field(default_factory=DiffusionConfig)
    """Noise schedule."""
    denoiser: DenoiserTrainConfig = field(default_factory=DenoiserTrainConfig)
    """Stage 1: the denoiser."""
    generator: GeneratorTrainConfig = field(default_factory=GeneratorTrainConfig)
    """Stage 2: the generator."""
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    """Stage 3: RLHF / RLHF-ReS fine-tuning."""
    seed: int = 0
    """Seed for initialisation, shuffling, augmentation and noise."""

    def __post_init__(self) -> None:
        if self.model.tau > self.diffusion.num_steps:
            raise ConfigError("model.tau cannot exceed diffusion.num_steps")
        if self.data.reverse_context and not self.model.context_agents:
            raise ConfigError("data.reverse_context keeps context-only neighbours in reversed "
                              "scenes: it needs model.context_agents")  # fmt: skip


def to_dict(cfg: Any) -> dict[str, Any]:
    return dataclasses.asdict(cfg)


def from_dict(cls: type, data: dict[str, Any] | None, where: str = "", stored: str = "") -> Any:
    """Build dataclass ``cls`` from a nested dict; unknown keys are an error. ``stored``: what
    wrote the dict when a program did (``"a checkpoint's config"``), so that a key this
    version lacks is said to come from a newer trajpref, not to be a typo
    (``unknown_key_message``)."""
    if data is not None and not isinstance(data, dict):
        section = where.rstrip(".") or cls.__name__
        raise ConfigError(f"config {section} must be a section (key: value lines), got {data!r}")
    data = dict(data or {})
    hints = typing.get_type_hints(cls)
    known = [f.name for f in fields(cls)]
    unknown = sorted(set(data) - set(known), key=str)
    if unknown:
        raise ConfigError(unknown_key_message([str(u) for u in unknown], known, where, stored))
    kwargs = {}
    for name, value in data.items():
        hint = hints[name]
        if dataclasses.is_dataclass(hint):
            kwargs[name] = from_dict(hint, value, f"{where}{name}.", stored)
        else:
            kwargs[name] = _coerce(value, hint, f"{where}{name}")
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"{where or cls.__name__}: {exc}") from None
    except ConfigError as exc:
        if not where:
            raise
        raise ConfigError(in_section(str(exc), cls, where)) from None


def in_section(message: str, cls: type, where: str) -> str:
    """A dataclass's check message in the user's words: ``DenoiserTrainConfig.epochs must
    be > 0`` becomes ``denoiser.epochs must be > 0`` (``where`` is the section's dotted
    prefix); a message that names no field gets the section in front."""
    if message.startswith(where):  # it names its key as the user wrote it already
        return message
    named = [k.__name__ for k in cls.__mro__ if dataclasses.is_dataclass(k)]
    out = message
    for name in named:
        out = out.replace(f"{name}.", where).replace(f"{name} ", f"{where.rstrip('.')} ")
    return out if out != message else f"{where.rstrip('.')}: {message}"


def unknown_key_message(unknown: list[str], known: list[str], where: str = "",
                        stored: str = "") -> str:  # fmt: skip
    """One line for unknown config keys: the nearest valid key (difflib) and the valid keys of
    the section (``where`` is its dotted prefix, e.g. ``"data."``; empty at the top level).
    With ``stored`` (what wrote the config: a checkpoint's header) no typo is suggested: a
    key this version lacks there was most likely written by a newer trajpref."""
    more = f"; also unknown: {', '.join(where + u for u in unknown[1:])}" if unknown[1:] else ""
    section = f"section {where.rstrip('.')}" if where else "the top level"
    valid = f"valid keys of {section}: {', '.join(known)}"
    if stored:
        return (f"unknown config key {where}{unknown[0]} in {stored}{more}: probably written by "
                f"a newer trajpref than this one, which added the key; upgrade trajpref to read "
                f"it ({valid})")  # fmt: skip
    # names other libraries and papers use, which difflib matches to the wrong key
    # (reward_weight -> reg_weight, the regulariser; kl_weight -> value_weight); a
    # dotted one is in another section (``where`` not repeated)
    aliases = {
        "reward_weight": "policy_weight", "pg_weight": "policy_weight",
        "rl_weight": "policy_weight", "score_weight": "policy_weight",
        "critic_weight": "value_weight", "vf_coef": "value_weight", "value_coef": "value_weight",
        "kl_weight": "kl_coef", "kl_beta": "kl_coef", "kl_penalty": "kl_coef", "kl": "kl_coef",
        "sft_weight": "reg_weight", "bc_weight": "reg_weight",
        "learning_rate": "lr", "num_epochs": "epochs", "n_epochs": "epochs",
        "grad_norm": "grad_clip", "max_grad_norm": "grad_clip", "clip_grad_norm": "grad_clip",
        "cliprange": "clip", "clip_range": "clip", "cliprange_value": "value_clip",
        "clip_range_vf": "value_clip", "lam": "gae_lambda", "discount": "gamma",
        "batch_size": "data.max_agents",
    }  # fmt: skip
    alias = aliases.get(unknown[0], "")
    if where and alias.startswith(where):  # this section's own
        alias = alias[len(where) :]
    if "." in alias:
        close = [alias]  # another section's key, named in full
    elif alias in known:
        close = [where + alias]
    else:
        close = [where + c for c in difflib.get_close_matches(unknown[0], known, n=1, cutoff=0.6)]
    exact, near = _other_sections(unknown[0], where)
    elsewhere = exact if not alias else []
    if not close and not alias:
        elsewhere = near
    if elsewhere:  # a key of another section, written in this one (data.epochs, a top units)
        named = ", ".join(elsewhere[:-1]) + (" or " if elsewhere[:-1] else "") + elsewhere[-1]
        close = [f"{named}? {'it is a key' if exact else 'close to keys'} of "
                 f"{'another section' if len(elsewhere) == 1 else 'other sections'}"]  # fmt: skip
    hint = f" (did you mean {close[0]}{'' if elsewhere else '?'})" if close else ""
    return (f"unknown config key {where}{unknown[0]}{hint}{more}; {valid} (all keys with their "
            "meaning: trajpref config show)")  # fmt: skip


def _other_sections(key: str, where: str) -> tuple[list[str], list[str]]:
    """``key`` as a dotted name in the experiment config's sections (and its top level) other
    than ``where`` (``"data."``, or empty for the top level): a key written in the wrong
    section. Returns the exact names, and the close ones (difflib); both empty for a section
    that is not the experiment config's (nothing to compare with)."""
    hints = typing.get_type_hints(ExperimentConfig)
    places = {"": [f.name for f in fields(ExperimentConfig)
                   if not dataclasses.is_dataclass(hints[f.name])]}  # fmt: skip
    for f in fields(ExperimentConfig):
        if dataclasses.is_dataclass(hints[f.name]):
            places[f"{f.name}."] = [g.name for g in fields(hints[f.name])]
    if where not in places:
        return [], []
    others = {p: keys for p, keys in places.items() if p != where}
    exact = [p + key for p, keys in others.items() if key in keys]
    near = [p + k for p, keys in others.items()
            for k in difflib.get_close_matches(key, keys, n=1, cutoff=0.8)]  # fmt: skip
    return exact, near


def field_docs(cls: type) -> dict[str, str]:
    """The docstring written under each field of dataclass ``cls`` (inherited fields
    included; a subclass's own wins), each as one line."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        body = ast.parse(textwrap.dedent(inspect.getsource(klass))).body[0].body
        for node, after in zip(body, body[1:], strict=False):
            if not (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)):
                continue
            doc = getattr(after, "value", None)
            if isinstance(after, ast.Expr) and isinstance(doc, ast.Constant):
                if isinstance(doc.value, str):
                    docs[node.target.id] = " ".join(doc.value.split())
    return docs


def config_entries(cfg: Any, prefix: str = "") -> list[tuple[str, Any, str]]:
    """``(dotted key, value, docstring)`` for every leaf of a config dataclass, in field
    order (what ``trajpref config show`` prints)."""
    docs = field_docs(type(cfg))
    out: list[tuple[str, Any, str]] = []
    for f in fields(cfg):
        value = getattr(cfg, f.name)
        if dataclasses.is_dataclass(value):
            out.extend(config_entries(value, f"{prefix}{f.name}."))
        else:
            out.append((prefix + f.name, value, docs.get(f.name, "")))
    return out


def _brief(value: Any, limit: int = 120) -> str:
    """``repr(value)``, cut to ``limit`` characters: a config error names the value it got, and
    a YAML file's aliases can make one of a few hundred bytes megabytes long."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def _coerce(value: Any, hint: Any, name: str) -> Any:
    args = typing.get_args(hint)
    if typing.get_origin(hint) is Literal:
        if value not in args:
            options = ", ".join(repr(a) for a in args)
            raise ConfigError(f"config {name} must be one of {options}, got {_brief(value)}")
        return value
    if value is None:
        if type(None) in args:
            return None
        raise ConfigError(f"config {name} may not be null")
    base = next((a for a in args if a is not type(None)), hint) if args else hint
    if base is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "false", "1", "0", "yes", "no"):
            return value.lower() in ("true", "1", "yes")
        raise ConfigError(f"config {name} must be true or false, got {_brief(value)}")
    if base in (int, float) and isinstance(value, bool):
        raise ConfigError(f"config {name} must be {base.__name__}, got {_brief(value)}")
    if base in (int, float, str) and isinstance(value, (list, tuple, dict, set)):
        raise ConfigError(f"config {name} must be {base.__name__}, got a "
                          f"{type(value).__name__}: {_brief(value)}")  # fmt: skip
    if base in (int, float, str):
        try:
            out = base(value)
        except (TypeError, ValueError):
            raise ConfigError(
                f"config {name} must be {base.__name__}, got {_brief(value)}"
            ) from None
        if base is int and isinstance(value, float) and value != out:
            raise ConfigError(f"config {name} must be an integer, got {_brief(value)}")
        return out
    return value


LEGACY_MOVES = {
    ("generator", "samples"): ("model", "samples"),
    ("generator", "tau"): ("model", "tau"),
}
"""Keys that moved between sections: (old section, key) -> (new section, key). Configs written
before the move (checkpoints, YAML files) still load."""


def upgrade_config_dict(data: dict[str, Any]) -> dict[str, Any]:
    """A copy of a config dict in today's layout: moved keys are carried to their new section
    (an old key given explicitly wins over the new section's value)."""
    data = copy.deepcopy(data)
    for (old_sec, old_key), (new_sec, new_key) in LEGACY_MOVES.items():
        section = data.get(old_sec)
        if isinstance(section, dict) and old_key in section:
            warnings.warn(f"config key {old_sec}.{old_key} is now {new_sec}.{new_key}",
                          TrajprefDeprecationWarning, stacklevel=3)  # fmt: skip
            target = data.setdefault(new_sec, {})
            if not isinstance(target, dict):
                raise ConfigError(f"config section {new_sec} must be a mapping")
            target[new_key] = section.pop(old_key)
    return data


def experiment_from_dict(data: dict[str, Any] | None, stored: str = "") -> ExperimentConfig:
    """An ``ExperimentConfig`` from a nested dict, in today's layout or an older one.
    ``stored``: what wrote it, when a program did (``from_dict``)."""
    return from_dict(ExperimentConfig, upgrade_config_dict(data or {}), stored=stored)


BUILTIN_CONFIGS = Path(__file__).resolve().parent / "configs"
"""The default configs of the published models, shipped with the package (the repository's
``configs/`` links here)."""


def builtin_configs() -> list[str]:
    """Names of the shipped default configs (``zara1``, ``sdd``, ...), sorted."""
    return sorted(p.stem for p in BUILTIN_CONFIGS.glob("*.yaml"))


def resolve_config(path: str | Path) -> Path:
    """A config file: ``path`` when it is one, else the shipped default config of that name
    (``zara1`` or ``zara1.yaml``), so that ``--config zara1`` works outside the repository.
    A clear error names the shipped configs otherwise."""
    given = Path(path)
    if given.is_file():
        return given
    bare = "/" not in str(path) and os.sep not in str(path)  # a name, not a path
    if bare and given.suffix in ("", ".yaml"):
        shipped = BUILTIN_CONFIGS / f"{given.stem}.yaml"
        if shipped.is_file():
            return shipped
    raise ConfigNotFound(f"{path}: no such config file (the shipped configs: "
                         f"{', '.join(builtin_configs())}, e.g. --config zara1)")  # fmt: skip


def _repeated_keys(node: yaml.Node, prefix: str = "",
                   seen: set[int] | None = None) -> tuple[str, int, int] | None:  # fmt: skip
    """The first key that a composed YAML mapping (at any depth) gives twice: its dotted
    name, and the lines (1-based) of its first and second appearance; None when none is."""
    seen = set() if seen is None else seen
    if id(node) in seen:  # an alias: its anchor's mapping was checked where it was written
        return None
    seen.add(id(node))
    if isinstance(node, yaml.MappingNode):
        first: dict[tuple[str, str], int] = {}
        for key, value in node.value:
            if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                name = (key.tag, key.value)
                if name in first:
                    return f"{prefix}{key.value}", first[name], key.start_mark.line + 1
                first[name] = key.start_mark.line + 1
            inner = f"{prefix}{key.value}." if isinstance(key, yaml.ScalarNode) else prefix
            found = _repeated_keys(value, inner, seen)
            if found is not None:
                return found
    elif isinstance(node, yaml.SequenceNode):
        for item in node.value:
            found = _repeated_keys(item, prefix, seen)
            if found is not None:
                return found
    return None


def read_yaml(path: str | Path | None, text: str | None = None, name: str = "",
              prefix: str = "", hint: str = "") -> Any:  # fmt: skip
    """The YAML document of file ``path`` (or ``text``, shown as ``name``; its keys named
    after ``prefix``, a ``--set`` key's ``data.``), refusing a key given twice in one mapping,
    at any depth, with a ``ConfigError`` naming the key, the file and both lines: YAML's
    readers keep the last of them without a word, so a second ``data:`` section would drop
    the first one's keys (a run on the default dataset). Invalid YAML is a ``ConfigError``
    too (``hint``, when given, follows its message). Every YAML file a user writes is read
    with it."""
    shown = name or str(path)
    try:
        text = Path(path).read_text() if text is None else text
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        more = f"; {hint}" if hint else ""
        raise ConfigError(f"{shown}: not valid YAML ({exc.__class__.__name__}){more}") from None
    repeated = _repeated_keys(node, prefix) if node is not None else None
    if repeated is not None:
        key, first, again = repeated
        where = f"{shown}, line {again}: " if text.count("\n") else f"{shown}: "
        lines = f" (first on line {first})" if first != again else ""
        if "." in key:
            what = "YAML keeps only the last value without a word: write it once"
        else:
            what = (f"YAML keeps only the last {key}: section, and the first one's keys would "
                    f"be dropped without a word: write one {key}: section holding all its "
                    "keys")  # fmt: skip
        raise ConfigError(f"{where}{key} is given twice{lines}; {what}")
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:  # well-formed, but not plain data (a !tag)
        more = f"; {hint}" if hint else ""
        raise ConfigError(f"{shown}: not valid YAML ({exc.__class__.__name__}){more}") from None


def load_config(
    path: str | Path | None,
    overrides: list[str] | None = None,
    base: dict[str, Any] | None = None,
    sections: tuple[str, ...] | None = None,
) -> ExperimentConfig:
    """Read a YAML config (or the defaults when ``path`` is None) and apply ``key=value``
    overrides such as ``denoiser.epochs=5``.

    With ``base`` (a config dict, e.g. a checkpoint's), the YAML file only replaces the
    top-level ``sections`` named (all when None) on top of ``base``.
    """
    data: dict[str, Any] = copy.deepcopy(base) if base is not None else {}
    if path is not None:
        path = resolve_config(path)
        loaded = read_yaml(path) or {}
        if not isinstance(loaded, dict):
            raise ConfigError(f"{path}: the top level must be a mapping")
        for key, value in loaded.items():
            if sections is None or key in sections:
                data[key] = value
    for item in overrides or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"override {item!r} must look like section.key=value")
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ConfigError(f"override {item!r}: {part} is not a section")
        node[parts[-1]] = set_value(key, value)
    return experiment_from_dict(data)


EMPTY_SPELLINGS = frozenset({"", "null", "Null", "NULL", "~", '""', "''"})
"""How a ``--set`` value says "nothing" (null) or the empty text on purpose."""


def set_value(key: str, value: str) -> Any:
    """The value of one ``--set key=value`` override, read as YAML (``read_yaml``). A text
    made of YAML's own characters is refused with the quoting that means it, rather than read
    as something else: ``,`` or ``:`` is invalid YAML, and ``|``, ``>``, ``&a`` or ``#x`` read
    as the empty text or as null, which a config would take without a word (``data.delimiter=|``
    would become ``''``)."""
    item = f"{key}={value}"
    quoted = f"--set '{key}=\"{value.strip()}\"'"
    hint = f"a text holding YAML's own characters goes in quotes: {quoted}"
    parsed = read_yaml(None, value, f"--set {item}", f"{key}.", hint=hint)
    if parsed in ("", None) and value.strip() not in EMPTY_SPELLINGS:
        what = "the empty text" if parsed == "" else "nothing (null)"
        raise ConfigError(f"--set {item}: YAML reads {value.strip()!r} as {what}; to mean those "
                          f"characters, quote them: {quoted}")  # fmt: skip
    return parsed


def save_config(cfg: ExperimentConfig, path: str | Path) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))
