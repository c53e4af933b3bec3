"""``TrajectoryScorer.from_checkpoint`` builds its denoiser without random initialisation
(walkthrough 69): it built it with it, inside ``torch.random.fork_rng``, whose restore of
torch's global generator repeated another thread's draws. The scorers it builds now rank as
the old build's did, bit for bit (that build is kept here as the reference)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from models.rng_guard import refuse_global_randomness, tensors_of

import trajpref
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.models import checkpoint as ckpt
from trajpref.models.timing import attach_timing
from trajpref.score.scorer import TrajectoryScorer, rank_samples

INDEX = Path(trajpref.__file__).parent / "zoo" / "index.json"
PUBLISHED = [r["name"] for r in json.loads(INDEX.read_text())["models"]]
"""Every published model: a denoiser, or a generator whose embedded denoiser scores."""
CHECKED = ["zara1/denoiser", "robo/denoiser", "sdd/denoiser", "eth/denoiser",
           "eth/generator-pace", "zara1/generator"]  # fmt: skip


def old_scorer(spec: str) -> TrajectoryScorer:
    """The scorer as ``from_checkpoint`` built it before 2026-12 (random initialisation, then
    the weights copied in): the reference."""
    header = ckpt.load(spec)
    payload = ckpt.denoiser_of(header)
    with torch.random.fork_rng(devices=[]):
        denoiser, cfg = ckpt.build_denoiser(payload)  # training's build
    denoiser = ckpt.as_float32(denoiser)
    schedule = DDPMSchedule.from_config(cfg.diffusion)
    radius = ckpt.config_of(header).model.neighbour_radius
    scorer = TrajectoryScorer(denoiser, schedule, payload["scale"], neighbour_radius=radius)
    return attach_timing(scorer, header)


def _scene(scorer: TrajectoryScorer, k: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Three walkers and ``k`` futures of theirs, at the scorer's scale: [3, T_h, 2] and
    [K, 3, T_f, 2]."""
    rng = np.random.default_rng(1)
    step = 0.06 * float(scorer.scale)
    history = np.cumsum(rng.normal(0.0, step, (3, scorer.t_hist, 2)), 1) + 3 * step
    moves = (
        rng.normal(0.0, step, (k, 3, scorer.t_fut, 2))
        + (history[:, -1] - history[:, -2])[None, :, None]
    )
    futures = history[None, :, -1:] + np.cumsum(moves, 2)
    return history.astype(np.float32), futures.astype(np.float32)


@pytest.mark.parametrize("name", PUBLISHED)
def test_from_checkpoint_draws_saves_and_restores_nothing(monkeypatch, name):
    state = torch.get_rng_state()
    seen = refuse_global_randomness(monkeypatch)
    scorer = TrajectoryScorer.from_checkpoint(name)
    monkeypatch.undo()
    assert torch.equal(torch.get_rng_state(), state)
    assert seen, "the denoiser's initialisers ran on the meta device (the check saw them)"
    left = [n for n, t in tensors_of(scorer.denoiser, scorer.schedule)
            if t.is_meta or t.device.type != "cpu"]  # fmt: skip
    assert not left, left
    assert {t.dtype for _, t in tensors_of(scorer.denoiser)} == {torch.float32}


@pytest.mark.parametrize("name", CHECKED)
def test_scorers_rank_as_the_old_build(name):
    new, old = TrajectoryScorer.from_checkpoint(name), old_scorer(name)
    new_tensors, old_tensors = (
        tensors_of(new.denoiser, new.schedule),
        tensors_of(old.denoiser, old.schedule),
    )
    assert [n for n, _ in new_tensors] == [n for n, _ in old_tensors]
    for (key, a), (_, b) in zip(new_tensors, old_tensors, strict=True):
        assert a.dtype == b.dtype and a.requires_grad == b.requires_grad, key
        assert torch.equal(a, b), key
    assert (new.steps, new.seed, new.neighbour_radius) == (old.steps, old.seed,
                                                           old.neighbour_radius)  # fmt: skip
    history, futures = _scene(new)
    for final in (False, True):
        got, want = rank_samples(new, history, futures, final=final), rank_samples(
            old, history, futures, final=final)  # fmt: skip
        np.testing.assert_array_equal(got[0], want[0])  # the order
        np.testing.assert_array_equal(got[1], want[1])  # the residuals
