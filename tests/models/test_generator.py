import pytest
import torch
from synthetic import make_scene

from trajpref.config import ModelConfig
from trajpref.models.encoder import scene_features
from trajpref.models.generator import Generator
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
