"""Every exception and warning class of trajpref is importable from ``trajpref.errors`` and
can be caught or filtered by class (library-hygiene walkthrough 69): every error has
``TrajprefError`` as an ancestor, a missing file, folder, model or dataset is a
``FileNotFoundError`` too, and the classes defined in other modules before are the same
objects there."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

import trajpref.errors as errors
from trajpref.errors import (
    ConfigError,
    ConfigNotFound,
    DataError,
    DataNotFound,
    ModelNotFound,
    NotADataset,
    NotAPredictor,
    NotAScorer,
    NotFound,
    TrajprefError,
    TrajprefWarning,
)

ERRORS = [c for c in vars(errors).values()
          if inspect.isclass(c) and issubclass(c, BaseException)
          and not issubclass(c, Warning)]  # fmt: skip
WARNINGS = [c for c in vars(errors).values() if inspect.isclass(c) and issubclass(c, Warning)]

MOVED = [
    ("trajpref.evaluation", "NotAPredictor"),
    ("trajpref.evaluation", "PredictionError"),
    ("trajpref.evaluation", "NonFinitePrediction"),
    ("trajpref.models.checkpoint", "DenoiserConflict"),
    ("trajpref.models.checkpoint", "WeightsConflict"),
    ("trajpref.results", "ResultConflict"),
    ("trajpref.survey.store", "AnswerError"),
    ("trajpref.survey.store", "StoreError"),
    ("trajpref.data", "FrameRateWarning"),
    ("trajpref.data", "GapWarning"),
    ("trajpref.data", "LeftOutWarning"),
    ("trajpref.data.trajnet", "FrameRateWarning"),
    ("trajpref.data.trajnet", "ObservedOnlyWarning"),
    ("trajpref.data.text", "GapWarning"),
    ("trajpref.data.tracker", "LeftOutWarning"),
    ("trajpref.train.run", "NothingLeftToTrain"),
    ("trajpref.train.distributed", "EveryRankError"),
]


def test_every_error_is_a_trajpref_error_and_every_warning_a_trajpref_warning():
    assert len(ERRORS) >= 18 and len(WARNINGS) >= 10
    for cls in ERRORS:
        assert issubclass(cls, TrajprefError), cls
    for cls in WARNINGS:
        assert issubclass(cls, TrajprefWarning) and issubclass(cls, UserWarning), cls


@pytest.mark.parametrize(("module", "name"), MOVED)
def test_a_moved_class_is_the_same_object_in_errors_and_its_old_module(module, name):
    assert getattr(importlib.import_module(module), name) is getattr(errors, name)


def test_the_moved_classes_keep_their_bases():
    assert issubclass(errors.NotAPredictor, TypeError)
    assert issubclass(errors.PredictionError, DataError)
    assert issubclass(errors.NonFinitePrediction, errors.PredictionError)
    assert issubclass(errors.AnswerError, ValueError)
    assert issubclass(errors.StoreError, errors.AnswerError)
    assert errors.StoreError("for the rater", "for the log").status == 503
    for cls in (errors.DenoiserConflict, errors.WeightsConflict, errors.ResultConflict):
        assert issubclass(cls, TrajprefError)
    for cls in (errors.FrameRateWarning, errors.ObservedOnlyWarning, errors.GapWarning,
                errors.LeftOutWarning):  # fmt: skip
        assert issubclass(cls, errors.DataWarning)
    assert issubclass(errors.TrajprefDeprecationWarning, FutureWarning)


def test_errors_imports_nothing_of_trajpref():
    tree = ast.parse(Path(errors.__file__).read_text())
    names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert not [n for n in names if n.startswith("trajpref")], names


def test_not_found_is_a_file_not_found_error_with_its_message():
    exc = DataNotFound("no such folder", "/nowhere")
    assert isinstance(exc, FileNotFoundError) and isinstance(exc, DataError)
    assert str(exc) == "/nowhere: no such folder" and exc.path == "/nowhere"
    assert str(ModelNotFound("x: no such checkpoint")) == "x: no such checkpoint"
    assert issubclass(ConfigNotFound, ConfigError) and issubclass(ConfigNotFound, NotFound)


# --- where each is raised --------------------------------------------------------------------


def _both(exc_info, cls=NotFound) -> None:
    assert isinstance(exc_info.value, cls)
    assert isinstance(exc_info.value, TrajprefError)
    assert isinstance(exc_info.value, FileNotFoundError)


def test_a_missing_model_file_is_model_not_found(tmp_path):
    from trajpref.models import checkpoint
    from trajpref.models.registry import load_predictor
    from trajpref.score import TrajectoryScorer

    missing = tmp_path / "nope.safetensors"
    for call in (lambda: load_predictor(str(missing)), lambda: checkpoint.load(missing),
                 lambda: TrajectoryScorer.from_checkpoint(str(missing)),
                 lambda: load_predictor("zara1/no-such-model")):  # fmt: skip
        with pytest.raises(FileNotFoundError) as caught:
            call()
        _both(caught, ModelNotFound)
    with pytest.raises(ModelNotFound, match=r"nope\.safetensors: no such checkpoint"):
        checkpoint.resolve_path(missing)


def test_a_generator_without_the_denoiser_it_names_is_model_not_found(tmp_path):
    from trajpref.models import checkpoint, zoo

    published = zoo.resolve("zara1/generator")
    copy = tmp_path / "zara1" / "generator.safetensors"  # its denoiser is not beside it
    copy.parent.mkdir()
    copy.write_bytes(published.read_bytes())
    if "denoiser_ref" not in checkpoint.load(published):
        pytest.skip("zara1/generator embeds its denoiser")
    with pytest.raises(ModelNotFound, match="names its denoiser instead of embedding it"):
        checkpoint.load(copy)


def test_missing_data_is_data_not_found(tmp_path, monkeypatch):
    from trajpref.data import load_dataset, resolve_data_root
    from trajpref.data.arrays import load_npz
    from trajpref.data.text import read_folder, track_files

    calls = [
        lambda: load_dataset(str(tmp_path / "none"), "test"),  # a folder path
        lambda: load_dataset("zara9", "test"),  # neither built in nor a path
        lambda: resolve_data_root(tmp_path / "no-root"),
        lambda: load_dataset("zara1", "test", root=tmp_path),  # the root without eth_ucy/
        lambda: track_files(tmp_path / "none"),
        lambda: read_folder(tmp_path / "none", 8, 12),
        lambda: load_npz(tmp_path / "none.npz", ("a",)),
    ]
    for call in calls:
        with pytest.raises(FileNotFoundError) as caught:
            call()
        _both(caught, DataNotFound)
        assert isinstance(caught.value, DataError)  # as it was: except DataError catches it
    # a split folder the user folder lacks
    (tmp_path / "mine" / "train").mkdir(parents=True)
    with pytest.raises(DataNotFound, match="no test/ sub-folder"):
        load_dataset(str(tmp_path / "mine"), "test")
    # a broken link is missing; a symlink loop and a file in a folder's place are not
    (tmp_path / "gone").symlink_to(tmp_path / "nowhere")
    with pytest.raises(DataNotFound, match="broken symlink"):
        track_files(tmp_path / "gone")
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(DataError, match="symlink loop") as caught:
        track_files(tmp_path / "loop")
    assert not isinstance(caught.value, FileNotFoundError)
    (tmp_path / "file").write_text("")
    with pytest.raises(DataError, match="data root is not a folder") as caught:
        resolve_data_root(tmp_path / "file")
    assert not isinstance(caught.value, FileNotFoundError)


def test_a_missing_folder_says_no_such_folder_not_cannot_read():
    from trajpref.data.text import track_files

    # DataNotFound is an OSError: track_files' own handler of a folder it cannot search
    # must not turn it into "cannot read folder"
    with pytest.raises(DataNotFound, match=r"/no/such/place: no such folder$"):
        track_files(Path("/no/such/place"))


def test_a_bad_split_protocol_or_root_setting_is_a_config_error(monkeypatch, tmp_path):
    from trajpref.data import load_dataset, resolve_data_root
    from trajpref.data.registry import check_protocol

    with pytest.raises(ConfigError, match="unknown split 'testing'"):
        load_dataset("zara1", "testing")
    with pytest.raises(ConfigError, match="unknown protocol"):
        check_protocol("nope")
    monkeypatch.delenv("TRAJPREF_DATA", raising=False)
    with pytest.raises(ConfigError, match="no data root"):
        resolve_data_root(None)
    with pytest.raises(ConfigError, match="no public training split"):
        load_dataset("robo", "train", root=tmp_path)


def test_a_missing_config_file_or_study_folder_is_config_not_found(tmp_path):
    from trajpref.config import resolve_config
    from trajpref.survey.manifest import load_study

    with pytest.raises(ConfigNotFound, match="no such config file"):
        resolve_config(tmp_path / "nope.yaml")
    with pytest.raises(ConfigNotFound, match="no such study folder"):
        load_study(tmp_path / "nope")


def test_a_wrong_dataset_or_scorer_argument_has_its_own_class():
    from trajpref.evaluation import check_inputs, check_scorer
    from trajpref.models.baseline import ConstantVelocity

    with pytest.raises(NotADataset, match="load it first, trajpref.data.load_dataset") as caught:
        check_inputs(ConstantVelocity(), "zara1")
    assert isinstance(caught.value, NotAPredictor) and isinstance(caught.value, TypeError)
    with pytest.raises(NotAScorer, match="got the name 'zara1/denoiser'") as caught:
        check_scorer("zara1/denoiser")
    assert isinstance(caught.value, NotAPredictor)
    with pytest.raises(NotAPredictor, match="model must be a predictor") as caught:
        check_inputs("zara1/generator", "zara1")
    assert type(caught.value) is NotAPredictor


def test_a_checkpoint_path_that_is_not_there_is_model_not_found(tmp_path):
    from trajpref.io import read_checkpoint_header

    with pytest.raises(errors.ModelNotFound, match="no such checkpoint file"):
        read_checkpoint_header(tmp_path / "gone.safetensors")
    with pytest.raises(FileNotFoundError):
        read_checkpoint_header(tmp_path / "gone.safetensors")


def test_a_published_models_repository_path_outside_the_repository_is_model_not_found(
    tmp_path, monkeypatch
):
    from trajpref.cli import _check_checkpoint

    monkeypatch.chdir(tmp_path)  # outside the repository: the path is no file here
    with pytest.raises(errors.ModelNotFound, match="zara1/generator"):
        _check_checkpoint("--model", "models/zara1/generator.safetensors")


def test_a_checkpoint_write_that_fails_in_safetensors_names_the_file(tmp_path, monkeypatch):
    """A full disk reaches ``save_file`` as a ``SafetensorError`` (no ``OSError``, no file
    name): one line naming the checkpoint, and nothing left behind."""
    from safetensors import SafetensorError

    from trajpref.models import checkpoint

    def full(*args, **kwargs):
        raise SafetensorError("Error while serializing: I/O error: No space left on device")

    monkeypatch.setattr(checkpoint, "save_file", full)
    out = tmp_path / "model.safetensors"
    payload = {"kind": "denoiser", "config": {}, "state_dict": {}}
    with pytest.raises(TrajprefError, match=r"model\.safetensors: cannot write the checkpoint "
                       r"\(.*No space left on device; [\d,]+ MB free there\)"):  # fmt: skip
        checkpoint.save(out, payload)
    assert list(tmp_path.iterdir()) == []


def test_a_folder_given_as_a_model_is_a_config_error_not_not_found(tmp_path):
    """A folder is there, only not a model: no ``NotFound`` (a ``FileNotFoundError``), which
    a host's "if missing, fetch it" handler would take for a model to download."""
    from trajpref.models.registry import load_predictor

    with pytest.raises(ConfigError, match="a folder, not a checkpoint file") as caught:
        load_predictor(str(tmp_path))
    assert not isinstance(caught.value, FileNotFoundError)
