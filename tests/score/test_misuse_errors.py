"""Plausible misuse of the planning API is one trajpref error saying what to do, not a bare
built-in exception from deep inside (walkthrough 69): a selection setting that is no
``SelectionConfig``, a loaded model where ``chosen_selection`` takes its name, and a tensor
on the ``meta`` device."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from score.helpers import _scene

from trajpref.errors import ConfigError, DataError
from trajpref.models import zoo
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import predict_scene, predict_scenes, rank_samples
from trajpref.score.selection import (
    SelectingPredictor,
    SelectionConfig,
    chosen_selection,
    published_name,
    select_for_scene,
)


def _samples(history: np.ndarray, k: int = 20) -> np.ndarray:
    """[K, P, 12, 2] futures that continue ``history``, spread a little."""
    rng = np.random.default_rng(0)
    step = history[:, -1] - history[:, -2]  # [P, 2]
    path = history[:, -1, None] + step[:, None] * np.arange(1, 13)[:, None]  # [P, 12, 2]
    return (path[None] + rng.normal(0.0, 0.1, (k, *path.shape))).astype(np.float32)


# ------------------------------------------------------------------- a: SelectionConfig


@pytest.mark.parametrize(("cfg", "got"), [(None, "None"), ({"keep": 5}, "dict"),
                                          ("score-facility", "str")])  # fmt: skip
def test_select_for_scene_takes_a_selection_config_only(scorer, cfg, got):
    history = _scene()
    with pytest.raises(ConfigError, match=rf"^select_for_scene: cfg must be a SelectionConfig, "
                       rf"got {got}; make one"):  # fmt: skip
        select_for_scene(scorer, history, _samples(history), cfg)


def test_a_dict_of_fields_is_told_how_to_become_a_config(scorer):
    history = _scene()
    with pytest.raises(ConfigError, match=r"SelectionConfig\(\*\*fields\)"):
        select_for_scene(scorer, history, _samples(history), {"keep": 5})
    idx = select_for_scene(scorer, history, _samples(history), SelectionConfig(**{"keep": 5}))
    assert idx.shape == (5, 3)


def test_a_selecting_predictor_takes_a_selection_config_only(zara1):
    with pytest.raises(ConfigError, match=r"^SelectingPredictor: cfg must be a SelectionConfig, "
                       r"got dict"):  # fmt: skip
        SelectingPredictor(zara1, {"keep": 5, "method": "fps"})


# ------------------------------------------------------------------- b: chosen_selection


def test_a_loaded_model_stands_for_the_name_it_was_loaded_by(zara1):
    assert chosen_selection(zara1) == chosen_selection("zara1/generator")
    assert chosen_selection(zara1, keep=3, cheap=True) == chosen_selection(
        "zara1/generator", keep=3, cheap=True)  # fmt: skip
    assert published_name(zara1) == "zara1/generator"


def test_a_model_loaded_from_a_published_file_stands_for_that_file():
    model = load_predictor(zoo.resolve("zara1/generator"))
    assert chosen_selection(model) == chosen_selection("zara1/generator")


def test_a_model_without_chosen_settings_says_so_by_its_name(scorer):
    """A scorer records its checkpoint too: the denoiser has no chosen setting."""
    with pytest.raises(ConfigError, match=r"no chosen selection setting for 'zara1/denoiser'"):
        chosen_selection(scorer)


@pytest.mark.parametrize(
    ("model", "got"), [(None, "None"), (3, "int"), (load_predictor("cv"), "ConstantVelocity")]
)
def test_what_names_no_checkpoint_is_a_config_error(model, got):
    message = (rf"^chosen_selection: model is a published name such as 'zara1/generator'.*; "
               rf"got {got}, which names no checkpoint$")  # fmt: skip
    with pytest.raises(ConfigError, match=message):
        chosen_selection(model)


# ------------------------------------------------------------------- f: the meta device


def _meta(array: np.ndarray) -> torch.Tensor:
    return torch.empty(array.shape, device="meta")


def test_a_meta_history_or_sample_tensor_is_a_data_error(scorer, zara1):
    history = _scene()
    samples = _samples(history)
    message = r"a tensor on the meta device holds no values \(only a shape \[3, 8, 2\]\)"
    with pytest.raises(DataError, match=rf"^history: {message}; pass the values themselves"):
        rank_samples(scorer, _meta(history), torch.as_tensor(samples))
    with pytest.raises(DataError, match=r"^samples: a tensor on the meta device"):
        rank_samples(scorer, history, _meta(samples))
    with pytest.raises(DataError, match=r"^history: a tensor on the meta device"):
        select_for_scene(scorer, _meta(history), torch.as_tensor(samples),
                         chosen_selection("zara1/generator"))  # fmt: skip
    with pytest.raises(DataError, match=r"^history: a tensor on the meta device"):
        predict_scene(zara1, _meta(history))
    with pytest.raises(DataError, match=r"^histories\[1\]: a tensor on the meta device"):
        predict_scenes(zara1, [torch.as_tensor(history), _meta(history)])


def test_meta_agent_types_are_a_data_error(scorer):
    history = _scene()
    with pytest.raises(DataError, match=r"^agent_type: a tensor on the meta device"):
        rank_samples(scorer, history, _samples(history), torch.zeros(3, device="meta"))
