"""The ``trajpref`` command line: ``data stats``, ``evaluate``, ``predict``, ``plot``,
``train``, ``finetune``, ``models``."""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import itertools
import json
import math
import os
import shlex
import signal
import sys
import textwrap
import threading
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch
import yaml

from trajpref import __version__
from trajpref.adapt import ADAPT_OBJECTIVES, ADAPT_PARAMS, AdaptConfig, evaluate_in_context
from trajpref.config import (
    FINETUNE_METHODS,
    ExperimentConfig,
    ModelConfig,
    config_entries,
    field_docs,
    in_section,
    load_config,
    read_yaml,
    to_dict,
    uses_rl,
)
from trajpref.data import (
    PROTOCOLS,
    ReadOptions,
    hold_out_scene,
    load_dataset,
    mean_speed,
    speed_note,
    speed_text,
)
from trajpref.data.loader import SceneLoader
from trajpref.data.registry import (
    DEFAULT_FRAME_INTERVAL,
    ETH_UCY,
    NAMES,
    SGAN_TEST_FILES,
    SPECS,
    SPLITS,
    check_frame_interval,
    check_protocol_for,
    own_reading_note,
    sgan_folds,
    split_folders,
)
from trajpref.data.trajnet import require_future, write_trajnet, write_trajnet_truth
from trajpref.device import resolve_device
from trajpref.errors import (
    ConfigError,
    ConfigNotFound,
    DataWarning,
    EveryRankError,
    IgnoredWarning,
    ModelNotFound,
    NothingLeftToTrain,
    OverlapWarning,
    TrajprefError,
    TrajprefWarning,
)
from trajpref.evaluation import (
    AGENT_SETS,
    CLI_WORDS,
    check_trained_on,
    evaluate,
    fold_notes,
    lineage_folds,
    predict_dataset,
    resolve_collision_radius,
    role_notes,
    sampled_batches,
    warn_observed_pace,
    warn_untyped_data,
)
from trajpref.evaluation import flat_dataset as _flat_dataset
from trajpref.evaluation import held_out_split as _held_out_split  # noqa: F401 (as before)
from trajpref.evaluation import own_split as _own_split  # noqa: F401 (their old names here)
from trajpref.evaluation import same_path as _same_path
from trajpref.evaluation import shared_split as _shared_split  # noqa: F401
from trajpref.evaluation import training_data_name as _training_data
from trajpref.io import (
    atomic_path,
    check_output_dir,
    check_output_file,
    dotted,
    dumps_json,
    json_safe,
    write_json,
)
from trajpref.metrics import SCENE_SIZE_EDGES, check_bin_edges, min_ade_fde
from trajpref.models import checkpoint as ckpt
from trajpref.models import export as model_export
from trajpref.models import zoo
from trajpref.models.registry import load_predictor
from trajpref.models.timing import (
    UNKNOWN_UNITS,
    model_timing,
    same_units,
)
from trajpref.results import machine
from trajpref.rl.presets import (
    EQUAL_BUDGET_VALIDATIONS,
    EQUAL_BUDGET_WARMUP,
    PAPER_WEIGHTS,
    PRESETS,
    check_no_pretraining_keys,
    finetune_config,
)
from trajpref.score import TrajectoryScorer, score_timesteps
from trajpref.score.scorer import PRECISIONS
from trajpref.score.selection import (
    CHOSEN_SAMPLES,
    METHODS,
    SelectingPredictor,
    SelectionConfig,
    chosen_selection,
)
from trajpref.survey.cli import add_parser as add_survey_parser
from trajpref.train import compare
from trajpref.train.distributed import (
    env_info,
    fallback_launcher,
    launcher_command,
    launcher_note,
)
from trajpref.train.loop import Terminated
from trajpref.train.run import (
    STAGE_NAMES,
    cli_resume_command,
    finetune,
    interval_note,
    last_state_path,
    train_stage,
)
from trajpref.train.stages import finetune_preset
from trajpref.types import AGENT_BALL, WINDOW, collate

# trajpref.viz.plot (matplotlib) is imported inside the commands that draw, not here: every
# other command would pay for it at start-up (about a second). trajpref.survey.cli imports its
# heavy modules (scipy, matplotlib) inside its commands for the same reason
# (tests/test_cli_imports.py).

FRAME_INTERVAL_HELP = (
    "seconds between consecutive rows of an agent (between consecutive distinct frame values "
    "of its files), not per frame number nor per video frame: 0.1 for 10 Hz tracks, 0.4 for "
    "ETH/UCY's frames numbered 10 apart; --time-step then reads every n-th (default: the step "
    "of a frame column headed time or timestamp, read as seconds, or time_ms or timestamp_ms, "
    "read as milliseconds; TrajNet++ files: the fps their scenes declare; else 0.4, assumed)"
)
"""What ``--frame-interval`` means, in the help of the data options and of ``train``."""


def _add_data_args(p: argparse.ArgumentParser, split_default: str = "test") -> None:
    p.add_argument(
        "--dataset",
        required=True,
        help=f"{' '.join(NAMES)}, or a folder of 'frame agent x y' text files (with "
        "train/val/test sub-folders when present)",
    )
    p.add_argument("--split", default=split_default, choices=["train", "val", "test"],
                   help=f"which split to read (default {split_default})")  # fmt: skip
    p.add_argument("--data-root", default=None, help="data folder (default: $TRAJPREF_DATA)")
    p.add_argument(
        "--frame-interval",
        type=float,
        default=None,
        metavar="SECONDS",
        help=f"for a folder dataset: {FRAME_INTERVAL_HELP}",
    )
    p.add_argument("--units", default=None,
                   help="coordinate units, for a folder dataset (default unknown)")  # fmt: skip
    p.add_argument("--delimiter", default=None, help="text columns separated by: comma, "
                   "semicolon, tab, '|' or whitespace (default: sniffed)")  # fmt: skip
    p.add_argument("--max-gap", type=int, default=None, help="missing frames a window may "
                   "span (default: any, with a warning; 0: none; docs/data_format.md)")  # fmt: skip
    p.add_argument("--max-coord", type=float, default=1e6, help="largest accepted |x| or |y| "
                   "in the dataset's units (default 1e6); larger is an error")  # fmt: skip
    p.add_argument("--time-step", type=float, default=1.0, metavar="F",
                   help="read text track files every F frame steps, positions interpolated "
                   "in time (e.g. 4 for 10 Hz data and a 2.5 Hz model; give the files' 0.1 s "
                   "with --frame-interval too, unless their frame column is a time in "
                   "seconds; default 1: as recorded; docs/data_format.md)")  # fmt: skip
    p.add_argument("--history", type=int, default=None, metavar="FRAMES",
                   help="observed frames per window that text track files are cut into "
                   "(default 8; with a --model or --scorer checkpoint, its own, which a value "
                   "given must equal; docs/data_format.md, \"Window lengths\")")  # fmt: skip
    p.add_argument("--future", type=int, default=None, metavar="FRAMES",
                   help="future frames per window, the horizon (default 12; with a "
                   "checkpoint, its own)")  # fmt: skip
    p.add_argument("--protocol", default="all", choices=list(PROTOCOLS),
                   help="which windows count: all (default: every window with a fully observed "
                   "agent) or sgan (windows with at least two, as Social-GAN's loader keeps; "
                   "docs/data.md)")  # fmt: skip
    p.add_argument("--holdout-scene", default=None, metavar="PREFIX",
                   help="with --split val: the windows (train and val files) of the training "
                   "scene whose file names start with PREFIX, the validation split of a run "
                   "trained with data.holdout_scene=PREFIX (docs/data.md)")  # fmt: skip


NUMBER_OR_NONE = {
    "max_log_sigma": ("--max-log-sigma", "a number (model units) or none (no cap)", False),
    "neighbour_radius": ("--neighbour-radius", "a distance > 0 in the data's units (the "
                         "model's: metres, pixels) or none (every pair of a scene attends)",
                         True),
}  # fmt: skip
"""The options that take a number or the word ``none`` (``_number_or_none``), by their
``args`` names: the flag, what it takes (as its error says), and whether the number must be
finite and > 0 here (the radius; the cap's number is checked where the generator takes it,
``_set_generator``)."""


def _number_or_none(args, name: str) -> tuple[bool, float | None]:
    """An option of ``NUMBER_OR_NONE`` as given: ``(False, None)`` when absent (each file's
    own value applies), ``(True, None)`` for ``none`` in any case (no cap; every pair of a
    scene attends), else ``(True, number)``. ConfigError for anything else."""
    text = getattr(args, name, None)
    if text is None:
        return False, None
    flag, takes, positive = NUMBER_OR_NONE[name]
    if str(text).strip().lower() == "none":
        return True, None
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or (positive and not (math.isfinite(value) and value > 0)):
        raise ConfigError(f"{flag} takes {takes}, got {text!r}")
    return True, value


def _model_setting(args, name: str) -> tuple[bool, object]:
    """A generator option of ``MODEL_SETTINGS`` as given: ``(False, None)`` when absent (the
    file's own value applies), else ``(True, value)``; ``--max-log-sigma none`` is ``(True,
    None)``, no cap (``_number_or_none``)."""
    if name in NUMBER_OR_NONE:
        return _number_or_none(args, name)
    value = getattr(args, name, None)
    return value is not None, value


def _add_generator_settings(p: argparse.ArgumentParser) -> None:
    """A generator file's sampling settings that a command may set without retraining
    (evaluate, predict, plot, and export, which fixes them in its file)."""
    p.add_argument("--max-speed", type=float, default=None,
                   help="generators: see agents faster than this many model units per "
                   "observed step at that speed and scale their prediction back up (0: off; "
                   "default: the file's model.max_speed; docs/pretraining.md, 'An input speed "
                   "clamp')")  # fmt: skip
    p.add_argument("--spread-scale", type=float, default=None,
                   help="generators: multiply the spread of the K initial samples about their "
                   "mean by this (1: as trained; default: the file's model.spread_scale; "
                   "docs/pretraining.md, 'The samples' spread at prediction time')")  # fmt: skip
    p.add_argument("--max-log-sigma", default=None, metavar="C|none",
                   help="generators: cap each sample's log sigma at this (model units); none: "
                   "no cap (default: the file's model.max_log_sigma, 1 for sdd/generator; "
                   "docs/pretraining.md, 'A cap on the samples' sigma')")  # fmt: skip
    p.add_argument("--neighbour-radius", default=None, metavar="R|none",
                   help="diffusion models and --scorer: agents whose last observed positions "
                   "lie farther apart than R do not attend to each other, for scenes wider "
                   "than the training scenes; R is in the data's units: metres for ETH/UCY "
                   "(their training scenes span about 16 m), pixels for sdd (docs/data.md, "
                   "'SDD in pixels'); none: every pair of a scene attends (default: the "
                   "file's model.neighbour_radius, none for the published models; "
                   "docs/pretraining.md, 'A neighbour radius')")  # fmt: skip


def _add_model_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--model", default="cv", help="'cv' (constant velocity), a published model "
                   "(DATASET/NAME, see `trajpref models`) or a checkpoint path")  # fmt: skip
    p.add_argument("--samples", type=int, default=20, help="K, samples per agent (default 20)")
    p.add_argument("--seed", type=int, default=None, help="random seed for sampling (default 0; "
                   "a model that draws no noise, such as a published generator, gives the "
                   "same samples at every seed, and says so)")  # fmt: skip
    p.add_argument(
        "--sampler",
        default=None,
        choices=["leapfrog", "full"],
        help="diffusion checkpoints: leapfrog (generator + tau denoising steps; the default for a "
        "generator) or full (all S steps from noise; the default for a bare denoiser)",
    )
    steps = p.add_mutually_exclusive_group()
    steps.add_argument("--deterministic", action="store_true",
                       help="diffusion models: no ancestral noise in the tau denoising steps "
                       "(each is the posterior mean; the default of generators published "
                       "since 2026-11-24)")  # fmt: skip
    steps.add_argument("--stochastic", action="store_true",
                       help="diffusion models: DDPM's ancestral noise in the tau denoising "
                       "steps (how generators published before 2026-11-24 sampled; those "
                       "published since 2026-11-27 have no denoising step, tau 0, so neither "
                       "flag changes them, and it says so)")  # fmt: skip
    _add_generator_settings(p)
    p.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    p.add_argument("--max-agents", type=int, default=MAX_AGENTS,
                   help="a batch size, not a scene filter: at most this many agents per batch "
                   "of whole scenes (default 1024); no scene is skipped, whatever its "
                   "size: one larger than this is a batch of its own (survey build's "
                   "--max-agents, by contrast, skips larger scenes). Lower it to save "
                   "memory, but note that it is not only a memory setting: the random draws "
                   "come from one stream in batch order, so another batching gives each agent "
                   "other draws and sampled metrics move within their sampling noise; "
                   "deterministic predictions (cv with --samples 1, a generator with "
                   "--deterministic) agree to float rounding")  # fmt: skip
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")


def _add_max_scenes_arg(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--max-scenes", type=int, default=None, metavar="N",
                   help=f"{what} only N scenes of the split, evenly spaced over it (its first "
                   "and last scene and N-2 between, in order), for a quick look: the output "
                   "records max_scenes and the split's scene count (split_scenes), and its "
                   "numbers are a subset's, not the split's (default: every scene)")  # fmt: skip


def _add_scorer_arg(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--scorer", default=None, help=f"a denoiser (or generator) checkpoint: {what}")


MAX_AGENTS = 1024
"""``--max-agents``' default: agents per evaluation batch of whole scenes."""

RANK_SCORE_EVERY = 3
"""``--score-every``'s default for ``predict --rank`` and ``evaluate --scorer``: the paper's 34
steps of 100, ``TrajectoryScorer``'s own (``--keep`` selects at ``SelectionConfig``'s)."""


CHOSEN_KINDS = ("full", "cheap")
"""``--chosen``'s values: the chosen setting at 34 score steps (``--chosen`` alone) or its
cheap one (``--chosen cheap``)."""
SELECTION_FLAGS = {"method": "--select", "per": "--select-per", "drop": "--drop",
                   "trust_speed": "--trust-speed", "bandwidth": "--bandwidth",
                   "temperature": "--select-temperature", "score_every": "--score-every",
                   "score_from": "--score-from"}  # fmt: skip
"""``SelectionConfig`` fields and the options that set them."""
CHOSEN_SETS = tuple(flag for field, flag in SELECTION_FLAGS.items() if field != "per")
"""The options whose settings ``--chosen`` takes from ``chosen_selection`` (giving one beside
it is a ConfigError; ``--select-per`` and ``--score-precision`` stay the user's)."""


class _Given(argparse.Action):
    """An option stored as argparse stores it, and also noted as given on the command line
    (``args._given``, by its first option string) even where its value is the default:
    ``--chosen`` refuses the selection options it sets."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        vars(namespace).setdefault("_given", set()).add(self.option_strings[0])


def _given(args) -> set[str]:
    """The ``_Given`` options given on the command line (their first option strings)."""
    return getattr(args, "_given", set())


def _add_selection_args(p: argparse.ArgumentParser, scorer: str) -> None:
    """The options of ``--keep``'s selection and of the score's steps; ``scorer``: the other
    option that scores (``--rank`` or ``--scorer``), which the score's options apply to too.
    The options that ``--chosen`` sets are ``_Given`` (it refuses them)."""
    p.add_argument("--keep", type=int, default=None, metavar="K'",
                   help="keep K' of the --samples futures (default: keep all)")  # fmt: skip
    p.add_argument("--chosen", nargs="?", const="full", default=None, choices=CHOSEN_KINDS,
                   metavar="cheap",
                   help="with --keep and a published generator that has one (zara1/, eth/, "
                   "robo/, robo-mix/generator, eth/generator-pace): select with the setting "
                   "chosen for it on validation, scored by its own denoiser "
                   "(trajpref.score.selection.chosen_selection; docs/selection.md) instead of "
                   "the options' defaults; --chosen cheap: its cheap setting (1 or 2 score "
                   "steps). It sets --select, --drop, --bandwidth, --select-temperature, "
                   "--trust-speed, --score-every and --score-from")  # fmt: skip
    p.add_argument("--select", default="score-facility", choices=METHODS, action=_Given,
                   help="how to keep them (default score-facility: drop the worst-scored, "
                   "then cover the endpoints weighted by the score; docs/selection.md); "
                   "score-* and top use --scorer or the model's own denoiser")  # fmt: skip
    p.add_argument("--drop", type=float, default=0.3, action=_Given,
                   help="score-* selections: the fraction dropped first (0.3)")  # fmt: skip
    p.add_argument("--bandwidth", type=float, default=0.5, action=_Given,
                   help="facility selections: the similarity's bandwidth, as a multiple of "
                   "each item's median squared sample distance (0.5)")  # fmt: skip
    p.add_argument("--select-temperature", type=float, default=2.0, action=_Given,
                   help="score-facility and score-medoids: sample weights "
                   "exp(-z / T), z the standardised residual (2)")  # fmt: skip
    p.add_argument("--select-per", default="agent", choices=["agent", "scene"],
                   help="per agent, or one set of indices per scene (joint metrics)")  # fmt: skip
    p.add_argument("--score-every", type=int, default=None, metavar="E", action=_Given,
                   help="the score's steps: every E of the S, for --keep's score selections "
                   f"(default {SelectionConfig.score_every}) and for {scorer} (default "
                   f"{RANK_SCORE_EVERY}: the paper's 34 of 100)")  # fmt: skip
    p.add_argument("--score-from", type=int, default=0, action=_Given,
                   help="the score's first step (0, the lowest noise level; a later one "
                   "keeps only the noisier steps, docs/selection.md), for --keep's score "
                   f"selections and {scorer}")  # fmt: skip
    p.add_argument("--score-precision", default=None, choices=PRECISIONS,
                   help="arithmetic of the score's passes, for --keep's score selections and "
                   f"{scorer} (default fp32; bf16: about 3x faster on a CPU with bfloat16 "
                   "instructions; docs/selection.md)")  # fmt: skip
    p.add_argument("--trust-speed", type=float, default=0.0, metavar="V", action=_Given,
                   help="score-* selections: agents observed faster than V (the scorer's "
                   "model units per step, as --max-speed) are selected without the score, "
                   "which never saw their pace (0: off; docs/selection.md)")  # fmt: skip


def _add_run_args(p: argparse.ArgumentParser, example: str, last: str, seed: str) -> None:
    """Options every training stage shares (train and finetune); ``seed``: what --seed does."""
    p.add_argument("--out", required=True, help="run folder: checkpoints, config, metrics")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override a config value, e.g. --set {example} (repeatable)",
    )
    p.add_argument("--resume", default=None, help=f"{last} to continue from")
    p.add_argument("--data-root", default=None, help="data folder (default: $TRAJPREF_DATA)")
    p.add_argument("--seed", type=int, default=None, help=seed)
    p.add_argument("--device", default="auto", help="auto, cpu or cuda (default auto)")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")


class _Parser(argparse.ArgumentParser):
    """argparse, with usage errors in the one-line form that every other error takes, and
    without argparse's abbreviations of long options (``--max-sc`` for ``--max-scenes``): a
    script that abbreviates would break, or change meaning, when a later option shares the
    prefix. Its sub-commands' parsers, ``survey``'s included, are of this class too
    (``add_subparsers`` makes its parsers of the parent's class)."""

    def __init__(self, *args, allow_abbrev: bool = False, **kwargs):
        super().__init__(*args, allow_abbrev=allow_abbrev, **kwargs)

    def error(self, message: str):
        self.exit(2, f"trajpref: error: {message} (see: {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="trajpref",
        description="Human trajectory prediction with a diffusion model refined by RLHF.",
    )
    parser.add_argument("--version", action="version", version=f"trajpref {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    data = sub.add_parser("data", help="inspect datasets")
    data_sub = data.add_subparsers(dest="data_command", required=True, metavar="COMMAND")
    stats = data_sub.add_parser("stats", help="counts and basic statistics of one split")
    _add_data_args(stats)
    stats.add_argument("--json", action="store_true", help="print JSON")
    stats.add_argument("--reverse-context", action="store_true",
                       help="also count the context-only agents of each window played backwards "
                       "(what data.reverse_context trains with; as much memory again as the "
                       "forward ones): 'context_agents_reversed'")  # fmt: skip
    stats.set_defaults(func=cmd_data_stats)

    ev = sub.add_parser("evaluate", help="minADE/minFDE (per agent and joint) of a model")
    _add_data_args(ev)
    _add_model_args(ev)
    ev.add_argument("--json", action="store_true", help="print JSON")
    ev.add_argument("--out", default=None, metavar="FILE.json|FILE.csv",
                    help="also write the result to this file: .json (the JSON that --json "
                    "prints) or .csv (a header and one row, nested results such as --bins' "
                    "as dotted columns); with what made it (model settings, version, date, "
                    "machine, command)")  # fmt: skip
    ev.add_argument("--agents", default="all", choices=list(AGENT_SETS),
                    help="which agents every metric averages over: all (default: every "
                    "predicted agent, NBA's ball included, as the published numbers), "
                    "persons (agent_type 0 only: NBA's players, as SocialVAE scores its NBA "
                    "split; the ball stays in each scene as a neighbour the model reads; "
                    "joint metrics over each scene's persons, collisions among them) or "
                    "primary (TrajNet++ .ndjson data only: each scene's primary pedestrian, "
                    "the one agent per scene TrajNet++'s evaluator scores; the model still "
                    "reads the whole scene, and Col-I/Col-II test the primary against all its "
                    "neighbours); the result records agent_set")  # fmt: skip
    _add_max_scenes_arg(ev, "evaluate")
    ev.add_argument("--allow-overlap", action="store_true",
                    help="evaluate an ETH/UCY fold's model (or scorer) on another fold "
                    "anyway: its leave-one-out training files hold most of that fold's "
                    "windows, so it is refused without this flag; the result records "
                    "'overlap'")  # fmt: skip
    _add_scorer_arg(ev, "adds max_ats, max_fts and the top-1/top-5 recall of the "
                    "ground-truth-free ranking")  # fmt: skip
    _add_selection_args(ev, "--scorer")
    ev.add_argument(
        "--bins",
        nargs="?",
        const=",".join(map(str, SCENE_SIZE_EDGES)),
        default=None,
        metavar="EDGES",
        help="also every metric per scene-size bin: upper edges of the bins in "
        "agents per scene (default 5,10,20: <=5, 6-10, 11-20, >20); JSON: 'bins'",
    )
    ev.add_argument("--slots", nargs="?", const="auto", default=None, metavar="R",
                    help="also minADE/minFDE (and Col-I/Col-II) per agent's place in its "
                    "scene: places 1..R each on their own, the agents after them together "
                    "(default R: the model's agent roles, else 3). For data whose scenes list "
                    "their agents in fixed roles, as Robo's leader, follower, approacher; "
                    "elsewhere a place is only the listing order; JSON: 'slots'")  # fmt: skip
    ev.add_argument("--collision-radius", type=float, default=None, metavar="R",
                    help="Col-I/Col-II person radius, in the data's units (collision when "
                    "centres come within 2R; default: TrajNet++'s 0.1 for data in metres, "
                    "off for other units such as SDD's pixels; docs/social.md)")  # fmt: skip
    ev.add_argument(
        "--in-context",
        type=int,
        default=None,
        metavar="CTX_FRAMES",
        help="in-context adaptation (docs/in_context.md): before each window, adapt "
        "a copy of the generator on the windows of the same recording that lie in "
        "the CTX_FRAMES frames ending at its last observed frame (e.g. 40)",
    )
    ev.add_argument("--adapt-steps", type=int, default=5, help="adaptation steps (default 5)")
    ev.add_argument("--adapt-lr", type=float, default=1e-4,
                    help="adaptation learning rate (default 1e-4)")  # fmt: skip
    ev.add_argument("--adapt-params", default="heads", choices=list(ADAPT_PARAMS),
                    help="generator parameters that adapt (default heads)")  # fmt: skip
    ev.add_argument(
        "--adapt-trust",
        type=float,
        default=0.0,
        help="trust region: weight of the L2 penalty to the start weights (0)",
    )
    ev.add_argument(
        "--adapt-objective",
        default="supervised",
        choices=list(ADAPT_OBJECTIVES),
        help="supervised (best-of-K on the context windows), score (the diffusion score of "
        "Eq. 6, the fine-tuning's reward) or both (default supervised)",
    )
    ev.set_defaults(func=cmd_evaluate)

    pr = sub.add_parser("predict", help="save sampled futures of a split (.npz or TrajNet++)")
    _add_data_args(pr)
    _add_model_args(pr)
    pr.add_argument("--out", required=True, help="output .npz file (.ndjson with --format trajnet)")
    pr.add_argument(
        "--format",
        choices=["npz", "trajnet"],
        default="npz",
        help="npz: every array, and meta: a JSON string of what made them (model, hashes, "
        "dataset, split, protocol, seed, K, version, command; default); trajnet: a TrajNet++ "
        "prediction file that trajnetplusplustools' evaluator reads: for TrajNet++ input, "
        "its own scenes, ids and frames (one .ndjson file given as --dataset: one file; a "
        "folder: a folder named as --out without its suffix, one file per source file that "
        "has chosen scenes, even for one file or with --max-scenes); for other data, one "
        "TrajNet++ scene per agent (docs/data_format.md)",
    )
    pr.add_argument(
        "--truth",
        default=None,
        metavar="FILE.ndjson",
        help="with --format trajnet: also write the matching ground-truth file",
    )
    pr.add_argument("--json", action="store_true", help="print a JSON summary")
    _add_max_scenes_arg(pr, "predict")
    pr.add_argument(
        "--rank",
        action="store_true",
        help="order each scene's samples best first by the diffusion score (no "
        "ground truth used); saves `order` and `residual` [K, B] too (npz only: --format "
        "trajnet writes the samples in that order, so that its prediction 0, TrajNet++'s "
        "Top-1, is the score's top-1; without --rank it is an arbitrary sample)",
    )
    _add_scorer_arg(pr, "the denoiser that ranks (default: the model's own)")
    _add_selection_args(pr, "--rank")
    pr.set_defaults(func=cmd_predict)

    pl = sub.add_parser("plot", help="a figure of one scene (PNG, PDF or SVG): histories, "
                        "ground truth, samples",
                        description="A figure of one scene, and its minADE/minFDE printed. A "
                        "model that samples at random (cv, --stochastic, a bare denoiser) is run "
                        "over the split's batches up to the scene's, as predict and evaluate run "
                        "it, so that the figure shows their samples at --seed and --max-agents "
                        "(a late scene with --sampler full takes a while); a model whose samples "
                        "do not change with the seed is run on the scene alone.")  # fmt: skip
    _add_data_args(pl)
    _add_model_args(pl)
    pl.add_argument("--scene", default="0", metavar="INDEX|SCENE_ID",
                    help="the scene: its index in the split as read (with --protocol) or its "
                    "scene id, e.g. biwi_eth.txt@frame=830 (printed by plot, and saved by "
                    "predict as scene_id; default 0)")  # fmt: skip
    pl.add_argument("--out", required=True, help="output figure: .png, .pdf or .svg, written "
                    "in the format its suffix names")  # fmt: skip
    _add_scorer_arg(pl, "beside the ground truth, draw each agent's best samples by their "
                    "diffusion score (ATS) against the ground truth, thickest and darkest the "
                    "best (the paper's Fig. 2; --draw-samples: how many, default 2; each "
                    "agent's own best, where predict --rank orders whole scenes)")  # fmt: skip
    pl.add_argument("--dpi", type=float, default=None,
                    help="a PNG's pixels per inch (default 120; e.g. 300 for print); PDF and "
                    "SVG are vector files")  # fmt: skip
    pl.add_argument("--width", type=float, default=None, metavar="INCHES",
                    help="the figure's width; its text has its printed size at this width, so "
                    "give the width it is printed at: 3.3 for a paper's column, where --scorer "
                    "stacks its two panels (default 6.4; 7 with --scorer). The figure is "
                    "exactly this wide, its height follows the scene; a longer title is "
                    "wrapped onto more lines (the one made is long: give --title or "
                    "--no-title)")  # fmt: skip
    pl.add_argument("--limits", default="auto", metavar="auto|all|X0,X1,Y0,Y1",
                    help="the axes: auto (default) holds every history and ground truth and the "
                    "bulk of the samples, leaving out a sample that reaches farther from its "
                    "agent's last observed position than 3 interquartile ranges (and a quarter of "
                    "the quartile) above the upper quartile of that agent's samples' reaches (it "
                    "runs off the axes); all holds every "
                    "sample drawn; or the x and y ranges in the data's units (write "
                    "--limits=-5,5,-3,3 when the first is negative)")  # fmt: skip
    pl.add_argument("--draw-samples", type=int, default=None, metavar="N",
                    help="samples drawn per agent: the first N of the --samples K (or of the "
                    "--keep K') (default all); with --scorer, the N best by score (default 2). "
                    "The minADE/minFDE printed count all K (K')")  # fmt: skip
    pl.add_argument("--no-numbers", action="store_true",
                    help="no agent numbers beside the agents (default: each agent's index, "
                    "as the minADE/minFDE lines print it)")  # fmt: skip
    _add_selection_args(pl, "--scorer")
    titles = pl.add_mutually_exclusive_group()
    titles.add_argument("--title", default=None,
                        help="the figure's title, in place of the one made (the split, scene, "
                        "model, K and the settings that change the samples: the seed where the "
                        "model draws at random, the sampler, --max-speed and the like, and the "
                        "scorer)")  # fmt: skip
    titles.add_argument("--no-title", action="store_true",
                        help="no title (a paper's caption says it)")  # fmt: skip
    pl.set_defaults(func=cmd_plot)

    tr = sub.add_parser("train", help="train the denoiser (diffusion) or the generator")
    tr.add_argument("stage", choices=["diffusion", "denoiser", "generator"],
                    help="diffusion (also called denoiser: the stage's files are denoiser.*): "
                    "the denoiser of Eq. 2, the diffusion score's model; generator: the "
                    "leapfrog generator trained through a frozen denoiser "
                    "(--denoiser)")  # fmt: skip
    tr.add_argument("--config", default=None, help="YAML config, or a shipped config's name "
                    "(e.g. zara1; `trajpref config show --config zara1` prints it); default: "
                    "the built-in defaults")  # fmt: skip
    tr.add_argument("--dataset", default=None, help="shortcut for --set data.dataset=NAME")
    tr.add_argument("--frame-interval", type=float, default=None, metavar="SECONDS",
                    help=f"a folder dataset's {FRAME_INTERVAL_HELP}; --set "
                    "data.frame_interval; the model records it")  # fmt: skip
    tr.add_argument("--units", default=None, help="a folder dataset's coordinate units (--set "
                    "data.units; default unknown); the model records them")  # fmt: skip
    tr.add_argument("--time-step", type=float, default=None, metavar="F",
                    help="read text track files every F frame steps (--set data.time_step; "
                    "e.g. 4 for 10 Hz data and a 0.4 s model, with --frame-interval 0.1 "
                    "unless the files' frame column is a time in seconds); the model records "
                    "it")  # fmt: skip
    tr.add_argument("--history", type=int, default=None, metavar="FRAMES",
                    help="observed frames per window (--set model.t_hist; default: the "
                    "config's, 8 in the shipped ones): the text track files are cut into "
                    "windows of --history + --future frames, and the networks sized for them; "
                    "the model records both")  # fmt: skip
    tr.add_argument("--future", type=int, default=None, metavar="FRAMES",
                    help="future frames per window, the horizon (--set model.t_fut; default: "
                    "the config's, 12 in the shipped ones)")  # fmt: skip
    tr.add_argument("--denoiser", default=None, help="generator stage: the denoiser "
                    "checkpoint (default OUT/denoiser.safetensors)")  # fmt: skip
    _add_run_args(
        tr,
        "denoiser.epochs=5",
        "a <stage>_last.pt",
        "override the config's seed (default: the config's, 0 unless it sets one)",
    )
    tr.set_defaults(func=cmd_train)

    ft = sub.add_parser(
        "finetune",
        help="RLHF / RLHF-ReS fine-tuning of a pretrained generator",
        description="Fine-tune a pretrained generator with RLHF or RLHF-ReS (the paper's Sec. "
        "5-6), or train the supervised control that an RL gain is measured against. The "
        "reward is the diffusion score by default; --set finetune.reward=set gives the "
        "set-aware reward (each sample rewarded by its marginal gain in a score-weighted DPP "
        "over its agent's K endpoints: plausible samples that cover what the others do not; "
        "with --method rlhf), --set finetune.reward=sda the paper's hand-crafted social "
        "baseline (Sec. 8.1). A reward of your own is registered from Python "
        "(trajpref.rl.register_reward, docs/rlhf.md); this command cannot register one and "
        "refuses its name. docs/rlhf.md describes every setting (trajpref config show lists "
        "them).",
    )
    ft.add_argument("--method", required=True, choices=list(FINETUNE_METHODS),
                    help="rlhf: the policy and value losses on all K samples of each agent "
                    "(Eq. 15-17); rlhf-res: on each scene's best-scored sample k* only "
                    "(Eq. 18-20); control: the supervised generator loss alone on clean "
                    "rollouts, with no reward (it refuses the RL settings, which it does not "
                    "read): the equal-budget control")  # fmt: skip
    ft.add_argument("--from", dest="start", required=True,
                    help="a generator checkpoint: a file or a published name (e.g. "
                    "zara1/generator; `trajpref models` lists them)")  # fmt: skip
    ft.add_argument(
        "--preset",
        default=None,
        choices=list(PRESETS),
        help="'paper': Eq. 13-20 as written, with the paper's loss weights for the method "
        "(default: FinetuneConfig's values, which depart from the equations as printed where "
        "validation said so: kl_form, ratio_against, likelihood, score_every, value_target, "
        "adv_norm, reward_clip (docs/rlhf.md), and use RLHF-ReS's weights 0.3 / 1.5 for "
        "both methods)",
    )
    ft.add_argument(
        "--equal-budget",
        type=float,
        default=None,
        metavar="MINUTES",
        help="the equal-budget protocol (docs/rlhf.md), the same for every method: train for "
        "MINUTES of this process's CPU time (finetune.budget_clock=cpu; validation is not "
        f"counted, so the run takes longer), validate after every MINUTES/"
        f"{EQUAL_BUDGET_VALIDATIONS} of it, warm up {EQUAL_BUDGET_WARMUP} steps, no epoch "
        "limit. Run each method on one thread (OMP_NUM_THREADS=1), as the table's runs",
    )
    ft.add_argument("--config", default=None, help="YAML, or a shipped config's name (e.g. "
                    "zara1), whose 'finetune' section applies (its other sections are not "
                    "read: data and model come from the checkpoint; --set "
                    "data.dataset=FOLDER fine-tunes on other data)")  # fmt: skip
    _add_run_args(
        ft,
        "finetune.lr=5e-5",
        "a finetune_last.pt",
        "the run's seed (default 0, whatever seed the start was trained with)",
    )
    ft.set_defaults(func=cmd_finetune)

    cf = sub.add_parser("config", help="the training config's keys, values and meanings")
    cf_sub = cf.add_subparsers(dest="config_command", required=True, metavar="COMMAND")
    show = cf_sub.add_parser("show", help="print every config key with its value and docstring "
                          "(--yaml: as a YAML file to edit)")  # fmt: skip
    show.add_argument("--config", default=None, help="YAML config to resolve, or a shipped "
                      "config's name (e.g. zara1); default: the built-in defaults")  # fmt: skip
    show.add_argument("--set", dest="overrides", action="append", default=[],
                      metavar="KEY=VALUE", help="override a value, as train and finetune "
                      "take it (repeatable)")  # fmt: skip
    show.add_argument("--yaml", action="store_true", help="print the resolved config as a "
                      "YAML file that --config reads back (every key, without the docstrings): "
                      "`trajpref config show --config zara1 --yaml > my.yaml`, edit it, then "
                      "--config my.yaml")  # fmt: skip
    show.set_defaults(func=cmd_config_show)
    add_survey_parser(sub, add_data_args=_add_data_args, check_data_args=_check_data_args,
                      warn_if_trained_otherwise=_warn_if_trained_otherwise)  # fmt: skip

    mo = sub.add_parser("models", help="the published models (the zoo): list them or show a card")
    mo.add_argument("name", nargs="?", default=None,
                    help="DATASET/NAME (e.g. zara1/generator): print its model card")  # fmt: skip
    mo.add_argument("--json", action="store_true", help="print the index entries as JSON")
    mo.set_defaults(func=cmd_models)

    ex = sub.add_parser("export", help="one model as a .pt2 file that PyTorch alone runs "
                        "(torch.export): a planner's or a robot's predictor")  # fmt: skip
    ex.add_argument("model", help="a generator checkpoint or a published one (DATASET/NAME, "
                    "e.g. zara1/generator); with --scorer, a denoiser's (or a generator's, "
                    "whose own denoiser scores)")  # fmt: skip
    ex.add_argument("--out", required=True, help="the file to write (.pt2)")
    ex.add_argument(
        "--samples",
        type=int,
        default=None,
        metavar="K",
        help="futures per agent: the first K of the generator's (default all)",
    )
    ex.add_argument("--max-agents", type=int, default=model_export.MAX_AGENTS, metavar="N",
                    help="the most agents of one scene the file takes (default "
                    f"{model_export.MAX_AGENTS}; a model with agent roles: at most its "
                    "roles)")  # fmt: skip
    _add_generator_settings(ex)  # as evaluate's, fixed in the file
    ex.add_argument("--scorer", action="store_true",
                    help="export MODEL's diffusion score instead (its denoiser, a generator "
                    "file's own): (history, samples [K, P, T_f, 2], agent_type) -> residuals "
                    "[K, P, T_f] to rank the samples by, as rank_samples does")  # fmt: skip
    ex.add_argument("--score-every", type=int, default=None, metavar="E",
                    help="with --scorer: score at every E-th of the S diffusion steps "
                    "(default 3: 34 of 100, as evaluate's scorer; 50 gives 2, the cheap "
                    "setting)")  # fmt: skip
    ex.add_argument("--score-from", type=int, default=None, metavar="S",
                    help="with --scorer: the first score step (default 0)")  # fmt: skip
    ex.set_defaults(func=cmd_export)

    co = sub.add_parser("compare", help="validation of training runs side by side: kept "
                        "epochs, seed means and spreads, curves at equal shares of the "
                        "schedule")  # fmt: skip
    co.add_argument("groups", nargs="+", metavar="NAME=DIR[,DIR...]",
                    help="a group of runs (e.g. the seeds of one setting) or one run folder; "
                    "changes are against the first group")  # fmt: skip
    co.add_argument("--stage", choices=compare.STAGES, default="generator",
                    help="which stage's <stage>_metrics.jsonl to read (default "
                    "generator)")  # fmt: skip
    co.add_argument("--metrics", nargs="+", default=None,
                    help="validated metrics to show (keys of <stage>_metrics.jsonl; default "
                    "val_min_ade val_min_fde, for the denoiser val_denoise_loss); the kept "
                    "epoch is always the lowest val_score, as the training loop keeps "
                    "it")  # fmt: skip
    co.add_argument("--shares", nargs="+", type=float, default=[0.25, 0.5, 0.75, 1.0],
                    help="shares of each run's schedule (its epochs, or its time budget when "
                    "that ended it) at which to show its curve (default 0.25 0.5 0.75 "
                    "1)")  # fmt: skip
    co.add_argument("--json", action="store_true", help="print the numbers as JSON")
    co.set_defaults(func=cmd_compare)
    return parser


def _check_data_args(args) -> None:
    """Checks the data options, and fills in the defaults of --frame-interval and --units
    (None until here, so that a built-in dataset can tell when either was given at all)."""
    if getattr(args, "_data_checked", False):  # a command may check twice; warn once
        return
    given = args.frame_interval is not None or args.units is not None
    args._interval_given = args.frame_interval is not None
    if args.frame_interval is None:
        args.frame_interval = DEFAULT_FRAME_INTERVAL
    args.units = "unknown" if args.units is None else args.units
    try:  # the registry's rule, in the option's words
        check_frame_interval(args.frame_interval)
    except ConfigError:
        raise ConfigError(f"--frame-interval must be a number of seconds > 0, "
                          f"got {args.frame_interval}") from None  # fmt: skip
    args._data_checked = True
    if args.dataset in SPECS and given:
        warnings.warn(own_reading_note(args.dataset, "--frame-interval and --units",
                                       "they are ignored"),
                      category=IgnoredWarning, stacklevel=2)  # fmt: skip
    _read_options(args)  # --delimiter, --max-gap, --max-coord, --time-step
    check_protocol_for(args.dataset, args.protocol)  # sgan is ETH/UCY's (not SDD's, NBA's)
    if args.holdout_scene is not None:
        if not args.holdout_scene:
            raise ConfigError("--holdout-scene needs a file-name prefix, e.g. biwi_hotel")
        if args.split != "val":
            raise ConfigError(f"--holdout-scene selects a validation split: use it with "
                              f"--split val, not --split {args.split}")  # fmt: skip


def _read_options(args) -> ReadOptions:
    history, future = getattr(args, "history", None), getattr(args, "future", None)
    try:
        return ReadOptions(delimiter=args.delimiter, max_gap=args.max_gap,
                           max_coord=args.max_coord, time_step=args.time_step,
                           reverse_context=getattr(args, "reverse_context", False),
                           t_hist=WINDOW[0] if history is None else history,
                           t_fut=WINDOW[1] if future is None else future)  # fmt: skip
    except ConfigError as exc:  # in the flags' words
        said = str(exc)
        for key, flag in (("t_hist", "--history"), ("t_fut", "--future")):
            said = said.replace(f"{key} must be", f"{flag} must be")
        raise ConfigError(said) from None


def _checkpoint_windows(spec: str) -> tuple[int, int] | None:
    """(T_h, T_f) of the checkpoint ``spec`` names, from its header; None for ``cv`` (any
    lengths) or where it cannot be read (loading it later says why)."""
    if spec == "cv":
        return None
    try:
        return ckpt.windows_of(spec)
    except (TrajprefError, OSError, KeyError, TypeError, ValueError, AttributeError):
        return None


def _resolve_windows(args) -> None:
    """Fill in --history / --future: a checkpoint reads windows of its own lengths
    (``model.t_hist``, ``model.t_fut``), so the data are cut as --model (or --scorer) needs by
    default; given, the flags must agree with it, and --model and --scorer with each other
    (``checkpoint.agreed_windows``). Without a checkpoint (--model cv alone): as given, else
    8 + 12. Once per command (a command may check its options twice)."""
    if getattr(args, "_windows_resolved", False):
        return
    args._windows_resolved = True
    specs = (("--model", args.model), ("--scorer", getattr(args, "scorer", None)))
    readers = {f"{flag} {spec}": _checkpoint_windows(spec) for flag, spec in specs if spec}
    args.history, args.future = ckpt.agreed_windows(readers, (args.history, args.future))


def _interval_given(args) -> bool:
    """Whether --frame-interval was given (``_check_data_args`` fills in its default)."""
    return getattr(args, "_interval_given", True)


def _load(args):
    """The split the data options name. Every command but ``predict`` without ``--truth``
    reads each window's future (scores against it, writes it, or its speed): for them,
    observation-only scenes (TrajNet++ test files, their future hidden) are a ``DataError``
    naming the file (``trajnet.require_future``)."""
    ds = _load_split(args)
    if args.command == "predict":
        if args.truth is not None:
            require_future(ds, "predict --truth")
    else:
        sub = getattr(args, "data_command", None)  # data stats
        require_future(ds, f"{args.command} {sub}" if sub else args.command)
    return ds


def _load_split(args):
    folder = args.dataset not in SPECS  # a built-in's were warned of by _check_data_args

    def split(name: str):
        return load_dataset(
            args.dataset,
            name,
            args.data_root,
            # not given: None, so that TrajNet++ files use the fps they declare, silently
            frame_interval=args.frame_interval if folder and _interval_given(args) else None,
            units=args.units if folder else None,
            options=_read_options(args),
            protocol=args.protocol,
        )

    if args.holdout_scene:  # the held-out scene's windows of both splits (_check_data_args)
        return hold_out_scene(split("train"), split("val"), args.holdout_scene)[1]
    return split(args.split)


def _check_model_args(args) -> None:
    """The options every sampling command takes (checked before any model or data is read);
    fills in --seed's default, 0 (None until here, so that a command can tell it was given)."""
    _check_data_args(args)
    if not hasattr(args, "_seed_given"):  # a command may check twice
        args._seed_given = args.seed is not None
        args.seed = 0 if args.seed is None else args.seed
    if args.samples < 1:
        raise ConfigError("--samples must be >= 1")
    if getattr(args, "max_scenes", None) is not None and args.max_scenes < 1:
        raise ConfigError(f"--max-scenes must be >= 1, got {args.max_scenes}")
    if args.max_agents < 1:
        raise ConfigError("--max-agents must be >= 1")
    keep = getattr(args, "keep", None)
    if keep is not None and not 1 <= keep <= args.samples:
        raise ConfigError(f"--keep must lie in 1..--samples ({args.samples}), got {keep}")
    if getattr(args, "sampler", None) is not None and args.model == "cv":
        raise ConfigError("--sampler applies to diffusion checkpoints; --model cv has none")
    if args.model != "cv":
        _check_checkpoint("--model", args.model)
    if getattr(args, "scorer", None):
        _check_checkpoint("--scorer", args.scorer)
    _resolve_windows(args)
    _check_chosen(args)
    _number_or_none(args, "max_log_sigma")  # ConfigError for a bad value
    given, _ = _number_or_none(args, "neighbour_radius")  # ConfigError for a bad value
    if given and args.model == "cv" and not getattr(args, "scorer", None):
        raise ConfigError("--neighbour-radius applies to diffusion models and scorers: "
                          "--model cv has no attention across agents (with --scorer it sets "
                          "the scorer's)")  # fmt: skip


def cmd_data_stats(args) -> int:
    _check_data_args(args)
    ds = _load(args)
    sizes = np.array([s.num_agents for s in ds.scenes])
    speed = mean_speed(ds)  # scene by scene: no copy of the whole split
    out = {
        "dataset": ds.info.name,
        "split": ds.info.split,
        "protocol": ds.info.protocol,
        "scenes": len(ds),
        "agents": int(sizes.sum()),
        "agents_per_scene": {
            "min": int(sizes.min()),
            "mean": float(sizes.mean()),
            "max": int(sizes.max()),
        },
        # context-only agents: seen at the last observed frame, and over the whole history
        "context_agents": sum(0 if s.context is None else len(s.context) for s in ds.scenes),
        "context_agents_whole_history": sum(
            0 if s.context is None else int(np.isfinite(s.context).all(axis=(1, 2)).sum())
            for s in ds.scenes
        ),
        "units": ds.info.units,
        "frame_interval": ds.info.frame_interval,  # seconds per window step: time step included
        "interval_from": ds.info.interval_from,
        "time_step": ds.info.time_step,
        "t_hist": ds.info.t_hist,
        "t_fut": ds.info.t_fut,
        "mean_speed": speed,  # the dataset's units per second
        "source": ds.info.source,
    }
    info = ds.info
    note = speed_note(speed, info.units, info.frame_interval, info.interval_from, info.time_step)
    if note is not None:  # no walking pace in metres: the interval (or the units) may be wrong
        warnings.warn(f"{info.name}: {note}", category=DataWarning, stacklevel=2)
    if args.reverse_context:  # the same for the windows played backwards (data.reverse_context)
        out["context_agents_reversed"] = sum(
            0 if s.context_reverse is None else len(s.context_reverse) for s in ds.scenes
        )
    if args.json:
        print(dumps_json(out))
    else:
        width = max(len(k) for k in out)
        for key, value in out.items():
            if isinstance(value, dict):
                value = ", ".join(f"{k} {v}" if isinstance(v, int) else f"{k} {v:.3g}"
                                  for k, v in value.items())  # fmt: skip
            elif key == "mean_speed":
                value = speed_text(value, ds.info.units)
            elif key == "frame_interval":
                value = f"{value:g} s{interval_note(ds.info)}"
            elif key in ("interval_from", "time_step"):
                continue  # in frame_interval's note
            print(f"{key:>{width}}: {value}")
    return 0


def _predictor(args):
    _check_model_args(args)
    device = resolve_device(args.device)
    model = load_predictor(args.model, device=device, sampler=args.sampler)
    if args.deterministic or args.stochastic:
        flag = "--deterministic" if args.deterministic else "--stochastic"
        if not hasattr(model, "stochastic"):
            raise ConfigError(f"{flag} applies to diffusion checkpoints only")
        if model.sampler == "leapfrog" and model.tau == 0:
            warnings.warn(f"{args.model} takes no denoising step (model.tau 0): its samples are "
                          f"the generator's own, and {flag} changes nothing",
                          category=IgnoredWarning, stacklevel=2)  # fmt: skip
        model.stochastic = bool(args.stochastic)
    _apply_generator_settings(args, model)
    return model, device


def _apply_generator_settings(args, model) -> None:
    """Set the options of ``_add_generator_settings`` that were given on ``model``."""
    for flag, name in (("--max-speed", "max_speed"), ("--spread-scale", "spread_scale"),
                       ("--max-log-sigma", "max_log_sigma")):  # fmt: skip
        given, value = _model_setting(args, name)
        if given:
            _set_generator(model, flag, **{name: value})
    given, radius = _number_or_none(args, "neighbour_radius")
    if given and hasattr(model, "neighbour_radius"):  # cv has none (its --scorer takes it)
        model.neighbour_radius = radius


def _warn_fixed_sampling(args, model) -> None:
    """evaluate, predict and plot: one warning each when --samples asks a generator that
    emits a fixed set of K (``model.samples``, trained best-of-K) for fewer (it takes the
    first of its set, an arbitrary subset), and when --seed is given to a model that draws no
    noise (a leapfrog generator with no denoising step or deterministic ones, without --keep's
    selection, which draws with the seed)."""
    generator = getattr(model, "generator", None)
    if getattr(model, "sampler", None) != "leapfrog" or generator is None:
        return
    fixed, asked = generator.samples, args.samples
    selects = getattr(args, "keep", None) is not None  # a command without --keep lacks it
    if asked < fixed:
        keep = args.keep if selects else asked
        warnings.warn(f"{args.model} emits a set of K = {fixed} samples (trained best-of-"
                      f"{fixed}), and --samples {asked} takes its first {asked}, an arbitrary "
                      f"subset: to keep {keep} chosen from all {fixed}, give --samples {fixed} "
                      f"--keep {keep} (--select facility without the score, score-facility "
                      "with it; docs/selection.md), or --sampler full for independent "
                      "draws", category=TrajprefWarning, stacklevel=2)  # fmt: skip
    if args._seed_given and not selects and (model.tau == 0 or not model.stochastic):
        steps = ("no denoising step, model.tau 0" if model.tau == 0
                 else "its denoising steps are the posterior mean")  # fmt: skip
        recorded = "" if args.command == "plot" else " (it is still recorded)"
        warnings.warn(f"{args.model} draws no noise ({steps}): every seed gives the same "
                      f"samples, and --seed {args.seed} changes nothing{recorded}",
                      category=IgnoredWarning, stacklevel=2)  # fmt: skip


def _warn_if_trained_otherwise(spec: str, ds, root: str | None = None,
                               holdout: str | None = None) -> str | None:  # fmt: skip
    """One warning when the model was trained on data whose units or pace differ from this
    data's (as far as both are known): its predictions would be in the wrong units or at the
    wrong pace. The model's side: what its checkpoint recorded of its training data
    (``model_timing``: a built-in dataset's own, or a folder's interval, time step and units);
    this data's: ``ds.info`` (its step with the ``--time-step`` it was read with, and where
    its interval comes from). A model trained on a folder before that record is compared
    only with the same folder read at another ``--time-step``. Where nothing known differs
    but this data's interval is only assumed or its units unknown while the model recorded
    its own, the warning names the model's (for a folder model, the flags that read data as
    it did) and the flags that give this data's.

    A second warning when this data is the model's own training folder, read whole because
    it has no split sub-folders (``evaluation.training_windows``), or a split it trained or
    chose its epoch on (``evaluation.own_split``; ``root``: the data root, for a fold's split
    folder given as a path); its short form is returned, for the result to record
    (``evaluate``'s ``overlap``); with ``holdout`` (``--holdout-scene``: that scene's windows
    of both splits), whether the model trained on them or chose its epoch on them
    (``evaluation.held_out_split``). None otherwise. The checks are the library's
    (``evaluation.check_trained_on``, which Python's ``evaluate`` and ``predict_dataset``
    make too), in the command's words (``evaluation.CLI_WORDS``)."""
    if spec == "cv":
        return None
    try:
        header = ckpt.header_of(spec)  # a legacy .pt file too
        model = model_timing(header)
    except (TrajprefError, KeyError, TypeError, ValueError, AttributeError, OSError):
        return None  # not a checkpoint this check can read: loading it has said what it needed
    data = header["config"]["data"]  # model_timing has read it
    return check_trained_on(spec, model, data, ds.info, root, holdout, CLI_WORDS, dataset=ds)


def _trained_on(spec: str) -> list[tuple[str, str | None]]:
    """``(fold, via)`` for each ETH/UCY fold that checkpoint ``spec`` (a path or a published
    name) was trained on: its own ``data.dataset``'s (``via`` None), then those of the other
    runs of its training lineage (``evaluation.lineage_folds``: the generator a fine-tune
    started from, a generator's denoiser; ``via`` names it). Empty for cv, other data, or a
    file whose header this cannot read (loading it says what is wrong)."""
    if spec == "cv":
        return []
    try:
        return lineage_folds(model_timing(ckpt.header_of(spec)))
    except (TrajprefError, KeyError, TypeError, ValueError, AttributeError, OSError):
        return []


def _data_folds(dataset: str) -> tuple[str, ...]:
    """The ETH/UCY folds whose data ``dataset`` is: a fold's name, or a folder holding
    Social-GAN's test files of folds (``registry.sgan_folds``: ``eth_ucy/zara1`` given as a
    path, or a folder of ``crowds_zara01.txt``, is the zara1 fold); empty otherwise."""
    if dataset in ETH_UCY:
        return (dataset,)
    return () if dataset in NAMES else sgan_folds(dataset)


def _fold_overlaps(args) -> list[tuple[str, str, str, str | None]]:
    """``(role, checkpoint, fold, via)`` for each checkpoint of the command (``model``:
    --model; ``scorer``: a --scorer naming another one) trained on an ETH/UCY fold other than
    the data's (``_data_folds``: --dataset's fold, or the folds whose Social-GAN test files a
    --dataset folder holds), itself (``via`` None) or through another run of its training
    lineage (``_trained_on``: a fine-tune's start, a generator's denoiser). Social-GAN's
    leave-one-out folders give each fold's training split the other four scenes' ``*_train``
    files, which hold most of their windows (84 % of the rows of zara1's test file are in the
    zara2 fold's training files): such a model has seen this data, whatever the split."""
    folds = _data_folds(args.dataset)
    if not folds:
        return []
    specs = {"model": args.model}
    scorer = getattr(args, "scorer", None)
    if scorer and not (scorer == args.model or _same_path(scorer, args.model)):
        specs["scorer"] = scorer
    found = []
    for role, spec in specs.items():
        for fold, via in _trained_on(spec):
            if any(f != fold for f in folds):
                found.append((role, spec, fold, via))
    return found


def _check_fold_overlap(args) -> str | None:
    """evaluate: refuse a model (or scorer) trained on another ETH/UCY fold than the data's
    (``_fold_overlaps``), unless --allow-overlap, which warns and returns what the result
    records as ``overlap`` (``zara2 model on zara1``; for a folder, its path after); predict
    and plot: warn. None when nothing overlaps. The advice names the data's fold's published
    model (``zara1/generator``) only where there is one (``trajpref models``)."""
    found = _fold_overlaps(args)
    if not found:
        return None
    data = args.dataset
    folds = _data_folds(data)
    folder = data not in ETH_UCY
    trained = " and ".join(
        f"{spec}{f' (through {via})' if via else ''} was trained on {_training_data(fold)}, "
        f"{' and '.join(f for f in folds if f != fold)} among them"
        for _, spec, fold, via in found
    )
    scenes = " and ".join(folds)
    where = ""
    if folder:
        files = ", ".join(name for f in folds for name in SGAN_TEST_FILES[f])
        where = f"--dataset {data} holds {scenes}'s Social-GAN test files ({files}), and "
    own = " and ".join(dict.fromkeys(fold for _, _, fold, _ in found))
    target = f"--dataset {data}" if not folder else "that folder"
    if len(folds) > 1:
        advice = "evaluate each fold's scenes apart, each with its own fold's models"
    else:
        published = zoo.published()
        picks = []
        for role in dict.fromkeys(role for role, *_ in found):
            name = f"{folds[0]}/{'generator' if role == 'model' else 'denoiser'}"
            picks.append((f"--{role} {name}", name in published))
        if all(ok for _, ok in picks):
            advice = (f"evaluate each fold with its own fold's models, e.g. "
                      f"{' '.join(p for p, _ in picks)} on {target}")  # fmt: skip
        else:
            roles = dict.fromkeys(role for role, *_ in found)
            picks = [p if ok else f"a {role} of your own trained on the {folds[0]} fold"
                     for (p, ok), role in zip(picks, roles, strict=True)]  # fmt: skip
            advice = (f"evaluate each fold with its own fold's models: on {target}, "
                      f"{' and '.join(picks)}")  # fmt: skip
    problem = (f"{trained}: {where}those training files hold most of {scenes}'s windows, so "
               f"this uses data it trained on (its own fold is {own}; {advice})")  # fmt: skip
    if args.command == "evaluate" and not args.allow_overlap:
        raise ConfigError(f"{problem}; --allow-overlap evaluates it anyway and records the "
                          "overlap in the result")  # fmt: skip
    warnings.warn(problem, category=OverlapWarning, stacklevel=2)
    tail = f" ({data})" if folder else ""
    return fold_notes([(role, fold, via) for role, _, fold, via in found], folds, tail)


def _warn_model_and_scorer(args, ds) -> str | None:
    """``_warn_if_trained_otherwise`` for the command's model and, when it names another one,
    its ``--scorer`` (a scorer of other units or pace ranks on what it cannot read; as
    ``survey build`` checks its scorer). Returns what a result records of those trained on
    this very data (``model trained on these windows (...)``), None when neither was."""
    root = getattr(args, "data_root", None)
    holdout = getattr(args, "holdout_scene", None)
    found = {"model": _warn_if_trained_otherwise(args.model, ds, root, holdout)}
    scorer = getattr(args, "scorer", None)
    if scorer and not (scorer == args.model or _same_path(scorer, args.model)):
        found["scorer"] = _warn_if_trained_otherwise(scorer, ds, root, holdout)
    notes = [role_notes(role, note) for role, note in found.items() if note]
    return "; ".join(notes) or None


def _warn_untyped_data(args, model, scorer, ds) -> None:
    """``evaluation.warn_untyped_data`` for the command's model (a selecting predictor's
    generator) and its ``--scorer``: one warning when either learned from agent-type flags
    (NBA's ball) and this data flag no ball (a walkthrough measured minFDE 0.256 -> 0.319 m on
    NBA scenes whose ball was read as a player)."""
    warn_untyped_data(_checked_objects(args, model, scorer), ds)


def _warn_observed_pace(args, model, scorer, ds) -> None:
    """``evaluation.warn_observed_pace`` for the command's model (a selecting predictor's
    generator), else its ``--scorer`` (the constant-velocity baseline reads any units): one
    warning per cause and run when the split is far from the model's training (data in other
    units, a tracker's id switch, agents faster than training without a speed clamp, a window
    wider than any training scene without a neighbour radius)."""
    warn_observed_pace(_checked_objects(args, model, scorer), ds)


def _checked_objects(args, model, scorer) -> list[tuple[str, object]]:
    """``(name, object)`` of the command's model (a selecting predictor's generator, named by
    --model) and its scorer (named by --scorer, else ``the scorer``), for the data checks."""
    base = getattr(model, "base", model)  # a SelectingPredictor's generator
    pairs = ((args.model, base), (getattr(args, "scorer", None) or "the scorer", scorer))
    return [(name, obj) for name, obj in pairs if obj is not None]


def _joined(*notes: str | None) -> str | None:
    """What a result records as ``overlap``: the notes given, joined; None when none."""
    return "; ".join(n for n in notes if n) or None


def _set_generator(model, flag: str, **setting) -> None:
    """Change a sampling setting of a leapfrog predictor's generator (ConfigError for other
    models)."""
    generator = getattr(model, "generator", None)
    if generator is None:
        raise ConfigError(f"{flag} applies to generator checkpoints only")
    try:  # ModelConfig.__post_init__ checks the value; the message names the flag
        generator.cfg = dataclasses.replace(generator.cfg, **setting)
    except ConfigError as err:
        raise ConfigError(f"{flag}: {in_section(str(err), ModelConfig, 'model.')}") from None


def _scorer(path: str, device, args=None, every: int = RANK_SCORE_EVERY):
    """The scorer of checkpoint ``path``; with a command's ``args``, at its
    --neighbour-radius (default: the file's) and, where the command has them,
    its --score-every (default ``every``), --score-from and --score-precision."""
    scorer = TrajectoryScorer.from_checkpoint(path, device)
    if args is None:
        return scorer
    given, radius = _number_or_none(args, "neighbour_radius")
    if given:
        scorer.neighbour_radius = radius
    if not hasattr(args, "score_every"):
        return scorer
    every = args.score_every if args.score_every is not None else every
    steps = score_timesteps(scorer.schedule.num_steps, every, args.score_from)
    return scorer.with_steps(steps, args.score_precision or "fp32")


SELECTION_ONLY = ("method", "per", "drop", "trust_speed", "bandwidth", "temperature")
"""The selection's own settings (the score's steps serve --rank and --scorer too)."""


def _denoiser_hash(header: dict) -> str | None:
    """The weights hash of the denoiser a checkpoint header scores with: its own for a
    denoiser, the one a generator names or embeds."""
    if header.get("kind") == "denoiser":
        return header.get("hash")
    return (header.get("denoiser_ref") or header.get("denoiser") or {}).get("hash")


def _check_chosen(args) -> None:
    """``--chosen`` (before any model or data is read): it needs --keep, the K = 20 samples
    the setting was chosen from, none of the options it sets, a model with a chosen setting
    (``chosen_selection``'s ConfigError otherwise) and no --scorer other than the model's own
    denoiser, which the setting was chosen with."""
    chosen = getattr(args, "chosen", None)
    if chosen is None:
        return
    flag = "--chosen" + (" cheap" if chosen == "cheap" else "")
    if args.keep is None:
        raise ConfigError(f"{flag} needs --keep K' (how many of the {CHOSEN_SAMPLES} samples "
                          "to keep)")  # fmt: skip
    given = [f for f in CHOSEN_SETS if f in _given(args)]
    if given:
        raise ConfigError(f"{flag} sets {', '.join(given)} (the setting chosen for "
                          f"{args.model}): leave {'it' if len(given) == 1 else 'them'} out, or "
                          f"leave out --chosen to set the selection yourself")  # fmt: skip
    try:  # first: a model without a chosen setting is told so, whatever its --samples
        chosen_selection(args.model, args.keep, chosen == "cheap", per=args.select_per)
    except ConfigError as err:
        raise ConfigError(f"{flag}: {err}") from None
    if args.samples != CHOSEN_SAMPLES:
        raise ConfigError(f"{flag}: the setting was chosen keeping K' of the K = "
                          f"{CHOSEN_SAMPLES} samples a published generator emits; give "
                          f"--samples {CHOSEN_SAMPLES} (the default), not "
                          f"{args.samples}")  # fmt: skip
    if args.scorer is not None:
        own, other = (_denoiser_hash(ckpt.header_of(s)) for s in (args.model, args.scorer))
        if own != other:
            raise ConfigError(f"{flag}: the setting was chosen with {args.model}'s own "
                              f"denoiser as the scorer, and --scorer {args.scorer} is another "
                              "one: leave --scorer out (or --chosen, and set the selection "
                              "yourself)")  # fmt: skip


def _selection_config(args) -> SelectionConfig:
    """--keep's selection as the options give it (score steps at the selection's default),
    or with --chosen the setting chosen for the model (``chosen_selection``) at the run's
    seed."""
    chosen = getattr(args, "chosen", None)
    if chosen is not None and args.keep is not None:
        cfg = chosen_selection(args.model, args.keep, chosen == "cheap", per=args.select_per)
        return dataclasses.replace(cfg, seed=args.seed)
    return SelectionConfig(keep=args.keep or 1, method=args.select, drop=args.drop,
                           per=args.select_per, seed=args.seed, bandwidth=args.bandwidth,
                           temperature=args.select_temperature, trust_speed=args.trust_speed,
                           score_every=(SelectionConfig.score_every if args.score_every is None
                                        else args.score_every),
                           score_from=args.score_from)  # fmt: skip


def _warn_unread(args, cfg: SelectionConfig, scores: bool) -> None:
    """One warning naming the selection and score options given that nothing reads: with
    --keep, those its --select does not read; without, every selection option. The score's
    options (--score-every, --score-from, --score-precision) count as read when ``scores``
    (--rank or --scorer scores too)."""
    given = [k for k in SELECTION_FLAGS if getattr(cfg, k) != getattr(SelectionConfig, k)]
    score = [SELECTION_FLAGS[k] for k in given if k not in SELECTION_ONLY]
    if args.score_precision not in (None, "fp32"):
        score.append("--score-precision")
    if args.keep is not None:
        unread = [SELECTION_FLAGS[k] for k in cfg.unread()]
        if not cfg.uses_score and args.score_precision not in (None, "fp32"):
            unread.append("--score-precision")
        unread = [f for f in unread if not (scores and f in score)]
        if unread:
            warnings.warn(f"--select {args.select} does not read {', '.join(unread)}: "
                          f"{'it changes' if len(unread) == 1 else 'they change'} nothing",
                          category=IgnoredWarning, stacklevel=3)  # fmt: skip
        return
    selection = [SELECTION_FLAGS[k] for k in given if k in SELECTION_ONLY]
    score = [] if scores else score
    clauses = []
    for flags, needs in ((selection, "--keep"), (score, f"--keep or {_score_option(args)}")):
        if flags:
            clauses.append(f"{', '.join(flags)} only {'apply' if len(flags) > 1 else 'applies'}"
                           f" with {needs}")  # fmt: skip
    if clauses:
        one = len(selection) + len(score) == 1
        warnings.warn(f"{'; '.join(clauses)}: here {'it changes' if one else 'they change'} "
                      "nothing", category=IgnoredWarning, stacklevel=3)  # fmt: skip


def _kept_by(args) -> str:
    """How evaluate's summary line names --keep's selection: its method, and ``chosen`` or
    ``chosen cheap`` with --chosen."""
    chosen = getattr(args, "chosen", None)
    tag = {None: "", "full": " (chosen)", "cheap": " (chosen cheap)"}[chosen]
    return f"{_selection_config(args).method}{tag}"


def _score_option(args) -> str:
    """The command's option that scores beside --keep: --rank (predict) or --scorer."""
    return "--rank" if args.command == "predict" else "--scorer"


def _selecting(args, model, device, scores: bool = False):
    """The model, wrapped to keep --keep of its --samples futures when asked, and the number
    of futures it returns. ``scores``: the command scores beside the selection (--rank,
    --scorer), so the score's options are read whatever --select is."""
    cfg = _selection_config(args)
    _warn_unread(args, cfg, scores)
    if args.keep is None:
        return model, args.samples
    scorer = None
    if cfg.uses_score:
        if args.scorer is None and args.model == "cv":
            raise ConfigError(f"--select {cfg.method} with --model cv needs --scorer")
        scorer = _scorer(args.scorer or args.model, device, args, cfg.score_every)
    return SelectingPredictor(model, cfg, args.samples, scorer), args.keep


MODEL_SETTINGS = ("max_speed", "spread_scale", "max_log_sigma")
"""The generator's ``model`` settings that ``_predictor``'s options of the same names replace
(``--neighbour-radius``, the predictor's own and ``None`` for ``none``, is handled beside
them)."""


def _model_fields(args) -> dict:
    """Who made a result, beside the model's path: ``model_hash`` (what predicted, as a results
    row records it: weights, denoiser, data scale and model settings, with this command's
    --max-speed, --spread-scale, --max-log-sigma, --neighbour-radius, --deterministic or
    --stochastic applied;
    ``models.checkpoint.header_model_hash``), ``weights_hash`` (the weights' own content hash,
    which a fine-tuned model's ``start_hash`` names), and for a fine-tuned model
    ``finetune_method``, ``finetune_preset``, ``finetune_reward`` and ``start_hash`` (the
    header's ``meta.method``, ``meta.preset``, ``models.checkpoint.finetune_reward`` and
    ``meta.from``; a fine-tune written before ``meta.preset``: the preset whose values its
    config's finetune section holds, ``train.stages.finetune_preset``, None for none). None for
    cv."""
    if args.model == "cv":
        return {"model_hash": None, "weights_hash": None}
    header = ckpt.header_of(args.model)
    header = {**header, "config": {**header["config"], "model": dict(header["config"]["model"])}}
    model = header["config"]["model"]
    for name in MODEL_SETTINGS:
        given, value = _model_setting(args, name)
        if given and model.get(name) != value:  # the file's own value: the file's digest
            model[name] = value
    given, radius = _number_or_none(args, "neighbour_radius")
    if given and model.get("neighbour_radius") != radius:  # the file's own: its digest
        model["neighbour_radius"] = radius
    if args.deterministic or args.stochastic:
        model["stochastic_steps"] = bool(args.stochastic)
    sampler = args.sampler or ("full" if header["kind"] == "denoiser" else "leapfrog")
    out = {"model_hash": ckpt.header_model_hash(header, sampler),
           "weights_hash": header.get("hash")}  # fmt: skip
    meta = header.get("meta") or {}
    if meta.get("method") is not None:
        preset = (meta["preset"] if "preset" in meta
                  else finetune_preset(header["config"].get("finetune")))  # fmt: skip
        out.update(finetune_method=meta["method"], finetune_preset=preset,
                   finetune_reward=ckpt.finetune_reward(header),
                   start_hash=meta.get("from"))  # fmt: skip
    return out


def _sampling_fields(model) -> dict:
    """How the command's predictor samples, as its options left it: ``sampler`` (leapfrog or
    full; None for cv), ``stochastic_steps`` (ancestral noise in the denoising steps), and the
    generator's ``max_speed``, ``spread_scale`` and ``max_log_sigma`` in effect (the file's
    unless an option replaced them; None where no generator samples: cv, the full sampler),
    and the predictor's ``neighbour_radius`` (either sampler; None: every pair attends, and
    for cv)."""
    sampler = getattr(model, "sampler", None)
    generator = getattr(model, "generator", None) if sampler == "leapfrog" else None
    stochastic = getattr(model, "stochastic", None)
    return {"sampler": sampler,
            "stochastic_steps": None if stochastic is None else bool(stochastic),
            **{name: None if generator is None else getattr(generator.cfg, name)
               for name in MODEL_SETTINGS},
            "neighbour_radius": getattr(model, "neighbour_radius", None)}  # fmt: skip


def _command_line(args) -> str:
    """The command as typed (``main``'s arguments), for a result's ``command``."""
    argv = getattr(args, "argv", None)
    return shlex.join(["trajpref", *(sys.argv[1:] if argv is None else argv)])


def _run_fields(args, device) -> dict:
    """Where and how a result was made: trajpref's and torch's versions, the UTC time, the
    machine (as the benchmark rows describe it: ``results.machine``), the device, torch's
    threads, --max-agents (it orders the random draws) and the command."""
    return {"max_agents": args.max_agents, "device": str(device),
            "threads": torch.get_num_threads(), "trajpref_version": __version__,
            "torch_version": torch.__version__,
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "machine": machine(), "command": _command_line(args)}  # fmt: skip


RESULT_SUFFIXES = (".json", ".csv")
"""The files ``evaluate --out`` writes, by suffix."""


def _check_result_file(path: str) -> None:
    """``evaluate --out``: a writable .json or .csv file (checked before any work)."""
    check_output_file(path)
    suffix = Path(path).suffix.lower()
    if suffix not in RESULT_SUFFIXES:
        given = suffix or "no suffix"
        raise ConfigError(f"--out {path}: the output must be a .json or .csv file (its "
                          f"suffix names the format), not {given}")  # fmt: skip


def _data_fields(ds) -> dict:
    """What a result records of the data's reading beside its name and split: ``units``,
    ``frame_interval`` (seconds per window step, ``--time-step`` included), ``time_step``,
    ``interval_from`` (where the interval comes from: ``default`` when only assumed), and
    ``t_hist`` and ``t_fut``, the window's observed and future frames."""
    info = ds.info
    return {"units": info.units, "frame_interval": info.frame_interval,
            "time_step": info.time_step, "interval_from": info.interval_from,
            "t_hist": info.t_hist, "t_fut": info.t_fut}  # fmt: skip


def _note_replaced(path: str, what: str) -> None:
    """A note on stderr when ``--out`` names a file already there, which ``what`` (this
    command's output) replaces: evaluate, predict and plot write one output per file."""
    if Path(path).is_file():
        print(f"trajpref: note: --out {path} existed and is replaced by this {what} (one "
              f"{what} per file: give each run its own --out to keep both)",
              file=sys.stderr)  # fmt: skip


def _write_result(path: str, out: dict) -> None:
    """Write ``evaluate``'s result as its suffix says: JSON, or CSV (a header and one row;
    null and non-finite numbers as empty cells, nested results as dotted columns). A file
    already there is replaced, and a note on stderr says so (one result per file)."""
    _note_replaced(path, "result")
    if Path(path).suffix.lower() != ".csv":
        write_json(path, out)
        return
    row = dotted(json_safe(out))
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh)
            writer.writerow(row)
            writer.writerow(["" if v is None else json.dumps(v) if isinstance(v, (bool, list))
                             else v for v in row.values()])  # fmt: skip


def _selection_fields(args) -> dict:
    """What a result records of --keep's selection: the settings it ran with (with --chosen,
    the chosen ones, and ``chosen``: ``full`` or ``cheap``)."""
    if args.keep is None:
        return {}
    cfg = _selection_config(args)
    chosen = getattr(args, "chosen", None)
    return {"candidates": args.samples, "select": cfg.method, "select_per": cfg.per,
            "drop": cfg.drop, "bandwidth": cfg.bandwidth,
            "select_temperature": cfg.temperature, "trust_speed": cfg.trust_speed,
            "score_every": cfg.score_every, "score_from": cfg.score_from,
            "score_precision": args.score_precision or "fp32",
            **({"chosen": chosen} if chosen else {})}  # fmt: skip


def _scorer_fields(args, scorer) -> dict:
    """``evaluate --scorer``: the scorer and the steps its metrics were computed at."""
    if scorer is None:
        return {}
    every = RANK_SCORE_EVERY if args.score_every is None else args.score_every
    return {"scorer": args.scorer, "scorer_score_every": every,
            "scorer_score_from": args.score_from, "scorer_score_steps": len(scorer.steps),
            "scorer_score_precision": scorer.precision,
            "scorer_neighbour_radius": scorer.neighbour_radius}  # fmt: skip


SCORE_LINE = (("max_ats", "maxATS"), ("max_fts", "maxFTS"), ("mean_ats", "meanATS"))
SCORE_RECALL = ("top1_recall_ats", "top5_recall_ats", "top1_recall_fts", "top5_recall_fts")
BIN_COLUMNS = (("min_ade", "minADE"), ("min_fde", "minFDE"), ("joint_min_ade", "jADE"),
               ("joint_min_fde", "jFDE"), ("col_i_pct", "Col-I%"), ("col_ii_pct", "Col-II%"),
               ("max_ats", "maxATS"))  # fmt: skip


def _parse_bins(text: str | None) -> tuple[int, ...] | None:
    """``--bins 5,10,20`` -> (5, 10, 20); ConfigError unless increasing integers >= 1."""
    if text is None:
        return None
    try:
        edges = tuple(int(v) for v in text.split(","))
        check_bin_edges(edges)
    except ValueError:
        raise ConfigError(f"--bins takes increasing integers >= 1 separated by commas "
                          f"(e.g. 5,10,20), got {text!r}") from None  # fmt: skip
    return edges


def _scene_subset(args, ds):
    """``--max-scenes``: N scenes of the split, evenly spaced (``evenly_spaced``), and what
    the output records of it (``max_scenes``, ``split_scenes``: the split's count); a note on
    stderr when it is fewer than the split's, so the numbers are not taken for the split's."""
    total = len(ds)
    fields = {"max_scenes": args.max_scenes, "split_scenes": total}
    if args.max_scenes is None or args.max_scenes >= total:
        return ds, fields
    ds = ds.evenly_spaced(args.max_scenes)
    print(f"trajpref: note: --max-scenes {args.max_scenes}: {len(ds)} of the split's {total} "
          "scenes, evenly spaced; the numbers are this subset's, not the split's",
          file=sys.stderr)  # fmt: skip
    return ds, fields


AGENT_SET_TAGS = {"all": "", "persons": ", persons only", "primary": ", primary agents only"}
"""What evaluate's header adds to the protocol for each ``--agents`` set."""

AGENT_SET_NOUNS = {"all": "agents", "persons": "persons", "primary": "primary agents"}
"""What evaluate's header calls the agents it counted, for each ``--agents`` set."""


def _protocol_tag(ds, holdout: str | None = None, agents: str = "all") -> str:
    """`` (protocol all)`` after the split in evaluate's header, whichever the protocol (a
    pasted log says which windows counted), with ``, persons only`` under ``--agents
    persons`` (``, primary agents only`` under ``primary``), and the held-out scene when
    there is one."""
    tag = f" (protocol {ds.info.protocol}{AGENT_SET_TAGS[agents]})"
    return tag + (f" (held-out scene {holdout}*)" if holdout else "")


def _windows_tag(ds) -> str:
    """``, windows of 6 + 16 frames`` in evaluate's header where the data were cut into other
    windows than the published models' 8 + 12 (a minFDE over 16 future frames is not one
    over 12)."""
    windows = (ds.info.t_hist, ds.info.t_fut)
    return "" if windows == WINDOW else f", windows of {windows[0]} + {windows[1]} frames"


def _fmt(value) -> str:
    return "-" if value is None else f"{value:.4f}" if isinstance(value, float) else str(value)


def _print_collisions(out: dict) -> None:
    if out.get("col_radius") is None:
        print(f"  collisions off (units {out['units']}; pass --collision-radius in these units)")
        return
    if not out["col_agents"]:  # the rates are NaN: no agent is in them
        print(f"  Col-I n/a  Col-II n/a   ground truth n/a   (no agent has a neighbour; radius "
              f"{out['col_radius']:g} {out['units']})")  # fmt: skip
        return
    print(f"  Col-I {out['col_i_pct']:.2f} %  Col-II {out['col_ii_pct']:.2f} %   ground truth "
          f"{out['col_gt_pct']:.2f} %   (of {out['col_agents']} agents with a neighbour; "
          f"radius {out['col_radius']:g} {out['units']})")  # fmt: skip


def _print_bins(bins: dict) -> None:
    cols = [(k, name) for k, name in BIN_COLUMNS if any(k in row for row in bins.values())]
    print("  " + f"{'size':>8} {'scenes':>7} {'agents':>8} "
          + " ".join(f"{name:>8}" for _, name in cols))  # fmt: skip
    for label, row in bins.items():
        print("  " + f"{label:>8} {row['scenes']:>7} {row['agents']:>8} "
              + " ".join(f"{_fmt(row.get(k)):>8}" for k, _ in cols))  # fmt: skip


def _parse_slots(text: str | None, model: object) -> int | None:
    """``--slots [R]`` -> R; ``auto`` (the flag alone): the model's agent roles
    (``Predictor.agent_roles``), else 3. ConfigError unless an integer >= 1."""
    if text is None:
        return None
    if text == "auto":
        return int(getattr(model, "agent_roles", 0) or 0) or 3
    try:
        slots = int(text)
    except ValueError:
        slots = 0
    if slots < 1:
        raise ConfigError(f"--slots takes an integer >= 1 (or nothing: the model's agent roles, "
                          f"else 3), got {text!r}")  # fmt: skip
    return slots


def _print_slots(slots: dict) -> None:
    cols = [(k, name) for k, name in BIN_COLUMNS[:2] + BIN_COLUMNS[4:6]
            if any(k in row for row in slots.values())]  # fmt: skip
    print("  " + f"{'place':>8} {'agents':>8} " + " ".join(f"{name:>8}" for _, name in cols))
    for label, row in slots.items():
        print("  " + f"{label:>8} {row['agents']:>8} "
              + " ".join(f"{_fmt(row.get(k)):>8}" for k, _ in cols))  # fmt: skip


def cmd_evaluate(args) -> int:
    _check_model_args(args)
    if args.out:
        _check_result_file(args.out)
    overlap = _check_fold_overlap(args)  # refused unless --allow-overlap
    if args.in_context is not None:
        return _evaluate_in_context(args, overlap)
    bins = _parse_bins(args.bins)
    if args.collision_radius is not None:
        resolve_collision_radius(args.collision_radius, "")  # ConfigError unless > 0
    model, device = _predictor(args)
    slots = _parse_slots(args.slots, model)
    _warn_fixed_sampling(args, model)
    sampling = _sampling_fields(model)
    scorer = _scorer(args.scorer, device, args) if args.scorer else None
    model, samples = _selecting(args, model, device, scores=scorer is not None)
    ds = _load(args)
    overlap = _joined(overlap, _warn_model_and_scorer(args, ds))
    _warn_observed_pace(args, model, scorer, ds)
    _warn_untyped_data(args, model, scorer, ds)
    ds, subset = _scene_subset(args, ds)
    start = time.perf_counter()
    result = evaluate(
        model, ds, samples, args.seed, device, args.max_agents,
        progress=not args.no_progress, scorer=scorer,
        collision_radius="auto" if args.collision_radius is None else args.collision_radius,
        bins=bins, allow_overlap=True,  # _check_fold_overlap has refused or been allowed
        agents=args.agents, slots=slots, check_data=False,  # checked above, in its words
    )  # fmt: skip
    seconds = time.perf_counter() - start
    out = {
        "dataset": ds.info.name,
        "split": ds.info.split,
        "protocol": ds.info.protocol,
        "agent_set": args.agents,
        **subset,
        **({"holdout_scene": args.holdout_scene} if args.holdout_scene else {}),
        "model": args.model,
        **_model_fields(args),
        "samples": samples,
        "seed": args.seed,
        **_selection_fields(args),
        **_scorer_fields(args, scorer),
        **{k: v for k, v in result.items() if k not in ("bins", "slots")},
        **_data_fields(ds),
        "seconds": round(seconds, 3),
        "overlap": overlap,
        **sampling,
        **_run_fields(args, device),
    }
    if bins is not None:
        out["bins"] = result["bins"]
    if slots is not None:
        out["slots"] = result["slots"]
    bad = [k for k, v in out.items() if isinstance(v, float) and not math.isfinite(v)]
    if bad:
        collisions = {"col_i_pct", "col_ii_pct", "col_gt_pct"}
        why = " (no agent has a neighbour)" if set(bad) <= collisions else ""
        shown = "printed as n/a" if set(bad) <= collisions else "printed as nan"
        where = "the JSON output holds null" if args.json or args.out else shown
        warnings.warn(
            f"{', '.join(bad)} not finite{why}: {where}", category=TrajprefWarning, stacklevel=1
        )
    if args.out:
        _write_result(args.out, out)
    if args.json:
        print(dumps_json(out))
    else:
        print(
            f"{ds.info.name}/{ds.info.split}{_protocol_tag(ds, args.holdout_scene, args.agents)}"
            f"  model={args.model}"
            f"{'' if args.sampler is None else f' ({args.sampler} sampler)'}"
            f"  K={samples}  ({out['agents']} {AGENT_SET_NOUNS[args.agents]}"
            f", {out['scenes']} scenes, "
            f"units {ds.info.units}{_windows_tag(ds)})"
            + ("" if args.keep is None else f", kept by {_kept_by(args)} of {args.samples}")
        )
        print(
            f"  minADE {out['min_ade']:.4f}  minFDE {out['min_fde']:.4f}   "
            f"joint minADE {out['joint_min_ade']:.4f}  joint minFDE {out['joint_min_fde']:.4f}"
        )
        if scorer is not None:
            print("  " + "  ".join(f"{name} {out[k]:.4f}" for k, name in SCORE_LINE)
                  + "   top-1/top-5 recall: by ATS {:.3f}/{:.3f}  by FTS {:.3f}/{:.3f}".format(
                      *(out[k] for k in SCORE_RECALL)))  # fmt: skip
        _print_collisions(out)
        if bins is not None:
            _print_bins(out["bins"])
        if slots is not None:
            _print_slots(out["slots"])
    return 0


def _evaluate_in_context(args, overlap: str | None = None) -> int:
    """``evaluate --in-context``: the usual metrics with per-window adaptation, plus the
    windows that had context, before/after on them and seconds per window. ``overlap``: what
    ``_check_fold_overlap`` allowed."""
    if args.keep is not None or args.scorer or args.bins is not None or args.slots is not None:
        raise ConfigError("--in-context does not combine with --keep, --scorer, --bins or "
                          "--slots")  # fmt: skip
    if args.agents != "all" or args.max_scenes is not None:  # its context is the split's
        raise ConfigError("--in-context does not combine with --agents persons or primary, "
                          "or --max-scenes (it adapts on the split's other windows)")  # fmt: skip
    _warn_unread(args, _selection_config(args), scores=False)
    cfg = AdaptConfig(ctx_frames=args.in_context, steps=args.adapt_steps, lr=args.adapt_lr,
                      params=args.adapt_params, trust=args.adapt_trust,
                      objective=args.adapt_objective)  # fmt: skip
    model, device = _predictor(args)
    sampling = _sampling_fields(model)
    ds = _load(args)
    own = _warn_if_trained_otherwise(
        args.model, ds, getattr(args, "data_root", None), getattr(args, "holdout_scene", None)
    )
    _warn_observed_pace(args, model, None, ds)
    _warn_untyped_data(args, model, None, ds)
    overlap = _joined(overlap, own and f"model {own}")
    result = evaluate_in_context(model, ds, cfg, args.samples, args.seed, device=device,
                                 progress=not args.no_progress)  # fmt: skip
    out = {"dataset": ds.info.name, "split": ds.info.split, "protocol": ds.info.protocol,
           "model": args.model, **_model_fields(args), "samples": args.samples,
           "seed": args.seed,
           "in_context": args.in_context, "adapt_steps": cfg.steps, "adapt_lr": cfg.lr,
           "adapt_params": cfg.params, "adapt_trust": cfg.trust,
           "adapt_objective": cfg.objective, **result,
           **_data_fields(ds), "overlap": overlap, **sampling,
           **_run_fields(args, device)}  # fmt: skip
    if args.out:
        _write_result(args.out, out)
    if args.json:
        print(dumps_json(out))
        return 0
    print(
        f"{ds.info.name}/{ds.info.split}{_protocol_tag(ds, args.holdout_scene)}  "
        f"model={args.model}  K={args.samples}  in-context "
        f"{cfg.ctx_frames} frames, {cfg.steps} steps of {cfg.params} at lr {cfg.lr:g}"
        f"{_windows_tag(ds)}"
    )
    print(
        f"  minADE {out['min_ade']:.4f}  minFDE {out['min_fde']:.4f}   "
        f"joint minADE {out['joint_min_ade']:.4f}  joint minFDE {out['joint_min_fde']:.4f}"
    )
    print(
        f"  {out['windows_with_context']} of {out['windows']} windows have context; "
        f"{out['seconds_per_window']:.3f} s per window"
    )
    for key in ("before", "after"):
        if out[key] is not None:
            print(
                f"  {key:>6} (windows with context): minADE {out[key]['min_ade']:.4f}  "
                f"minFDE {out[key]['min_fde']:.4f}"
                + (" (no adaptation step: as before)" if key == "after" and not cfg.steps else "")
            )
    return 0


def _trajnet_sources(args) -> tuple[list[Path], list[Path], bool]:
    """What ``predict --format trajnet`` reads, found before any model or data is read (the
    rule of ``registry._user_folder``, without reading a file): the TrajNet++ ``.ndjson``
    files, the folders read as data (a folder given as --dataset and the split sub-folder read
    from it; both splits' with --holdout-scene), and whether the input is a folder of
    TrajNet++ files (written as a folder, ``trajnet.write_trajnet_scenes``; a single
    ``.ndjson`` file given as --dataset is written as one file). No files for a built-in
    dataset or a text folder; nothing at all where the input cannot be read (loading it
    later says why)."""
    from trajpref.data import text as data_text

    if args.dataset in NAMES:
        return [], [], False
    path = Path(args.dataset).expanduser()
    try:
        if path.suffix.lower() == ".ndjson" and path.is_file():
            return [path], [], False
        if not path.is_dir():
            return [], [], False
        splits = split_folders(path)
        names = ("train", "val") if args.holdout_scene else (args.split,)
        read = [splits[n] for n in names if n in splits] if splits else [path]
        files = [f for folder in read
                 if data_text.matching_files(folder, ("*.ndjson",))
                 for f in data_text.track_files(folder, "*.ndjson")]  # fmt: skip
    except (TrajprefError, OSError):
        return [], [], False
    # with split sub-folders, the root's other files are not read: the split folders (any
    # of the three, also one not there yet, which an output would create) are what to guard
    guarded = [*splits.values(), *(path / n for n in SPLITS if n not in splits)]
    return files, guarded if splits else [path], bool(files)


def _resolved(path: Path) -> Path:
    with contextlib.suppress(OSError, RuntimeError):
        return path.expanduser().resolve()
    return path.expanduser().absolute()


def _within(inner: Path, outer: Path) -> bool:
    """Whether ``inner`` is ``outer`` or lies under it (both resolved)."""
    return inner == outer or outer in inner.parents


def _check_trajnet_targets(args) -> None:
    """``predict --format trajnet``'s output paths, checked before any model or data is read:
    every file and folder the prediction and ``--truth`` will be (for TrajNet++ input,
    ``trajnet.trajnet_output_paths``) can be written, none is a source file, a folder read as
    data (any folder input, ``_trajnet_sources``) or inside one (writing there replaced the
    user's files, or changed what the folder reads as), and ``--out`` and ``--truth`` are
    apart (neither the same path nor one inside the
    other: the second written replaced the first)."""
    from trajpref.data.trajnet import trajnet_output_base, trajnet_output_paths

    files, folders, folder = _trajnet_sources(args)
    args._trajnet_folder = folder  # the layout, from the input alone
    outputs = [("--out", args.out)] + ([("--truth", args.truth)] if args.truth else [])
    bases = {}
    for flag, given in outputs:
        base = trajnet_output_base(given, folder)
        bases[flag] = _resolved(base)
        written = trajnet_output_paths(given, [f.name for f in files], True) if folder else {}
        if folder:
            check_output_dir(base, flag)
            for target in written.values():
                check_output_file(target, ".ndjson", flag)
            others = sorted(p.name for p in base.glob("*.ndjson")
                            if base.is_dir() and p.name not in written)  # fmt: skip
            if others:  # the evaluator pairs files by name: a stale one would be scored too
                raise ConfigError(f"{flag} {given}: the folder {base} holds .ndjson files this "
                                  f"run does not write ({', '.join(others[:3])}"
                                  f"{', ...' if len(others) > 3 else ''}; an earlier run's?), "
                                  "which an evaluator reading the folder would score too: "
                                  "write to a new folder or remove them")  # fmt: skip
        data = Path(args.dataset).expanduser()
        if data.is_dir() and bases[flag] == _resolved(data):  # the data folder itself
            raise ConfigError(f"{flag} {given}: writes {base}, the source folder {args.dataset} "
                              "itself: write the predictions elsewhere")  # fmt: skip
        for source in folders:
            if _within(bases[flag], _resolved(source)):
                what = "the source folder" if bases[flag] == _resolved(source) else (
                    "inside the source folder")  # fmt: skip
                raise ConfigError(f"{flag} {given}: writes {base}, {what} {source} (it would "
                                  "replace or add to the data read): write the predictions "
                                  "outside it")  # fmt: skip
        targets = [base, *written.values()]  # every file written, against every source file
        for source, target in itertools.product(files, targets):
            if _resolved(source) == _resolved(target) or (
                target.exists() and source.exists() and os.path.samefile(source, target)
            ):  # a symlinked source file is its target's file too
                raise ConfigError(f"{flag} {given}: writes {target}, the source file "
                                  f"{source} itself: write the predictions elsewhere")  # fmt: skip
    if len(bases) == 2:
        out, truth = bases["--out"], bases["--truth"]
        if _within(out, truth) or _within(truth, out):
            raise ConfigError(f"--out {args.out} and --truth {args.truth} write "
                              f"{trajnet_output_base(args.out, folder)} and "
                              f"{trajnet_output_base(args.truth, folder)}: the same path or one "
                              "inside the other, so the second would replace the first: give "
                              "them apart")  # fmt: skip


def _check_trajnet_predict(args) -> None:
    """``predict --format trajnet``'s own checks, before any model or data is read: its output
    paths (``_check_trajnet_targets``); with --rank, a note on stderr that prediction 0, its
    Top-1, is then the diffusion score's top-1 (the samples are written best first) and that
    the order and residual arrays are npz's only. Without --rank, prediction 0 is an arbitrary
    sample (--rank's help says so). Any K is written: TrajNet++'s evaluator reads Top-3 only
    with more than two predictions, so K = 1 or 2 gets Top-1 alone."""
    _check_trajnet_targets(args)
    if args.rank:
        print("trajpref: note: --format trajnet --rank writes each scene's samples best first "
              "by the diffusion score, so prediction_number 0 (TrajNet++'s Top-1) is its top-1; "
              "the order and residual arrays are not written in this format (--format npz "
              "saves them)", file=sys.stderr)  # fmt: skip


def cmd_predict(args) -> int:
    _check_model_args(args)
    trajnet = args.format == "trajnet"
    check_output_file(args.out, ".ndjson" if trajnet else ".npz")
    if args.truth is not None:
        if not trajnet:
            raise ConfigError("--truth needs --format trajnet")
        check_output_file(args.truth, ".ndjson")
    if trajnet:
        _check_trajnet_predict(args)
    # --truth writes each window's future: observation-only data (TrajNet++ test files) is
    # refused before any model is read, so the data is read first then
    ds = None if args.truth is None else _load(args)
    overlap = _check_fold_overlap(args)  # a warning
    model, device = _predictor(args)
    _warn_fixed_sampling(args, model)
    sampling = _sampling_fields(model)
    scorer = None
    if args.rank:
        if args.scorer is None and args.model in ("cv",):
            raise TrajprefError("--rank with --model cv needs --scorer CHECKPOINT")
        scorer = _scorer(args.scorer or args.model, device, args)
    model, samples = _selecting(args, model, device, scores=scorer is not None)
    if ds is None:  # observation-only scenes too: their future is NaN (docs/data_format.md)
        ds = _load(args)
    overlap = _joined(overlap, _warn_model_and_scorer(args, ds))
    _warn_observed_pace(args, model, scorer, ds)
    _warn_untyped_data(args, model, scorer, ds)
    ds, subset = _scene_subset(args, ds)
    arrays = predict_dataset(
        model, ds, samples, args.seed, device, args.max_agents,
        progress=not args.no_progress, scorer=scorer, check_data=False,  # checked above
    )  # fmt: skip
    ids = arrays.get("agent_id")  # [N] the source data's ids, or None
    if trajnet:
        from trajpref.data.trajnet import from_trajnet, write_trajnet_scenes

        _warn_trajnet_units(ds)
        interval = ds.info.frame_interval
        if from_trajnet(ds.scenes):  # TrajNet++ files: their scenes, ids and frames (a folder
            # given: one file each, in a folder named as --out without its suffix)
            args.out = str(write_trajnet_scenes(args.out, ds.scenes, arrays["pred"],
                                                arrays["scene"], truth=args.truth,
                                                folder=args._trajnet_folder))  # fmt: skip
        else:
            write_trajnet(args.out, arrays["history"], arrays["pred"], arrays["scene"],
                          interval, agent_id=ids)  # fmt: skip
            if args.truth is not None:
                write_trajnet_truth(args.truth, arrays["history"], arrays["future"],
                                    arrays["scene"], interval, agent_id=ids)  # fmt: skip
    else:
        arrays["split"] = np.array(ds.info.split)  # 0-d: scene_id names the file, not its split
        meta = _predict_meta(args, ds, samples, scorer, overlap, sampling, device) | subset
        _note_replaced(args.out, "prediction")
        with atomic_path(args.out) as tmp:
            with open(tmp, "wb") as fh:  # meta: a 0-d string, read without pickle
                np.savez_compressed(fh, **arrays, meta=np.array(dumps_json(meta)))
    summary = {
        "out": args.out,
        "agents": int(arrays["future"].shape[0]),
        "scenes": len(ds),
        **subset,
        "samples": samples,
        "pred_shape": list(arrays["pred"].shape),
    }
    print(
        dumps_json(summary)
        if args.json
        else f"wrote {args.out}: pred {tuple(arrays['pred'].shape)} [K, N, T_f, 2]"
    )
    return 0


def _warn_trajnet_units(ds) -> None:
    """A warning when ``predict --format trajnet`` writes data in other units than metres
    (units given and not metres: pixels, centimetres): TrajNet++'s tools assume metres (its
    collision radius is 0.1 m). Unknown units (a folder read without ``--units``) pass."""
    units = ds.info.units
    if units in UNKNOWN_UNITS or same_units(units, "m"):
        return
    warnings.warn(
        f"--format trajnet writes this data's coordinates as they are, in {units}; "
        "TrajNet++'s tools assume metres (its collision metrics use a 0.1 m radius): "
        "convert them to metres for its evaluator",
        category=DataWarning,
        stacklevel=2,
    )


def _predict_meta(args, ds, samples: int, scorer, overlap, sampling: dict, device) -> dict:
    """What made a ``predict`` .npz (its ``meta`` array, JSON): the data (dataset, split,
    protocol, and how it was read: ``_data_fields``), the model and its hashes, K, the seed,
    the selection and ranking, the sampling settings, and where and how it ran
    (``_run_fields``)."""
    rank = ({"rank_scorer": args.scorer or args.model, "rank_score_steps": len(scorer.steps),
             "rank_neighbour_radius": scorer.neighbour_radius}
            if scorer is not None else {})  # fmt: skip
    return {"dataset": ds.info.name, "split": ds.info.split, "protocol": ds.info.protocol,
            **({"holdout_scene": args.holdout_scene} if args.holdout_scene else {}),
            **_data_fields(ds),
            "model": args.model, **_model_fields(args), "samples": samples, "seed": args.seed,
            **_selection_fields(args), **rank, "overlap": overlap, **sampling,
            **_run_fields(args, device)}  # fmt: skip


def _check_plot_args(args) -> None:
    """plot's own options, before any model or data is read: --out's format, --dpi, --width,
    --limits (parsed into ``args.limits``), --draw-samples and --scene."""
    from trajpref.viz import plot  # matplotlib: imported only by the commands that draw
    from trajpref.viz.plot import FORMATS, check_limits

    path = check_output_file(args.out)
    if path.suffix.lower() not in FORMATS:
        raise ConfigError(f"--out {path}: the output must be a .png file, or .pdf or .svg "
                          "(its suffix names the format)")  # fmt: skip
    if not plot.in_range(args.dpi, plot.DPI_RANGE):
        low, high = plot.DPI_RANGE
        raise ConfigError(f"--dpi takes pixels per inch from {low:g} to {high:g}, "
                          f"got {args.dpi:g}")  # fmt: skip
    if not plot.in_range(args.width, plot.WIDTH_RANGE):
        low, high = plot.WIDTH_RANGE
        raise ConfigError(f"--width takes inches from {low:g} to {high:g}, got {args.width:g}")
    if args.limits not in ("auto", "all"):
        try:
            box = tuple(float(v) for v in args.limits.split(","))
        except ValueError:
            box = ()
        if len(box) != 4:
            raise ConfigError(f"--limits takes auto, all or X0,X1,Y0,Y1 (four numbers in the "
                              f"data's units), got {args.limits!r}")  # fmt: skip
        try:
            args.limits = check_limits(box)
        except ConfigError as err:
            raise ConfigError(f"--limits {args.limits}: {err}") from None
    if args.draw_samples is not None and args.draw_samples < 1:
        raise ConfigError(f"--draw-samples must be >= 1, got {args.draw_samples}")
    scene = str(args.scene).strip()
    if scene.lstrip("-").isdigit():  # an index; anything else is a scene id
        args.scene = int(scene)
        if args.scene < 0:
            raise ConfigError(f"--scene {args.scene}: scene indices start at 0")
    elif not scene:
        raise ConfigError("--scene takes a scene index or a scene id such as "
                          "biwi_eth.txt@frame=830")  # fmt: skip


def _frame_number(text: str) -> float | None:
    """A scene id's frame label as a number (frames may be written as times, e.g. 0.4), or
    None when it is not one."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _scene_index(args, ds) -> int:
    """``--scene``'s index in the split as read: the index given, or the scene whose id it
    names (``plot`` prints ids; ``predict`` saves them as ``scene_id``)."""
    where = f"{ds.info.name}/{ds.info.split} (protocol {ds.info.protocol})"
    if isinstance(args.scene, int):
        if not 0 <= args.scene < len(ds):
            raise TrajprefError(f"--scene {args.scene}: the split has scenes 0..{len(ds) - 1}")
        return args.scene
    ids = [s.scene_id for s in ds.scenes]
    if args.scene in ids:
        return ids.index(args.scene)
    file, _, frame = args.scene.partition("@frame=")
    same = [i for i in ids if i.partition("@frame=")[0] == file]
    asked, frames = _frame_number(frame), [_frame_number(i.partition("@frame=")[2]) for i in same]
    if same and asked is not None and None not in frames:  # that file's ids nearest the frame
        order = sorted(range(len(same)), key=lambda j: abs(frames[j] - asked))
        near = f"; the nearest of {file}: {', '.join(same[j] for j in order[:3])}"
    elif same:
        near = f"; {file}'s first: {same[0]}"
    else:
        files = sorted({i.partition("@")[0] for i in ids})
        near = f"; its files: {', '.join(files[:5])}{', ...' if len(files) > 5 else ''}"
    dropped = (" (--protocol sgan leaves out the scenes of fewer than two agents)"
               if ds.info.protocol == "sgan" else "")  # fmt: skip
    raise TrajprefError(f"--scene {args.scene}: no scene of {where} has this id{dropped}"
                        f"{near}. Ids are FILE@frame=FIRST_FRAME: plot prints its scene's, "
                        "and `trajpref predict ... --out p.npz` saves every scene's as "
                        "scene_id (in index order); --scene also takes an index")  # fmt: skip


def _plot_samples(model, ds, args, device, samples: int) -> tuple[object, torch.Tensor, bool]:
    """The scene's batch (the scene alone) and its ``samples`` pred [K, P, T_f, 2] (K' of
    them with --keep: ``model`` is then ``_selecting``'s, as predict's) as predict and
    evaluate draw them at --seed and --max-agents, and whether the model draws at random.
    A model whose samples do not change with the seed is run on the scene alone; one that
    draws at random runs over the split's batches in order up to the scene's, as those
    commands do (one random stream in batch order), so that the figure's samples are theirs."""
    one = collate([ds[args.scene]]).to(device)
    pred = model.predict(one, samples, torch.Generator().manual_seed(args.seed))
    other = model.predict(one, samples, torch.Generator().manual_seed(args.seed + 1))
    if torch.equal(pred, other):  # the draws change nothing: this is predict's sample
        return one, pred, False
    groups = SceneLoader(ds, max_agents=args.max_agents, shuffle=False).batches()
    stop = next(j for j, g in enumerate(groups) if args.scene in g)
    for j, (batch, drawn) in enumerate(sampled_batches(model, ds, samples, args.seed,
                                                       device, args.max_agents,
                                                       not args.no_progress, "plot")):  # fmt: skip
        if j == stop:
            where = int(np.flatnonzero(groups[j] == args.scene)[0])  # the scene in its batch
            return one, drawn[:, batch.scene == where], True  # [K, P, T_f, 2]
    raise AssertionError("the scene's batch was not reached")  # pragma: no cover


def _plot_title(args, ds, scene, random: bool) -> str:
    """The figure's title: --title, none with --no-title, else where the scene is from, then
    the model and what changes its samples (the seed and --max-agents where it draws at
    random), and the scorer."""
    if args.no_title:
        return ""
    if args.title is not None:
        return args.title
    info = ds.info
    # a folder without split sub-folders is read whole whatever --split says
    split = "" if _same_path(info.source, info.name) else f"/{info.split}"
    where = f"{info.name}{split} scene {args.scene} ({scene.scene_id})"
    if info.protocol != "all":
        where += f", protocol {info.protocol}"
    if args.holdout_scene:
        where += f", held-out scene {args.holdout_scene}*"
    settings = [args.model, f"K={args.samples}"]
    if args.keep is not None:
        settings.append(_plot_kept(args))
    if random:
        settings.append(f"seed {args.seed}")
        if args.max_agents != MAX_AGENTS:
            settings.append(f"max-agents {args.max_agents}")
    if args.sampler:
        settings.append(f"sampler {args.sampler}")
    if args.stochastic or args.deterministic:
        settings.append("stochastic" if args.stochastic else "deterministic")
    for name in MODEL_SETTINGS:
        given, value = _model_setting(args, name)
        if given:
            settings.append(f"{name.replace('_', '-')} {'none' if value is None else f'{value:g}'}")
    given, radius = _number_or_none(args, "neighbour_radius")
    if given:
        settings.append(f"neighbour-radius {'none' if radius is None else f'{radius:g}'}")
    scorer = f"; ranked by {args.scorer}" if args.scorer else ""
    return f"{where}\n{', '.join(settings)}{scorer}"


def _print_scene_metrics(args, scene, pred: torch.Tensor, units: str, order=None,
                         scores=None) -> None:  # fmt: skip
    """The scene's minADE_K/minFDE_K over all K samples (as evaluate computes them), mean
    and per agent; with a scorer, each agent's drawn samples' scores, best first."""
    future = torch.as_tensor(scene.future, dtype=pred.dtype, device=pred.device)  # [P, T_f, 2]
    ade, fde = (v.cpu().numpy() for v in min_ade_fde(pred, future))  # [P], [P]
    k = pred.shape[0]
    unit = "" if not units or units in UNKNOWN_UNITS else f" {units}"  # as the axes: none
    print(f"scene {args.scene} ({scene.scene_id}): minADE_{k} {ade.mean():.4f}{unit}, "
          f"minFDE_{k} {fde.mean():.4f}{unit} (the mean of its {len(ade)} agents; "
          f"every sample counts)")  # fmt: skip
    for i in range(len(ade)):
        ball = " (the ball)" if int(scene.agent_type[i]) == AGENT_BALL else ""  # drawn as a star
        line = f"  agent {i}{ball}: minADE {ade[i]:.4f}  minFDE {fde[i]:.4f}"
        if scores is not None:
            shown = ", ".join(f"{scores[j, i]:.3f}" for j in order[:, i])
            line += f"  ATS of the drawn: {shown}"
        print(line)


def _plot_kept(args) -> str:
    """How plot's title and legend say --keep's selection: ``kept 5 of 20 by score-facility
    (chosen)``."""
    return f"kept {args.keep} of {args.samples} by {_kept_by(args)}"


def cmd_plot(args) -> int:
    from trajpref.viz import plot as figures  # matplotlib: only the commands that draw

    _check_model_args(args)
    _check_plot_args(args)
    _check_fold_overlap(args)  # a warning
    model, device = _predictor(args)
    _warn_fixed_sampling(args, model)
    ds = _load(args)
    _warn_model_and_scorer(args, ds)
    scorer = _scorer(args.scorer, device, args) if args.scorer else None  # --neighbour-radius
    model, count = _selecting(args, model, device, scores=scorer is not None)  # predict's --keep
    _warn_observed_pace(args, model, scorer, ds)
    _warn_untyped_data(args, model, scorer, ds)
    args.scene = _scene_index(args, ds)
    scene = ds[args.scene]
    batch, pred, random = _plot_samples(model, ds, args, device, count)  # pred [K, P, T_f, 2]
    title = _plot_title(args, ds, scene, random)
    style = {"limits": args.limits, "width": args.width, "dpi": args.dpi,
             "numbers": not args.no_numbers,
             "selection": "" if args.keep is None else _plot_kept(args)}  # fmt: skip
    samples = pred.cpu().numpy()  # [K, P, T_f, 2]
    order = scores = None
    _note_replaced(args.out, "figure")
    if scorer is not None:
        scores = scorer.score(batch, pred).agent_ats.cpu().numpy()  # [K, P]
        top = min(args.draw_samples or 2, count)
        order = np.argsort(-scores, axis=0, kind="stable")[:top]  # [top, P] as drawn
        figures.plot_scene_scored(scene.history, scene.future, samples, scores, args.out,
                          ds.info.units, title, top, agent_type=scene.agent_type,
                          **style)  # fmt: skip
    else:
        figures.plot_scene(scene.history, scene.future, samples, args.out, ds.info.units, title,
                   scene.agent_type, max_samples=args.draw_samples, **style)  # fmt: skip
    print(f"wrote {args.out}")
    _print_scene_metrics(args, scene, pred, ds.info.units, order, scores)
    return 0


def _is_main_process() -> bool:
    """False on the ranks > 0 of a torchrun launch (only rank 0 reports)."""
    return os.environ.get("RANK", "0") == "0"


TRAIN_SHORTCUTS = (("dataset", "data.dataset"), ("frame_interval", "data.frame_interval"),
                   ("units", "data.units"), ("time_step", "data.time_step"),
                   ("history", "model.t_hist"), ("future", "model.t_fut"))  # fmt: skip
"""``train``'s flags that are shortcuts for ``--set KEY=...``: (``args`` name, config key)."""


def _train_shortcuts(args) -> list[str]:
    """The ``--set`` overrides that ``train``'s shortcut flags stand for (after the user's own,
    so they apply last). ``ConfigError`` where a ``--set`` gives the same key another value:
    one of the two would be dropped without a word (``--history 6 --set model.t_hist=5``
    trained at 6)."""
    given = {}
    for text in args.overrides:
        key, sep, value = text.partition("=")
        if sep:
            with contextlib.suppress(yaml.YAMLError):
                given[key.strip()] = (text, yaml.safe_load(value))
    out = []
    for name, key in TRAIN_SHORTCUTS:
        value = getattr(args, name)
        if value is None:
            continue
        if key in given and given[key][1] != value:
            flag = "--" + name.replace("_", "-")
            raise ConfigError(f"{flag} {value} and --set {given[key][0]} both set {key}: give "
                              "it once")  # fmt: skip
        out.append(f"{key}={json.dumps(value)}")  # a path as it is
    return out


def cmd_train(args) -> int:
    check_output_dir(args.out)
    if args.denoiser is not None:
        _check_checkpoint("--denoiser", args.denoiser)
    overrides = list(args.overrides) + _train_shortcuts(args)
    cfg = load_config(args.config, overrides)
    _check_folders_beside_config(cfg.data, args.config)
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, seed=args.seed)
    _warn_if_validation_reads_training(cfg.data)
    if args.stage == "generator" and args.denoiser is not None:
        _warn_if_data_seen_before("--denoiser", args.denoiser, "the denoiser", cfg.data.dataset)
    summary = train_stage(
        args.stage,
        cfg,
        args.out,
        args.data_root,
        args.device,
        args.resume,
        args.denoiser,
        progress=not args.no_progress,
    )
    if summary.get("rank", 0) == 0:
        kept = Path(args.out) / f"{STAGE_NAMES[args.stage]}{ckpt.SUFFIX}"
        print(_summary_line(f"trained {args.stage}", summary, kept))
    return 0


def _check_folders_beside_config(data, config: str | None) -> None:
    """A ``ConfigError`` for a config file's relative ``data.dataset`` (or ``val_dataset``)
    that is no folder here but is one beside the config file: a relative path is read from
    the current folder, not the config file's (which ``unknown dataset`` did not say)."""
    if config is None or not Path(config).is_file():
        return  # the defaults, or a shipped config's name
    given = read_yaml(config)
    given = given.get("data") if isinstance(given, dict) else None
    for key in ("dataset", "val_dataset"):
        value = getattr(data, key)
        if not isinstance(given, dict) or given.get(key) != value:
            continue  # not the file's (--dataset, --set)
        if not value or value in NAMES or Path(value).expanduser().is_absolute():
            continue
        folder = Path(config).resolve().parent  # where the file's relative paths would hold
        beside = folder / Path(value).expanduser()
        if not Path(value).expanduser().exists() and beside.exists():
            raise ConfigNotFound(
                f"data.{key}: {value}: no such folder in the current folder ({Path.cwd()}); a "
                f"relative path in a config file is read from the folder trajpref runs in, not "
                f"the config file's ({config}), beside which {beside} is: write data.{key}: "
                f"{beside} in the file, or run trajpref from {folder}"
            )


def _summary_line(what: str, summary: dict, kept: Path) -> str:
    """The line a finished training command prints: its training time over every session,
    the kept epoch's validation numbers, and ``kept``, the best checkpoint, when it exists."""
    best = dict(summary["best"])
    epoch = best.pop("epoch", None)
    numbers = " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                       for k, v in best.items())  # fmt: skip
    at = f" at epoch {epoch}" if epoch is not None else ""
    wrote = f"; kept {kept}" if kept.is_file() else ""
    return (
        f"{what} in {summary['train_seconds']:.0f} s (training time over all sessions); "
        f"best validation{at}: {numbers}{wrote}"
    )


REWARD_LABELS = {"set": "set-aware reward", "sda": "SDA reward"}
"""How the summary line names a ``finetune.reward`` other than the diffusion score."""


def _method_label(finetune_cfg, preset: str | None = None) -> str:
    """A fine-tuning run's method as its summary line names it: ``rlhf``, with a reward
    other than the score ``rlhf, set-aware reward`` (the checkpoint's ``meta.method`` keeps
    the plain method; ``config.finetune.reward`` says the reward), and with the preset whose
    values the config holds (``train.stages.finetune_preset``, the checkpoint's
    ``meta.preset``) ``rlhf, paper preset``; ``preset`` (--preset) with a value of it changed
    by --set: ``rlhf, paper preset with finetune.clip changed``."""
    reward = REWARD_LABELS.get(finetune_cfg.reward) if uses_rl(finetune_cfg.method) else None
    label = finetune_cfg.method + (f", {reward}" if reward else "")
    held = finetune_preset(finetune_cfg)
    if held is not None:
        return f"{label}, {held} preset"
    if preset is not None and preset in PRESETS:
        changed = [f"finetune.{k}" for k, v in PRESETS[preset].items()
                   if getattr(finetune_cfg, k, v) != v]  # fmt: skip
        if finetune_cfg.method in PAPER_WEIGHTS:
            weights = dict(zip(("policy_weight", "value_weight"),
                               PAPER_WEIGHTS[finetune_cfg.method], strict=True))  # fmt: skip
            changed += [f"finetune.{k}" for k, v in weights.items()
                        if getattr(finetune_cfg, k) != v]  # fmt: skip
        return f"{label}, {preset} preset" + (f" with {', '.join(changed)} changed"
                                              if changed else "")  # fmt: skip
    return label


def _check_checkpoint(flag: str, spec: str) -> None:
    """A checkpoint option's value that is no file but the repository path of a published
    model (``models/zara1/generator.safetensors`` outside the repository): a ConfigError that
    names the published name, which works in any folder."""
    message = zoo.not_here_message(spec, flag)  # the rule the Python API's errors use too
    if message is not None:
        raise ModelNotFound(message)


def _warn_if_validation_reads_training(data) -> None:
    """One warning when a run's validation split is its training split: a folder dataset (or
    one TrajNet++ file) without train/ and val/ sub-folders, with neither another validation
    dataset nor a held-out scene."""
    if data.holdout_scene or (data.val_dataset and data.val_dataset != data.dataset):
        return
    if data.dataset in NAMES or not _is_main_process():
        return
    if _flat_dataset(data.dataset):  # what cannot be read: reading the data says why
        warnings.warn(f"{data.dataset} has no train/ and val/ sub-folders, so validation (and "
                      "the choice of the kept checkpoint) reads the training windows: give it "
                      "train/ and val/ sub-folders, or --set data.val_dataset=FOLDER, or --set "
                      "data.holdout_scene=PREFIX (its files whose names start with PREFIX "
                      "leave training for validation)",
                      category=OverlapWarning, stacklevel=2)  # fmt: skip


def cmd_finetune(args) -> int:
    check_output_dir(args.out)
    if Path(args.start).is_dir():  # a run folder: name the generator in it
        generator = Path(args.start) / f"generator{ckpt.SUFFIX}"
        hint = (
            f": pass {generator}" if generator.is_file() else " with no generator checkpoint in it"
        )
        raise ConfigError(f"--from {args.start}: a folder, not a checkpoint file{hint}")
    _check_checkpoint("--from", args.start)
    check_no_pretraining_keys(args.overrides or [])  # the user's own --set
    cfg = finetune_config(args.start, args.method, args.preset, args.config, args.overrides,
                          args.seed, args.equal_budget)  # fmt: skip
    _warn_if_validation_reads_training(cfg.data)
    _warn_if_data_seen_before("--from", args.start, "the start", cfg.data.dataset)
    summary = finetune(cfg, args.start, args.out, args.data_root, args.device, args.resume,
                       progress=not args.no_progress, equal_budget=args.equal_budget)  # fmt: skip
    if summary.get("rank", 0) == 0:
        label = _method_label(cfg.finetune, args.preset)
        print(_summary_line(f"fine-tuned ({label})", summary,
                            Path(args.out) / f"finetune{ckpt.SUFFIX}"))  # fmt: skip
    return 0


def _warn_if_data_seen_before(flag: str, spec: str, what: str, dataset: str) -> None:
    """One warning (first process alone) when the checkpoint a run builds on (``spec``, given
    as ``flag``: finetune's --from, train generator's --denoiser) was trained, itself or
    through its own lineage (``_trained_on``), on an ETH/UCY fold other than the run's data
    (``dataset``: a fold, or a folder of Social-GAN test files): that fold's leave-one-out
    training files hold most of the run's data's windows, so the result cannot be tested on
    its own data's test split (``evaluate`` refuses it without --allow-overlap)."""
    folds = _data_folds(dataset)
    if not folds or not _is_main_process():
        return
    found = [(fold, via) for fold, via in _trained_on(spec) if any(f != fold for f in folds)]
    if not found:
        return
    own = " and ".join(folds)
    seen = " and ".join(f"the {fold} fold" + (f" (through {via})" if via else "")
                        for fold, via in found)  # fmt: skip
    warnings.warn(f"{flag} {spec}: {what} was trained on {seen}, whose leave-one-out training "
                  f"files (the other four scenes') hold most of {own}'s windows: what this "
                  f"run writes has seen most of {own}'s test split, and evaluate refuses it there "
                  f"(--allow-overlap records the overlap); for numbers on {own}, build on "
                  f"{own}'s own models", category=OverlapWarning, stacklevel=2)  # fmt: skip


def _yaml_value(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def config_yaml(cfg: ExperimentConfig, source: str) -> str:
    """``cfg`` as a YAML document, every key, that ``load_config`` reads back to an equal
    config; ``source``: what it was resolved from (the command), said in its first comment."""
    source = " ".join(source.splitlines())  # one comment line
    head = (
        f"# {source} (trajpref {__version__}): every key, resolved.\n"
        "# `trajpref config show` documents each key; read this file with --config FILE.\n"
    )
    return head + yaml.safe_dump(to_dict(cfg), sort_keys=False)


def cmd_config_show(args) -> int:
    """Every key of the (resolved) config, its value and its docstring, section by section;
    with --yaml, the resolved config as a YAML file (``config_yaml``)."""
    cfg = load_config(args.config, args.overrides)
    if args.yaml:
        words = ["trajpref", "config", "show"]
        words += ["--config", args.config] if args.config else []
        words += [w for item in args.overrides for w in ("--set", item)]
        print(config_yaml(cfg, shlex.join([*words, "--yaml"])), end="")
        return 0
    sections = field_docs(ExperimentConfig)
    current = ""  # the section printed last (None: top-level keys)
    for key, value, doc in config_entries(cfg):
        section = key.partition(".")[0] if "." in key else None
        if section != current:
            if current != "":
                print()
            if section is not None:
                print(f"# {section}: {sections.get(section, '')}")
            current = section
        print(f"{key} = {_yaml_value(value)}")
        print(textwrap.fill(doc, 96, initial_indent="    ", subsequent_indent="    "))
    return 0


def cmd_export(args) -> int:
    """Write ``args.model`` as an exported program (``models.export``), checked against the
    model, and say how to run it."""
    check_output_file(args.out, model_export.EXPORT_SUFFIX)
    _check_checkpoint("", args.model)  # a positional MODEL: the message names no flag
    if args.scorer:
        return _export_scorer(args)
    if args.score_every is not None or args.score_from is not None:
        raise ConfigError("--score-every and --score-from go with --scorer")
    _number_or_none(args, "max_log_sigma")  # a bad value: before the model is read
    _number_or_none(args, "neighbour_radius")
    for flag, value in (("--samples", args.samples), ("--max-agents", args.max_agents)):
        if value is not None and value < 1:
            raise ConfigError(f"{flag} must be >= 1, got {value}")
    model = load_predictor(args.model, device="cpu")
    _apply_generator_settings(args, model)  # cv: refused by the export itself
    fixed = getattr(getattr(model, "generator", None), "samples", None)
    if fixed is not None and args.samples is not None and args.samples > fixed:
        raise ConfigError(f"--samples {args.samples}: {args.model} emits K = {fixed} samples")
    if fixed is not None and args.samples is not None and args.samples < fixed:
        warnings.warn(f"{args.model} emits a set of K = {fixed} samples (trained best-of-"
                      f"{fixed}), and --samples {args.samples} keeps its first {args.samples}, "
                      f"an arbitrary subset: to keep {args.samples} chosen from all {fixed}, "
                      "export all and select outside (trajpref.score.selection, "
                      "docs/selection.md)", category=TrajprefWarning, stacklevel=2)  # fmt: skip
    program = model_export.export_predictor(model, args.samples, args.max_agents)
    meta = model_export.export_meta(model, program, args.model)
    bound = meta["max_agents"]
    model_export.save_exported(program, args.out, meta)
    pace = f", {model.frame_interval:g} s per step" if model.frame_interval else ""
    units = f" in {model.units}" if model.units else ""
    print(f"wrote {args.out}: history [P, {model.t_hist}, 2]{units}{pace} and agent_type [P] "
          f"-> futures [{meta['samples']}, P, {model.t_fut}, 2], P from 1 to {bound}; checked "
          "against the model. Run it with PyTorch alone: "
          f"torch.export.load({str(args.out)!r}).module()(history, agent_type)")  # fmt: skip
    return 0


def _export_scorer(args) -> int:
    """``export --scorer``: MODEL's diffusion score as an exported program
    (``score.export``)."""
    from trajpref.score.export import export_scorer, scorer_meta  # only this command's

    given = [flag for flag, value in (("--samples", args.samples), ("--max-speed", args.max_speed),
                                      ("--spread-scale", args.spread_scale),
                                      ("--max-log-sigma", args.max_log_sigma))
             if value is not None]  # fmt: skip
    if given:
        raise ConfigError(f"{', '.join(given)}: a generator's settings; --scorer exports the "
                          "score, which takes the samples as they come")  # fmt: skip
    every = 3 if args.score_every is None else args.score_every
    start = 0 if args.score_from is None else args.score_from
    for flag, value, least in (("--max-agents", args.max_agents, 1), ("--score-every", every, 1),
                               ("--score-from", start, 0)):  # fmt: skip
        if value < least:
            raise ConfigError(f"{flag} must be >= {least}, got {value}")
    given_radius, radius = _number_or_none(args, "neighbour_radius")
    scorer = TrajectoryScorer.from_checkpoint(args.model)
    if start >= scorer.schedule.num_steps:
        raise ConfigError(f"--score-from {start}: the scorer's steps are 0.."
                          f"{scorer.schedule.num_steps - 1}")  # fmt: skip
    steps = score_timesteps(scorer.schedule.num_steps, every, start)
    scorer = scorer.with_steps(steps)
    if given_radius:
        scorer.neighbour_radius = radius
    program = export_scorer(scorer, args.max_agents)
    meta = scorer_meta(scorer, program, args.model)
    model_export.save_exported(program, args.out, meta)
    units = f" in {scorer.units}" if scorer.units else ""
    print(f"wrote {args.out}: history [P, {scorer.t_hist}, 2]{units}, samples [K, P, "
          f"{scorer.t_fut}, 2] and agent_type [P] -> residuals [K, P, {scorer.t_fut}] at "
          f"{len(steps)} score steps, P from 1 to {meta['max_agents']}, K from 1 to "
          f"{meta['max_samples']}; checked against the scorer. Rank with PyTorch alone: "
          f"torch.export.load({str(args.out)!r}).module()(history, samples, agent_type)"
          ".sum(-1).sum(-1).argsort()")  # fmt: skip
    return 0


def cmd_models(args) -> int:
    """List the zoo (name, kind, method, test row, training machine and minutes), or print
    one model's card. Names work wherever a checkpoint path does (--model, --from, ...)."""
    if args.name is not None:
        zoo.resolve(args.name)  # an unknown name lists the published ones
        if args.json:
            print(json.dumps(zoo.entry(args.name)))
        else:
            print(zoo.card(args.name), end="")
        return 0
    rows = zoo.entries()
    print(json.dumps(rows) if args.json else zoo.table(rows))
    return 0


def cmd_compare(args) -> int:
    """Runs' validation side by side (``train/compare.py``): what each kept, each group's mean
    and spread over its runs and its change against the first group, and the curves."""
    groups: dict[str, list] = {}
    metrics = tuple(args.metrics) if args.metrics else compare.default_metrics(args.stage)
    for text in args.groups:
        name, runs = compare.parse_group(text)
        if name in groups:
            raise ConfigError(f"group {name!r} is given twice")
        groups[name] = [compare.read_curve(r, args.stage, metrics) for r in runs]
    shares = tuple(args.shares)
    if args.json:
        print(dumps_json({"stage": args.stage, "groups": compare.summarise(groups, metrics),
                          "curves": compare.curve_rows(groups, metrics, shares)}))  # fmt: skip
    else:
        print(compare.format_report(groups, metrics, shares))
    return 0


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"trajpref: warning: {message}", file=sys.stderr)


def _resume_state(args) -> tuple[Path | None, tuple[int, int] | None]:
    """A training command's ``<stage>_last.pt`` and its (inode, modification time); None when
    there is none yet. Each save is a new file renamed into place: a new inode."""
    if args.command not in ("train", "finetune"):
        return None, None
    state = last_state_path(args.out, args.stage if args.command == "train" else "finetune")
    with contextlib.suppress(OSError):
        return state, (state.stat().st_ino, state.stat().st_mtime_ns)
    return state, None


def _resume_hint(args, argv: list[str], before: tuple[int, int] | None) -> str:
    """After Ctrl-C: the command that continues a training run, or why there is none.
    ``before``: the resume state's identity when the command started."""
    state, now = _resume_state(args)
    if state is None:
        return ""
    if now is not None and now != before:  # written by this run: an epoch ended
        resume = str(state)
    elif args.resume is not None:
        resume = args.resume  # no epoch ended in this run: the state it started from
    else:
        return "; no epoch ended, so there is nothing to resume (run the command again)"
    # under torchrun, the launcher's own options (the same processes repeat the run's draws)
    info = env_info()
    launcher = launcher_command()
    if info.enabled:
        command = cli_resume_command(argv, resume, info.world_size, None,
                                     launcher or fallback_launcher(info))  # fmt: skip
        note = launcher_note(info, launcher is not None)
    else:
        command, note = cli_resume_command(argv, resume), ""
    return f"; to continue from the last finished epoch:\n  {command}{note}"


TRAINING = ("train", "finetune")
"""The commands that run under torchrun (each process a rank); the others run in one."""


def _open_bars() -> set:
    """The progress bars open now (none when tqdm was never imported)."""
    bars = sys.modules.get("tqdm.std")
    return set(getattr(bars.tqdm, "_instances", ())) if bars is not None else set()


def _close_bars(earlier: set) -> None:
    """Close the progress bars an exception left open (a bar over a loop, not a ``with``,
    is closed only when it is freed), but not those open before the command (``earlier``:
    an application's own, when it calls ``main`` in-process): on a terminal each clears its
    line, so that the message after it starts one (``io.bar_options``: where stderr is no
    terminal, bars write whole lines)."""
    for bar in _open_bars() - earlier:
        with contextlib.suppress(Exception):
            bar.close()


def _raise_terminated(signum, frame) -> None:
    """SIGTERM during training: ``Terminated`` (``train.loop``; a BaseException, as Ctrl-C's
    KeyboardInterrupt, so that neither an ``except Exception`` nor a finalizer drops it)."""
    raise Terminated


def _refuse_under_torchrun(args) -> str | None:
    """Why a command other than training does not run under torchrun (None when it may):
    each process would run the whole command, printing and writing its output N times."""
    if args.command in TRAINING or not env_info().enabled:
        return None
    return (
        f"trajpref {args.command} runs in one process; under torchrun each of the "
        f"{env_info().world_size} processes would run all of it and write its output: "
        f"run it without torchrun (trajpref {args.command} ...)"
    )


def main(argv: list[str] | None = None) -> int:
    """Run one command. Everything a user can get wrong ends in one line on stderr,
    ``trajpref: error: ...``, and exit status 2 (argparse's own usage errors included).

    Exit statuses: 0 success (a ``--resume`` with nothing left to train included: a note on
    stderr, so that a requeued job of a finished run succeeds), 2 an error of the input or
    the options (or a file that could not be read or written), 130 Ctrl-C (SIGINT), 143
    SIGTERM (both with the resume advice of a training run), 141 stdout closed early (a
    broken pipe, ``| head``); 1 is a bug (a Python traceback)."""
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        args.argv = argv  # the command as typed, which a result records (_command_line)
        if getattr(args, "command", None) == "train" and args.stage == "denoiser":
            args.stage = "diffusion"  # the stage's other name, as its files and compare call it
    except SystemExit as exc:  # --help, --version, or a usage error (already printed)
        return exc.code if isinstance(exc.code, int) else 2
    before = _resume_state(args)[1]
    main_rank = _is_main_process()  # under torchrun, rank 0 alone prints what all ranks share
    refused = _refuse_under_torchrun(args)
    if refused is not None:
        if main_rank:
            print(f"trajpref: error: {refused}", file=sys.stderr)
        return 2
    training = args.command in TRAINING
    # SIGTERM gets the advice Ctrl-C gets (the default would end silently); signal handlers
    # can only be set from the main thread
    on_term = training and threading.current_thread() is threading.main_thread()
    if on_term:
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
    bars_before = _open_bars()  # an application's own bars, which an error leaves open
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning  # restored when the command ends
            return args.func(args)
    except NothingLeftToTrain as exc:  # every rank alike: rank 0 says it
        if main_rank:
            print(f"trajpref: note: {exc}", file=sys.stderr)
        return 0
    except TrajprefError as exc:
        _close_bars(bars_before)
        # under torchrun each rank says what it met (one rank's own: a file missing on its
        # machine), prefixed with its rank; what every rank raises alike, rank 0 alone
        if main_rank:
            print(f"trajpref: error: {exc}", file=sys.stderr)
        elif not isinstance(exc, EveryRankError):
            print(f"trajpref: error: [rank {os.environ.get('RANK')}] {exc}", file=sys.stderr)
        return 2
    except Terminated:
        _close_bars(bars_before)
        if main_rank:
            print(f"trajpref: terminated (SIGTERM){_resume_hint(args, argv, before)}",
                  file=sys.stderr)  # fmt: skip
        return 143
    except RuntimeError:
        _close_bars(bars_before)
        # under torchrun, a rank that died (killed, out of memory) fails the others in their
        # next collective: say how to continue, then torch's own traceback
        if training and env_info().enabled and main_rank:
            print(f"trajpref: a process of this run failed{_resume_hint(args, argv, before)}",
                  file=sys.stderr)  # fmt: skip
        raise
    except BrokenPipeError:  # stdout closed early (`| head`): not an error of the command
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # a file the command could not read or write
        _close_bars(bars_before)
        where = f"{exc.filename}: " if exc.filename else ""
        rank = "" if main_rank else f"[rank {os.environ.get('RANK')}] "  # may be its own
        print(f"trajpref: error: {rank}{where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        _close_bars(bars_before)
        if main_rank:
            print(f"trajpref: interrupted{_resume_hint(args, argv, before)}", file=sys.stderr)
        return 130
    finally:
        if on_term:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
