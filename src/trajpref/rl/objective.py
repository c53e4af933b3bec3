"""RLHF and RLHF-ReS fine-tuning of the generator (the paper's Steps A-C, Eq. 10-20).

Policy G_theta (from a pretrained generator), frozen reference G_0 (a copy), critic V_psi on
the policy's social encoding, frozen denoiser D as refiner (D^r, tau steps) and rewarder (the
diffusion score r). One update reads top-down: rollout -> log-likelihoods and reward ->
values and advantages -> selection -> losses. The PPO arithmetic lives in ``rl.ppo`` as pure
functions; the rollout is ``DiffusionPredictor.rollout``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn

from trajpref.config import FINETUNE_METHODS, USES_RL, FinetuneConfig, GeneratorTrainConfig, uses_rl
from trajpref.data.transforms import from_model_frame, to_model_frame
from trajpref.errors import ConfigError
from trajpref.metrics import scene_sum
from trajpref.models.critic import Critic
from trajpref.models.losses import generator_loss
from trajpref.models.predictor import Condition, DiffusionPredictor, Rollout
from trajpref.rl import ppo
from trajpref.rl.rewards import call_reward, handcrafted_reward, hide_future
from trajpref.rl.set_reward import marginal_gains
from trajpref.score.scorer import TrajectoryScorer, score_timesteps
from trajpref.types import Batch

LOSS_SAMPLES = {"rlhf": "all", "rlhf-res": "best"}
"""Which samples each RL method's policy and value losses see (``RLObjective.selection``):
``all`` K samples of each agent (RLHF) or ``best``, each scene's best-scored one, k*
(RLHF-ReS). Every RL method of ``config.USES_RL`` has an entry; a method without one is an
error, never trained as another (docs/rlhf.md, "Adding a fine-tuning method")."""
if set(LOSS_SAMPLES) != {m for m in FINETUNE_METHODS if USES_RL[m]}:
    raise AssertionError("rl.objective: LOSS_SAMPLES must name every RL method of "
                         "config.FinetuneMethod")  # fmt: skip


def loss_samples(method: str) -> str:
    """``LOSS_SAMPLES``'s entry of RL ``method``; a ``ConfigError`` for a name without one."""
    if method not in LOSS_SAMPLES:
        raise ConfigError(f"fine-tuning method {method!r} has no entry in "
                          f"rl.objective.LOSS_SAMPLES (which samples its losses see); known: "
                          f"{', '.join(LOSS_SAMPLES)}")  # fmt: skip
    return LOSS_SAMPLES[method]


def best_sample(r: torch.Tensor, scene: torch.Tensor, num_scenes: int) -> torch.Tensor:
    """RLHF-ReS's k*: per scene, argmax_k sum_{p,t} r[k, p, t]. r [K, N, T] -> [B]."""
    return scene_sum(r.sum(-1), scene, num_scenes).argmax(0)


def take_sample(x: torch.Tensor, k_star: torch.Tensor, scene: torch.Tensor) -> torch.Tensor:
    """x [K, N, ...] -> [1, N, ...]: each agent's entry at its scene's k*."""
    idx = k_star[scene]  # [N]
    return x[idx, torch.arange(x.shape[1], device=x.device)][None]


def step_reward(scorer: TrajectoryScorer, context: torch.Tensor, futures: torch.Tensor,
                target: torch.Tensor, clip: float | None) -> torch.Tensor:  # fmt: skip
    """The per-step score r (Eq. 6) that fine-tuning maximises, clipped to [-clip, clip]
    when ``clip`` is set: futures [M, N, T_f, 2] and target [N, T_f, 2] in the denoiser's
    frame, context [N, H] -> [M, N, T_f]."""
    r = scorer.step_scores(context, futures, target)
    return r.clamp(-clip, clip) if clip is not None else r


@dataclass
class Actions:
    """K actions of one rollout and what the update needs of them. [K, N, T_f] each."""

    logp: torch.Tensor
    """Eq. 12 under the policy (differentiable)."""
    logp_ref: torch.Tensor
    """Eq. 12 under the frozen reference."""
    action: torch.Tensor
    """[K, N, T_f, 2] the denoised samples (detached): what is scored."""
    chosen: torch.Tensor
    """[K, N, T_f, 2] what Eq. 12's density is evaluated at (detached): the explored initial
    sample (``sample`` likelihood) or the denoised sample (``mean``)."""
    score: torch.Tensor | None = None
    """r, the clipped per-step diffusion score (Eq. 6), or the hand-crafted reward in its place
    (built-in or registered: ``rl.rewards``; then also what RLHF-ReS's k* maximises)."""
    div: torch.Tensor | None = None
    """The KL penalty (Eq. 13)."""
    reward: torch.Tensor | None = None
    """R = r - div."""


@dataclass
class Memo:
    """A collected rollout: what the update epochs on it share."""

    cond: Condition
    """The batch's features and the denoiser's context."""
    target: torch.Tensor
    """[N, T_f, 2] the ground truth in the networks' frame (L_reg's target)."""
    acts: list[Actions]
    """The policy's actions (and the antithetic twin's), with their rewards."""
    policy: Rollout | None
    """The policy rollout with its graph (one update on it), or None (re-evaluate)."""
    values: torch.Tensor | None
    """[K, N, T_f] V with its graph (with ``policy``), or None."""
    select: Callable[[torch.Tensor], torch.Tensor]
    """All K samples (RLHF) or each scene's k* (RLHF-ReS)."""
    adv: torch.Tensor
    """Selected advantages, the twin's (-A) appended."""
    values_ref: torch.Tensor
    """Selected V_0 of the reference prediction (Eq. 16's clip centre)."""
    v_target: torch.Tensor
    """[K, N, T_f] value targets of all samples (the losses see ``select(v_target)``)."""


def _fork(generator: torch.Generator) -> torch.Generator:
    """A generator in the same state: its draws repeat ``generator``'s."""
    return torch.Generator().set_state(generator.get_state())


class RLObjective(nn.Module):
    """One PPO step on a fresh rollout: L = w_reg L_reg + w_p L_pg + w_v L_val (Eq. 17 / 20).

    ``sampler`` holds the policy generator and the frozen denoiser; the reference is a frozen
    copy of the policy taken here."""

    def __init__(self, sampler: DiffusionPredictor, critic: Critic, cfg: FinetuneConfig,
                 reg_cfg: GeneratorTrainConfig):  # fmt: skip
        super().__init__()
        assert sampler.generator is not None
        self.policy = sampler.generator
        self.critic = critic
        self.denoiser = sampler.denoiser.requires_grad_(False).eval()
        self.reference = copy.deepcopy(self.policy).requires_grad_(False).eval()
        self.sampler = sampler
        self.reference_sampler = DiffusionPredictor(
            self.denoiser,
            sampler.schedule,
            sampler.scale,
            self.reference,
            sampler.tau,
            stochastic=sampler.stochastic,
        )
        self.rl = cfg
        self.reg_cfg = reg_cfg
        # a hand-crafted reward's callable, looked up once (a name not registered in this
        # process is refused here, before any step); None for the diffusion score's rewards
        # (an unknown method is refused here too: every dispatch below has its entry)
        rl_method = uses_rl(cfg.method)
        if rl_method:
            loss_samples(cfg.method)
        self.handcrafted = handcrafted_reward(cfg.reward) if rl_method else None
        steps = score_timesteps(sampler.schedule.num_steps, cfg.score_every)
        self.scorer = TrajectoryScorer(self.denoiser, sampler.schedule, sampler.scale, steps)
        t_f = sampler.denoiser.cfg.t_fut
        # smooth exploration: noise in the span of t and t^2 over the future (rl/ppo.py)
        self.register_buffer("basis", ppo.smooth_basis(t_f) if cfg.explore == "smooth" else None,
                             persistent=False)  # fmt: skip

    def explore_noise(self, shape: torch.Size, generator: torch.Generator | None) -> torch.Tensor:
        """The ``smooth`` exploration noise [K, N, T_f, 2] (rollout's ``explore_noise``)."""
        return ppo.smooth_noise(shape, self.basis, self.rl.explore_std, generator)

    def sample_log_prob(self, chosen: torch.Tensor, initial: torch.Tensor) -> torch.Tensor:
        """Eq. 12 of the ``sample`` likelihood: the explored initial samples ``chosen`` under
        the exploration density centred on ``initial`` [K, N, T_f, 2] -> [K, N, T_f]."""
        if self.basis is not None:
            return ppo.smooth_log_prob(chosen, initial, self.rl.explore_std, self.basis)
        log_std = torch.full(chosen.shape[:2], math.log(self.rl.explore_std)).to(chosen)
        return ppo.gaussian_log_prob(chosen, initial, log_std, per_sample=True)

    def train(self, mode: bool = True):
        super().train(mode)
        self.reference.eval()
        self.denoiser.eval()
        # a policy trained with dropout (model.generator_dropout) fine-tunes without it, as
        # TRL does: the PPO ratio compares the same network on the rollout and in the update
        for m in self.policy.modules():
            if isinstance(m, nn.Dropout):
                m.eval()
        return self

    def forward(self, batch: Batch, generator: torch.Generator | None = None,
                memo: Memo | None = None):  # fmt: skip
        """One update: on ``memo`` (a rollout collected earlier by ``collect``, for several
        PPO epochs per rollout) or, without it, on a fresh rollout whose graph the losses
        reuse (one update per rollout)."""
        if not uses_rl(self.rl.method):
            return self.supervised(batch, generator)
        if memo is None:
            memo = self.collect(batch, generator, live=True)
        return self.update(batch, memo, generator)

    def supervised(self, batch: Batch, generator: torch.Generator | None = None):
        """The control: L_reg alone on a clean rollout (no score, no reference, no critic)."""
        roll = self.sampler.rollout(batch, generator)
        target = to_model_frame(batch.future, batch, self.sampler.scale)  # [N, T_f, 2]
        reg_loss, reg_logs = generator_loss(roll.out, roll.y, target, self.reg_cfg)
        logs = {
            "reg_loss": float(reg_loss.detach()),
            **{f"reg_{k}": v for k, v in reg_logs.items()},
        }
        return self.rl.reg_weight * reg_loss, logs

    @torch.no_grad()
    def collect_frozen(self, batch: Batch, generator: torch.Generator | None = None) -> Memo:
        """``collect`` without gradients: the rollout several update epochs reuse."""
        return self.collect(batch, generator, live=False)

    def collect(self, batch: Batch, generator: torch.Generator | None, live: bool) -> Memo:
        """Steps A and B, and the advantages: everything an update needs that does not change
        while the policy is updated. ``live`` keeps the policy rollout's graph (for a single
        update on it)."""
        cond = self.sampler.condition(batch)
        target = to_model_frame(batch.future, batch, self.sampler.scale)  # [N, T_f, 2]

        # Step A: rollouts of the policy and the reference (Eq. 1, 3, 10), and for the
        # antithetic baseline the -xi twin under the same denoising noise
        policy, reference, twin = self.rollouts(batch, cond, generator)

        # Step B: log-likelihoods (Eq. 12), score (Eq. 6) and reward R = r - div (Eq. 13)
        acts = [self.actions(policy, policy, reference)]
        if twin is not None:
            acts.append(self.actions(twin, policy, reference))
        self.rewards(acts, cond.context, target, batch)

        # Step C (first half): values and advantages (Eq. 14); which samples the losses see
        ctx = policy.out.context.detach() if self.rl.detach_critic else policy.out.context
        values = self.critic(ctx, acts[0].action)  # [K, N, T_f]
        with torch.no_grad():
            values_ref = self.critic(reference.out.context, reference.y)  # V_0 (Eq. 16)
            adv, v_target = self.advantages(acts, values.detach(), batch)
        sel = self.selection(acts[0].score, batch)
        adv = torch.cat([sel(adv), -sel(adv)][: len(acts)])  # a twin's advantage is -A
        return Memo(cond, target, acts, policy if live else None, values if live else None,
                    sel, adv, sel(values_ref), v_target)  # fmt: skip

    def update(self, batch: Batch, memo: Memo, generator: torch.Generator | None = None):
        """Step C (second half): the clipped losses (Eq. 15-17) on all K samples (RLHF) or
        each scene's best-scored k* only (RLHF-ReS), with L_reg."""
        rl, sel, main = self.rl, memo.select, memo.acts[0]
        reg_roll = memo.policy  # the explored rollout (legacy), or a clean one (below)
        if rl.reg_on == "clean" or reg_roll is None:
            reg_roll = self.sampler.rollout(batch, generator, cond=memo.cond)
        if memo.policy is not None:  # one update on the rollout just collected
            logp = torch.cat([sel(a.logp) for a in memo.acts])
            values = memo.values
        else:  # the policy has moved since the rollout: re-evaluate its actions
            logp = torch.cat([sel(self.relikelihood(a, reg_roll)) for a in memo.acts])
            ctx = reg_roll.out.context.detach() if rl.detach_critic else reg_roll.out.context
            values = self.critic(ctx, main.action)  # [K, N, T_f]
        logp_ref = torch.cat([sel(a.logp_ref) for a in memo.acts])
        logp_old = torch.cat([sel(a.logp.detach()) for a in memo.acts])
        # the ratio's denominator: the frozen reference (Eq. 15 as printed) or the rollout
        # policy (standard PPO; the KL to G_0 stays in the reward)
        old = logp_ref if rl.ratio_against == "reference" else logp_old
        pg_loss, clip_frac, approx_kl = ppo.policy_loss(logp, old, memo.adv, rl.clip)
        v_loss = ppo.value_loss(sel(values), memo.values_ref, sel(memo.v_target), rl.value_clip)
        reg_loss, reg_logs = generator_loss(reg_roll.out, reg_roll.y, memo.target, self.reg_cfg)
        loss = rl.reg_weight * reg_loss + rl.policy_weight * pg_loss + rl.value_weight * v_loss
        logs = {
            "reward": float(main.score.mean()),
            "reward_total": float(main.reward.mean()),
            "kl_div": float(main.div.mean()),
            "pg_loss": float(pg_loss.detach()),
            "value_loss": float(v_loss.detach()),
            "clip_fraction": float(clip_frac),
            "approx_kl": float(approx_kl),
            # k3 estimate of KL(G_theta || G_0) from the policy's samples (any denominator)
            "kl_to_reference": float(ppo.k3_divergence(main.logp_ref, main.logp.detach())),
            "explained_variance": float(
                ppo.explained_variance(values.detach(), memo.v_target)
            ),  # fmt: skip
            "reg_loss": float(reg_loss.detach()),
            **{f"reg_{k}": v for k, v in reg_logs.items()},
        }
        return loss, logs

    def relikelihood(self, acts: Actions, policy: Rollout) -> torch.Tensor:
        """Eq. 12 of stored actions under the current policy (its rollout ``policy``)."""
        if self.rl.likelihood == "sample":
            return self.sample_log_prob(acts.chosen, policy.initial)
        return ppo.gaussian_log_prob(acts.chosen, policy.out.mean, policy.out.log_sigma)

    def rollouts(self, batch: Batch, cond, generator: torch.Generator | None):
        """-> (policy, reference, twin or None) rollouts, in this order of random draws."""
        rl = self.rl
        explore = rl.explore_std if rl.likelihood == "sample" else 0.0
        twin_gen = None
        if rl.baseline == "antithetic":
            if generator is None:
                generator = torch.Generator().manual_seed(int(torch.randint(2**62, ())))
            twin_gen = _fork(generator)
        noise = self.explore_noise if explore > 0 and self.basis is not None else None
        policy = self.sampler.rollout(batch, generator, explore_std=explore, cond=cond,
                                      explore_noise=noise)  # fmt: skip
        with torch.no_grad():
            reference = self.reference_sampler.rollout(batch, generator, cond=cond)
            twin = None
            if twin_gen is not None:
                twin = self.sampler.rollout(batch, twin_gen, explore_std=explore,
                                            explore_sign=-1.0, cond=cond,
                                            explore_noise=noise)  # fmt: skip
        return policy, reference, twin

    def actions(self, roll: Rollout, policy: Rollout, reference: Rollout) -> Actions:
        """Eq. 12 for the actions of ``roll`` under the policy and the reference.

        ``sample`` likelihood: the action is the explored initial sample, with density
        N(Y^tau + xi; Y^tau, explore_std). ``mean``: the denoised sample under N(mu, sigma_k)."""
        if self.rl.likelihood == "sample":
            chosen = roll.y_tau.detach()  # [K, N, T_f, 2]
            logp = self.sample_log_prob(chosen, policy.initial)  # [K, N, T_f]
            logp_ref = self.sample_log_prob(chosen, reference.initial)
        else:
            chosen = roll.y.detach()
            logp = ppo.gaussian_log_prob(chosen, policy.out.mean, policy.out.log_sigma)
            logp_ref = ppo.gaussian_log_prob(chosen, reference.out.mean,
                                             reference.out.log_sigma)  # fmt: skip
        return Actions(logp, logp_ref, roll.y.detach(), chosen)

    @torch.no_grad()
    def rewards(self, acts: list[Actions], context: torch.Tensor, target: torch.Tensor,
                batch: Batch) -> None:  # fmt: skip
        """Fill each ``Actions``' score, KL penalty and reward (one score call for all, so
        they share the noise)."""
        rl = self.rl
        futures = torch.cat([a.action for a in acts])  # [K * len(acts), N, T_f, 2]
        if self.handcrafted is not None:  # in the data's units, blind to the future
            observed = hide_future(batch)
            absolute = from_model_frame(futures, observed, self.sampler.scale)  # [M, N, T_f, 2]
            scores = call_reward(rl.reward, self.handcrafted, observed, absolute, rl)  # [M, N, T_f]
        else:
            scores = step_reward(self.scorer, context, futures, target, rl.reward_clip)
        for a, r in zip(acts, scores.chunk(len(acts)), strict=True):
            a.score = r
            a.div = ppo.kl_penalty(a.logp.detach(), a.logp_ref, rl.kl_coef, rl.kl_form)
            if rl.reward == "set":  # each sample's marginal gain to its set, spread over T_f
                gain = marginal_gains(
                    a.action[..., -1, :], r.sum(-1), rl.set_bandwidth, rl.set_alpha
                )  # fmt: skip  [K, N]
                r = (gain / r.shape[-1])[..., None].expand_as(r)
            a.reward = r - a.div  # [K, N, T_f]

    def advantages(self, acts: list[Actions], values: torch.Tensor, batch: Batch):
        """-> (advantages of the main actions, value target), both [K, N, T_f]. With a twin,
        the advantage is the antithetic difference instead of the critic's TD error."""
        rl, main = self.rl, acts[0]
        adv, returns = ppo.gae(main.reward, values, rl.gamma, rl.gae_lambda)
        if len(acts) > 1:
            adv, _ = ppo.antithetic_advantage(main.reward, acts[1].reward)
        if rl.adv_norm == "scene":
            adv = ppo.whiten_per_group(adv, batch.scene, batch.num_scenes)
        return adv, main.reward if rl.value_target == "reward" else returns

    def selection(
        self, score: torch.Tensor, batch: Batch
    ) -> Callable[[torch.Tensor], torch.Tensor]:
        """Which samples the policy and value losses see: all K (RLHF) or k* (RLHF-ReS), as
        ``LOSS_SAMPLES`` says of the method (a method without an entry is an error)."""
        samples = loss_samples(self.rl.method)
        if samples == "all":
            return lambda x: x
        if samples == "best":
            k_star = best_sample(score, batch.scene, batch.num_scenes)  # [B]
            return lambda x: take_sample(x, k_star, batch.scene)
        raise ConfigError(f"rl.objective.LOSS_SAMPLES[{self.rl.method!r}] = {samples!r}: "
                          "RLObjective.selection knows 'all' and 'best'")  # fmt: skip
