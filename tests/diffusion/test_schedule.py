import pytest
import torch

from trajpref.diffusion import DDPMSchedule
from trajpref.diffusion.samplers import denoise
from trajpref.errors import ConfigError


def test_golden_values():
    s = DDPMSchedule(100, 1e-4, 5e-2)
    # beta_s = 1e-4 + s * (5e-2 - 1e-4) / 99
    assert s.betas[0].item() == pytest.approx(1e-4)
    assert s.betas[50].item() == pytest.approx(1e-4 + 50 * 0.0499 / 99)
    assert s.betas[99].item() == pytest.approx(5e-2)
    # alpha_bar_1 = (1 - beta_0)(1 - beta_1), by hand
    assert s.alphas_cumprod[1].item() == pytest.approx(0.9999 * (1 - (1e-4 + 0.0499 / 99)))
    # docs/design.md: alpha_bar at the last step is about 0.08 (not pure noise)
    assert s.alphas_cumprod[99].item() == pytest.approx(0.078234, abs=1e-5)
    assert s.alphas_cumprod[49].item() == pytest.approx(0.533811, abs=1e-5)
    # posterior variance: beta_s (1 - abar_{s-1}) / (1 - abar_s); zero at s = 0
    assert s.posterior_variance[0].item() == 0.0
    expected = 5e-2 * (1 - s.alphas_cumprod[98].item()) / (1 - s.alphas_cumprod[99].item())
    assert s.posterior_variance[99].item() == pytest.approx(expected, rel=1e-5)


def test_timesteps():
    s = DDPMSchedule()
    assert s.timesteps(5) == [4, 3, 2, 1, 0]
    assert s.timesteps() == list(range(99, -1, -1))
    with pytest.raises(ValueError, match=r"^start must lie in 1\.\.100$"):
        s.timesteps(0)
    with pytest.raises(ValueError, match=r"^start must lie in 1\.\.100$"):
        s.timesteps(101)


def test_add_noise_broadcasts_per_sample_steps():
    s = DDPMSchedule()
    y0 = torch.ones(3, 4, 12, 2)
    z = torch.zeros_like(y0)
    steps = torch.tensor([[0, 10, 50, 99]] * 3)  # [3, 4]
    out = s.add_noise(y0, z, steps)
    expected = s.sqrt_alphas_cumprod[steps][..., None, None].expand_as(y0)
    torch.testing.assert_close(out, expected)
    with pytest.raises(ValueError, match=r"^step indices must lie in 0\.\.99$"):
        s.add_noise(y0, z, torch.tensor(100))


def test_perfect_denoiser_recovers_the_input():
    torch.manual_seed(0)
    s = DDPMSchedule()
    y0 = torch.randn(5, 12, 2)
    z = torch.randn(5, 12, 2)
    for step in (0, 1, 30, 99):
        y_s = s.add_noise(y0, z, torch.tensor(step))
        out = s.step(z, step, y_s, noise=torch.zeros_like(y0))
        torch.testing.assert_close(out.pred_original_sample, y0, atol=1e-4, rtol=1e-4)
    # a perfect (oracle) denoiser run over the whole leapfrog chain returns y0 exactly
    tau = 5
    y_tau = s.add_noise(y0, z, torch.tensor(tau - 1))

    def oracle(y, step):  # eps such that the x0 estimate is y0
        a, b = s.sqrt_alphas_cumprod[step], s.sqrt_one_minus_alphas_cumprod[step]
        return (y - a * y0) / b

    g = torch.Generator().manual_seed(0)
    out = denoise(s, oracle, y_tau, tau, g)
    torch.testing.assert_close(out, y0, atol=1e-4, rtol=1e-4)


def test_step_at_zero_adds_no_noise_and_is_seeded_elsewhere():
    s = DDPMSchedule()
    y = torch.randn(4, 12, 2)
    eps = torch.randn(4, 12, 2)
    a = s.step(eps, 0, y, torch.Generator().manual_seed(1)).prev_sample
    b = s.step(eps, 0, y, torch.Generator().manual_seed(2)).prev_sample
    assert torch.equal(a, b)
    a = s.step(eps, 10, y, torch.Generator().manual_seed(1)).prev_sample
    b = s.step(eps, 10, y, torch.Generator().manual_seed(1)).prev_sample
    c = s.step(eps, 10, y, torch.Generator().manual_seed(2)).prev_sample
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_bad_schedule():
    with pytest.raises(ConfigError, match=r"^num_steps must be >= 1$"):
        DDPMSchedule(0)
    with pytest.raises(ConfigError, match=r"^need 0 < beta_start <= beta_end < 1$"):
        DDPMSchedule(100, 0.1, 0.01)
