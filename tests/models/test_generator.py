import dataclasses

import pytest
import torch
from synthetic import make_scene

from trajpref.config import ModelConfig
from trajpref.errors import ConfigError, DataError
from trajpref.models.baseline import ConstantVelocity
from trajpref.models.encoder import agent_site, heading_rotation, scene_features, speed_factor
from trajpref.models.generator import Generator, time_projection
from trajpref.types import collate

K = 6
TINY = ModelConfig(hidden=16, heads=2, encoder_layers=1, denoiser_width=32, denoiser_blocks=1,
                   generator_width=32, samples=K, tau=2)  # fmt: skip


@pytest.fixture
def out():
    torch.manual_seed(0)
    gen = Generator(TINY)
    batch = collate([make_scene(3), make_scene(2, seed=1)])  # N = 5
    return gen(scene_features(batch, 1.0))


def test_output_shapes(out):
    assert out.mean.shape == (5, 12, 2)  # [N, T_f, 2]
    assert out.log_sigma.shape == (K, 5)  # [K, N]
    assert out.shifts.shape == (K, 5, 12, 2)  # [K, N, T_f, 2]
    assert out.context.shape == (5, 16)  # [N, H]
    assert out.initial_sample().shape == (K, 5, 12, 2)


def test_shifts_have_zero_mean_and_unit_spread_per_agent(out):
    s = out.shifts.detach()
    torch.testing.assert_close(s.mean(0), torch.zeros(5, 12, 2), atol=1e-5, rtol=0)
    rms = s.pow(2).mean(dim=(0, 2, 3)).sqrt()  # [N]
    torch.testing.assert_close(rms, torch.ones(5), atol=1e-4, rtol=0)
    # the samples are not all the same
    assert s.std(0).min() > 0


def test_initial_sample_is_mean_plus_sigma_times_shift(out):
    y = out.initial_sample()
    for k in range(K):
        for n in range(5):
            expected = out.mean[n] + torch.exp(out.log_sigma[k, n]) * out.shifts[k, n]
            torch.testing.assert_close(y[k, n], expected)


def test_samples_follow_config():
    torch.manual_seed(0)
    gen = Generator(ModelConfig(hidden=16, heads=2, encoder_layers=1, generator_width=8, samples=3))
    assert gen.samples == 3
    o = gen(scene_features(collate([make_scene(2)]), 1.0))
    assert o.shifts.shape == (3, 2, 12, 2)


def _rotated(features, angle: float):
    """The same scene turned by ``angle`` about the origin (row vectors x -> x @ R.T)."""
    c, s = torch.cos(torch.tensor(angle)), torch.sin(torch.tensor(angle))
    rot = torch.stack([torch.stack([c, -s]), torch.stack([s, c])])  # [2, 2]
    n, t = features.hist.shape[:2]
    b, p = features.mask.shape
    hist = (features.hist.view(n, t, 2, 2) @ rot.T).view(n, t, 4)
    geom = (features.geom.view(b, p, p, 2, 2) @ rot.T).view(b, p, p, 4)
    return dataclasses.replace(features, hist=hist, geom=geom), rot


def _assert_turns_and_scales_with_the_scene(gen: Generator, angle: float) -> None:
    """A heading-frame generator with a speed clamp below every agent's speed: the scene
    turned by ``angle`` gets the turned mean, and the scene three times faster gets three
    times the samples."""
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    turned, rot = _rotated(features, angle)
    fast = dataclasses.replace(features, hist=3 * features.hist, geom=3 * features.geom)
    with torch.no_grad():
        a, b, c = gen(features), gen(turned), gen(fast)
    torch.testing.assert_close(b.mean, a.mean @ rot.T, atol=1e-4, rtol=0)
    torch.testing.assert_close(c.initial_sample(), 3 * a.initial_sample(), atol=1e-4, rtol=1e-4)


def test_heading_rotation_turns_the_observed_displacement_onto_x():
    hist = torch.zeros(3, 8, 4)
    hist[0, 0, :2] = torch.tensor([-3.0, -4.0])  # came from (-3, -4): moved along (3, 4)
    hist[1, 0, :2] = torch.tensor([0.0, 2.0])  # moved along -y
    rot = heading_rotation(hist)  # agent 2 did not move
    torch.testing.assert_close(rot[0] @ torch.tensor([3.0, 4.0]), torch.tensor([5.0, 0.0]))
    torch.testing.assert_close(rot[1] @ torch.tensor([0.0, -2.0]), torch.tensor([2.0, 0.0]))
    torch.testing.assert_close(rot[2], torch.eye(2))
    torch.testing.assert_close(rot @ rot.mT, torch.eye(2).expand(3, 2, 2))


@pytest.mark.parametrize("frame", ["heading", "scene"])
def test_only_the_heading_frame_turns_its_prediction_with_the_scene(frame):
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, agent_frame=frame)).eval()
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    turned, rot = _rotated(features, 1.1)
    with torch.no_grad():
        a, b = gen(features), gen(turned)
    equivariant = torch.allclose(b.mean, a.mean @ rot.T, atol=1e-4) and torch.allclose(
        b.shifts, a.shifts @ rot.T, atol=1e-4
    )
    assert equivariant == (frame == "heading")
    if frame == "heading":  # the scales and the context do not depend on the orientation
        torch.testing.assert_close(b.log_sigma, a.log_sigma, atol=1e-4, rtol=0)
        torch.testing.assert_close(b.context, a.context, atol=1e-4, rtol=0)


def test_the_agent_frame_is_a_generator_setting_checked_on_construction():
    assert ModelConfig(agent_frame="heading").denoiser_part() == ModelConfig()
    with pytest.raises(ConfigError, match="agent_frame"):
        ModelConfig(agent_frame="polar")


def test_speed_factor_brings_fast_agents_down_to_the_clamp_and_leaves_slow_ones():
    hist = torch.zeros(3, 8, 4)
    hist[0, 0, :2] = torch.tensor([-7.0, 0.0])  # 1 unit per step over the 7 observed steps
    hist[1, 0, :2] = torch.tensor([0.0, -1.4])  # 0.2 units per step
    c = speed_factor(hist, max_speed=0.5)  # agent 2 did not move
    torch.testing.assert_close(c, torch.tensor([2.0, 1.0, 1.0]))


@pytest.mark.parametrize("max_speed", [0.0, 1e-3])
def test_with_the_clamp_a_faster_copy_of_a_scene_gets_a_scaled_copy_of_the_prediction(max_speed):
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, agent_frame="heading", max_speed=max_speed)).eval()
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    fast = dataclasses.replace(features, hist=3 * features.hist, geom=3 * features.geom)
    with torch.no_grad():
        a, b = gen(features), gen(fast)
    scaled = torch.allclose(b.mean, 3 * a.mean, atol=1e-4) and torch.allclose(
        b.initial_sample(), 3 * a.initial_sample(), atol=1e-4
    )
    # every agent of the synthetic scenes moves faster than 1e-3 units per step
    assert scaled == (max_speed > 0)
    if max_speed > 0:  # the shifts keep unit spread; the scale goes into sigma
        torch.testing.assert_close(b.shifts, a.shifts, atol=1e-4, rtol=0)
        torch.testing.assert_close(b.context, a.context, atol=1e-4, rtol=0)


def test_a_clamp_above_every_agents_speed_changes_nothing():
    torch.manual_seed(0)
    gen = Generator(TINY).eval()
    clamped = Generator(dataclasses.replace(TINY, max_speed=1e6)).eval()
    clamped.load_state_dict(gen.state_dict())
    features = scene_features(collate([make_scene(3)]), 1.0)
    with torch.no_grad():
        a, b = gen(features), clamped(features)
    torch.testing.assert_close(b.initial_sample(), a.initial_sample())


def test_the_speed_clamp_is_a_generator_setting_checked_on_construction():
    assert ModelConfig(max_speed=0.45).denoiser_part() == ModelConfig()
    with pytest.raises(ConfigError, match="max_speed must be >= 0"):
        ModelConfig(max_speed=-0.1)


@pytest.mark.parametrize("frame", ["scene", "heading"])
def test_the_spread_scale_widens_the_samples_about_an_unchanged_mean(frame):
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, agent_frame=frame, max_speed=1e-3)).eval()
    wide = Generator(dataclasses.replace(gen.cfg, spread_scale=2.0)).eval()
    wide.load_state_dict(gen.state_dict())
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    with torch.no_grad():
        a, b = gen(features), wide(features)
    torch.testing.assert_close(b.mean, a.mean)
    torch.testing.assert_close(b.shifts, a.shifts)
    # every sample twice as far from the mean: sigma doubled, also for clamped agents
    torch.testing.assert_close(b.initial_sample() - b.mean, 2 * (a.initial_sample() - a.mean))


def test_the_spread_scale_is_a_generator_setting_checked_on_construction():
    assert ModelConfig(spread_scale=1.2).denoiser_part() == ModelConfig()
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError, match="spread_scale must be > 0"):
            ModelConfig(spread_scale=bad)


def test_the_history_encoder_is_a_generator_setting_checked_on_construction():
    assert ModelConfig(history_encoder="temporal").denoiser_part() == ModelConfig()
    with pytest.raises(ConfigError, match="history_encoder"):
        ModelConfig(history_encoder="lstm")


def test_the_temporal_encoder_reads_the_order_of_the_steps_and_learns():
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, history_encoder="temporal"))
    assert isinstance(gen.encoder.temporal, torch.nn.GRU)
    assert Generator(TINY).encoder.temporal is None
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    before = {k: v.clone() for k, v in gen.encoder.temporal.state_dict().items()}
    opt = torch.optim.SGD(gen.parameters(), lr=0.1)
    gen(features).mean.pow(2).sum().backward()
    opt.step()
    assert all(not torch.equal(v, before[k]) for k, v in gen.encoder.temporal.state_dict().items())
    # its part of the context: the GRU's last state, which depends on the steps' order
    with torch.no_grad():
        _, last = gen.encoder.temporal(features.hist)
        _, swapped = gen.encoder.temporal(features.hist.flip(1))
    assert not torch.allclose(last, swapped, atol=1e-3)


def test_the_heading_frame_stays_equivariant_with_the_temporal_encoder():
    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, agent_frame="heading", history_encoder="temporal")
    gen = Generator(cfg).eval()
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    turned, rot = _rotated(features, 0.7)
    with torch.no_grad():
        a, b = gen(features), gen(turned)
    torch.testing.assert_close(b.mean, a.mean @ rot.T, atol=1e-4, rtol=0)
    torch.testing.assert_close(b.context, a.context, atol=1e-4, rtol=0)


def test_a_temporal_generator_runs_under_bf16_autocast():
    gen = Generator(dataclasses.replace(TINY, history_encoder="temporal"))
    features = scene_features(collate([make_scene(3)]), 1.0)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = gen(features)
    out.mean.float().sum().backward()
    assert gen.encoder.temporal.weight_hh_l0.grad is not None


@pytest.mark.parametrize("social", [True, False])
def test_without_social_attention_an_agents_samples_ignore_its_neighbours(social):
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, generator_social=social)).eval()
    assert len(gen.encoder.layers) == (TINY.encoder_layers if social else 0)
    scene = make_scene(3)
    alone = dataclasses.replace(scene, history=scene.history[:1], future=scene.future[:1],
                                agent_type=scene.agent_type[:1])  # fmt: skip
    with torch.no_grad():
        crowd = gen(scene_features(collate([scene]), 1.0))
        single = gen(scene_features(collate([alone]), 1.0))
    same = torch.allclose(crowd.mean[0], single.mean[0], atol=1e-5) and torch.allclose(
        crowd.shifts[:, 0], single.shifts[:, 0], atol=1e-5
    )
    assert same == (not social)  # agent 0's samples depend on the others only with attention
    assert ModelConfig(generator_social=False).denoiser_part() == ModelConfig()


def test_dropout_acts_in_training_only_and_keeps_the_parameter_names():
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    f = scene_features(batch, 1.0)
    torch.manual_seed(0)
    plain = Generator(TINY)
    torch.manual_seed(0)
    dropped = Generator(dataclasses.replace(TINY, generator_dropout=0.5))
    # same parameters under the same names: a published file without dropout still loads
    assert plain.state_dict().keys() == dropped.state_dict().keys()
    dropped.load_state_dict(plain.state_dict())
    plain.eval()
    dropped.eval()  # evaluation never drops: the two agree exactly
    torch.testing.assert_close(dropped(f).initial_sample(), plain(f).initial_sample())
    dropped.train()
    torch.manual_seed(1)
    a = dropped(f).mean
    torch.manual_seed(2)
    b = dropped(f).mean
    assert not torch.allclose(a, b)  # training draws a fresh mask each pass
    # the encoding the critic reads is not dropped
    torch.testing.assert_close(dropped(f).context, plain(f).context)


def test_encoder_dropout_acts_inside_the_encoder_in_training_only():
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    f = scene_features(batch, 1.0)
    torch.manual_seed(0)
    plain = Generator(TINY)
    dropped = Generator(dataclasses.replace(TINY, encoder_dropout=0.5))
    # no parameters of its own: files trained with or without it load into either
    assert plain.state_dict().keys() == dropped.state_dict().keys()
    dropped.load_state_dict(plain.state_dict())
    plain.eval()
    dropped.eval()
    torch.testing.assert_close(dropped(f).initial_sample(), plain(f).initial_sample())
    dropped.train()
    plain.train()
    torch.manual_seed(1)
    a = dropped(f).context
    torch.manual_seed(2)
    b = dropped(f).context
    assert not torch.allclose(a, b)  # the encoding itself is dropped, unlike generator_dropout
    torch.testing.assert_close(plain(f).context, plain(f).context)  # nothing random without it
    assert ModelConfig(encoder_dropout=0.1).denoiser_part() == ModelConfig()


@pytest.mark.parametrize("p", [-0.1, 1.0])
def test_dropout_is_checked_on_construction(p):
    with pytest.raises(ConfigError, match="generator_dropout"):
        dataclasses.replace(TINY, generator_dropout=p)
    with pytest.raises(ConfigError, match="encoder_dropout"):
        dataclasses.replace(TINY, encoder_dropout=p)


def test_time_projection_keeps_polynomial_paths_and_removes_the_rest():
    t = torch.arange(1, 13, dtype=torch.float32)  # [T_f]
    pi = time_projection(12, 3)  # [T_f, T_f]
    torch.testing.assert_close(pi @ pi, pi, atol=1e-5, rtol=0)  # a projection
    assert torch.linalg.matrix_rank(pi) == 3
    path = 0.3 * t - 0.02 * t**2 + 0.001 * t**3  # a cubic through the last position
    torch.testing.assert_close(pi @ path, path, atol=1e-4, rtol=0)
    zigzag = torch.tensor([1.0, -1.0] * 6)  # alternating steps: not smooth
    assert (pi @ zigzag).norm() < 0.3 * zigzag.norm()
    constant = torch.ones(12)  # a jump away from the last position is not a path
    assert (pi @ constant - constant).norm() > 0.1
    torch.testing.assert_close(time_projection(12, 0), torch.eye(12))


@pytest.mark.parametrize("frame", ["scene", "heading"])
def test_a_low_rank_generator_emits_smooth_paths_and_keeps_its_frame(frame):
    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, future_rank=3, agent_frame=frame)
    gen = Generator(cfg).eval()
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    with torch.no_grad():
        out = gen(features)
    pi = time_projection(12, 3)
    y = out.initial_sample()  # [K, N, T_f, 2]
    torch.testing.assert_close(pi @ y, y, atol=1e-5, rtol=0)  # every sample in the span
    s = out.shifts
    torch.testing.assert_close(s.mean(0), torch.zeros(5, 12, 2), atol=1e-5, rtol=0)
    # unit spread up to the 1e-6 guard (the projected raw shifts of an untrained net are small)
    torch.testing.assert_close(s.pow(2).mean(dim=(0, 2, 3)).sqrt(), torch.ones(5), atol=1e-3,
                               rtol=0)  # fmt: skip
    # the free generator with the same weights does not emit paths in the span
    free = Generator(dataclasses.replace(cfg, future_rank=0)).eval()
    free.load_state_dict(gen.state_dict())  # the projection is not in the state dict
    with torch.no_grad():
        y_free = free(features).initial_sample()
    assert (pi @ y_free - y_free).abs().max() > 1e-3
    if frame == "heading":  # still rotation-equivariant
        turned, rot = _rotated(features, 0.7)
        with torch.no_grad():
            b = gen(turned)
        torch.testing.assert_close(b.mean, out.mean @ rot.T, atol=1e-4, rtol=0)


@pytest.mark.parametrize("rank", [-1, 13])
def test_the_future_rank_is_checked_on_construction(rank):
    with pytest.raises(ConfigError, match="future_rank"):
        dataclasses.replace(TINY, future_rank=rank)
    assert ModelConfig(future_rank=4).denoiser_part() == ModelConfig()


def test_agent_site_is_the_last_position_and_the_unit_heading_in_scene_coordinates():
    # agent 0 walks up (+y) and ends at (3, 4); agent 1 stands at (-1, 2)
    t = torch.arange(8, dtype=torch.float32)
    walker = torch.stack([torch.full((8,), 3.0), 4.0 - 0.5 * (7 - t)], -1)  # [T_h, 2]
    stander = torch.tensor([-1.0, 2.0]).repeat(8, 1)  # [T_h, 2]
    scene = dataclasses.replace(make_scene(2), history=torch.stack([walker, stander]).numpy())
    f = scene_features(collate([scene]), 2.0)  # scale 2: positions halve
    site = agent_site(f, None)  # [N, 4]
    expected = torch.tensor([[1.5, 2.0, 0.0, 1.0], [-0.5, 1.0, 1.0, 0.0]])
    torch.testing.assert_close(site, expected, atol=1e-6, rtol=0)


@pytest.mark.parametrize("site", [False, True])
def test_only_a_generator_with_scene_position_depends_on_where_the_scene_is(site):
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, scene_position=site)).eval()
    scene = make_scene(3)
    moved = dataclasses.replace(scene, history=scene.history + 5.0, future=scene.future + 5.0)
    with torch.no_grad():
        a = gen(scene_features(collate([scene]), 1.0))
        b = gen(scene_features(collate([moved]), 1.0))
    same = torch.allclose(a.mean, b.mean, atol=1e-5) and torch.allclose(a.shifts, b.shifts,
                                                                        atol=1e-5)  # fmt: skip
    assert same == (not site)
    assert ModelConfig(scene_position=True).denoiser_part() == ModelConfig()


def test_the_encoder_wants_a_site_exactly_when_built_with_one():
    f = scene_features(collate([make_scene(2)]), 1.0)
    with pytest.raises(ValueError, match="site"):
        Generator(dataclasses.replace(TINY, scene_position=True)).encoder(f)
    with pytest.raises(ValueError, match="site"):
        Generator(TINY).encoder(f, agent_site(f, None))


QUERIES = dataclasses.replace(TINY, query_layers=2, query_width=8)


def test_the_query_decoder_keeps_the_outputs_contract():
    torch.manual_seed(0)
    gen = Generator(QUERIES).eval()
    scene = make_scene(3)
    f = scene_features(collate([scene]), 1.0)
    with torch.no_grad():
        out = gen(f)
    assert out.log_sigma.shape == (K, 3) and out.shifts.shape == (K, 3, 12, 2)
    torch.testing.assert_close(out.shifts.mean(0), torch.zeros(3, 12, 2), atol=1e-5, rtol=0)
    rms = out.shifts.pow(2).mean(dim=(0, 2, 3)).sqrt()  # [N]
    torch.testing.assert_close(rms, torch.ones(3), atol=1e-4, rtol=0)
    assert out.shifts.std(0).min() > 0  # the K learned embeddings make K different proposals
    # one shared read-out: the MLP heads are not built, and the denoiser part is unchanged
    assert not hasattr(gen, "shift_head") and not hasattr(gen, "sigma_head")
    assert QUERIES.denoiser_part() == TINY.denoiser_part()


def test_the_default_head_keeps_its_parameter_names():
    # published generators (query_layers = 0) must load unchanged
    names = set(Generator(TINY).state_dict())
    assert {n.split(".")[0] for n in names} == {"encoder", "mean_head", "sigma_head",
                                                 "shift_head"}  # fmt: skip


def test_the_query_tokens_train_and_see_each_other():
    torch.manual_seed(0)
    gen = Generator(QUERIES)
    f = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    before = {n: p.detach().clone() for n, p in gen.named_parameters()}
    opt = torch.optim.SGD(gen.parameters(), lr=0.1)
    gen(f).initial_sample().pow(2).sum().backward()
    opt.step()
    for name in ("queries", "query_in.weight", "query_out.1.weight"):
        assert not torch.equal(before[name], dict(gen.named_parameters())[name]), name
    # attention across the K tokens: moving one sample's embedding moves the other samples
    gen.eval()
    with torch.no_grad():
        a = gen(f).shifts
        gen.queries[0] += torch.randn(8)  # (a constant would vanish in the layer norms)
        b = gen(f).shifts
    assert not torch.allclose(a[1:], b[1:], atol=1e-6)


def test_a_query_decoder_runs_under_bf16_autocast():
    gen = Generator(QUERIES)
    f = scene_features(collate([make_scene(3)]), 1.0)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = gen(f)
    assert torch.isfinite(out.initial_sample().float()).all()


@pytest.mark.parametrize(("field", "value"), [("query_layers", -1), ("query_width", 7),
                                              ("query_width", 0)])  # fmt: skip
def test_the_query_decoder_is_checked_on_construction(field, value):
    with pytest.raises(ConfigError, match=field):
        dataclasses.replace(QUERIES, **{field: value})


def test_the_query_width_is_not_checked_when_there_is_no_query_decoder():
    # a config with 3 heads was valid before the query decoder existed and stays valid
    cfg = dataclasses.replace(TINY, hidden=18, heads=3)
    assert cfg.query_layers == 0 and cfg.query_width % cfg.heads
    with pytest.raises(ConfigError, match="query_width"):
        dataclasses.replace(cfg, query_layers=1)


def test_pair_distances_keep_the_heading_frame_and_the_speed_clamp_equivariant():
    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, agent_frame="heading", max_speed=1e-3, pair_distance=True)
    assert cfg.denoiser_part() == dataclasses.replace(cfg, pair_distance=False).denoiser_part()
    gen = Generator(cfg).eval()
    _assert_turns_and_scales_with_the_scene(gen, 1.1)
    plain = Generator(dataclasses.replace(cfg, pair_distance=False))
    assert set(gen.state_dict()) == set(plain.state_dict())  # only the edge width differs


def test_the_sigma_cap_bounds_every_samples_log_sigma_and_leaves_the_rest():
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, max_speed=1e-3)).eval()
    features = scene_features(collate([make_scene(3), make_scene(2, seed=1)]), 1.0)
    with torch.no_grad():
        a = gen(features)
        # the output's log sigma includes the clamp's log c (a few units at max_speed 1e-3),
        # so 10 below its median lies below every value the head emits
        cap = float(a.log_sigma.median()) - 10.0
        gen.cfg = dataclasses.replace(gen.cfg, max_log_sigma=cap)
        low = gen(features)
        gen.cfg = dataclasses.replace(gen.cfg, max_log_sigma=1e6)
        high = gen(features)
    torch.testing.assert_close(high.log_sigma, a.log_sigma)  # above every sample: no change
    torch.testing.assert_close(low.mean, a.mean)
    torch.testing.assert_close(low.shifts, a.shifts)
    # every agent's K samples now share one sigma: the cap, then the clamp's log c on top
    assert torch.allclose(low.log_sigma, low.log_sigma[:1].expand_as(low.log_sigma))
    assert (low.log_sigma < a.log_sigma).all()


@pytest.mark.parametrize("value", [float("inf"), float("nan")])
def test_the_sigma_cap_is_checked_on_construction(value):
    assert ModelConfig(max_log_sigma=1.0).denoiser_part() == ModelConfig()
    with pytest.raises(ConfigError, match="max_log_sigma"):
        ModelConfig(max_log_sigma=value)


@pytest.mark.parametrize("roles", [0, 3])
def test_only_a_generator_with_agent_roles_depends_on_the_order_of_a_scenes_agents(roles):
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, agent_roles=roles)).eval()
    scene = make_scene(3)
    order = [2, 0, 1]
    swapped = dataclasses.replace(scene, history=scene.history[order],
                                  future=scene.future[order])  # fmt: skip
    with torch.no_grad():
        a = gen(scene_features(collate([scene]), 1.0))
        b = gen(scene_features(collate([swapped]), 1.0))
    # without roles, agent 2's prediction follows it to slot 0; with roles it changes
    same = torch.allclose(a.mean[order], b.mean, atol=1e-5)
    assert same == (roles == 0)
    assert ModelConfig(agent_roles=3).denoiser_part() == ModelConfig()


def test_a_generator_with_agent_roles_refuses_a_scene_with_more_agents_than_roles():
    gen = Generator(dataclasses.replace(TINY, agent_roles=2)).eval()
    gen(scene_features(collate([make_scene(2)]), 1.0))  # two agents, two roles: fine
    with pytest.raises(DataError, match="3 agents, but this model knows 2 agent roles"):
        gen(scene_features(collate([make_scene(3)]), 1.0))
    with pytest.raises(ConfigError, match="agent_roles"):
        ModelConfig(agent_roles=-1)


def _scene_with_leaver(seed: int, targets: int, leavers: int):
    """A scene of ``targets`` agents plus ``leavers`` more, and the same scene with the
    leavers as context-only agents."""
    full = make_scene(targets + leavers, seed=seed)
    ctx = dataclasses.replace(full, history=full.history[:targets], future=full.future[:targets],
                              agent_type=full.agent_type[:targets],
                              context=full.history[targets:])  # fmt: skip
    return full, ctx


@pytest.mark.parametrize("frame", ["scene", "heading"])
def test_a_context_agent_is_a_neighbour_whose_prediction_is_dropped(frame):
    # golden equivalence: the targets' outputs with context agents equal those of the same
    # generator on the scene where the context agents are ordinary agents
    cfg = dataclasses.replace(TINY, context_agents=True, agent_frame=frame, max_speed=0.3,
                              history_encoder="temporal")  # fmt: skip
    torch.manual_seed(0)
    gen = Generator(cfg).eval()
    full_a, ctx_a = _scene_with_leaver(0, 2, 2)
    full_b, ctx_b = _scene_with_leaver(1, 3, 1)
    plain = make_scene(2, seed=2)  # no context at all
    out = gen(scene_features(collate([ctx_a, plain, ctx_b]), 1.0, context=True))
    ref = gen(scene_features(collate([full_a, plain, full_b]), 1.0))
    keep = torch.tensor([0, 1, 4, 5, 6, 7, 8])  # the targets' rows in the full batch
    assert out.mean.shape == (7, 12, 2)
    torch.testing.assert_close(out.mean, ref.mean[keep])
    torch.testing.assert_close(out.log_sigma, ref.log_sigma[:, keep])
    torch.testing.assert_close(out.shifts, ref.shifts[:, keep])
    # and the context agents do change the targets' prediction
    alone = gen(scene_features(collate([ctx_a, plain, ctx_b]), 1.0))
    assert not torch.allclose(alone.mean[:2], out.mean[:2])
    torch.testing.assert_close(alone.mean[2:4], out.mean[2:4])  # the scene without any


def test_context_agents_need_the_social_encoder_and_no_roles():
    with pytest.raises(ConfigError, match="needs generator_social"):
        dataclasses.replace(TINY, context_agents=True, generator_social=False)
    with pytest.raises(ConfigError, match="agent_roles do not combine"):
        dataclasses.replace(TINY, context_agents=True, agent_roles=4)


def _zero_mean_head(gen: Generator) -> None:
    """The mean head's last layer at zero: its output, the departure from the prior, is 0."""
    last = gen.mean_head[-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.zeros_(last.bias)


PRIOR_CASES = [("scene", 0.0, 0), ("heading", 0.0, 0), ("heading", 1e-3, 0), ("heading", 0.0, 3)]


@pytest.mark.parametrize("frame,max_speed,rank", PRIOR_CASES)
def test_a_velocity_prior_with_a_silent_head_gives_the_constant_velocity_path(
    frame, max_speed, rank
):
    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, mean_prior="velocity", agent_frame=frame,
                              max_speed=max_speed, future_rank=rank)  # fmt: skip
    gen = Generator(cfg).eval()
    _zero_mean_head(gen)
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    scale = 2.0
    with torch.no_grad():
        mean = gen(scene_features(batch, scale)).mean  # [N, T_f, 2]
    cv = ConstantVelocity().predict(batch, 1)[0]  # [N, T_f, 2] absolute positions
    expected = (cv - batch.origin[:, None]) / scale  # relative, in model units
    torch.testing.assert_close(mean, expected, atol=1e-5, rtol=0)
    # without the prior the same silent head predicts standing still
    plain = Generator(dataclasses.replace(cfg, mean_prior="none")).eval()
    plain.load_state_dict(gen.state_dict())  # the prior adds no parameters
    with torch.no_grad():
        still = plain(scene_features(batch, scale)).mean
    torch.testing.assert_close(still, torch.zeros_like(still))


def test_the_velocity_prior_keeps_the_heading_frame_and_the_clamp_equivariant():
    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, mean_prior="velocity", agent_frame="heading", max_speed=1e-3)
    _assert_turns_and_scales_with_the_scene(Generator(cfg).eval(), 0.9)


def test_the_velocity_prior_moves_the_mean_by_the_last_step_and_trains():
    torch.manual_seed(0)
    gen = Generator(dataclasses.replace(TINY, mean_prior="velocity"))
    features = scene_features(collate([make_scene(3)]), 1.0)
    pushed = features.hist.clone()
    pushed[:, -1, 2:] += torch.tensor([0.5, -0.25])  # only the last velocity feature changes
    gen.eval()
    with torch.no_grad():
        a = gen(features).mean
        head_b = gen(dataclasses.replace(features, hist=pushed)).mean
    # the head's own output moves too (it reads the features); the prior adds exactly v t
    plain = Generator(dataclasses.replace(TINY, mean_prior="none")).eval()
    plain.load_state_dict(gen.state_dict())
    with torch.no_grad():
        pa = plain(features).mean
        pb = plain(dataclasses.replace(features, hist=pushed)).mean
    t = torch.arange(1, 13, dtype=torch.float32)[:, None]  # [T_f, 1]
    step = (t * torch.tensor([0.5, -0.25])).expand(3, 12, 2)  # [N, T_f, 2]
    torch.testing.assert_close((head_b - pb) - (a - pa), step, atol=1e-5, rtol=0)
    gen.train()
    loss = gen(features).mean.pow(2).mean()
    loss.backward()
    assert gen.mean_head[-1].weight.grad.abs().sum() > 0


def test_the_mean_prior_is_a_generator_setting_checked_on_construction():
    assert ModelConfig(mean_prior="velocity").denoiser_part() == ModelConfig()
    with pytest.raises(ConfigError, match="mean_prior"):
        ModelConfig(mean_prior="acceleration")
