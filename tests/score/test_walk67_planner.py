"""Walkthrough 67 (a robotics engineer's planning loop): samples that do not continue the
history (another frame, offsets) are refused instead of ranked; ``select_for_scene`` can return
the residuals and the pace gate it used; the selection's pace helper has its own name."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from trajpref.errors import DataError
from trajpref.score import TrajectoryScorer, predict_scene, rank_samples, selection
from trajpref.score.selection import SelectionConfig, chosen_selection, select_for_scene
from trajpref.types import AGENT_BALL, AGENT_PERSON

FRAME = "samples do not continue the history.*another frame.*offsets"


def _scene(fast: float = 1.4) -> np.ndarray:
    """[3, 8, 2] three walkers in a map frame (50, 20) m from its origin; agent 2 at ``fast``
    m/s."""
    t = np.arange(8) * 0.4
    walkers = [np.stack([t * 1.2, 0 * t], -1), np.stack([5 - t, 3 + 0 * t], -1),
               np.stack([2 + 0 * t, -2 + fast * t], -1)]  # fmt: skip
    return (np.stack(walkers) + np.array([50.0, 20.0])).astype(np.float32)


@pytest.fixture(scope="module")
def scene(zara1):
    history = _scene()
    return history, predict_scene(zara1, history)  # [3, 8, 2], [20, 3, 12, 2]


# ----------------------------------------------------------------------------- finding 1


def test_samples_in_another_frame_or_as_offsets_are_refused(scorer, scene):
    history, samples = scene
    cfg = chosen_selection("zara1/generator", keep=3)
    offsets = samples - history[None, :, -1:]  # each from its agent's last position
    for wrong in (offsets, samples + 100.0, samples - np.array([50.0, 20.0])):  # robot frame
        with pytest.raises(DataError, match=FRAME):
            rank_samples(scorer, history, wrong)
        with pytest.raises(DataError, match=FRAME):
            select_for_scene(scorer, history, wrong, cfg)
        with pytest.raises(DataError, match=FRAME):  # tensors alike
            rank_samples(scorer, torch.from_numpy(history), torch.from_numpy(wrong))
    with pytest.raises(DataError, match=r"agent\(s\) 0 \(\d.*1 \(.*2 \(.*7\.36 m"):
        rank_samples(scorer, history, samples + 100.0)
    # the fix the message names gives the absolute samples back
    order, _ = rank_samples(scorer, history, history[None, :, -1:] + offsets)
    np.testing.assert_array_equal(order, rank_samples(scorer, history, samples)[0])


def test_the_models_own_samples_pass_without_a_warning(zara1, scorer, scene):
    history, samples = scene
    cfg = chosen_selection("zara1/generator", keep=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rank_samples(scorer, history, samples)
        select_for_scene(scorer, history, samples, cfg)
        far = history + 1e3  # a map frame km off: both in it, nothing to say
        rank_samples(scorer, far, predict_scene(zara1, far))


def test_only_every_sample_of_an_agent_far_off_is_refused(scorer, scene):
    history, samples = scene
    stray = samples.copy()
    stray[:19, 1] += 100.0  # one of agent 1's 20 samples still starts where it is
    rank_samples(scorer, history, stray)
    one = samples.copy()
    one[:, 1] += 100.0  # every sample of one agent: refused, naming it alone
    with pytest.raises(DataError, match=r"agent\(s\) 1 \(") as caught:
        rank_samples(scorer, history, one)
    assert "agent(s) 1 (" in str(caught.value) and " 0 (" not in str(caught.value)
    # a ball may be that fast; an agent whose history jumps is the jump warning's
    ball = np.array([AGENT_PERSON, AGENT_BALL, AGENT_PERSON])
    rank_samples(scorer, history, one, ball)
    jumped = history.copy()
    jumped[1, 4:] += 10.0  # a 10 m step: an id switch, already warned of
    with pytest.warns(UserWarning, match="jumps more than"):
        rank_samples(scorer, jumped, one)


# ----------------------------------------------------------------------------- finding 2


def test_return_info_gives_the_residual_and_the_gate_of_the_same_pass(
    scorer, zara1, monkeypatch
):  # fmt: skip
    history = _scene(fast=2.0)  # agent 2: 0.8 m per step, above zara1's trust_speed 0.445
    samples = predict_scene(zara1, history)
    cfg = chosen_selection("zara1/generator", keep=3)
    idx = select_for_scene(scorer, history, samples, cfg)
    calls = []
    real = TrajectoryScorer.residual
    monkeypatch.setattr(TrajectoryScorer, "residual",
                        lambda self, *a, **k: calls.append(1) or real(self, *a, **k))  # fmt: skip
    info = select_for_scene(scorer, history, samples, cfg, return_info=True)
    assert len(calls) == 1  # one scoring pass
    got, residual, trusted = info  # a named tuple
    assert isinstance(info, selection.SceneSelection) and info.idx is got
    np.testing.assert_array_equal(got, idx)  # the default's indices
    assert residual.shape == (20, 3) and residual.dtype == np.float32
    assert trusted.dtype == np.bool_ and trusted.tolist() == [True, True, False]
    # the per-agent numbers rank_samples sums, at the selection's score steps
    _, total = rank_samples(selection.score_steps(scorer, cfg), history, samples)
    np.testing.assert_allclose(residual.sum(1), total, rtol=1e-5)
    kept = residual[got, np.arange(3)]  # the docstring's take: [K', P]
    assert kept.shape == (3, 3)
    # one scene: every agent falls back when any does
    scene_cfg = chosen_selection("zara1/generator", keep=3, per="scene")
    assert select_for_scene(scorer, history, samples, scene_cfg,
                            return_info=True).trusted.tolist() == [False] * 3  # fmt: skip
    # no gate: all trusted; a score-free method: nothing scored, nothing trusted
    plain = select_for_scene(scorer, history, samples, SelectionConfig(keep=3), return_info=True)
    assert plain.trusted.tolist() == [True] * 3
    free = select_for_scene(scorer, history, samples, SelectionConfig(keep=3, method="fps"),
                            return_info=True)  # fmt: skip
    assert free.residual is None and free.trusted.tolist() == [False] * 3
    # tensors in, tensors out
    out = select_for_scene(scorer, torch.from_numpy(history), samples, cfg, return_info=True)
    assert all(isinstance(t, torch.Tensor) for t in out)
    empty = select_for_scene(scorer, np.zeros((0, 8, 2)), np.zeros((20, 0, 12, 2)), cfg,
                             return_info=True)  # fmt: skip
    assert empty.idx.shape == (3, 0) and empty.residual.shape == (20, 0)
    assert empty.trusted.shape == (0,)


# ----------------------------------------------------------------------------- finding 4


def test_the_selections_pace_helper_is_not_a_twin_of_the_transforms_one():
    from trajpref.data import transforms

    assert not hasattr(selection, "observed_pace")  # one name, one argument
    batch = selection.Batch(history=torch.tensor([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]]),
                            future=torch.zeros(1, 12, 2), scene=torch.zeros(1, dtype=torch.int64),
                            agent_type=torch.zeros(1, dtype=torch.int64),
                            num_scenes=1)  # fmt: skip
    torch.testing.assert_close(selection.batch_observed_pace(batch, 2.0),
                               transforms.observed_pace(batch.history, 2.0))  # fmt: skip
