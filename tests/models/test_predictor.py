import numpy as np
import pytest
import torch
from synthetic import make_scene

from trajpref.config import DiffusionConfig, ModelConfig
from trajpref.data.transforms import from_model_frame, to_model_frame
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import ConfigError
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator
from trajpref.models.predictor import DiffusionPredictor
from trajpref.types import Scene, collate

K = 4
TINY = ModelConfig(hidden=16, heads=2, encoder_layers=1, denoiser_width=32, denoiser_blocks=1,
                   generator_width=32, samples=K, tau=2)  # fmt: skip
SCALE = 0.5


def _predictor(sampler: str = "leapfrog", with_generator: bool = True) -> DiffusionPredictor:
    torch.manual_seed(0)
    schedule = DDPMSchedule.from_config(DiffusionConfig(num_steps=10))
    generator = Generator(TINY) if with_generator else None
    return DiffusionPredictor(Denoiser(TINY), schedule, SCALE, generator, tau=3, sampler=sampler)


@pytest.fixture
def batch():
    return collate([make_scene(3), make_scene(2, seed=1)])  # N = 5


def test_model_frame_round_trip_hand_computed():
    hist = np.array([[[0.0, 0.0], [1.0, 2.0]]], np.float32)  # [P=1, T_h=2, 2], origin (1, 2)
    fut = np.array([[[3.0, 2.0], [5.0, 6.0]]], np.float32)  # [1, T_f=2, 2]
    batch = collate([Scene(hist, fut, np.zeros(1, np.int64), "hand")])
    y = to_model_frame(batch.future, batch, 2.0)
    assert y.tolist() == [[[1.0, 0.0], [2.0, 2.0]]]  # (future - origin) / 2
    assert torch.equal(from_model_frame(y, batch, 2.0), batch.future)
    # with leading sample axes [K, N, T, 2]
    ys = torch.stack([y, -y])
    assert from_model_frame(ys, batch, 2.0)[1].tolist() == [[[-1.0, 2.0], [-3.0, -2.0]]]


def test_predict_is_rollout_in_absolute_coordinates(batch):
    pred = _predictor()
    out = pred.predict(batch, K, torch.Generator().manual_seed(5))
    assert out.shape == (K, 5, 12, 2)
    roll = pred.rollout(batch, torch.Generator().manual_seed(5), K)
    torch.testing.assert_close(out, from_model_frame(roll.y, batch, SCALE))
    # fewer samples: the first k of the generator's K
    assert pred.predict(batch, 2, torch.Generator().manual_seed(5)).shape == (2, 5, 12, 2)


def test_predict_is_seeded(batch):
    pred = _predictor()
    a = pred.predict(batch, K, torch.Generator().manual_seed(1))
    b = pred.predict(batch, K, torch.Generator().manual_seed(1))
    c = pred.predict(batch, K, torch.Generator().manual_seed(2))
    assert torch.equal(a, b)
    assert not torch.allclose(a, c)


def test_rollout_without_exploration(batch):
    roll = _predictor().rollout(batch, torch.Generator().manual_seed(0))
    assert roll.explore is None
    assert torch.equal(roll.y_tau, roll.initial)
    torch.testing.assert_close(roll.initial, roll.out.initial_sample())


def test_antithetic_exploration_twin(batch):
    pred = _predictor()
    g = torch.Generator().manual_seed(3)
    fork = torch.Generator().set_state(g.get_state())
    roll = pred.rollout(batch, g, explore_std=0.1)
    twin = pred.rollout(batch, fork, explore_std=0.1, explore_sign=-1)
    assert roll.explore is not None and roll.explore.shape == (K, 5, 12, 2)
    assert torch.equal(twin.explore, -roll.explore)
    assert torch.equal(twin.initial, roll.initial)
    torch.testing.assert_close(roll.y_tau, roll.initial + roll.explore)
    torch.testing.assert_close(twin.y_tau, roll.initial - roll.explore)
    # the noise has the asked std (K * N * T_f * 2 = 480 draws)
    assert 0.08 < roll.explore.std() < 0.12
    # identical denoising noise: with exploration off, both forks give the same samples
    g = torch.Generator().manual_seed(4)
    fork = torch.Generator().set_state(g.get_state())
    assert torch.equal(pred.rollout(batch, g).y, pred.rollout(batch, fork).y)


def test_antithetic_twin_shares_denoising_noise(batch):
    # with eps = 0 each step is y_{s-1} = y_s / sqrt(alpha_s) + sigma_s z_s, so under shared
    # noise z the twins differ by exactly prod_s 1 / sqrt(alpha_s) * 2 xi
    pred = _predictor()
    for p in pred.denoiser.out[1].parameters():
        torch.nn.init.zeros_(p)
    g = torch.Generator().manual_seed(3)
    fork_a = torch.Generator().set_state(g.get_state())
    fork_b = torch.Generator().set_state(g.get_state())
    plus = pred.rollout(batch, fork_a, explore_std=0.1)
    minus = pred.rollout(batch, fork_b, explore_std=0.1, explore_sign=-1)
    gain = pred.schedule.alphas[: pred.tau].rsqrt().prod()  # steps tau-1 .. 0
    torch.testing.assert_close(plus.y - minus.y, gain * 2 * plus.explore, atol=1e-5, rtol=1e-4)


def test_more_samples_than_the_generator_emits(batch):
    pred = _predictor()
    with pytest.raises(ConfigError, match="emits K"):
        pred.predict(batch, K + 1)
    with pytest.raises(ConfigError, match="emits K"):
        pred.rollout(batch, num_samples=K + 1)


def test_leapfrog_needs_a_generator():
    with pytest.raises(ConfigError, match="generator"):
        _predictor("leapfrog", with_generator=False)


def test_bad_sampler_and_tau():
    schedule = DDPMSchedule(10)
    with pytest.raises(ConfigError, match="sampler"):
        DiffusionPredictor(Denoiser(TINY), schedule, 1.0, Generator(TINY), sampler="bogus")
    with pytest.raises(ConfigError, match="tau"):
        DiffusionPredictor(Denoiser(TINY), schedule, 1.0, Generator(TINY), tau=11)
    with pytest.raises(ConfigError, match="tau"):
        DiffusionPredictor(Denoiser(TINY), schedule, 1.0, Generator(TINY), tau=-1)
    with pytest.raises(ConfigError, match="tau must be >= 0"):
        ModelConfig(tau=-1)


def test_tau_zero_predicts_the_generator_samples_without_the_denoiser(batch):
    base = _predictor()
    pred = DiffusionPredictor(base.denoiser, base.schedule, SCALE, base.generator, tau=0)
    calls = []
    pred.denoiser.register_forward_hook(lambda *a: calls.append(1))
    roll = pred.rollout(batch, torch.Generator().manual_seed(0))
    assert calls == []  # no denoising pass
    assert torch.equal(roll.y, roll.initial)  # the prediction is mu + sigma S itself
    loss = roll.y.square().sum()
    loss.backward()  # gradients reach the generator directly
    assert any(p.grad is not None for p in pred.generator.parameters())


@pytest.mark.parametrize("with_generator", [False, True])
def test_full_sampler_accepts_any_k(batch, with_generator):
    pred = _predictor("full", with_generator=with_generator)
    out = pred.predict(batch, 3 * K + 1, torch.Generator().manual_seed(0))
    assert out.shape == (3 * K + 1, 5, 12, 2)
    assert torch.isfinite(out).all()
    again = pred.predict(batch, 3 * K + 1, torch.Generator().manual_seed(0))
    assert torch.equal(out, again)


@pytest.mark.parametrize("tau", [0, 3])
def test_the_denoisers_context_is_computed_only_when_a_rollout_denoises_and_then_once(batch, tau):
    base = _predictor()
    pred = DiffusionPredictor(base.denoiser, base.schedule, SCALE, base.generator, tau=tau)
    calls = []
    pred.denoiser.encoder.register_forward_hook(lambda *a: calls.append(1))
    cond = pred.condition(batch)
    assert calls == []  # nothing yet
    first = pred.rollout(batch, torch.Generator().manual_seed(0), cond=cond)
    again = pred.rollout(batch, torch.Generator().manual_seed(0), cond=cond)
    assert len(calls) == (1 if tau else 0)  # shared by both rollouts on the same condition
    assert torch.equal(first.y, again.y)
    if tau:  # the same context as computing it by hand
        with torch.no_grad():
            expected = pred.denoiser.context(cond.features)
        torch.testing.assert_close(cond.context, expected)


def _context_batch():
    import dataclasses

    rng = np.random.default_rng(3)
    scene = dataclasses.replace(make_scene(3), context=rng.normal(size=(2, 8, 2)).astype("f4"))
    return collate([scene, make_scene(2, seed=1)])


def test_only_a_context_generator_reads_context_agents_and_the_denoiser_never_does():
    import dataclasses

    from trajpref.models.encoder import scene_features

    batch = _context_batch()
    plain = _predictor()
    with_ctx = _predictor()
    with_ctx.generator.cfg = dataclasses.replace(TINY, context_agents=True)
    for pred, reads in ((plain, False), (with_ctx, True)):
        cond = pred.condition(batch)
        bare = pred.condition(batch.without_context())
        torch.testing.assert_close(cond.context, bare.context)  # the denoiser's
        assert (cond.features.targets is not None) is reads
        y = pred.rollout(batch, torch.Generator().manual_seed(1)).y
        y0 = pred.rollout(batch.without_context(), torch.Generator().manual_seed(1)).y
        assert y.shape == (K, 5, 12, 2)
        assert torch.allclose(y[:, :3], y0[:, :3]) is not reads
    with pytest.raises(ValueError, match="the generator's"):
        plain.denoiser.context(scene_features(batch, SCALE, context=True))


def test_context_frames_admits_the_agents_seen_over_the_last_frames():
    import dataclasses

    ctx = np.random.default_rng(4).normal(size=(3, 8, 2)).astype("f4")
    ctx[1, :3] = np.nan  # entered at frame 3
    ctx[2, :6] = np.nan  # seen over the last two frames only
    batch = collate([dataclasses.replace(make_scene(2), context=ctx)])
    pred = _predictor()
    counts = []
    for frames in (0, 5, 2):
        pred.generator.cfg = dataclasses.replace(TINY, context_agents=True,
                                                 context_frames=frames)  # fmt: skip
        features = pred.condition(batch).features
        counts.append(features.hist.shape[0] - features.targets)
        assert torch.isfinite(features.hist).all() and torch.isfinite(features.geom).all()
    assert counts == [1, 2, 3]
    with pytest.raises(ConfigError, match="context_frames"):
        dataclasses.replace(TINY, context_frames=1)


def test_predict_checks_what_a_python_caller_hands_it(batch):
    from dataclasses import replace

    from trajpref.errors import DataError

    pred = _predictor()
    for k in (0, -1, 2.0, True):
        with pytest.raises(ConfigError, match="num_samples must be an integer >= 1"):
            pred.predict(batch, k)
    with pytest.raises(DataError, match=r"expected \[N, 8, 2\] .*T_h = 8\), got \[5, 7, 2\]"):
        pred.predict(replace(batch, history=batch.history[:, 1:]), K)
    holed = batch.history.clone()
    holed[3, 2, 0] = float("nan")
    with pytest.raises(DataError, match="1 agent.* non-finite positions, the first at index 3"):
        pred.predict(replace(batch, history=holed), K)
    far = batch.history + 5e6  # UTM-like: float32 keeps about 0.25 of a unit there
    with pytest.raises(DataError, match="subtract an origin"):
        pred.predict(replace(batch, history=far, future=batch.future + 5e6), K)
    pred.predict(replace(batch, history=batch.history + 1e3), K)  # a plaza's size is fine


def test_loading_resolves_the_device_as_the_command_line_does(tiny_run, monkeypatch):
    from trajpref.models.registry import load_predictor
    from trajpref.score import TrajectoryScorer

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    path = str(tiny_run / "generator.safetensors")
    assert load_predictor(path, device="auto").device.type == "cpu"
    with pytest.raises(ConfigError, match="no CUDA GPU is available"):
        load_predictor(path, device="cuda")
    with pytest.raises(ConfigError, match="no CUDA GPU is available"):
        load_predictor("cv", device="cuda")
    with pytest.raises(ConfigError, match="no CUDA GPU is available"):
        TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", device="cuda")
    assert (
        TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", "auto").device.type
        == "cpu"
    )
