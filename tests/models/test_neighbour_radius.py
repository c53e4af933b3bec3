"""The neighbour radius (``ModelConfig.neighbour_radius``): agents farther apart than it do not
attend to each other, in the generator's and the denoiser's attention and in the scorer's,
measured in data units before the heading frame and the speed clamp; None changes nothing."""

import dataclasses
import math
import shutil

import numpy as np
import pytest
import torch

from trajpref.config import DiffusionConfig, ModelConfig, load_config
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scale_features, scene_features, speed_factor
from trajpref.models.generator import Generator
from trajpref.models.predictor import DiffusionPredictor
from trajpref.score.scorer import TrajectoryScorer
from trajpref.types import Scene, collate

K = 4
TINY = ModelConfig(hidden=16, heads=2, encoder_layers=2, denoiser_width=32, denoiser_blocks=1,
                   generator_width=32, samples=K, tau=2)  # fmt: skip
SCALE = 0.5
"""Data units per model unit: the radius is given in data units, the networks see /SCALE."""


def _predictor(cfg: ModelConfig = TINY, radius: float | None = None) -> DiffusionPredictor:
    torch.manual_seed(0)
    schedule = DDPMSchedule.from_config(DiffusionConfig(num_steps=10))
    return DiffusionPredictor(Denoiser(cfg), schedule, SCALE, Generator(cfg), tau=2,
                              stochastic=False, neighbour_radius=radius)  # fmt: skip


def _walker(start, step, t_h: int = 8) -> np.ndarray:
    """[T_h, 2] a straight walk from ``start`` with a constant ``step`` per frame."""
    return np.asarray(start, np.float32) + np.arange(t_h)[:, None] * np.asarray(step, np.float32)


def _batch(*agents: np.ndarray, context: np.ndarray | None = None):
    history = np.stack(agents).astype(np.float32)  # [P, T_h, 2]
    future = np.zeros((len(agents), 12, 2), np.float32)
    types = np.zeros(len(agents), np.int64)
    return collate([Scene(history, future, types, "s", context=context)])


AGENT = _walker([0.0, 0.0], [0.2, 0.0])  # agent 0: walks +x


def _sample(model, batch):
    return model.predict(batch, K, torch.Generator().manual_seed(0))  # [K, N, T_f, 2]


def test_without_a_radius_no_pair_mask_is_built_and_a_radius_beyond_every_pair_changes_nothing():
    batch = _batch(AGENT, _walker([0.0, 3.0], [0.2, 0.0]), _walker([5.0, -2.0], [0.0, 0.2]))
    assert scene_features(batch, SCALE).pairs is None  # the fast path of the published models
    pairs = scene_features(batch, SCALE, radius=1e6).pairs
    assert pairs.shape == (1, 3, 3) and bool(pairs.all())
    model = _predictor()
    plain = _sample(model, batch)
    model.neighbour_radius = 1e6  # every pair within: the masked path, nothing masked
    assert torch.equal(_sample(model, batch), plain)  # bit for bit


def test_an_agent_beyond_the_radius_leaves_an_agent_as_it_is_alone_and_one_within_it_matters():
    far = _walker([0.0, 20.0], [0.2, 0.0])  # 20 data units to the side
    near = _walker([0.0, 3.0], [0.2, 0.0])  # 3 data units: 6 model units, beyond a radius of 4
    model = _predictor()
    alone = _sample(model, _batch(AGENT))[:, 0]  # [K, T_f, 2]
    assert (_sample(model, _batch(AGENT, far))[:, 0] - alone).abs().max() > 1e-3  # no radius
    model.neighbour_radius = 8.0  # data units
    torch.testing.assert_close(_sample(model, _batch(AGENT, far))[:, 0], alone, atol=1e-5,
                               rtol=0)  # fmt: skip
    # the neighbour 3 data units away is within 8 (though 6 model units: data units count)
    assert (_sample(model, _batch(AGENT, near))[:, 0] - alone).abs().max() > 1e-3
    # both: agent 0's futures are those with its near neighbour alone
    torch.testing.assert_close(_sample(model, _batch(AGENT, near, far))[:, :2],
                               _sample(model, _batch(AGENT, near)), atol=1e-5,
                               rtol=0)  # fmt: skip


def test_the_radius_holds_for_context_only_neighbours_too():
    cfg = dataclasses.replace(TINY, context_agents=True)
    model = _predictor(cfg, radius=8.0)
    far = _walker([0.0, -30.0], [0.0, 0.2])[None]  # [1, T_h, 2], seen over the whole history
    near = _walker([1.0, 1.0], [0.0, 0.2])[None]
    alone = _sample(model, _batch(AGENT))[:, 0]
    torch.testing.assert_close(_sample(model, _batch(AGENT, context=far))[:, 0], alone,
                               atol=1e-5, rtol=0)  # fmt: skip
    assert (_sample(model, _batch(AGENT, context=near))[:, 0] - alone).abs().max() > 1e-3


def test_the_pairs_are_measured_before_the_heading_frame_and_the_speed_clamp():
    cfg = dataclasses.replace(TINY, agent_frame="heading", max_speed=0.3)  # model units
    fast = _walker([0.0, 0.0], [0.5, 0.5])  # 0.71 data units = 1.41 model units per step
    other = _walker([9.0, -9.0], [0.0, 0.01])  # 12.7 data units from fast's last position
    batch = _batch(fast, other)
    f = scene_features(batch, SCALE, radius=8.0)
    c = speed_factor(f.hist, cfg.max_speed)  # [N]
    assert c[0] > 2  # the clamp divides what agent 0 sees by c: 12.7 / c < 8 data units
    clamped = scale_features(f, c)
    seen = clamped.geom[0, 0, 1, :2].norm() * SCALE  # agent 1 as the clamped agent 0 sees it
    assert seen < 8.0 and clamped.pairs is f.pairs  # carried through as measured
    assert not bool(f.pairs[0, 0, 1]) and not bool(f.pairs[0, 1, 0])
    model = _predictor(cfg, radius=8.0)
    alone = _sample(model, _batch(fast))[:, 0]
    torch.testing.assert_close(_sample(model, batch)[:, 0], alone, atol=1e-5, rtol=0)
    model.neighbour_radius = None
    assert (_sample(model, batch)[:, 0] - alone).abs().max() > 1e-3


@pytest.mark.parametrize("bad", [0, -1.0, math.nan, math.inf, True, "8", [8.0]])
def test_a_bad_radius_is_a_config_error_wherever_it_is_set(bad):
    with pytest.raises(ConfigError, match="neighbour_radius must be"):
        ModelConfig(neighbour_radius=bad)
    model = _predictor()
    with pytest.raises(ConfigError, match=r"model\.neighbour_radius must be None .* > 0"):
        model.neighbour_radius = bad
    assert model.neighbour_radius is None  # left as it was
    scorer = TrajectoryScorer(model.denoiser, model.schedule, SCALE)
    with pytest.raises(ConfigError, match=r"scorer\.neighbour_radius must be"):
        scorer.neighbour_radius = bad
    with pytest.raises(ConfigError, match=r"scorer\.neighbour_radius must be"):
        TrajectoryScorer(model.denoiser, model.schedule, SCALE, neighbour_radius=bad)


def test_a_config_reads_the_radius_and_refuses_a_bad_one():
    assert load_config(None, ["model.neighbour_radius=8"]).model.neighbour_radius == 8.0
    assert load_config(None, []).model.neighbour_radius is None
    with pytest.raises(ConfigError, match="model.neighbour_radius must be null"):
        load_config(None, ["model.neighbour_radius=-2"])
    assert np.float64(4.0) == _predictor(radius=np.float64(4.0)).neighbour_radius


def test_the_scorer_reads_only_the_pairs_within_the_radius():
    model = _predictor()
    far = _walker([0.0, 20.0], [0.2, 0.0])
    futures = torch.cumsum(torch.full((3, 2, 12, 2), 0.2), 2)  # [M, N, T_f, 2] steps
    futures = futures + torch.tensor([[1.4, 0.0], [1.4, 20.0]])[:, None]  # from the last
    # speed_ref 0.05 shrinks this scene 4x before the denoiser (the far agent to 5 units, within
    # 8): the pairs are measured on the scene as given
    for speed_ref in (None, 0.05):
        # an even number of steps: an agent's noise is then the same beside another agent
        # (torch.randn redraws the tail of a draw whose size is no multiple of 16)
        scorer = TrajectoryScorer(model.denoiser, model.schedule, SCALE, [0, 3],
                                  speed_ref=speed_ref)  # fmt: skip
        alone = scorer.residual(_batch(AGENT), futures[:, :1])  # [M, 1, T_f]
        both = scorer.residual(_batch(AGENT, far), futures)[:, :1]
        assert (both - alone).abs().max() > 1e-4  # no radius: the far agent counts
        scorer.neighbour_radius = 8.0
        torch.testing.assert_close(scorer.residual(_batch(AGENT, far), futures)[:, :1], alone,
                                   atol=1e-5, rtol=1e-5)  # fmt: skip
        assert scorer.with_steps([0]).neighbour_radius == 8.0


def test_a_generator_file_carries_the_radius_to_the_predictor_the_scorer_and_the_hash(
        tiny_run, tmp_path):  # fmt: skip
    for name in ("generator", "denoiser"):
        shutil.copy(tiny_run / f"{name}.safetensors", tmp_path / f"{name}.safetensors")
    path = tmp_path / "generator.safetensors"
    before, before_full = ckpt.model_hash(path), ckpt.model_hash(path, "full")
    assert ckpt.load_predictor(path).neighbour_radius is None
    assert TrajectoryScorer.from_checkpoint(path).neighbour_radius is None
    assert ckpt.set_generator_setting(path, "neighbour_radius", 8.0, "far agents")
    assert ckpt.model_hash(path) != before  # a results row tells the two apart
    assert ckpt.model_hash(path, "full") != before_full  # the full sampler's denoiser reads it
    assert ckpt.model_hash(tmp_path / "denoiser.safetensors", "full") == before_full
    assert ckpt.load_predictor(path).neighbour_radius == 8.0
    assert ckpt.load_predictor(path, sampler="full").neighbour_radius == 8.0
    assert TrajectoryScorer.from_checkpoint(path).neighbour_radius == 8.0
    assert TrajectoryScorer.from_checkpoint(path, neighbour_radius=None).neighbour_radius is None
    with pytest.raises(ConfigError, match="neighbour_radius must be null"):
        ckpt.set_generator_setting(path, "neighbour_radius", -1.0, "bad")


def test_a_published_generator_predicts_an_agent_as_alone_beside_a_walker_40_m_away(zara1):
    from trajpref.score import predict_scene

    agent = _walker([0.0, 0.0], [0.52, 0.0])  # 1.3 m/s along +x
    walker = _walker([0.0, 40.0], [0.52, 0.0])  # parallel, 40 m to the side
    assert zara1.neighbour_radius is None  # the published file sets none
    try:
        alone = predict_scene(zara1, agent[None])[:, 0]  # [K, T_f, 2]
        with pytest.warns(UserWarning, match="it has no neighbour radius"):  # 27 model units
            beside = predict_scene(zara1, np.stack([agent, walker]))[:, 0]
        assert np.abs(beside - alone).max() > 0.1
        zara1.neighbour_radius = 8.0
        np.testing.assert_allclose(predict_scene(zara1, np.stack([agent, walker]))[:, 0], alone,
                                   atol=1e-5, rtol=0)  # fmt: skip
        near = _walker([0.0, 2.0], [0.52, 0.0])
        assert np.abs(predict_scene(zara1, np.stack([agent, near]))[:, 0] - alone).max() > 1e-3
    finally:
        zara1.neighbour_radius = None
