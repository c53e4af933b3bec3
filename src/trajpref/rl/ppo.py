"""PPO pieces as small pure functions (the paper's Eq. 12-16), in the style of cleanrl/TRL.

Shapes: K samples, N agents, T = T_f future steps. Every function works on any leading shape;
time is the last axis where it matters.
"""

from __future__ import annotations

import math

import torch

LOG_2PI = math.log(2 * math.pi)
LOG_RATIO_BOUND = 20.0
"""Log-ratios are clamped to +-this before exponentiation (numerical guard only)."""


def gaussian_log_prob(
    y: torch.Tensor, mean: torch.Tensor, log_sigma: torch.Tensor, per_sample: bool = False
):
    """Eq. 12: log N(y; mu, sigma^2 I) per step, summed over x and y.

    y [K, N, T, 2] (the action), mean [N, T, 2] shared by the K samples (or [K, N, T, 2] with
    ``per_sample``), log_sigma [K, N] -> [K, N, T]. The density is evaluated at the action,
    never at the mean itself.
    """
    var = torch.exp(2 * log_sigma)[..., None]  # [K, N, 1]
    sq = (y - (mean if per_sample else mean[None])).pow(2).sum(-1)  # [K, N, T]
    return -0.5 * sq / var - 2 * log_sigma[..., None] - LOG_2PI


def smooth_basis(steps: int, degree: int = 2) -> torch.Tensor:
    """Orthonormal columns [T, degree] spanning t, t^2, ... over the future steps t = 1..T
    (each vanishes at the last observed position): smooth exploration directions."""
    t = torch.arange(1, steps + 1, dtype=torch.float64) / steps  # [T]
    raw = torch.stack([t**j for j in range(1, degree + 1)], -1)  # [T, J]
    q, _ = torch.linalg.qr(raw)
    return q.float()  # [T, J]


def smooth_noise(shape: torch.Size, basis: torch.Tensor, std: float,
                 generator: torch.Generator | None = None) -> torch.Tensor:  # fmt: skip
    """Noise of shape [..., T, 2] in the span of ``basis`` [T, J] whose RMS per step and
    coordinate is ``std``: coefficients c ~ N(0, (std sqrt(T / J))^2), xi = basis @ c."""
    t, j = basis.shape
    coeff = torch.randn((*shape[:-2], j, shape[-1]), generator=generator)  # [..., J, 2]
    coeff = coeff.to(basis) * std * math.sqrt(t / j)
    return torch.einsum("tj,...jd->...td", basis, coeff)  # [..., T, 2]


def smooth_log_prob(y: torch.Tensor, mean: torch.Tensor, std: float,
                    basis: torch.Tensor) -> torch.Tensor:  # fmt: skip
    """Per-step log density of ``smooth_noise``: y, mean [K, N, T, 2] -> [K, N, T]. The
    difference is projected on the basis, so summed over T it is the Gaussian log density
    of the coefficients (up to a constant that cancels in every ratio); a policy change
    outside the smooth span does not move it."""
    t, j = basis.shape
    diff = y - mean  # [K, N, T, 2]
    proj = torch.einsum("tj,sj,...sd->...td", basis, basis, diff)  # [K, N, T, 2]
    var = std**2 * t / j
    return -0.5 * proj.pow(2).sum(-1) / var - math.log(var) - LOG_2PI


def kl_penalty(logp: torch.Tensor, logp_ref: torch.Tensor, beta: float, form: str = "paper"):
    """Eq. 13: the per-step divergence that is subtracted from the reward.

    ``paper``: beta * p_0 * (log p_0 - log p_theta), with p_0 the reference density, as
    printed. ``logratio``: beta * (log p_theta - log p_0), the usual RLHF estimator.
    Both are zero when the policy equals the reference.
    """
    if form == "paper":
        return beta * logp_ref.exp() * (logp_ref - logp)
    if form == "logratio":
        return beta * (logp - logp_ref)
    raise ValueError(f"unknown KL form {form!r}; use 'paper' or 'logratio'")


def gae(rewards: torch.Tensor, values: torch.Tensor, gamma: float, lam: float):
    """Advantages and returns over the last (time) axis, with V(T + 1) = 0.

    A_t = sum_l (gamma lam)^l delta_{t+l}, delta_t = R_t + gamma V_{t+1} - V_t.
    ``lam = 0`` is the paper's one-step Eq. 14. Returns ``(advantages, returns)``,
    returns = advantages + values.
    """
    t_len = rewards.shape[-1]
    next_values = torch.cat([values[..., 1:], torch.zeros_like(values[..., :1])], -1)
    deltas = rewards + gamma * next_values - values  # [..., T]
    if lam == 0:
        adv = deltas
    else:
        # discounted suffix sums as one matrix product: W[t, u] = (gamma lam)^(u - t), u >= t
        idx = torch.arange(t_len, device=rewards.device)
        power = (idx[None, :] - idx[:, None]).to(rewards.dtype)  # [T, T]
        w = torch.where(power >= 0, (gamma * lam) ** power.clamp(min=0), torch.zeros(()))
        adv = deltas @ w.T  # [..., T]
    return adv, adv + values


def antithetic_advantage(reward_plus: torch.Tensor, reward_minus: torch.Tensor):
    """Advantages of a pair of actions mean + xi and mean - xi rolled out under the same
    environment noise: A(+xi) = (R(+xi) - R(-xi)) / 2 and A(-xi) = -A(+xi).

    Whatever the pair shares (which sample it is, the denoising noise) cancels, so only the
    part of the reward the exploration xi changes is left. [K, N, T] -> two [K, N, T].
    """
    half = (reward_plus - reward_minus) / 2
    return half, -half


def policy_loss(logp: torch.Tensor, logp_ref: torch.Tensor, adv: torch.Tensor, clip: float):
    """Eq. 15: -E[min(rho A, clip(rho, 1 - eps, 1 + eps) A)], rho = p_theta / p_0, with
    ``logp_ref`` the ratio's denominator (the reference G_0 as printed, or the rollout policy).

    Returns ``(loss, clip_fraction, approx_kl)``; approx_kl is E[(rho - 1) - log rho] over the
    actions (Schulman's k3). The actions are drawn from the rollout policy p_old, so it
    estimates KL(p_old || p_theta) only when the denominator is p_old
    (``ratio_against=rollout``); against the reference it estimates no KL, and only says how
    far rho is from 1 on these actions (``kl_to_reference`` in the log is the KL to G_0).
    """
    # bounded before exp: a peaked Gaussian can give log-ratios of hundreds, whose exp
    # overflows to inf and then to NaN (inf * 0); beyond +-20 the ratio is clipped anyway
    log_ratio = (logp - logp_ref).clamp(-LOG_RATIO_BOUND, LOG_RATIO_BOUND)
    ratio = log_ratio.exp()
    unclipped = ratio * adv
    clipped = ratio.clamp(1 - clip, 1 + clip) * adv
    loss = -torch.minimum(unclipped, clipped).mean()
    with torch.no_grad():
        clip_frac = ((ratio - 1).abs() > clip).float().mean()
        approx_kl = k3_divergence(log_ratio)
    return loss, clip_frac, approx_kl


def k3_divergence(log_ratio: torch.Tensor, log_base: torch.Tensor | None = None) -> torch.Tensor:
    """Schulman's k3 estimate E[(rho - 1) - log rho] of KL(q || p) from samples of q, with
    log rho = log p - log q = ``log_ratio`` (or ``log_ratio - log_base`` when given)."""
    if log_base is not None:
        log_ratio = log_ratio - log_base
    return (log_ratio.exp() - 1 - log_ratio).mean()


def value_loss(values: torch.Tensor, values_ref: torch.Tensor, target: torch.Tensor, clip: float):
    """Eq. 16: E[max((V - R)^2, (clip(V, V_0 - eps, V_0 + eps) - R)^2)]."""
    clipped = values_ref + (values - values_ref).clamp(-clip, clip)
    return torch.maximum((values - target).pow(2), (clipped - target).pow(2)).mean()


def explained_variance(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """1 - Var(target - pred) / Var(target) (1 is perfect, 0 is no better than a constant)."""
    var = target.var()
    return 1 - (target - pred).var() / var if var > 0 else torch.tensor(float("nan"))


def whiten_per_group(x: torch.Tensor, group: torch.Tensor, num_groups: int, eps: float = 1e-8):
    """Normalise x [K, N, T] to zero mean and unit std within each scene (group [N])."""
    k, _, t = x.shape
    count = torch.bincount(group, minlength=num_groups).to(x.dtype) * k * t  # [B]
    total = x.new_zeros(num_groups).index_add_(0, group, x.sum((0, 2)))  # [B]
    mean = (total / count)[group][None, :, None]  # [1, N, 1]
    sq = x.new_zeros(num_groups).index_add_(0, group, (x - mean).pow(2).sum((0, 2)))
    std = (sq / count).sqrt()[group][None, :, None]
    return (x - mean) / (std + eps)
