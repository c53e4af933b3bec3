"""The PPO pieces against plain reference loops and torch.distributions."""

import math

import pytest
import torch
from torch.distributions import Normal

from trajpref.rl import ppo


def _loop_gae(rewards, values, gamma, lam):
    """cleanrl-style backward loop over one trajectory (lists)."""
    t_len = len(rewards)
    adv = [0.0] * t_len
    last = 0.0
    for t in reversed(range(t_len)):
        next_v = values[t + 1] if t + 1 < t_len else 0.0
        delta = rewards[t] + gamma * next_v - values[t]
        last = delta + gamma * lam * last
        adv[t] = last
    return adv, [a + v for a, v in zip(adv, values, strict=True)]


@pytest.mark.parametrize(("gamma", "lam"), [(0.99, 0.0), (0.99, 0.95), (1.0, 1.0), (0.9, 0.5)])
def test_gae_matches_a_plain_loop(gamma, lam):
    g = torch.Generator().manual_seed(0)
    rewards = torch.randn(3, 4, 12, generator=g, dtype=torch.float64)
    values = torch.randn(3, 4, 12, generator=g, dtype=torch.float64)
    adv, ret = ppo.gae(rewards, values, gamma, lam)
    for k in range(3):
        for n in range(4):
            a, r = _loop_gae(rewards[k, n].tolist(), values[k, n].tolist(), gamma, lam)
            torch.testing.assert_close(adv[k, n], torch.tensor(a, dtype=torch.float64))
            torch.testing.assert_close(ret[k, n], torch.tensor(r, dtype=torch.float64))


def test_lambda_zero_is_the_papers_one_step_advantage():
    rewards = torch.tensor([1.0, 2.0, 3.0])
    values = torch.tensor([0.5, 0.25, 1.0])
    adv, _ = ppo.gae(rewards, values, 0.5, 0.0)
    # Eq. 14: A_t = R_t + gamma V_{t+1} - V_t, with V_{T+1} = 0
    assert adv.tolist() == [1.0 + 0.5 * 0.25 - 0.5, 2.0 + 0.5 * 1.0 - 0.25, 3.0 - 1.0]


def test_log_prob_equals_torch_normal():
    g = torch.Generator().manual_seed(1)
    y = torch.randn(5, 3, 12, 2, generator=g)
    mean = torch.randn(3, 12, 2, generator=g)
    log_sigma = torch.randn(5, 3, generator=g) * 0.3
    ours = ppo.gaussian_log_prob(y, mean, log_sigma)
    dist = torch.distributions.Normal(mean[None], log_sigma.exp()[..., None, None])
    ref = dist.log_prob(y).sum(-1)  # summed over x and y
    torch.testing.assert_close(ours, ref)


def test_log_prob_is_not_evaluated_at_the_mean():
    mean = torch.zeros(1, 12, 2)
    log_sigma = torch.zeros(1, 1)
    near = ppo.gaussian_log_prob(torch.zeros(1, 1, 12, 2), mean, log_sigma)
    far = ppo.gaussian_log_prob(torch.ones(1, 1, 12, 2), mean, log_sigma)
    assert (near > far).all()


def _loop_policy_loss(logp, logp_ref, adv, clip):
    total = 0.0
    for lp, lr, a in zip(logp.flatten().tolist(), logp_ref.flatten().tolist(),
                         adv.flatten().tolist(), strict=True):  # fmt: skip
        ratio = math.exp(lp - lr)
        total += min(ratio * a, max(min(ratio, 1 + clip), 1 - clip) * a)
    return -total / logp.numel()


def test_policy_loss_matches_a_plain_loop():
    g = torch.Generator().manual_seed(2)
    logp = torch.randn(4, 3, 12, generator=g, dtype=torch.float64)
    logp_ref = logp + 0.3 * torch.randn(4, 3, 12, generator=g, dtype=torch.float64)
    adv = torch.randn(4, 3, 12, generator=g, dtype=torch.float64)
    loss, clip_frac, approx_kl = ppo.policy_loss(logp, logp_ref, adv, 0.2)
    assert loss.item() == pytest.approx(_loop_policy_loss(logp, logp_ref, adv, 0.2))
    pairs = list(zip(logp.flatten().tolist(), logp_ref.flatten().tolist(), strict=True))
    clipped = sum(not 0.8 <= math.exp(lp - lr) <= 1.2 for lp, lr in pairs)
    assert clip_frac.item() == pytest.approx(clipped / len(pairs)) and 0 < clipped < len(pairs)
    # k3 of the log-ratio log rho = logp - logp_ref: E[rho - 1 - log rho]
    k3 = sum(math.exp(lp - lr) - 1 - (lp - lr) for lp, lr in pairs) / len(pairs)
    assert approx_kl.item() == pytest.approx(k3) and k3 > 0


def test_value_loss_matches_a_plain_loop():
    g = torch.Generator().manual_seed(3)
    v = torch.randn(50, generator=g, dtype=torch.float64)
    v0 = torch.randn(50, generator=g, dtype=torch.float64)
    target = torch.randn(50, generator=g, dtype=torch.float64)
    expected = 0.0
    for a, b, r in zip(v.tolist(), v0.tolist(), target.tolist(), strict=True):
        clipped = min(max(a, b - 0.2), b + 0.2)
        expected += max((a - r) ** 2, (clipped - r) ** 2)
    assert ppo.value_loss(v, v0, target, 0.2).item() == pytest.approx(expected / 50)


@pytest.mark.parametrize("form", ["paper", "logratio"])
def test_kl_is_zero_when_policy_equals_reference(form):
    logp = torch.randn(4, 3, 12)
    assert torch.equal(ppo.kl_penalty(logp, logp.clone(), 0.5, form), torch.zeros_like(logp))
    with pytest.raises(ValueError, match=r"^unknown KL form 'other'; use 'paper' or 'logratio'$"):
        ppo.kl_penalty(logp, logp, 0.5, "other")


def test_kl_forms_by_hand():
    logp, logp_ref = torch.tensor([-1.0]), torch.tensor([-2.0])
    assert ppo.kl_penalty(logp, logp_ref, 0.5, "logratio").item() == pytest.approx(0.5)
    paper = 0.5 * math.exp(-2.0) * (-2.0 - -1.0)
    assert ppo.kl_penalty(logp, logp_ref, 0.5, "paper").item() == pytest.approx(paper)


def test_whiten_per_group():
    x = torch.cat([torch.full((2, 1, 3), 5.0), torch.arange(6.0).view(2, 1, 3)], 1)  # [2, 2, 3]
    out = ppo.whiten_per_group(x, torch.tensor([0, 1]), 2)
    assert torch.allclose(out[:, 0], torch.zeros(2, 3))  # a constant group becomes zero
    assert out[:, 1].mean().abs() < 1e-6 and (out[:, 1].std(unbiased=False) - 1).abs() < 1e-4


def test_explained_variance():
    t = torch.randn(100)
    assert ppo.explained_variance(t, t).item() == pytest.approx(1.0)
    assert ppo.explained_variance(torch.full_like(t, t.mean().item()), t).item() == pytest.approx(
        0.0, abs=1e-6
    )


def test_policy_loss_stays_finite_for_huge_log_ratios():
    logp = torch.tensor([500.0, -500.0, 0.0])
    loss, clip_frac, approx_kl = ppo.policy_loss(
        logp, torch.zeros(3), torch.tensor([1.0, -1.0, 0.0]), 0.2
    )
    assert torch.isfinite(loss) and torch.isfinite(approx_kl)
    assert clip_frac.item() == pytest.approx(2 / 3)


def test_antithetic_advantage_cancels_what_the_pair_shares():
    torch.manual_seed(0)
    shared = torch.randn(4, 3, 1) * 100  # [K, N, 1]: which sample it is, denoising noise
    effect = torch.randn(4, 3, 5)  # [K, N, T]: what +xi changes
    plus, minus = ppo.antithetic_advantage(shared + effect, shared - effect)
    assert torch.allclose(plus, effect, atol=1e-4) and torch.equal(minus, -plus)
    same = ppo.antithetic_advantage(shared.expand(4, 3, 5), shared.expand(4, 3, 5))[0]
    assert torch.count_nonzero(same) == 0
    # a plain loop
    a, b = torch.randn(2, 3, 4), torch.randn(2, 3, 4)
    plus = ppo.antithetic_advantage(a, b)[0]
    for i in range(2):
        for j in range(3):
            for t in range(4):
                assert plus[i, j, t] == (a[i, j, t] - b[i, j, t]) / 2


def test_smooth_basis_is_orthonormal_and_spans_t_and_t_squared():
    q = ppo.smooth_basis(12)  # [T, 2]
    assert torch.allclose(q.T @ q, torch.eye(2), atol=1e-6)
    t = torch.arange(1, 13) / 12
    for f in (t, t**2, 3 * t - t**2):
        assert torch.allclose(q @ (q.T @ f), f, atol=1e-5)  # inside the span
    assert not torch.allclose(q @ (q.T @ t**3), t**3, atol=1e-3)  # t^3 is not


def test_smooth_noise_is_smooth_and_has_the_asked_rms():
    q = ppo.smooth_basis(12)
    xi = ppo.smooth_noise(torch.Size([4000, 3, 12, 2]), q, 0.05, torch.Generator().manual_seed(0))
    proj = torch.einsum("tj,sj,ksnd->ktnd", q, q, xi.transpose(1, 2)).transpose(1, 2)
    assert torch.allclose(proj, xi, atol=1e-6)  # no component outside t, t^2
    assert float(xi.pow(2).mean().sqrt()) == pytest.approx(0.05, rel=0.03)


def test_smooth_log_prob_is_the_coefficients_gaussian_density_up_to_a_constant():
    q, std = ppo.smooth_basis(12), 0.1
    g = torch.Generator().manual_seed(1)
    mean = torch.randn(2, 3, 12, 2, generator=g)
    c = torch.randn(2, 3, 2, 2, generator=g) * 0.2  # [K, N, J, 2] coefficients
    y = mean + torch.einsum("tj,knjd->kntd", q, c)
    coeff_std = std * (12 / 2) ** 0.5
    exact = Normal(0.0, coeff_std).log_prob(c).sum((-1, -2))  # [K, N]
    ours = ppo.smooth_log_prob(y, mean, std, q).sum(-1)  # [K, N]
    offset = ours - exact
    assert torch.allclose(offset, offset.flatten()[0].expand_as(offset), atol=1e-4)
    # a change of the mean outside the span (a zig-zag) does not move the density
    zigzag = torch.tensor([(-1.0) ** i for i in range(12)])[:, None] * 0.3  # [T, 1]
    zig = zigzag - q @ (q.T @ zigzag)
    moved = ppo.smooth_log_prob(y, mean + zig, std, q)
    assert torch.allclose(moved, ppo.smooth_log_prob(y, mean, std, q), atol=1e-5)
