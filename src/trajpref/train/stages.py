"""The pretraining stages: the denoiser (Eq. 2) and the leapfrog generator (Eq. 1, 3, 4)."""

from __future__ import annotations

import dataclasses
from typing import Any

import torch
from torch import nn

from trajpref.config import DenoiserTrainConfig, ExperimentConfig, GeneratorTrainConfig
from trajpref.data.loader import SceneLoader
from trajpref.data.transforms import to_relative
from trajpref.diffusion.samplers import denoise
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.models.generator import Generator
from trajpref.models.predictor import DiffusionPredictor
from trajpref.train import checkpoint as ckpt
from trajpref.train.evaluate import evaluate
from trajpref.train.loop import Stage
from trajpref.types import Batch, TrajectoryDataset


def data_scale(dataset: TrajectoryDataset) -> float:
    """RMS of the future positions relative to each agent's last observation: networks see
    coordinates divided by it, so one config serves metres and pixels."""
    total, count = 0.0, 0
    for s in dataset.scenes:
        rel = s.future - s.history[:, -1:]  # [P, T_f, 2]
        total += float((rel.astype("float64") ** 2).sum())
        count += rel.size
    return max(1e-3, (total / max(1, count)) ** 0.5)


def _subset(dataset: TrajectoryDataset, max_scenes: int | None) -> TrajectoryDataset:
    if max_scenes is None or len(dataset) <= max_scenes:
        return dataset
    idx = torch.linspace(0, len(dataset) - 1, max_scenes).long().tolist()  # evenly spread
    return TrajectoryDataset([dataset.scenes[i] for i in idx], dataset.info)


class DenoiserObjective(nn.Module):
    """Eq. 2: || eps_theta(sqrt(abar_s) y + sqrt(1 - abar_s) z, s, X) - z ||^2."""

    def __init__(self, denoiser: Denoiser, schedule: DDPMSchedule, scale: float, draws: int):
        super().__init__()
        self.denoiser = denoiser
        self.schedule = schedule
        self.scale = scale
        self.draws = draws

    def forward(self, batch: Batch, generator: torch.Generator | None = None):
        device = batch.history.device
        f = scene_features(batch, self.scale)
        context = self.denoiser.context(f)  # [N, H]
        _, fut_rel = to_relative(batch)
        y0 = fut_rel / self.scale  # [N, T_f, 2]
        m, n = self.draws, batch.num_agents
        s = torch.randint(0, self.schedule.num_steps, (m, n), generator=generator).to(device)
        z = torch.randn((m, *y0.shape), generator=generator).to(device)  # [M, N, T_f, 2]
        y_s = self.schedule.add_noise(y0.expand(m, -1, -1, -1), z, s)  # [M, N, T_f, 2]
        eps = self.denoiser(y_s, s, context)  # [M, N, T_f, 2]
        loss = (eps - z).pow(2).mean()
        return loss, {}


def build_denoiser_stage(
    cfg: ExperimentConfig, train: TrajectoryDataset, val: TrajectoryDataset,
    device: torch.device,
) -> tuple[Stage, float]:  # fmt: skip
    """Stage 1. Validation: Eq. 2 on the validation split with fixed noise (lower is better)."""
    torch.manual_seed(cfg.seed)
    scale = data_scale(train)
    denoiser = Denoiser(cfg.model).to(device)
    schedule = DDPMSchedule(**vars(cfg.diffusion)).to(device)
    tcfg: DenoiserTrainConfig = cfg.denoiser
    objective = DenoiserObjective(denoiser, schedule, scale, tcfg.noise_draws)
    val_set = _subset(val, tcfg.eval_max_scenes)

    @torch.no_grad()
    def validate() -> dict[str, float]:
        gen = torch.Generator().manual_seed(12345)
        total, agents = 0.0, 0
        for batch in SceneLoader(val_set, max_agents=cfg.data.max_agents):
            loss, _ = objective(batch.to(device), gen)
            total += float(loss) * batch.num_agents
            agents += batch.num_agents
        return {"denoise_loss": total / agents, "score": total / agents}

    def payload(meta: dict[str, Any]) -> dict[str, Any]:
        return ckpt.denoiser_payload(denoiser, cfg, scale, meta)

    return Stage("denoiser", objective, denoiser, validate, payload), scale


class GeneratorObjective(nn.Module):
    """Trains G through tau steps of the frozen denoiser.

    loss = w_best * min_k (ADE_k + FDE_k) + w_mean * ADE(mu) + w_unc * (e^{-l} ADE(mu) + l)
           + w_reg * Eq. 4,   with l the agent's mean log sigma,
    all in normalised units on the denoised samples Y = D^r(X, mu + sigma * S).
    """

    def __init__(self, generator: Generator, denoiser: Denoiser, schedule: DDPMSchedule,
                 scale: float, cfg: GeneratorTrainConfig):  # fmt: skip
        super().__init__()
        self.generator = generator
        self.denoiser = denoiser.requires_grad_(False).eval()
        self.schedule = schedule
        self.scale = scale
        self.cfg = cfg

    def train(self, mode: bool = True):
        super().train(mode)
        self.denoiser.eval()  # frozen, always
        return self

    def forward(self, batch: Batch, generator: torch.Generator | None = None):
        f = scene_features(batch, self.scale)
        with torch.no_grad():
            context = self.denoiser.context(f)  # [N, H]
        out = self.generator(f)
        y_tau = out.initial_sample()  # [K, N, T_f, 2]
        y = denoise(
            self.schedule, lambda x, s: self.denoiser(x, s, context), y_tau, self.cfg.tau, generator
        )  # fmt: skip  [K, N, T_f, 2]
        target = to_relative(batch)[1] / self.scale  # [N, T_f, 2]
        return generator_loss(out, y, target, self.cfg)


def generator_loss(out, y: torch.Tensor, target: torch.Tensor, c: GeneratorTrainConfig):
    """The generator's supervised loss on denoised samples y [K, N, T_f, 2] (normalised):
    w_best * min_k (ADE_k + FDE_k) + w_mean * ADE(mu) + w_unc * (e^{-l} ADE(mu) + l)
    + w_reg * Eq. 4. Shared by pretraining and by the RL stages (their L_reg)."""
    err = torch.linalg.vector_norm(y - target, dim=-1)  # [K, N, T_f]
    ade, fde = err.mean(-1), err[..., -1]  # [K, N]
    best = (ade + fde).min(0).values.mean()
    mean_err = torch.linalg.vector_norm(out.mean - target, dim=-1).mean(-1)  # [N]
    log_sigma = out.log_sigma.mean(0)  # [N]
    unc = (torch.exp(-log_sigma) * mean_err.detach() + log_sigma).mean()
    reg = (y - target).pow(2).sum(-1).mean()  # Eq. 4
    loss = (c.best_of_k_weight * best + c.mean_weight * mean_err.mean()
            + c.uncertainty_weight * unc + c.reg_weight * reg)  # fmt: skip
    logs = {k: float(v.detach()) for k, v in (
        ("best_of_k", best), ("mean_ade", mean_err.mean()), ("uncertainty", unc),
        ("eq4", reg), ("sigma", out.log_sigma.exp().mean()))}  # fmt: skip
    return loss, logs


def build_generator_stage(
    cfg: ExperimentConfig, denoiser_payload: dict[str, Any], val: TrajectoryDataset,
    device: torch.device,
) -> Stage:  # fmt: skip
    """Stage 2. Validation: minADE_K + minFDE_K of the leapfrog sampler (lower is better)."""
    torch.manual_seed(cfg.seed)
    denoiser, dcfg = ckpt.build_denoiser(denoiser_payload)
    # G may have its own width; everything else describes the frozen denoiser or the data
    shared = dataclasses.replace(cfg.model, generator_width=dcfg.model.generator_width)
    if shared != dcfg.model or dcfg.diffusion != cfg.diffusion:
        raise ValueError(
            "the generator config's model/diffusion sections differ from the denoiser "
            "checkpoint's (only model.generator_width may differ)"
        )
    scale = denoiser_payload["scale"]
    denoiser = denoiser.to(device)
    gcfg: GeneratorTrainConfig = cfg.generator
    generator = Generator(cfg.model, gcfg.samples).to(device)
    schedule = DDPMSchedule(**vars(cfg.diffusion)).to(device)
    objective = GeneratorObjective(generator, denoiser, schedule, scale, gcfg)
    predictor = DiffusionPredictor(cfg.model, cfg.diffusion, scale, denoiser, generator,
                                   gcfg.tau, "leapfrog").to(device)  # fmt: skip
    val_set = _subset(val, gcfg.eval_max_scenes)

    def validate() -> dict[str, float]:
        res = evaluate(predictor, val_set, gcfg.samples, seed=0, device=device,
                       max_agents=cfg.data.max_agents, progress=False)  # fmt: skip
        return {"min_ade": res["min_ade"], "min_fde": res["min_fde"],
                "score": res["min_ade"] + res["min_fde"]}  # fmt: skip

    def payload(meta: dict[str, Any]) -> dict[str, Any]:
        return ckpt.generator_payload(generator, denoiser_payload, cfg, meta)

    return Stage("generator", objective, generator, validate, payload)
