"""Every training stage records its model's training width in the checkpoint's meta
(``training_width``: the farthest two agents of a training scene lie apart at its last observed
frame, in model units, over what the model reads), computed once from the training split
without drawing from any random stream; a loaded predictor takes its wide-scene limit from it
(``models.timing.wide_limit``)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest
import torch

from trajpref.config import ModelConfig
from trajpref.data.registry import run_splits
from trajpref.models import checkpoint as ckpt
from trajpref.models.registry import load_predictor
from trajpref.models.timing import dataset_width, model_width, wide_limit
from trajpref.score import predict_scene
from trajpref.train.stages import build_finetune_stage, build_generator_stage, width_meta
from trajpref.types import DatasetInfo, Scene, TrajectoryDataset

T = np.arange(8)[:, None]


@pytest.fixture(scope="module")
def splits(tiny_cfg):
    return run_splits(tiny_cfg.data)


def test_a_trained_checkpoint_records_its_training_width(tiny_run, splits):
    train, _ = splits
    den = ckpt.load(tiny_run / "denoiser.safetensors")
    gen = ckpt.load(tiny_run / "generator.safetensors")
    want = dataset_width(train, den["scale"])  # no context in the walks
    assert want > 1.0
    assert den["meta"]["training_width"] == pytest.approx(want)
    assert gen["meta"]["training_width"] == pytest.approx(want)
    assert gen["denoiser"]["meta"]["training_width"] == pytest.approx(want)


def test_its_predictor_warns_above_the_recorded_width_s_limit(tiny_run):
    model = load_predictor(tiny_run / "generator.safetensors", device="cpu")
    width, source = model_width(model)
    assert source == "checkpoint" and width == model.training_width
    limit = wide_limit(width) * model.scale  # data units
    walker = T * np.array([0.3, 0.0])

    def warned(distance: float) -> list[str]:
        pair = np.stack([walker, walker + [0.0, distance]]).astype(np.float32)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            predict_scene(model, pair, num_samples=4)
        return [str(w.message) for w in caught if "apart at its last" in str(w.message)]

    assert warned(0.98 * limit) == []
    shown = warned(1.02 * limit)
    assert len(shown) == 1 and f"more than {wide_limit(width):g} model units" in shown[0]
    assert "recorded in its checkpoint" in shown[0]


def test_the_generator_and_finetune_stages_record_theirs(tiny_cfg, tiny_run, splits):
    train, val = splits
    den = ckpt.load(tiny_run / "denoiser.safetensors")
    want = dataset_width(train, den["scale"])
    gen = build_generator_stage(tiny_cfg, den, val, torch.device("cpu"), train)
    assert gen.payload({})["meta"]["training_width"] == pytest.approx(want)
    # without the training split nothing is recorded (loading falls back)
    bare = build_generator_stage(tiny_cfg, den, val, torch.device("cpu"))
    assert "training_width" not in bare.payload({})["meta"]
    start = ckpt.load(tiny_run / "generator.safetensors")
    tune = build_finetune_stage(tiny_cfg, start, val, torch.device("cpu"), train)
    assert tune.payload({})["meta"]["training_width"] == pytest.approx(want)
    # a start that saw wider scenes keeps its width: the weights saw them first
    wide_start = {**start, "meta": {**start["meta"], "training_width": 40.0}}
    wider = build_finetune_stage(tiny_cfg, wide_start, val, torch.device("cpu"), train)
    assert wider.payload({})["meta"]["training_width"] == 40.0


def test_computing_the_width_draws_nothing(splits):
    train, _ = splits
    torch.manual_seed(3)
    state = torch.random.get_rng_state()
    width_meta(train, 1.0, ModelConfig(context_agents=True))
    assert torch.equal(torch.random.get_rng_state(), state)


def test_a_context_reading_generator_counts_the_context_it_reads():
    still = np.zeros((8, 2))
    ctx = np.stack([still + [0.0, 9.0]])  # seen over the whole history, 9 from the targets
    scene = Scene(np.stack([still, still + [1.0, 0.0]]), np.zeros((2, 12, 2)),
                  np.zeros(2, np.int64), "s", context=ctx)  # fmt: skip
    data = TrajectoryDataset([scene], DatasetInfo("hand", "train", "m", 0.4))
    plain = ModelConfig()
    reader = dataclasses.replace(plain, context_agents=True)
    assert width_meta(data, 1.0, plain) == {"training_width": pytest.approx(1.0)}
    assert width_meta(data, 1.0, reader) == {"training_width": pytest.approx(np.hypot(1, 9))}
    assert width_meta(None, 1.0) == {}
