"""Every exception and warning class of trajpref, importable from here (``from
trajpref.errors import ...``); the modules that raise or warn import them from here, and the
older names (``trajpref.evaluation.NotAPredictor``, ``trajpref.data.GapWarning``, ...) are the
same objects. The CLI turns a ``TrajprefError`` into a one-line message and a non-zero exit
status, and each warning into one ``trajpref: warning:`` line.

Errors: every class has ``TrajprefError`` as an ancestor, beside the built-in class a caller
would catch for the same mistake (``ValueError`` for a bad value, ``TypeError`` for an
argument of the wrong kind, ``FileNotFoundError`` for a named file, folder, model or dataset
that is not there). Warnings: every class is a ``TrajprefWarning`` (a ``UserWarning``), so
that ``warnings.filterwarnings("ignore", category=TrajprefWarning)`` selects all of them, and
the families below select a part; a warning's ``stacklevel`` mostly points at the caller's
line, so ``filterwarnings(module="trajpref")`` selects only some of them. This module
imports nothing of trajpref (the bottom layer of the import contracts)."""

from __future__ import annotations

from pathlib import Path

# --- errors -----------------------------------------------------------------------------------


class TrajprefError(Exception):
    """Base class for errors a user can fix (bad input, bad options)."""


class DataError(TrajprefError, ValueError):
    """Malformed or unusable input data. Names the file, and the line when there is one."""

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if path is not None:
            where = f"{path}:{line}: " if line is not None else f"{path}: "
        super().__init__(where + message)


class ConfigError(TrajprefError, ValueError):
    """An invalid configuration value."""


class RewardError(TrajprefError, ValueError):
    """A fine-tuning reward (``trajpref.rl.register_reward``) returned something other than a
    finite [M, N, T_f] tensor."""


class NotFound(TrajprefError, FileNotFoundError):
    """A named file, folder, model or dataset is not there. A ``FileNotFoundError`` too, so
    that ``except FileNotFoundError`` catches it; its ``errno`` and ``filename`` are None (the
    message names what is missing)."""


class ModelNotFound(NotFound):
    """No checkpoint file or published model by the name or path given (``load_predictor``,
    ``TrajectoryScorer.from_checkpoint``, ``models.checkpoint.load``), or a generator's
    denoiser or weights file that is not beside it."""


class DataNotFound(DataError, NotFound):
    """A dataset, data root, data file or folder (a split's sub-folder among them) that is not
    there, or a dataset name that is neither built in nor a path. A ``DataError`` (its
    ``path``), so ``except DataError`` still catches it, and a ``FileNotFoundError``."""


class ConfigNotFound(ConfigError, NotFound):
    """A named config file or study folder that is not there (a ``ConfigError``, as before,
    and a ``FileNotFoundError``)."""


class NotAPredictor(TrajprefError, TypeError):
    """What the evaluation loop was handed is not a loaded predictor (a model's name, a
    denoiser checkpoint's name). The base of ``NotADataset`` and ``NotAScorer``: catching it
    catches an argument of the wrong kind of any of the three, as it did when it was raised
    for all three."""


class NotADataset(NotAPredictor):
    """The evaluation loop's ``dataset`` is not a ``TrajectoryDataset`` (a dataset's name, a
    path). A ``NotAPredictor`` for compatibility: that class was raised for it before."""


class NotAScorer(NotAPredictor):
    """The evaluation loop's ``scorer`` is not a ``TrajectoryScorer`` (a checkpoint's name, a
    predictor). A ``NotAPredictor`` for compatibility: that class was raised for it before."""


class PredictionError(DataError):
    """A predictor's ``predict`` returned something the evaluation cannot score: not a torch
    tensor, not floating point, not [K, N, T_f, 2] for the batch and the K asked, on another
    device than the batch's, or holding NaN / infinite values (``check_prediction``)."""


class NonFinitePrediction(PredictionError):
    """A predictor returned NaN or infinite positions (``check_prediction``): a model that
    diverged, not a wrong interface; training's validation scores it as never the best."""


class DenoiserConflict(TrajprefError):
    """Publishing would replace a different denoiser that other checkpoints may name."""


class WeightsConflict(TrajprefError):
    """Publishing would replace the weights that settings-only variants beside it name."""


class NothingLeftToTrain(ConfigError):
    """A resume whose state has nothing left to train (its epochs done, or its time budget
    spent), found before anything is written. The CLI prints it as a note and exits with
    status 0, so that a job requeued after its run finished succeeds; from Python it is the
    ``ConfigError`` it always was."""


class EveryRankError(ConfigError):
    """A ``ConfigError`` that every rank of a launch raises alike: from what the ranks share
    (the launch's process count) or have compared with each other (``gather_objects``:
    ``train.run.check_same_run``). Rank 0 alone prints it (``cli.main``); a ``ConfigError`` of
    one rank's own (a file missing on its machine) is printed by that rank."""


class ResultConflict(TrajprefError):
    """Two rows of one measurement were taken on different checkpoints (``model_hash``): one
    of them is stale and must be measured again before the rows can be merged."""


class AnswerError(TrajprefError, ValueError):
    """An answer the survey store refuses; ``status`` is the HTTP status the server answers
    with (400 malformed, 403 consent not given, 404 unknown scene or panel, 409 conflict, 422
    invalid value)."""

    def __init__(self, message: str, status: int = 422):
        super().__init__(message)
        self.status = status


class StoreError(AnswerError):
    """The survey database could not take or give an answer (a disk error, a file locked for
    too long, the study folder deleted while serving): status 503. ``str()`` is for the rater
    (no path); ``log`` is the line for the researcher's log (with the database's path)."""

    def __init__(self, message: str, log: str):
        super().__init__(message, 503)
        self.log = log


# --- warnings ---------------------------------------------------------------------------------


class TrajprefWarning(UserWarning):
    """Base class of every warning trajpref issues (a ``UserWarning``)."""


class TrajprefDeprecationWarning(TrajprefWarning, FutureWarning):
    """A name, file or config key that still works but has a newer form (a legacy ``.pt``
    checkpoint, a renamed config key). A ``FutureWarning`` too, as these were before."""


class DataWarning(TrajprefWarning):
    """Something found in the data read that it reads anyway: a gap in a file's frames,
    frame rates that disagree, observation-only scenes, agents a tracker's cycle left out,
    units trajpref does not know."""


class GapWarning(DataWarning):
    """Some windows span frames missing from a file (a jump in its frame numbers)."""


class FrameRateWarning(DataWarning):
    """TrajNet++ scenes declare frame rates that disagree with each other or with the frame
    interval the user gave (``registry.trajnet_interval`` says which one is used), or the time
    columns of text files do not give one interval (``registry.text_interval``)."""


class ObservedOnlyWarning(DataWarning):
    """A TrajNet++ file holds both complete scenes and observation-only ones (their primary
    agent's observed frames alone, the future hidden: ``read_trajnet``). TrajNet++'s test files
    can (overlapping scenes show a scene's whole future); a complete file cut short can too."""


class LeftOutWarning(DataWarning):
    """``tracks_to_history`` left out agents that the tracker saw in its current cycle: their
    detections are stamped a little before ``now`` (per-detection timestamps a few ms apart
    within one cycle) or after it (a nominal cycle time as ``now``). The message suggests a
    ``hold=`` that keeps them; it names no agent, so that a planner's loop calling every cycle
    is warned once, not every call (Python shows a warning again only for a new text). The
    warning raised carries ``ages`` (each such agent's id -> the age in seconds at ``now`` of
    its latest stamp at or before it, in id order) and ``suggested_hold``; catch it with
    ``warnings.catch_warnings(record=True)`` to read them."""

    ages: dict
    """Each left-out agent seen in the current cycle: id -> age at ``now`` (s)."""
    suggested_hold: float
    """A ``hold=`` above the oldest of ``ages`` (1.25 times it, rounded up to 10 ms)."""


class OutOfRangeWarning(TrajprefWarning):
    """The input lies outside what the model or scorer was trained on: other units or time
    step, agents faster or jumping farther, scenes wider, agent-type flags other than its
    training data's. Its output there is an extrapolation."""


class OverlapWarning(TrajprefWarning):
    """The windows evaluated are ones the model trained on or chose its epoch on (its own
    training folder, split or files), so its numbers there are not a test's."""


class IgnoredWarning(TrajprefWarning):
    """An argument, option or input given changes nothing here (a dataset's own frame
    interval and units, context rows a model does not read, a config file's settings that the
    method does not read)."""
