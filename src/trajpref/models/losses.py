"""The supervised losses of the two pretraining stages, in the networks' frame.

The generator's loss is also fine-tuning's L_reg (Eq. 17 / 20), so it lives beside the
models rather than in a training stage.
"""

from __future__ import annotations

import torch

from trajpref.config import GeneratorTrainConfig
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import GeneratorOutput


def denoiser_loss(
    denoiser: Denoiser, schedule: DDPMSchedule, context: torch.Tensor, y0: torch.Tensor,
    draws: int, generator: torch.Generator | None = None,
) -> torch.Tensor:  # fmt: skip
    """Eq. 2: || eps_theta(sqrt(abar_s) y0 + sqrt(1 - abar_s) z, s, X) - z ||^2 averaged over
    ``draws`` (step, noise) pairs per agent. y0 [N, T_f, 2], context [N, H]."""
    device = y0.device
    m, n = draws, y0.shape[0]
    s = torch.randint(0, schedule.num_steps, (m, n), generator=generator).to(device)  # [M, N]
    z = torch.randn((m, *y0.shape), generator=generator).to(device)  # [M, N, T_f, 2]
    y_s = schedule.add_noise(y0.expand(m, -1, -1, -1), z, s)  # [M, N, T_f, 2]
    eps = denoiser(y_s, s, context)  # [M, N, T_f, 2]
    return (eps - z).pow(2).mean()


def wta_temperature(c: GeneratorTrainConfig, progress: float) -> float:
    """The annealed best-of-K temperature at ``progress`` (fraction of the run's optimiser
    steps done, 0..1): ``c.wta_temperature`` decaying geometrically to a thousandth of itself
    over the first ``c.wta_anneal`` of the run, then 0 (the hard minimum)."""
    if c.wta_temperature == 0 or progress >= c.wta_anneal:
        return 0.0
    return c.wta_temperature * 1e-3 ** (max(progress, 0.0) / c.wta_anneal)


def soft_best(distance: torch.Tensor, temperature: float) -> torch.Tensor:
    """Per agent, the best-of-K distance of ``distance`` [K, N]: the minimum over K when the
    temperature is 0, else the K distances weighted by their softmin at that temperature
    (weights without gradient: annealed winner-takes-all). Returns [N]."""
    if temperature == 0:
        return distance.min(0).values
    weights = torch.softmax(-distance.detach() / temperature, dim=0)  # [K, N]
    return (weights * distance).sum(0)


def generator_loss(
    out: GeneratorOutput, y: torch.Tensor, target: torch.Tensor, c: GeneratorTrainConfig,
    temperature: float = 0.0,
) -> tuple[torch.Tensor, dict[str, float]]:  # fmt: skip
    """The generator's supervised loss on denoised samples y [K, N, T_f, 2] against the
    target [N, T_f, 2]:

        w_best * min_k (ADE_k + w_fde FDE_k) + w_mean * ADE(mu) + w_unc * (e^{-l} ADE(mu) + l)
        + w_reg * Eq. 4,   with l the agent's mean log sigma

    (with ``winner: separate`` the first term is min_k ADE_k + w_fde min_k FDE_k).

    With a ``temperature`` > 0 the minimum is the softmin-weighted mean of ``soft_best``
    (annealed winner-takes-all; ``wta_temperature`` gives its schedule).
    A target with NaN steps (an agent that left the view, ``DataConfig.partial_future``; its
    first step must be seen) is scored on its seen steps only: its ADE terms are means over
    them, its endpoint is its last seen step, and Eq. 4 averages over seen steps.

    Returns ``(loss, logs)``."""
    seen = torch.isfinite(target).all(-1)  # [N, T_f]
    if not bool(seen.all()):
        return _partial_generator_loss(out, y, target, seen, c, temperature)
    err = torch.linalg.vector_norm(y - target, dim=-1)  # [K, N, T_f]
    ade, fde = err.mean(-1), err[..., -1]  # [K, N]
    if c.time_weights == "decreasing":  # LED's step weights T_f, ..., 1, mean 1
        t_f = err.shape[-1]
        w = torch.arange(t_f, 0, -1, dtype=err.dtype, device=err.device)  # [T_f]
        ade = (err * (w / w.mean())).mean(-1)  # [K, N]
    mean_err = torch.linalg.vector_norm(out.mean - target, dim=-1).mean(-1)  # [N]
    reg = (y - target).pow(2).sum(-1).mean()  # Eq. 4
    return _combine(out, c, ade, fde, temperature, mean_err, reg)


def _partial_generator_loss(
    out: GeneratorOutput, y: torch.Tensor, target: torch.Tensor, seen: torch.Tensor,
    c: GeneratorTrainConfig, temperature: float,
) -> tuple[torch.Tensor, dict[str, float]]:  # fmt: skip
    """``generator_loss`` over the seen steps ``seen`` [N, T_f] of each target."""
    steps = torch.arange(seen.shape[-1], device=seen.device)  # [T_f]
    n_seen = seen.sum(-1)  # [N]
    if not bool(seen[:, 0].all()) or bool((seen != (steps < n_seen[:, None])).any()):
        raise ValueError("generator_loss: a target's seen steps must be its first ones, at "
                         "least one (NaN from the first step it was not seen on)")  # fmt: skip
    w = seen.to(y.dtype)  # [N, T_f] 1 where seen
    if c.time_weights == "decreasing":  # LED's step weights T_f, ..., 1, masked
        w = w * (seen.shape[-1] - steps).to(y.dtype)  # [N, T_f]
    w = w / w.sum(-1, keepdim=True)  # [N, T_f], each agent's weights sum to 1
    clean = torch.where(seen[..., None], target, torch.zeros_like(target))  # [N, T_f, 2]
    err = torch.linalg.vector_norm(y - clean, dim=-1)  # [K, N, T_f]
    ade = (err * w).sum(-1)  # [K, N]
    last = n_seen - 1  # [N] the last seen step (seen steps come first)
    fde = err.gather(-1, last.expand(err.shape[0], -1)[..., None])[..., 0]  # [K, N]
    mean_err = (torch.linalg.vector_norm(out.mean - clean, dim=-1) * seen).sum(-1) / n_seen
    reg = ((y - clean).pow(2).sum(-1) * seen).sum() / (y.shape[0] * n_seen.sum())  # Eq. 4
    return _combine(out, c, ade, fde, temperature, mean_err, reg)


def _combine(
    out: GeneratorOutput, c: GeneratorTrainConfig, ade: torch.Tensor, fde: torch.Tensor,
    temperature: float, mean_err: torch.Tensor, reg: torch.Tensor,
) -> tuple[torch.Tensor, dict[str, float]]:  # fmt: skip
    """``generator_loss`` from each sample's ADE and FDE [K, N], the mean's error [N] and Eq.
    4: the best-of-K term, then the weighted sum of the terms, and its logs."""
    if c.winner == "separate":  # independent winners for the path and the endpoint
        best = (soft_best(ade, temperature) + c.fde_weight * soft_best(fde, temperature)).mean()
    else:
        best = soft_best(ade + c.fde_weight * fde, temperature).mean()  # [K, N] -> scalar
    log_sigma = out.log_sigma.mean(0)  # [N]
    unc = (torch.exp(-log_sigma) * mean_err.detach() + log_sigma).mean()
    loss = (c.best_of_k_weight * best + c.mean_weight * mean_err.mean()
            + c.uncertainty_weight * unc + c.reg_weight * reg)  # fmt: skip
    logs = {k: float(v.detach()) for k, v in (
        ("best_of_k", best), ("mean_ade", mean_err.mean()), ("uncertainty", unc),
        ("eq4", reg), ("sigma", out.log_sigma.exp().mean()))}  # fmt: skip
    return loss, logs
