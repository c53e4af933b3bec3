"""In-context adaptation keeps the model's ``neighbour_radius``: the adapted copy (and the
score objective's scorer) read only the pairs within it, as the model it copies does."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from synthetic import write_dataset

from trajpref.adapt import AdaptConfig, _with_generator, adapt_and_predict
from trajpref.data import load_dataset
from trajpref.models.registry import load_predictor

CFG = AdaptConfig(ctx_frames=40, steps=3, lr=1e-2, params="all")


@pytest.fixture(scope="module")
def long_walks(tmp_path_factory):
    """One 40-frame recording of 3 walkers (21 windows); window 16 has 5 context windows."""
    root = write_dataset(tmp_path_factory.mktemp("long_radius"), frames=40)
    return load_dataset(str(root), "test")


def _model(tiny_run, radius):
    model = load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")
    model.neighbour_radius = radius
    return model


def test_the_adapted_copy_keeps_the_radius(tiny_run):
    model = _model(tiny_run, 2.5)
    assert _with_generator(model, model.generator).neighbour_radius == 2.5


@pytest.mark.parametrize("objective", ["supervised", "score"])
def test_an_adapted_window_is_predicted_at_the_models_radius(tiny_run, long_walks, objective):
    cfg = dataclasses.replace(CFG, objective=objective)
    i = 16  # a window with context: predicted by an adapted copy of the generator
    every = adapt_and_predict(_model(tiny_run, None), long_walks, cfg, 4, seed=1, indices=[i])
    alone = adapt_and_predict(_model(tiny_run, 1e-3), long_walks, cfg, 4, seed=1, indices=[i])
    assert every.context == [[0, 1, 2, 3, 4]] and long_walks[i].num_agents == 3
    # a radius no pair is within (each walker alone) must change the adapted prediction; it
    # was dropped by the copy, which then predicted as if every pair attended
    assert not torch.allclose(every.pred[0], alone.pred[0], atol=1e-4)
