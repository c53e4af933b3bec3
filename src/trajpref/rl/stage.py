"""RLHF and RLHF-ReS fine-tuning of the generator (the paper's Steps A-C, Eq. 10-20).

Policy G_theta (from a pretrained generator), frozen reference G_0 (a copy), critic V_psi on
the policy's social encoding, frozen denoiser D as refiner (D^r, tau steps) and rewarder (the
diffusion score r). The PPO arithmetic lives in ``rl.ppo`` as pure functions.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import torch
from torch import nn

from trajpref.config import ExperimentConfig, FinetuneConfig
from trajpref.data.transforms import to_relative
from trajpref.diffusion.samplers import denoise
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.metrics import scene_sum
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.models.generator import Generator
from trajpref.models.predictor import DiffusionPredictor
from trajpref.rl import ppo
from trajpref.rl.critic import Critic
from trajpref.score.scorer import TrajectoryScorer, score_timesteps
from trajpref.train import checkpoint as ckpt
from trajpref.train.evaluate import evaluate
from trajpref.train.loop import Stage
from trajpref.train.stages import _subset, generator_loss
from trajpref.types import Batch, TrajectoryDataset


def best_sample(r: torch.Tensor, scene: torch.Tensor, num_scenes: int) -> torch.Tensor:
    """RLHF-ReS's k*: per scene, argmax_k sum_{p,t} r[k, p, t]. r [K, N, T] -> [B]."""
    return scene_sum(r.sum(-1), scene, num_scenes).argmax(0)


def take_sample(x: torch.Tensor, k_star: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
    """x [K, N, ...] -> [1, N, ...]: each agent's entry at its scene's k*."""
    idx = k_star[scene]  # [N]
    return x[idx, torch.arange(x.shape[1], device=x.device)][None]


def step_reward(scorer: TrajectoryScorer, context: torch.Tensor, futures: torch.Tensor,
                target: torch.Tensor, clip: float | None) -> torch.Tensor:  # fmt: skip
    """The per-step score r = 1 - d(Y) / d(Y_gt) (Eq. 6) that fine-tuning maximises, clipped
    to [-clip, clip] when ``clip`` is set: futures [M, N, T_f, 2] and target [N, T_f, 2] in
    the denoiser's frame, context [N, H] -> [M, N, T_f]."""
    d = scorer.residual_normalised(context, torch.cat([futures, target[None]]))  # [M+1, N, T_f]
    r = 1 - d[:-1] / d[-1]
    return r.clamp(-clip, clip) if clip is not None else r


class RLObjective(nn.Module):
    """One PPO step on a fresh rollout: L = w_reg L_reg + w_p L_pg + w_v L_val (Eq. 17 / 20)."""

    def __init__(self, policy: Generator, critic: Critic, denoiser: Denoiser,
                 schedule: DDPMSchedule, scale: float, cfg: ExperimentConfig):  # fmt: skip
        super().__init__()
        self.policy = policy
        self.critic = critic
        self.reference = copy.deepcopy(policy).requires_grad_(False).eval()
        self.denoiser = denoiser.requires_grad_(False).eval()
        self.schedule = schedule
        self.scale = scale
        self.cfg = cfg
        self.rl: FinetuneConfig = cfg.finetune
        steps = score_timesteps(schedule.num_steps, cfg.finetune.score_every)
        self.scorer = TrajectoryScorer(self.denoiser, schedule, scale, steps)

    def train(self, mode: bool = True):
        super().train(mode)
        self.reference.eval()
        self.denoiser.eval()
        return self

    def forward(self, batch: Batch, generator: torch.Generator | None = None):
        rl, tau = self.rl, self.cfg.generator.tau
        f = scene_features(batch, self.scale)
        target = to_relative(batch)[1] / self.scale  # [N, T_f, 2]
        with torch.no_grad():
            d_ctx = self.denoiser.context(f)  # [N, H]
        eps = lambda y, s: self.denoiser(y, s, d_ctx)  # noqa: E731

        # Step A: rollout of the policy (Eq. 1, 3, 10) and of the reference
        out = self.policy(f)
        mean_tau = out.initial_sample()  # [K, N, T_f, 2]
        with torch.no_grad():
            ref = self.reference(f)
            ref_tau = ref.initial_sample()
        y_tau = mean_tau
        antithetic = rl.baseline == "antithetic"
        if antithetic and generator is None:
            seed = int(torch.randint(2**62, ()))
            generator = torch.Generator().manual_seed(seed)
        if rl.likelihood == "sample":
            explore = torch.randn(y_tau.shape, generator=generator).to(y_tau) * rl.explore_std
            y_tau = mean_tau + explore
            chosen = y_tau.detach()  # the action: the perturbed initial sample
        if antithetic:  # the -xi twin is denoised with the same noise as the +xi action
            twin_gen = torch.Generator().set_state(generator.get_state())
        y = denoise(self.schedule, eps, y_tau, tau, generator)  # [K, N, T_f, 2]
        action = y.detach()
        with torch.no_grad():
            y_ref = denoise(self.schedule, eps, ref_tau, tau, generator)
            if antithetic:
                twin = (mean_tau - explore).detach()  # [K, N, T_f, 2]
                twin_action = denoise(self.schedule, eps, twin, tau, twin_gen)

        # Step B: per-step reward R = r - div (Eq. 6, 12, 13)
        if rl.likelihood == "sample":
            log_std = torch.full_like(out.log_sigma, math.log(rl.explore_std))  # [K, N]
            logp = ppo.gaussian_log_prob(chosen, mean_tau, log_std, per_sample=True)
            logp_ref = ppo.gaussian_log_prob(chosen, ref_tau, log_std, per_sample=True)
            if antithetic:
                logp_twin = ppo.gaussian_log_prob(twin, mean_tau, log_std, per_sample=True)
                logp_ref_twin = ppo.gaussian_log_prob(twin, ref_tau, log_std, per_sample=True)
        else:
            logp = ppo.gaussian_log_prob(action, out.mean, out.log_sigma)  # [K, N, T_f]
            logp_ref = ppo.gaussian_log_prob(action, ref.mean, ref.log_sigma)
        with torch.no_grad():
            futures = torch.cat([action, twin_action]) if antithetic else action
            r_all = step_reward(self.scorer, d_ctx, futures, target, rl.reward_clip)  # [K|2K,..]
            k = action.shape[0]
            r = r_all[:k]  # [K, N, T_f]
            div = ppo.kl_penalty(logp.detach(), logp_ref, rl.kl_coef, rl.kl_form)
            reward = r - div  # [K, N, T_f]
            if antithetic:
                div_twin = ppo.kl_penalty(logp_twin.detach(), logp_ref_twin, rl.kl_coef,
                                          rl.kl_form)  # fmt: skip
                reward_twin = r_all[k:] - div_twin  # [K, N, T_f]

        ctx = out.context.detach() if rl.detach_critic else out.context
        values = self.critic(ctx, action)  # [K, N, T_f]
        with torch.no_grad():
            values_ref = self.critic(ref.context, y_ref)  # V_0 from the reference prediction
            adv, returns = ppo.gae(reward, values.detach(), rl.gamma, rl.gae_lambda)
            if antithetic:
                adv, _ = ppo.antithetic_advantage(reward, reward_twin)
            if rl.adv_norm == "scene":
                adv = ppo.whiten_per_group(adv, batch.scene, batch.num_scenes)
            v_target = reward if rl.value_target == "reward" else returns

        # Step C: clipped policy and value losses, on all K (RLHF) or k* only (RLHF-ReS)
        if rl.method == "rlhf-res":
            k_star = best_sample(r, batch.scene, batch.num_scenes)  # [B]
            sel = lambda x: take_sample(x, k_star, batch.scene)  # noqa: E731
            logp_pg, logp_ref_pg, adv_pg = sel(logp), sel(logp_ref), sel(adv)
            v_pg, v_ref_pg, target_pg = sel(values), sel(values_ref), sel(v_target)
        else:
            sel = lambda x: x  # noqa: E731
            logp_pg, logp_ref_pg, adv_pg = logp, logp_ref, adv
            v_pg, v_ref_pg, target_pg = values, values_ref, v_target
        if antithetic:  # the twins' actions enter with the opposite advantage
            logp_pg = torch.cat([logp_pg, sel(logp_twin)])
            logp_ref_pg = torch.cat([logp_ref_pg, sel(logp_ref_twin)])
            adv_pg = torch.cat([adv_pg, -adv_pg])
        # the ratio's denominator: the frozen reference (Eq. 15 as printed) or the rollout
        # policy itself (one update per rollout, standard PPO; KL to G_0 stays in the reward)
        old_pg = logp_ref_pg if rl.ratio_against == "reference" else logp_pg.detach()
        pg_loss, clip_frac, approx_kl = ppo.policy_loss(logp_pg, old_pg, adv_pg, rl.clip)
        v_loss = ppo.value_loss(v_pg, v_ref_pg, target_pg, rl.value_clip)
        reg_loss, reg_logs = generator_loss(out, y, target, self.cfg.generator)
        loss = rl.reg_weight * reg_loss + rl.policy_weight * pg_loss + rl.value_weight * v_loss
        logs = {
            "reward": float(r.mean()),
            "reward_total": float(reward.mean()),
            "kl_div": float(div.mean()),
            "pg_loss": float(pg_loss.detach()),
            "value_loss": float(v_loss.detach()),
            "clip_fraction": float(clip_frac),
            "approx_kl": float(approx_kl),
            # k3 estimate of KL(G_theta || G_0) from the policy's samples (any ratio denominator)
            "kl_to_reference": float(
                ((logp_ref - logp.detach()).exp() - 1 - (logp_ref - logp.detach())).mean()
            ),
            "explained_variance": float(ppo.explained_variance(values.detach(), v_target)),
            "reg_loss": float(reg_loss.detach()),
            **{f"reg_{k}": v for k, v in reg_logs.items()},
        }
        return loss, logs


class PolicyAndCritic(nn.Module):
    """What fine-tuning optimises and saves."""

    def __init__(self, policy: Generator, critic: Critic):
        super().__init__()
        self.policy = policy
        self.critic = critic


def build_finetune_stage(
    cfg: ExperimentConfig, start: dict[str, Any], val: TrajectoryDataset, device: torch.device,
) -> Stage:  # fmt: skip
    """Fine-tuning from a generator checkpoint payload ``start``. Validation: minADE_K +
    minFDE_K of the policy's leapfrog samples (lower is better), with maxATS/maxFTS logged."""
    torch.manual_seed(cfg.seed)
    policy, _ = ckpt.build_generator(start)
    denoiser_payload = start["denoiser"]
    denoiser, _ = ckpt.build_denoiser(denoiser_payload)
    policy, denoiser = policy.to(device), denoiser.to(device)
    scale = start["scale"]
    schedule = DDPMSchedule(**vars(cfg.diffusion)).to(device)
    critic = Critic(cfg.model.hidden, cfg.model.t_fut, cfg.model.generator_width).to(device)
    objective = RLObjective(policy, critic, denoiser, schedule, scale, cfg)
    trainable = PolicyAndCritic(policy, critic)
    predictor = DiffusionPredictor(cfg.model, cfg.diffusion, scale, denoiser, policy,
                                   cfg.generator.tau, "leapfrog").to(device)  # fmt: skip
    val_set = _subset(val, cfg.finetune.eval_max_scenes)
    metric_scorer = TrajectoryScorer(denoiser, schedule, scale)  # the paper's every-3 steps

    def validate() -> dict[str, float]:
        res = evaluate(predictor, val_set, cfg.generator.samples, seed=0, device=device,
                       max_agents=cfg.data.max_agents, progress=False,
                       scorer=metric_scorer)  # fmt: skip
        keys = ("min_ade", "min_fde", "max_ats", "max_fts", "mean_ats", "top1_recall_ats")
        return {k: res[k] for k in keys} | {"score": res["min_ade"] + res["min_fde"]}

    def payload(meta: dict[str, Any]) -> dict[str, Any]:
        meta = {**meta, "method": cfg.finetune.method, "from": start.get("hash")}
        out = ckpt.generator_payload(policy, denoiser_payload, cfg, meta)
        out["critic"] = {k: v.detach().cpu().clone() for k, v in critic.state_dict().items()}
        return out

    return Stage("finetune", objective, trainable, validate, payload)
