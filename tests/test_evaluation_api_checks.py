"""Walkthrough 66, the Python API: ``evaluate`` and ``predict_dataset`` check what the CLI
checks before evaluating (the data's step and units against the model's training, the observed
pace, a split the model trained on, recorded as ``overlap``), and refuse in one line what they
cannot take (a seed or count that is not an integer, a model on another device, a scorer's
name, text for a radius, numpy bins and slots are taken)."""

from __future__ import annotations

import json
import warnings
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest
import torch
from synthetic import make_scene

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.errors import ConfigError, DataError
from trajpref.evaluation import NotAPredictor, evaluate, predict_dataset, sampled_batches
from trajpref.metrics import check_bin_edges, slot_labels
from trajpref.models.baseline import ConstantVelocity
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import TrajectoryScorer
from trajpref.types import DatasetInfo, TrajectoryDataset

ZARA1 = "the model was trained on the zara1 fold (leave-one-out: the other four scenes)"
WHO = " [the model: zara1/generator]"
"""What ends every warning of zara1/generator's checks in Python (``model_identity``: the name
``load_predictor`` was given)."""


def _logged(root: Path, scale: float = 1.0) -> Path:
    """A robot's 10 Hz log, ``time,id,x,y`` in seconds: three walkers at 1.2 m/s along x,
    their positions times ``scale`` (100: centimetres)."""
    rows = []
    for k in range(100):
        t = Decimal("3.0") + k * Decimal("0.1")
        rows += [f"{t},{a},{(0.12 * k + a) * scale:.3f},{0.5 * a * scale:.3f}" for a in (1, 2, 3)]
    (root / "test").mkdir(parents=True)
    (root / "test" / "log.csv").write_text("time,id,x,y\n" + "\n".join(rows) + "\n")
    return root


def _messages(call, *args, **kwargs) -> tuple[list[str], object]:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        out = call(*args, **kwargs)
    return [str(w.message) for w in seen if issubclass(w.category, UserWarning)], out


def _data(name: str, split: str = "test", scenes: int = 2) -> TrajectoryDataset:
    info = DatasetInfo(name, split, "m", 0.4, interval_from="dataset")
    return TrajectoryDataset([make_scene(2, seed=i) for i in range(scenes)], info)


def _recorded(timing: dict) -> ConstantVelocity:
    """A predictor carrying a checkpoint's record (``models.timing.attach_timing``)."""
    model = ConstantVelocity()
    model.timing = timing
    return model


# ------------------------------------------------------------- 1: the checks the CLI makes


def test_data_at_another_step_than_the_models_warn_in_evaluate_and_predict_dataset(
    tmp_path, zara1
):  # fmt: skip
    data = load_dataset(str(_logged(tmp_path / "log")), "test")  # 0.1 s from the time column
    assert data.info.frame_interval == pytest.approx(0.1)
    pace = ("this data steps 0.1 s, the model's 0.4 s (options=ReadOptions(time_step=4) reads "
            "it at the model's step)")  # fmt: skip
    for call in (evaluate, predict_dataset):
        messages, _ = _messages(call, zara1, data, progress=False)
        assert f"{ZARA1}: {pace}{WHO}" in messages, call.__name__
    # the advice read as given: 0.4 s windows say nothing of the step
    data = load_dataset(str(tmp_path / "log"), "test", units="m",
                        options=_every(4))  # fmt: skip
    messages, res = _messages(evaluate, zara1, data, progress=False)
    assert messages == [] and res["overlap"] is None


def _every(n: int):
    from trajpref.data import ReadOptions

    return ReadOptions(time_step=n)


def test_data_in_other_units_warn_of_units_and_pace(tmp_path, zara1):
    data = load_dataset(str(_logged(tmp_path / "cm", 100.0)), "test", units="cm",
                        options=_every(4))  # fmt: skip
    messages, _ = _messages(evaluate, zara1, data, progress=False)
    assert (
        f"{ZARA1}: this data is in cm, the model's in m (units are named, not converted: "
        f"multiply x and y by 0.01 to give m before reading them, and the futures, in m, "
        f"by 100 for cm){WHO}"
    ) in messages
    assert any(m.startswith("the model is given agents much faster than it was trained on")
               and m.endswith(WHO) for m in messages)  # fmt: skip
    messages, _ = _messages(predict_dataset, zara1, data, progress=False)
    assert len(messages) == 2


def test_the_models_own_training_split_warns_and_is_recorded(data_root, zara1):
    train = load_dataset("zara1", "train").evenly_spaced(3)
    messages, res = _messages(evaluate, zara1, train, progress=False)
    assert messages == [
        f"the model trained on these windows: {train.info.source} is the train split of "
        "zara1, its training data, so numbers on it are training numbers, not a test (evaluate "
        f"on the test split, or on files it did not train on){WHO}"
    ]
    assert res["overlap"] == "model trained on these windows (train split of zara1)"
    # its test split: nothing to say, nothing overlaps
    messages, res = _messages(evaluate, zara1, load_dataset("zara1", "test").evenly_spaced(3),
                              progress=False)  # fmt: skip
    assert messages == [] and res["overlap"] is None
    # check_data=False (the CLI, which has checked): no warning, no key
    messages, res = _messages(evaluate, zara1, train, progress=False, check_data=False)
    assert messages == [] and "overlap" not in res
    messages, _ = _messages(predict_dataset, zara1, train, progress=False, check_data=False)
    assert messages == []


def test_the_cli_warns_once_and_records_what_python_records(capsys, data_root):
    code = main(["evaluate", "--dataset", "zara1", "--split", "train", "--model",
                 "zara1/generator", "--max-scenes", "3", "--no-progress", "--json"])  # fmt: skip
    out, err = capsys.readouterr()
    warned = [line for line in err.splitlines() if line.startswith("trajpref: warning:")]
    assert code == 0 and len(warned) == 1
    assert warned[0].startswith("trajpref: warning: zara1/generator trained on these windows: ")
    assert json.loads(out)["overlap"] == "model trained on these windows (train split of zara1)"


def test_another_folds_model_allowed_is_recorded_as_the_cli_records_it():
    model = _recorded({"trained_on": "zara2"})
    res = evaluate(model, _data("zara1"), 2, progress=False, allow_overlap=True)
    assert res["overlap"] == "zara2 model on zara1"


def test_a_validation_split_is_named_where_the_record_says_where_the_epoch_was_chosen():
    run = {"num_samples": 2, "progress": False, "collision_radius": None}
    # the record says: it chose its epoch on Robo's val split, not robo-sim's
    model = _recorded({"trained_on": "robo-sim", "val_dataset": "robo"})
    messages, res = _messages(evaluate, model, _data("robo", "val"), **run)
    assert res["overlap"] == "model chose its epoch on these windows (robo's val split)"
    assert len(messages) == 1 and "chose its epoch on these windows" in messages[0]
    assert evaluate(model, _data("robo-sim", "val"), **run)["overlap"] is None
    # no word of it (models.timing records no val_dataset today): not named, never wrongly
    model = _recorded({"trained_on": "robo-sim"})
    assert _messages(evaluate, model, _data("robo-sim", "val"), **run)[0] == []
    messages, res = _messages(evaluate, model, _data("robo-sim", "train"), **run)
    assert res["overlap"] == "model trained on these windows (train split of robo-sim)"
    assert messages == ["the model trained on these windows: this data is the train split of "
                        "robo-sim, its training data, so numbers on it are training numbers, "
                        "not a test (evaluate on the test split, or on files it did not train "
                        "on) [the model: a checkpoint trained on robo-sim]"]  # fmt: skip


def _lineage(*stages: str, dataset: str = "robo-sim") -> list[dict]:
    return [{"stage": st, "dataset": dataset, "val_dataset": None, "holdout_scene": None}
            for st in stages]  # fmt: skip


def test_a_loop_over_models_is_warned_of_each_model(capsys):
    """Review of walkthrough 66: the texts named every model "the model", so Python's default
    filter (a text once per line that issues it) showed the first model's warning alone when
    one line evaluated several models on a split they trained on. Each text now ends with
    which model it is about: the checkpoint where the object names one, else its stage and
    training data from its record."""
    run = {"num_samples": 2, "progress": False, "collision_radius": None}
    data = _data("robo-sim", "train")
    generator = _recorded({"trained_on": "robo-sim",
                           "lineage": _lineage("denoiser", "generator")})  # fmt: skip
    tuned = _recorded({"trained_on": "robo-sim",
                       "lineage": _lineage("denoiser", "generator", "finetune")})  # fmt: skip
    named = _recorded({"trained_on": "robo-sim", "lineage": _lineage("generator")})
    named.checkpoint = "runs/robo-rlhf/finetune.safetensors"
    held = _recorded({"trained_on": "robo-sim", "holdout_scene": "sim_07",
                      "val_dataset": "robo"})  # fmt: skip
    with warnings.catch_warnings(record=True) as seen:
        warnings.resetwarnings()
        warnings.simplefilter("default")  # Python's own: once per text and line
        for model in (generator, tuned, named, generator, tuned):
            res = evaluate(model, data, **run)  # one line for every model
            assert res["overlap"] == "model trained on these windows (train split of robo-sim)"
    said = [str(w.message) for w in seen if issubclass(w.category, UserWarning)]
    tail = [m.rsplit(" [", 1)[1] for m in said]
    assert tail == ["the model: a generator trained on robo-sim]",
                    "the model: a fine-tune trained on robo-sim]",
                    "the model: runs/robo-rlhf/finetune.safetensors]"]  # fmt: skip
    assert all(m.startswith("the model trained on these windows: this data is the train split")
               for m in said)  # fmt: skip
    assert {w.filename for w in seen} == {__file__}  # at the user's line
    # what else a record says: its held-out scene and where it chose its epoch
    messages, _ = _messages(evaluate, held, _data("robo-sim", "train"), **run)
    assert all(
        m.endswith(
            "[the model: a checkpoint trained on robo-sim, held-out scene "
            "sim_07*, its epoch chosen on robo's val split]"
        )
        for m in messages
    )
    # the CLI's texts name the model by its --model, as before: no label
    assert "[" not in capsys.readouterr().err


# ------------------------------------------------------------------------- 2: the seed


@pytest.mark.parametrize("seed", [None, 1.0, 2**70, True, "1"])
def test_a_seed_that_is_not_an_integer_is_one_line(seed):
    model, data = ConstantVelocity(), _data("zara1")
    for call in (evaluate, predict_dataset):
        with pytest.raises(ConfigError, match=r"^seed must be an integer .*got "):
            call(model, data, 2, seed=seed, progress=False)
    with pytest.raises(ConfigError, match=r"^seed must be an integer"):
        next(sampled_batches(model, data, 2, seed=seed, progress=False))


def test_numpy_integers_count_as_seeds_and_sample_counts():
    model, data = ConstantVelocity(), _data("zara1")
    plain = evaluate(model, data, 3, seed=1, progress=False)
    assert evaluate(model, data, np.int64(3), seed=np.int64(1), progress=False) == plain
    arrays = predict_dataset(model, data, np.int32(3), seed=np.int64(1), progress=False)
    assert arrays["pred"].shape[0] == 3
    with pytest.raises(ConfigError, match=r"^num_samples must be an integer >= 1, got 20\.0$"):
        evaluate(model, data, 20.0, progress=False)
    with pytest.raises(ConfigError, match=r"^num_samples must be an integer >= 1, got 0$"):
        predict_dataset(model, data, 0, progress=False)


# ----------------------------------------------------------------------- 3: the device


def test_a_model_on_another_device_is_one_line_before_any_work(zara1):
    data = _data("zara1")
    model = load_predictor("zara1/generator").to("meta")
    for call in (evaluate, predict_dataset):
        with pytest.raises(ConfigError, match=r"the model's weights are on meta, where it "
                           r"cannot run .*model\.to\('cpu'\)"):  # fmt: skip
            call(model, data, progress=False)
        with pytest.raises(ConfigError, match=r"\(device='cpu'\): the model's weights are on "
                           r"meta: move it first, model\.to\('cpu'\)"):  # fmt: skip
            call(model, data, device="cpu", progress=False)
    # a scorer elsewhere than the batches
    scorer = TrajectoryScorer(zara1.denoiser, zara1.schedule, zara1.scale)
    scorer.denoiser = load_predictor("zara1/generator").to("meta").denoiser
    with pytest.raises(ConfigError, match=r"the scorer's weights are on meta and the batches go "
                       r"to cpu"):  # fmt: skip
        evaluate(zara1, data, progress=False, scorer=scorer)


def test_the_default_device_is_the_models_own(zara1, monkeypatch):
    from types import SimpleNamespace

    from trajpref.evaluation import pass_device

    data = _data("zara1")
    assert evaluate(zara1, data, progress=False) == evaluate(zara1, data, device="cpu",
                                                             progress=False)  # fmt: skip
    assert evaluate(ConstantVelocity(), data, 2, progress=False)["agents"] == 4
    # on this CPU machine the CPU is every model's device: pretend to have two GPUs, and a
    # model (or, for a model without weights, the scorer) on the second one
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    second = torch.device("cuda:1")
    on_second = ConstantVelocity()
    on_second.device = second
    assert pass_device(on_second, None) == second
    assert pass_device(ConstantVelocity(), None, SimpleNamespace(device="cuda:1")) == second
    assert pass_device(ConstantVelocity(), None) == torch.device("cpu")  # no weights anywhere


# ------------------------------------------------------------ 4: the other arguments


class _Counting(ConstantVelocity):
    calls = 0

    def predict(self, batch, num_samples, generator=None):
        type(self).calls += 1
        return super().predict(batch, num_samples, generator)


def test_a_scorers_name_is_refused_before_any_work():
    model, data = _Counting(), _data("zara1")
    with pytest.raises(NotAPredictor, match=r"scorer must be a TrajectoryScorer, got the name "
                       r"'zara1/denoiser': build it first, TrajectoryScorer\.from_checkpoint\("
                       r"'zara1/denoiser'\)"):  # fmt: skip
        evaluate(model, data, 2, progress=False, scorer="zara1/denoiser")
    with pytest.raises(TypeError, match=r"from_checkpoint"):
        predict_dataset(model, data, 2, progress=False, scorer=Path("zara1/denoiser"))
    with pytest.raises(TypeError, match=r"got a predictor \(ConstantVelocity\)"):
        evaluate(model, data, 2, progress=False, scorer=ConstantVelocity())
    assert _Counting.calls == 0


def test_a_radius_given_as_text_is_one_line():
    with pytest.raises(ConfigError, match=r"^the collision radius must be a finite number > 0, "
                       r"got '0\.1'$"):  # fmt: skip
        evaluate(ConstantVelocity(), _data("zara1"), 2, progress=False, collision_radius="0.1")
    res = evaluate(ConstantVelocity(), _data("zara1"), 2, progress=False,
                   collision_radius=np.float32(0.1))  # fmt: skip
    assert res["col_radius"] == pytest.approx(0.1)


def test_numpy_bins_and_slots_are_taken():
    model, data = ConstantVelocity(), _data("zara1", scenes=3)
    plain = evaluate(model, data, 2, progress=False, bins=(1, 3, 8), slots=3)
    res = evaluate(model, data, 2, progress=False, bins=np.array([1, 3, 8]), slots=np.int64(3))
    assert res == plain and list(res["slots"]) == ["1", "2", "3", ">3"]
    assert list(res["bins"]) == ["<=1", "2-3", "4-8", ">8"]
    for bins in ((1.0, 3), (True, 3), np.array([1.5, 3.0]), 3, "138"):
        with pytest.raises(ConfigError, match=r"^bin edges must be strictly increasing integers "
                           r">= 1, got "):  # fmt: skip
            evaluate(model, data, 2, progress=False, bins=bins)
    for slots in (3.0, True, np.bool_(True), 0):
        with pytest.raises(ConfigError, match=r"^slots must be an integer >= 1, got "):
            evaluate(model, data, 2, progress=False, slots=slots)


def test_the_metrics_take_numpy_integers():
    assert check_bin_edges(np.array([5, 10, 20])) == (5, 10, 20)
    assert all(type(e) is int for e in check_bin_edges((np.int64(5), 10)))
    assert slot_labels(np.int64(2)) == ["1", "2", ">2"]
    for slots in (2.0, True, np.bool_(True), torch.tensor(True)):
        with pytest.raises(ValueError, match=r"^slots must be an integer >= 1"):
            slot_labels(slots)


# ------------------------------------------------------------- walkthrough 69: an empty split


@pytest.mark.parametrize("call", [evaluate, predict_dataset, sampled_batches])
def test_a_dataset_without_scenes_is_one_data_error_before_any_work(call):
    """``evaluate`` raised the metrics' bare "no agents were evaluated", ``predict_dataset``
    numpy's concatenate error and ``sampled_batches`` yielded nothing."""
    empty = TrajectoryDataset([], DatasetInfo("zara1", "test", "m", 0.4))
    with pytest.raises(DataError, match=r"^the dataset zara1/test holds no agents \(0 scenes\): "
                       r"nothing to predict; load a split with scenes"):  # fmt: skip
        out = call(_Counting(), empty, 2, progress=False)
        if call is sampled_batches:  # a generator: it runs when read
            next(out)
    assert _Counting.calls == 0
