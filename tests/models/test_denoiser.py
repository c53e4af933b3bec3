import pytest
import torch
from synthetic import make_scene

from trajpref.config import ModelConfig
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.types import collate

TINY = ModelConfig(hidden=16, heads=2, encoder_layers=1, denoiser_width=32, denoiser_blocks=2,
                   generator_width=32, samples=4, tau=2)  # fmt: skip


@pytest.fixture
def setup():
    torch.manual_seed(0)
    model = Denoiser(TINY)
    batch = collate([make_scene(3), make_scene(2, seed=1)])  # N = 5
    context = model.context(scene_features(batch, 1.0))  # [N, H]
    return model, context


def test_context_shape(setup):
    _, context = setup
    assert context.shape == (5, 16)


@pytest.mark.parametrize(
    "step",
    [3, torch.tensor(3), torch.tensor([0, 1, 2, 3, 4])],  # int, 0-d, per agent [N]
    ids=["int", "0-d", "per-agent"],
)
def test_output_has_the_shape_of_y(setup, step):
    model, context = setup
    y = torch.randn(5, 12, 2)  # [N, T_f, 2]
    assert model(y, step, context).shape == y.shape


def test_output_with_sample_axes(setup):
    model, context = setup
    y = torch.randn(4, 5, 12, 2)  # [K, N, T_f, 2]
    assert model(y, 7, context).shape == y.shape
    assert model(y, torch.randint(0, 10, (4, 5)), context).shape == y.shape


def test_broadcast_step_equals_per_element_steps(setup):
    model, context = setup
    y = torch.randn(4, 5, 12, 2)  # [K, N, T_f, 2]
    shared = model(y, 6, context)
    per_sample = model(y, torch.full((4, 5), 6), context)
    torch.testing.assert_close(shared, per_sample, atol=1e-5, rtol=1e-5)
    # the step does matter
    assert not torch.allclose(shared, model(y, 2, context))


def test_per_agent_steps_act_per_agent(setup):
    model, context = setup
    y = torch.randn(5, 12, 2)
    s = torch.tensor([0, 1, 2, 3, 4])
    out = model(y, s, context)
    for i in range(5):  # each agent's output is the one a shared step s_i gives it
        torch.testing.assert_close(out[i], model(y, int(s[i]), context)[i], atol=1e-5, rtol=1e-5)


def test_gradients_reach_every_parameter():
    torch.manual_seed(0)
    model = Denoiser(TINY)
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    context = model.context(scene_features(batch, 1.0))
    y = torch.randn(2, 5, 12, 2)
    loss = (model(y, torch.randint(0, 10, (2, 5)), context) - y).pow(2).mean()
    loss.backward()
    for name, p in model.named_parameters():
        assert p.grad is not None, name
        assert torch.isfinite(p.grad).all(), name
        assert p.grad.abs().sum() > 0, name


@pytest.mark.parametrize("roles", [0, 3])
def test_only_a_denoiser_with_roles_depends_on_the_order_of_a_scenes_agents(roles):
    import dataclasses

    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, denoiser_roles=roles)
    model = Denoiser(cfg).eval()
    scene = make_scene(3)
    order = [2, 0, 1]
    swapped = dataclasses.replace(scene, history=scene.history[order],
                                  future=scene.future[order])  # fmt: skip
    with torch.no_grad():
        a = model.context(scene_features(collate([scene]), 1.0))  # [N, H]
        b = model.context(scene_features(collate([swapped]), 1.0))
    assert torch.allclose(a[order], b, atol=1e-5) == (roles == 0)
    # a denoiser field: a generator's config must state the same value as its denoiser's
    assert cfg.denoiser_part() != TINY.denoiser_part() or roles == 0
