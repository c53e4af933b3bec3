"""trajpref: human trajectory prediction with a diffusion model refined by RL from a
quantified human preference (the diffusion score).

Entry points (the README's "Python API"; each subpackage is imported on first use, so that
``import trajpref`` stays light and ``trajpref.evaluation.evaluate(...)`` works after it):

    from trajpref.models.registry import load_predictor  # a published name, a file, "cv"
    from trajpref.score import predict_scene, predict_scenes  # a scene's histories -> futures
    from trajpref.score import TrajectoryScorer, rank_samples  # the diffusion score, ranking
    from trajpref.score.selection import chosen_selection, select_for_scene  # keep K' of K
    from trajpref.data import load_dataset, tracks_to_history  # datasets; a tracker's rows
    from trajpref.evaluation import evaluate, predict_dataset  # the evaluation pass
    from trajpref.config import load_config  # experiment configs: YAML plus key=value
    from trajpref.train import train_stage, finetune  # the training stages
    from trajpref.rl import register_reward  # a reward of one's own for fine-tuning
    from trajpref.rl.presets import finetune_config  # a fine-tuning config from a start
    from trajpref.viz import plot_scene, plot_scene_scored  # figures
    from trajpref.errors import TrajprefError, ConfigError, DataError  # what a user can fix

The command line is ``trajpref`` (``trajpref.cli``; ``trajpref --help``).

Shape vocabulary used in comments throughout the package:
    B scenes, P agents (per scene), N agents packed across a batch, K samples,
    T time (T_h history, T_f future), D = 2 coordinates.
"""

import os as _os

from trajpref.errors import TrajprefError

# PyTorch runs bfloat16 matrix products on the CPU through oneDNN, which builds (JIT-compiles)
# a kernel for every new shape and keeps the last 1,024 of them. Our batches pack a varying
# number of agents, so a training run meets thousands of shapes and, with the default, keeps
# rebuilding kernels it has built before: with a larger cache, bf16 generator steps ran 1.55x
# (hotel), 1.29x (zara1) and 1.05x (eth) faster on a 2-core CPU (docs/pretraining.md,
# "oneDNN's kernel cache"). It has to be set before the process's first oneDNN product; a
# value the user set is kept.
ONEDNN_CACHE_CAPACITY = 16384
_os.environ.setdefault("ONEDNN_PRIMITIVE_CACHE_CAPACITY", str(ONEDNN_CACHE_CAPACITY))

__version__ = "0.1.0"

SUBPACKAGES = ("adapt", "config", "data", "device", "diffusion", "errors", "evaluation", "io",
               "metrics", "models", "results", "rl", "score", "survey", "train", "types",
               "viz")  # fmt: skip
"""The library's modules and packages, read as attributes of ``trajpref`` on first use
(``__getattr__``) and listed by ``dir(trajpref)`` (but ``UNLISTED``); a test checks that they
are every module under ``trajpref`` but the entry points (``ENTRY_MODULES``) and
``__main__``."""
ENTRY_MODULES = ("cli", "demo")
"""The command line and ``make demo``: read as attributes too."""
UNLISTED = ("cli", "demo", "survey", "viz")
"""Read as attributes but left out of ``dir(trajpref)`` until they are imported:
``help(trajpref)`` and ``inspect.getmembers(trajpref)`` read every name that ``dir`` lists,
and would load matplotlib (``viz``, ``demo``) and the whole command line (``cli``) for it:
1,393 modules with them, 1,203 (torch, no matplotlib) without, 62 for ``import trajpref``.
``survey`` loads nothing itself, but it is the study tool's, with its own command line."""

__all__ = ["ONEDNN_CACHE_CAPACITY", "TrajprefError", "__version__"]
"""What ``from trajpref import *`` gives: the names defined here, no subpackage (a star import
would otherwise load every one, ``viz`` and matplotlib among them)."""


def __getattr__(name: str):
    """``trajpref.<subpackage>`` imported on first use (PEP 562): ``import trajpref`` loads
    none of them, and ``trajpref.evaluation.evaluate(...)`` works after it."""
    if name in SUBPACKAGES or name in ENTRY_MODULES:
        import importlib  # here, not at the top: the plain import stays as light as before

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    """The names defined here, the modules imported so far (an import sets its module as an
    attribute here) and the others but ``UNLISTED``."""
    lazy = (set(SUBPACKAGES) | set(ENTRY_MODULES)) - set(UNLISTED)
    return sorted(set(globals()) | lazy)
