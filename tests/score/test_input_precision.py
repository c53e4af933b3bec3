"""Inputs whose numbers cannot be positions are refused by the one conversion of the public
API (``score.scorer._float_tensor``: ``predict_scene``, ``rank_samples``,
``select_for_scene``), tensors and numpy arrays alike (walkthrough 68, finding 1): half
precision (bfloat16 rounded positions near 123 m to 0.5 m and moved zara1's futures by metres,
silently), booleans (read as 0/1) and complex numbers (the imaginary part dropped)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from trajpref.errors import DataError
from trajpref.score import predict_scene, rank_samples
from trajpref.score.selection import SelectionConfig, select_for_scene

HALF = r"half precision \({}\).*0\.5 m or 0\.06 m.*pass float32 or float64"


def _scene() -> np.ndarray:
    """[2, 8, 2] two walkers about 123 m from the origin (float64)."""
    t = np.arange(8)[:, None]
    return np.stack([t * [0.47, 0.13] + [123.4, 56.7], t * [-0.31, 0.42] + [126.1, 55.2]])


@pytest.mark.parametrize(
    ("make", "shown"),
    [
        (lambda h: torch.tensor(h, dtype=torch.bfloat16), "torch.bfloat16"),
        (lambda h: torch.tensor(h, dtype=torch.float16), "torch.float16"),
        (lambda h: h.astype(np.float16), "numpy float16"),
        (lambda h: list(h.astype(np.float16)), "numpy float16"),  # a list of its rows
    ],
)
def test_half_precision_histories_are_refused(zara1, make, shown):
    with pytest.raises(DataError, match="history: " + HALF.format(shown)):
        predict_scene(zara1, make(_scene()))


@pytest.mark.parametrize(
    ("make", "shown"),
    [
        (lambda h: h > 124, "numpy bool"),
        (lambda h: (h > 124).tolist(), "numpy bool"),
        (lambda h: h.astype(np.complex128), "numpy complex128"),
        (lambda h: h.astype(np.complex64), "numpy complex64"),
        (lambda h: torch.tensor(h > 124), "torch.bool"),
        (lambda h: torch.tensor(h, dtype=torch.complex64), "torch.complex64"),
    ],
)
def test_bool_and_complex_histories_are_refused_as_tensors_are(zara1, make, shown):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ComplexWarning before: now no conversion
        with pytest.raises(DataError, match=f"history: expected real numbers, got a {shown}"):
            predict_scene(zara1, make(_scene()))


@pytest.mark.parametrize(
    "make",
    [
        lambda h: h.astype(np.float32),
        lambda h: h,  # float64
        lambda h: np.round(h).astype(np.int64),
        lambda h: np.round(h).astype(np.int32),
        lambda h: h.tolist(),
        lambda h: torch.tensor(h, dtype=torch.float32),
        lambda h: torch.tensor(h, dtype=torch.float64),
        lambda h: torch.tensor(np.round(h)).long(),
    ],
)
def test_single_double_and_integer_histories_are_still_read(zara1, make):
    base = predict_scene(zara1, _scene().astype(np.float32))
    given = make(_scene())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = predict_scene(zara1, given)
    out = out.numpy() if isinstance(out, torch.Tensor) else out
    assert out.shape == base.shape and out.dtype == np.float32
    if not np.issubdtype(np.asarray(given).dtype, np.integer) and not (
        isinstance(given, torch.Tensor) and not given.is_floating_point()
    ):
        np.testing.assert_allclose(out, base, atol=1e-4)


def test_ranking_and_selection_refuse_half_precision_samples_and_histories(zara1, scorer):
    h = _scene().astype(np.float32)
    samples = predict_scene(zara1, h)
    half = torch.tensor(samples, dtype=torch.bfloat16)
    with pytest.raises(DataError, match="samples: " + HALF.format("torch.bfloat16")):
        rank_samples(scorer, h, half)
    with pytest.raises(DataError, match="history: " + HALF.format("numpy float16")):
        select_for_scene(scorer, h.astype(np.float16), samples, SelectionConfig(keep=5))
    with pytest.raises(DataError, match="samples: expected real numbers, got a numpy bool"):
        rank_samples(scorer, h, samples > 0)
    order, _ = rank_samples(scorer, h, samples.astype(np.float64))  # float64 still read
    assert sorted(order.tolist()) == list(range(len(samples)))


def test_context_of_half_precision_is_refused(zara1):
    h = _scene().astype(np.float32)
    context = torch.tensor(h[:1] + 3.0, dtype=torch.float16)
    with pytest.raises(DataError, match="context: " + HALF.format("torch.float16")):
        predict_scene(zara1, h, context=context)
