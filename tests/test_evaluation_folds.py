"""``trajpref.evaluation.evaluate`` refuses, as the CLI's ``evaluate`` does, a model (or
scorer) of one ETH/UCY fold on another fold's data: its leave-one-out training files hold most
of that fold's windows. ``allow_overlap=True`` evaluates it anyway."""

from __future__ import annotations

import pytest
from synthetic import make_scene, straight_rows, write_tracks

from trajpref.errors import ConfigError
from trajpref.evaluation import evaluate
from trajpref.models.baseline import ConstantVelocity
from trajpref.score.selection import SelectingPredictor, SelectionConfig
from trajpref.types import DatasetInfo, TrajectoryDataset


def _data(name: str) -> TrajectoryDataset:
    info = DatasetInfo(name, "test", "m", 0.4, interval_from="dataset")
    return TrajectoryDataset([make_scene(2, seed=i) for i in range(2)], info)


def _trained_on(fold: str | None) -> ConstantVelocity:
    """A predictor carrying a checkpoint's record (``models.timing.attach_timing``)."""
    model = ConstantVelocity()
    model.timing = None if fold is None else {"trained_on": fold}
    return model


def _run(model, data, **kwargs) -> dict:
    return evaluate(model, data, 2, progress=False, collision_radius=None, **kwargs)


def test_another_folds_model_is_refused_unless_allowed():
    with pytest.raises(ConfigError, match=r"evaluate on zara1: the model was trained on the zara2 "
                       r"fold, whose leave-one-out training files \(the other four scenes'\) "
                       r"hold most of zara1's windows, .*allow_overlap=True"):  # fmt: skip
        _run(_trained_on("zara2"), _data("zara1"))
    assert _run(_trained_on("zara2"), _data("zara1"), allow_overlap=True)["agents"] == 4
    # its own fold, other data, and models without a record pass
    for model, data in ((_trained_on("zara1"), "zara1"), (_trained_on("zara2"), "sdd"),
                        (_trained_on(None), "zara1"), (ConstantVelocity(), "eth")):  # fmt: skip
        assert _run(model, _data(data))["agents"] == 4


def test_a_folder_of_another_folds_sgan_test_files_counts_as_that_fold(tmp_path):
    write_tracks(tmp_path / "mine" / "test" / "crowds_zara01.txt", straight_rows(24))
    with pytest.raises(ConfigError, match=r"it holds zara1's Social-GAN test files\): the model "
                       r"was trained on the zara2 fold"):  # fmt: skip
        _run(_trained_on("zara2"), _data(str(tmp_path / "mine")))
    assert _run(_trained_on("zara1"), _data(str(tmp_path / "mine")))["agents"] == 4


def test_a_selecting_predictors_base_and_a_scorer_are_checked_too():
    selecting = SelectingPredictor(_trained_on("eth"), SelectionConfig(keep=1, method="first"), 2)
    with pytest.raises(ConfigError, match="the model was trained on the eth fold"):
        evaluate(selecting, _data("hotel"), 1, progress=False, collision_radius=None)
    scorer = _trained_on("univ")  # only its record is read before the refusal
    with pytest.raises(ConfigError, match="the scorer was trained on the univ fold"):
        _run(ConstantVelocity(), _data("hotel"), scorer=scorer)


def test_a_loaded_published_model_carries_its_fold():
    from trajpref.models.registry import load_predictor

    model = load_predictor("zara2/generator")
    with pytest.raises(ConfigError, match="trained on the zara2 fold"):
        _run(model, _data("zara1"))
