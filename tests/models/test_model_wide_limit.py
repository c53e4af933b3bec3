"""Each model's own wide-scene limit (``models.timing.wide_limit``): the lowest multiple of 5
model units above its training width, the farthest two agents of its training scenes lay apart
at their last observed frame. A checkpoint records the width (``meta.training_width``, since
2026-12-06); a published file, which records none, takes its built-in dataset's measured one
(``TRAINING_WIDTHS``); any other falls back to ``WIDE_LIMIT`` (25, above NBA's court). zara1's
generator (limit 15, 22.1 m) used to warn only above 36.8 m."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
from helpers import WIDE, walker_and_far

from trajpref.config import load_config
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator
from trajpref.models.registry import load_predictor
from trajpref.models.timing import (
    TRAINING_WIDTHS,
    WIDE_LIMIT,
    dataset_width,
    model_width,
    scene_widths,
    training_width,
    wide_limit,
    wide_problem,
)
from trajpref.score import TrajectoryScorer, predict_scene
from trajpref.types import DatasetInfo, Scene, TrajectoryDataset


def _warned(call) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [str(w.message) for w in caught if WIDE in str(w.message)]


# --- the rule --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("width", "limit"),
    [(21.39, 25.0), (13.39, 15.0), (10.47, 15.0), (10.72, 15.0), (9.25, 10.0), (7.83, 10.0),
     (15.0, 20.0), (14.999, 15.0), (0.0, 5.0), (4.2, 5.0)],
)  # fmt: skip
def test_the_limit_is_the_lowest_multiple_of_five_above_the_width(width, limit):
    assert wide_limit(width) == limit


@pytest.mark.parametrize("width", [None, math.nan, math.inf, -1.0, True, "13.4"])
def test_an_unknown_width_falls_back_to_the_one_limit(width):
    assert wide_limit(width) == WIDE_LIMIT == 25.0


def test_the_published_datasets_widths_give_the_limits_the_docstring_names():
    limits = {name: wide_limit(w) for name, w in TRAINING_WIDTHS.items()}
    assert limits == {"eth": 15, "hotel": 15, "univ": 15, "zara1": 15, "zara2": 15, "nba": 25,
                      "robo-sim": 10, "robo-mix": 10, "sdd": 10}  # fmt: skip


# --- the published models (their dataset's measured width) ---------------------------------


def test_zara1_warns_for_a_walker_25_m_to_the_side_not_10_m(zara1):
    assert model_width(zara1) == (TRAINING_WIDTHS["zara1"], "zara1")
    assert zara1.training_width == pytest.approx(13.39)
    assert _warned(lambda: predict_scene(zara1, walker_and_far(10.0))) == []
    shown = _warned(lambda: predict_scene(zara1, walker_and_far(25.0)))  # 17.0 model units
    assert len(shown) == 1
    assert "more than 15 model units apart" in shown[0] and "22.08 m" in shown[0]
    assert "13.39" in shown[0] and "zara1's training split" in shown[0]
    for remedy in ("model.neighbour_radius", "scorer.neighbour_radius", "--neighbour-radius",
                   "Scenes wider than the training scenes"):  # fmt: skip
        assert remedy in shown[0]


def test_zara1_is_warned_just_above_its_own_limit_not_just_below(zara1):
    limit = 15.0 * zara1.scale
    assert _warned(lambda: predict_scene(zara1, walker_and_far(0.99 * limit))) == []
    assert len(_warned(lambda: predict_scene(zara1, walker_and_far(1.01 * limit)))) == 1


def test_nba_does_not_warn_at_21_units_and_names_its_own_limit_above_25(nba):
    assert model_width(nba) == (21.39, "nba")
    ok = walker_and_far(21.0 * nba.scale)
    assert _warned(lambda: predict_scene(nba, ok, agent_type=np.zeros(2, np.int64))) == []
    far = walker_and_far(26.0 * nba.scale)
    shown = _warned(lambda: predict_scene(nba, far, agent_type=np.zeros(2, np.int64)))
    assert len(shown) == 1 and "more than 25 model units" in shown[0]
    assert "nba's training split" in shown[0] and "21.39" in shown[0]
    # the width is named as the widest scene's, not as the limit (walkthrough 70)
    assert ("its limit: the lowest multiple of 5 above the width of its widest training "
            "scene, which is 21.39 model units") in shown[0]  # fmt: skip


def test_a_scorer_keeps_its_limit_at_other_steps():
    scorer = TrajectoryScorer.from_checkpoint("sdd/denoiser")
    assert scorer.training_width == TRAINING_WIDTHS["sdd"]
    other = scorer.with_steps([0])  # a copy: its timing record carries the width
    assert other is not scorer and model_width(other) == (9.25, "sdd")
    text = wide_problem(other, walker_and_far(11.0 * scorer.scale), "this scorer")
    assert text is not None and "more than 10 model units" in text


# --- checkpoints: recorded, or not known ----------------------------------------------------


def _tiny_files(tmp_path, dataset: str, generator_width: float | None,
                denoiser_width: float | None) -> str:  # fmt: skip
    """A tiny generator file (random weights) trained, its header says, on ``dataset``, with
    the training widths given recorded in its meta and its denoiser's (None: none)."""
    from synthetic import TINY_OVERRIDES

    cfg = load_config(None, TINY_OVERRIDES)
    cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, dataset=dataset))
    den_meta = {} if denoiser_width is None else {"training_width": denoiser_width}
    gen_meta = {} if generator_width is None else {"training_width": generator_width}
    den = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 1.0, den_meta)
    path = tmp_path / "generator.safetensors"
    ckpt.save(path, ckpt.generator_payload(Generator(cfg.model), den, cfg, gen_meta))
    return str(path)


def test_a_checkpoint_without_a_width_and_an_unknown_dataset_falls_back(tmp_path):
    path = _tiny_files(tmp_path, str(tmp_path / "my-folder"), None, None)
    model = load_predictor(path, device="cpu")
    assert model.training_width is None and model_width(model) is None
    assert training_width(ckpt.load(path)) is None
    assert wide_problem(model, walker_and_far(24.0)) is None
    text = wide_problem(model, walker_and_far(26.0))
    assert text is not None and "more than 25 model units" in text
    assert "training width is not known" in text


def test_a_checkpoint_without_a_width_on_a_built_in_dataset_takes_the_table(tmp_path):
    model = load_predictor(_tiny_files(tmp_path, "sdd", None, None), device="cpu")
    assert model_width(model) == (9.25, "sdd")


def test_a_recorded_width_wins_and_each_network_reads_its_own(tmp_path):
    path = _tiny_files(tmp_path, "nba", 12.0, 3.0)  # recorded beats nba's table (21.39)
    leapfrog = load_predictor(path, device="cpu")
    assert model_width(leapfrog) == (12.0, "checkpoint")
    text = wide_problem(leapfrog, walker_and_far(16.0))
    assert text is not None and "more than 15 model units" in text
    assert "recorded in its checkpoint" in text
    # the full sampler and the scorer run the denoiser: its width (3 -> limit 5)
    assert model_width(load_predictor(path, device="cpu", sampler="full")) == (3.0, "checkpoint")
    scorer = TrajectoryScorer.from_checkpoint(path)
    assert model_width(scorer) == (3.0, "checkpoint")
    assert wide_problem(scorer, walker_and_far(4.0)) is None
    assert "more than 5 model units" in wide_problem(scorer, walker_and_far(6.0))
    # the timing record stays the file's alone: evaluate checks a shared record once
    assert scorer.timing == leapfrog.timing


def test_a_width_set_by_hand_is_used_and_said():
    class Model:
        scale = 2.0
        neighbour_radius = None
        training_width = 30.0

    text = wide_problem(Model(), walker_and_far(2.0 * 36.0))
    assert text is not None and "more than 35 model units" in text and "as set" in text
    assert wide_problem(Model(), walker_and_far(2.0 * 34.0)) is None


# --- the measure -----------------------------------------------------------------------------


def _info() -> DatasetInfo:
    return DatasetInfo(name="hand", split="train", units="m", frame_interval=0.4)


def test_dataset_width_by_hand_with_and_without_context():
    still = np.zeros((8, 2))
    a = Scene(np.stack([still, still + [3.0, 4.0]]), np.zeros((2, 12, 2)), np.zeros(2, np.int64),
              "a")  # fmt: skip
    whole = still + [0.0, 8.0]  # a context-only agent seen over the whole history: 8 from (0, 0)
    late = np.full((8, 2), np.nan)
    late[-2:] = [0.0, -12.0]  # one seen over the last 2 frames only: 12 from (0, 0), 20 from whole
    b = Scene(np.stack([still, still + [0.0, 2.0]]), np.zeros((2, 12, 2)), np.zeros(2, np.int64),
              "b", context=np.stack([whole, late]))  # fmt: skip
    data = TrajectoryDataset([a, b], _info())
    assert dataset_width(data, 1.0) == pytest.approx(5.0)  # targets: scene a's pair
    assert dataset_width(data, 2.0) == pytest.approx(2.5)  # model units
    assert dataset_width(data, 1.0, context=True) == pytest.approx(8.0)  # the late one unread
    assert dataset_width(data, 1.0, context=True, context_frames=2) == pytest.approx(20.0)
    lone = Scene(still[None], np.zeros((1, 12, 2)), np.zeros(1, np.int64), "c")
    assert dataset_width(TrajectoryDataset([lone], _info()), 1.0) == 0.0
    assert dataset_width(TrajectoryDataset([], _info()), 1.0) == 0.0


@pytest.mark.parametrize(
    "model", ["eth/generator", "hotel/generator", "univ/generator", "zara1/generator",
              "zara2/generator", "nba/generator", "robo/generator", "robo-mix/generator",
              "sdd/generator", "univ/denoiser"],
)  # fmt: skip
def test_no_published_test_scene_lies_above_its_models_limit(data_root, model):
    """Each model's own test split (robo's: robo) read as ``check_observed_steps`` measures
    it: no window's targets lie farther apart than the model's limit (2026-12-06: 0 of every
    split's scenes; the widest 18.16 of nba's 25, 9.02 of zara2's 15, 6.51 of SDD's 10)."""
    from trajpref.data.registry import load_dataset

    header = ckpt.load(model)
    config = ckpt.config_of(header)
    data = load_dataset(config.data.val_dataset or config.data.dataset, "test", root=data_root)
    history = np.concatenate([s.history for s in data.scenes])
    widths = scene_widths(history, [len(s.history) for s in data.scenes]) / header["scale"]
    limit = wide_limit(training_width(header)[0])
    assert int((widths > limit).sum()) == 0, (model, limit, float(widths.max()))
