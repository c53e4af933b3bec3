"""A host that has set ``torch.set_default_dtype(torch.float64)`` loads and runs the published
models as any other (walkthrough 69): the modules were built in float64 and refused float32
inputs (``mat1 and mat2 must have the same dtype``), the timestep embedding was float64, and
the scorer's noise was drawn in float64 (other numbers). Each test restores the default."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
import torch

from trajpref.models.layers import timestep_embedding
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import TrajectoryScorer, predict_scene, rank_samples, slot_noise
from trajpref.score.selection import SelectionConfig, chosen_selection, select_for_scene
from trajpref.types import Scene, collate


@contextlib.contextmanager
def default_dtype(dtype: torch.dtype):
    """torch's default dtype set to ``dtype`` inside, the previous one restored after."""
    previous = torch.get_default_dtype()
    torch.set_default_dtype(dtype)
    try:
        yield
    finally:
        torch.set_default_dtype(previous)


def _history() -> np.ndarray:
    rng = np.random.default_rng(0)
    return (np.cumsum(rng.normal(0.0, 0.3, (3, 8, 2)), 1) + 5.0).astype(np.float32)  # [P, 8, 2]


def _float_dtypes(module: torch.nn.Module) -> set[torch.dtype]:
    tensors = [*module.parameters(), *module.buffers()]
    return {t.dtype for t in tensors if t.is_floating_point()}


def _planning_pass() -> dict[str, np.ndarray]:
    """Load zara1's generator and denoiser, sample, rank and select: every number."""
    generator = load_predictor("zara1/generator")
    scorer = TrajectoryScorer.from_checkpoint("zara1/denoiser").with_steps([0, 3])
    assert _float_dtypes(generator) == {torch.float32}
    assert _float_dtypes(scorer.denoiser) == {torch.float32}
    history = _history()
    samples = predict_scene(generator, history, 20, seed=0)  # [K, P, T_f, 2]
    order, residual = rank_samples(scorer, history, samples)
    chosen = select_for_scene(scorer, history, samples, chosen_selection("zara1/generator"))
    drawn = select_for_scene(scorer, history, samples, SelectionConfig(method="random", keep=5))
    return {"samples": samples, "order": order, "residual": residual, "chosen": chosen,
            "random": drawn}  # fmt: skip


def test_published_models_give_the_same_numbers_under_a_float64_default():
    expected = _planning_pass()  # under float32, the default
    with default_dtype(torch.float64):
        got = _planning_pass()
        assert torch.get_default_dtype() == torch.float64  # loading left the host's default
    assert got["samples"].dtype == np.float32
    for name, value in expected.items():
        np.testing.assert_array_equal(got[name], value, err_msg=name)


def test_a_loaded_predictor_takes_float32_inputs_under_a_float64_default(zara1):
    scene = Scene(history=_history(), future=np.zeros((3, 12, 2), np.float32),
                  agent_type=np.zeros(3, np.int64), scene_id="s")  # fmt: skip
    batch = collate([scene])  # float32 tensors, as the data gives them
    with default_dtype(torch.float64):
        model = load_predictor("zara1/generator")
        pred = model.predict(batch, 4, torch.Generator().manual_seed(0))
    expected = zara1.predict(batch, 4, torch.Generator().manual_seed(0))
    torch.testing.assert_close(pred, expected, rtol=0, atol=0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_timestep_embedding_is_float32_whatever_the_default(dtype):
    s = torch.tensor([0, 5, 99])
    expected = timestep_embedding(s, 16)
    with default_dtype(dtype):
        got = timestep_embedding(s, 16)
    assert got.dtype == torch.float32
    torch.testing.assert_close(got, expected, rtol=0, atol=0)


def test_slot_noise_draws_the_same_numbers_under_a_float64_default():
    expected = slot_noise(3, (2, 12, 2), torch.Generator().manual_seed(1))
    with default_dtype(torch.float64):
        got = slot_noise(3, (2, 12, 2), torch.Generator().manual_seed(1))
    assert got.dtype == torch.float32
    torch.testing.assert_close(got, expected, rtol=0, atol=0)


@pytest.mark.parametrize("model", ["zara1/denoiser", "cv"])
def test_the_full_sampler_and_the_baseline_draw_the_same_under_a_float64_default(model):
    """The full sampler's start and step noise, and the constant-velocity baseline's spread,
    are drawn in float32 whatever the default: the same numbers as under float32."""
    history = _history()
    expected = predict_scene(load_predictor(model), history, 3, seed=0)  # [K, P, T_f, 2]
    with default_dtype(torch.float64):
        got = predict_scene(load_predictor(model), history, 3, seed=0)
    np.testing.assert_array_equal(got, expected)
