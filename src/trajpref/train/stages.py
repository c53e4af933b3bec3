"""The three training stages, built in one place: the denoiser (Eq. 2), the leapfrog generator
(Eq. 1, 3, 4) and RLHF / RLHF-ReS fine-tuning (Eq. 10-20). Each builder returns a ``Stage``
for the one training loop (``train.loop.fit``); validation runs the one evaluation loop."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from trajpref.config import (
    DataConfig,
    ExperimentConfig,
    GeneratorTrainConfig,
    ModelConfig,
    uses_rl,
)
from trajpref.data.loader import SceneLoader
from trajpref.data.transforms import to_model_frame
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import ConfigError
from trajpref.evaluation import NonFinitePrediction, evaluate
from trajpref.io import bar_options
from trajpref.models import checkpoint as ckpt
from trajpref.models.critic import Critic
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.models.generator import Generator
from trajpref.models.losses import denoiser_loss, generator_loss, wta_temperature
from trajpref.models.predictor import DiffusionPredictor
from trajpref.models.timing import (
    TRAINING_WIDTH_KEY,
    dataset_width,
    lineage_entry,
    split_files,
    training_lineage,
    training_width,
)
from trajpref.rl.objective import RLObjective
from trajpref.rl.presets import PAPER_WEIGHTS, PRESETS
from trajpref.score.scorer import TrajectoryScorer
from trajpref.types import Batch, TrajectoryDataset


@dataclass
class Stage:
    """What differs between training stages."""

    name: str
    """Checkpoint file stem: ``denoiser``, ``generator`` or ``finetune``."""
    objective: nn.Module
    """``forward(batch, generator) -> (loss, logs)``; holds the trainable and frozen parts."""
    trainable: nn.Module
    """The module whose parameters are optimised and saved."""
    validate: Callable[..., dict[str, float]]
    """``validate(progress=False)``: validation metrics; must include ``score`` (lower is
    better). ``progress`` shows a bar over the validation batches."""
    payload: Callable[[dict[str, Any]], dict[str, Any]]
    """Turns the trainable module (+ metadata) into a checkpoint payload."""
    collect: Callable[[Batch, torch.Generator], Any] | None = None
    """When set, called once per batch without gradients; its result is passed to
    ``objective(batch, generator, collected)`` for each of ``updates`` optimiser steps."""
    updates: int = 1
    """Optimiser steps per batch (PPO's update epochs on one rollout)."""
    on_progress: Callable[[float], None] | None = None
    """When set, called before each optimiser step with the fraction of the run's steps
    done (0..1; a resumed run continues from its step), for schedules inside the loss."""
    networks: tuple[nn.Module, ...] = ()
    """The networks whose forward passes the steps spend their time in: compiled in place
    (``nn.Module.compile``, parameters and state-dict keys unchanged) when the stage's
    ``OptimConfig.compile`` is on."""
    nonfinite_hint: str = "lower the learning rate"
    """What the error says to try when the loop gives up on repeated non-finite losses."""
    context: bool = False
    """Whether training batches keep their context-only agents (``Batch.context``): only for
    a generator built with ``ModelConfig.context_agents``; the others train on batches without
    them, so that their augmentation draws are what they were before context existed."""
    validate_start: bool = False
    """Whether the loop validates the start once before training (fine-tuning: its start is
    a trained generator, whose validation is what the run must beat); logged as epoch 0."""
    unused_parameters: bool = False
    """Whether a step leaves some of ``trainable``'s parameters without a gradient (the
    fine-tuning control never calls its critic): DDP then finds them each step
    (``find_unused_parameters``), where it would otherwise stop the run."""


def data_scale(dataset: TrajectoryDataset) -> float:
    """RMS of the future positions relative to each agent's last observation: networks see
    coordinates divided by it, so one config serves metres and pixels. Unseen future steps
    (NaN: ``data.partial_future``'s targets) are left out; they had made it 0.001."""
    total, count = 0.0, 0
    for s in dataset.scenes:
        rel = (s.future - s.history[:, -1:]).astype("float64")  # [P, T_f, 2]
        seen = np.isfinite(rel)
        total += float((rel[seen] ** 2).sum())
        count += int(seen.sum())
    return max(1e-3, (total / max(1, count)) ** 0.5)


def trained_on(cfg: ExperimentConfig, stage: str, before: dict[str, Any] | None = None,
               train: TrajectoryDataset | None = None,
               val: TrajectoryDataset | None = None) -> list[dict[str, Any]]:  # fmt: skip
    """What a checkpoint of ``stage`` (``denoiser``, ``generator``, ``finetune``) records in
    its meta as ``trained_on``: the training lineage of the checkpoint it builds on (``before``:
    the generator's denoiser, the fine-tune's start; ``models.timing.training_lineage``, which
    reads a file written before the record from its config), then this run's data
    (``timing.lineage_entry``), with the content digests of its ``train`` and ``val`` files
    where both are given (``timing.split_files``: evaluate finds a copy of a training file
    under another name or folder). The fold-overlap and own-windows checks read every entry:
    a fine-tune of a zara1 generator on eth has seen zara1's windows, whatever its
    ``data.dataset``."""
    earlier = training_lineage(before) if before is not None else []
    files = split_files(train, val) if train is not None and val is not None else None
    return [*earlier, lineage_entry(cfg.data, stage, files)]


def width_meta(train: TrajectoryDataset | None, scale: float, model: ModelConfig | None = None,
               before: dict[str, Any] | None = None) -> dict[str, float]:  # fmt: skip
    """What a checkpoint's meta records of its training width (``models.timing.dataset_width``:
    the farthest two agents of one training scene lie apart at its last observed frame, in
    model units of ``scale``), for the wide-scene warning's limit (``timing.wide_limit``): over
    ``train``'s targets and, for a generator ``model`` that reads them
    (``ModelConfig.context_agents``), its context-only agents; with ``before`` (a fine-tune's
    start) at least the start's (``timing.training_width``: recorded, or its built-in
    dataset's), whose scenes the weights saw first. Empty where nothing is known (no ``train``
    and no start's). Computed once per stage from the arrays: nothing is drawn from any random
    stream."""
    widths = []
    if train is not None:
        context = model is not None and model.context_agents
        frames = model.context_frames if model is not None else 0
        widths.append(dataset_width(train, scale, context, frames))
    earlier = training_width(before) if before is not None else None
    if earlier is not None:
        widths.append(earlier[0])
    return {TRAINING_WIDTH_KEY: max(widths)} if widths else {}


def finetune_preset(finetune: Any) -> str | None:
    """The preset (``rl.presets.PRESETS``) whose every value a fine-tuning config holds
    (``finetune``: a ``config.FinetuneConfig`` or its dict), with the method's policy and value
    weights (``PAPER_WEIGHTS``) as ``--preset`` sets them; None for any other (the default, a
    preset with a value changed, the control). A fine-tune's meta records it (``preset``) and
    ``evaluate --json`` shows it (``finetune_preset``): ``kl_form`` alone told a ``--preset
    paper`` run from a default one."""
    values = dataclasses.asdict(finetune) if dataclasses.is_dataclass(finetune) else finetune
    if not isinstance(values, dict) or values.get("method") not in PAPER_WEIGHTS:
        return None
    policy, value = PAPER_WEIGHTS[values["method"]]
    for name, preset in PRESETS.items():
        wanted = {**preset, "policy_weight": policy, "value_weight": value}
        if all(k in values and values[k] == v for k, v in wanted.items()):
            return name
    return None


def _leapfrog_validation(predictor: DiffusionPredictor, val: TrajectoryDataset, samples: int,
                         max_agents: int, device: torch.device,
                         scorer: TrajectoryScorer | None = None,
                         keys: tuple[str, ...] = ("min_ade", "min_fde")):  # fmt: skip
    """Validation of a generator: minADE_K + minFDE_K of its leapfrog samples (lower is
    better), plus ``keys`` of the evaluation's result."""

    def validate(progress: bool = False) -> dict[str, float]:
        # in eval mode whoever calls it (a generator trained with dropout samples without it
        # at prediction time), each module's mode restored after
        modes = [(m, m.training) for m in predictor.modules()]
        predictor.eval()
        try:
            # collision metrics off: none of them is among what validation returns
            res = evaluate(predictor, val, samples, seed=0, device=device, max_agents=max_agents,
                           progress=progress, scorer=scorer, collision_radius=None)  # fmt: skip
        except NonFinitePrediction as err:  # a diverged epoch: never kept, the run goes on
            tqdm.write(f"[validation] {err}: scored as never the best")
            return dict.fromkeys(keys, math.nan) | {"score": math.inf}
        finally:
            for module, mode in modes:
                module.training = mode
        return {k: res[k] for k in keys} | {"score": res["min_ade"] + res["min_fde"]}

    return validate


# ----------------------------------------------------------------------------- stage 1


class DenoiserObjective(nn.Module):
    """Eq. 2 on a batch: ``models.losses.denoiser_loss`` on the batch's futures."""

    def __init__(self, denoiser: Denoiser, schedule: DDPMSchedule, scale: float, draws: int):
        super().__init__()
        self.denoiser = denoiser
        self.schedule = schedule
        self.scale = scale
        self.draws = draws

    def forward(self, batch: Batch, generator: torch.Generator | None = None):
        context = self.denoiser.context(scene_features(batch, self.scale))  # [N, H]
        y0 = to_model_frame(batch.future, batch, self.scale)  # [N, T_f, 2]
        loss = denoiser_loss(self.denoiser, self.schedule, context, y0, self.draws, generator)
        return loss, {}


def build_denoiser_stage(
    cfg: ExperimentConfig, train: TrajectoryDataset, val: TrajectoryDataset,
    device: torch.device,
) -> tuple[Stage, float]:  # fmt: skip
    """Stage 1. Validation: Eq. 2 on the validation split with fixed noise (lower is better).
    Returns the stage and the data scale measured on ``train``."""
    if cfg.data.partial_future:
        raise ConfigError("data.partial_future trains the generator stage only: the "
                          "denoiser and its data scale learn from complete futures "
                          "(train_stage passes cfg.data.denoiser_part())")  # fmt: skip
    torch.manual_seed(cfg.seed)
    scale = data_scale(train)
    denoiser = Denoiser(cfg.model).to(device)
    schedule = DDPMSchedule.from_config(cfg.diffusion).to(device)
    objective = DenoiserObjective(denoiser, schedule, scale, cfg.denoiser.noise_draws)
    val_set = val.evenly_spaced(cfg.denoiser.eval_max_scenes)

    @torch.no_grad()
    def validate(progress: bool = False) -> dict[str, float]:
        gen = torch.Generator().manual_seed(12345)
        total, agents = 0.0, 0
        loader = SceneLoader(val_set, max_agents=cfg.data.max_agents)
        # closed here, not by its finalizer, where a Ctrl-C is lost (train.loop.keeps_interrupts)
        with tqdm(loader, desc="denoiser validation", unit="batch", leave=False,
                  **bar_options(progress)) as bar:  # fmt: skip
            for batch in bar:
                loss, _ = objective(batch.to(device), gen)
                total += float(loss) * batch.num_agents
                agents += batch.num_agents
        return {"denoise_loss": total / agents, "score": total / agents}

    lineage = trained_on(cfg, "denoiser", train=train, val=val)
    width = width_meta(train, scale)  # the denoiser reads no context-only agents

    def payload(meta: dict[str, Any]) -> dict[str, Any]:
        return ckpt.denoiser_payload(denoiser, cfg, scale,
                                     {**meta, "trained_on": lineage, **width})  # fmt: skip

    return Stage("denoiser", objective, denoiser, validate, payload,
                 networks=(denoiser,)), scale  # fmt: skip


# ----------------------------------------------------------------------------- stage 2


class GeneratorObjective(nn.Module):
    """Trains G through tau steps of the frozen denoiser: ``models.losses.generator_loss``
    on the leapfrog rollout's denoised samples."""

    def __init__(self, sampler: DiffusionPredictor, cfg: GeneratorTrainConfig):
        super().__init__()
        self.sampler = sampler
        self.denoiser = sampler.denoiser.requires_grad_(False).eval()
        self.cfg = cfg
        self.progress = 0.0
        """Fraction of the run's optimiser steps done: sets the annealed best-of-K
        temperature (``losses.wta_temperature``)."""

    def set_progress(self, progress: float) -> None:
        self.progress = progress

    def train(self, mode: bool = True):
        super().train(mode)
        self.denoiser.eval()  # frozen, always
        return self

    def forward(self, batch: Batch, generator: torch.Generator | None = None):
        roll = self.sampler.rollout(batch, generator)  # [K, N, T_f, 2] samples
        target = to_model_frame(batch.future, batch, self.sampler.scale)  # [N, T_f, 2]
        temperature = wta_temperature(self.cfg, self.progress)
        loss, logs = generator_loss(roll.out, roll.y, target, self.cfg, temperature)
        if self.cfg.wta_temperature > 0:
            logs["wta_temperature"] = temperature
        return loss, logs


def _check_matches_denoiser(cfg: ExperimentConfig, denoiser_cfg: ExperimentConfig) -> None:
    pairs = [("model", cfg.model.denoiser_part(), denoiser_cfg.model.denoiser_part()),
             ("diffusion", cfg.diffusion, denoiser_cfg.diffusion)]  # fmt: skip
    changed = [f"{section}.{f.name}: {getattr(theirs, f.name)!r} there, "
               f"{getattr(ours, f.name)!r} here"
               for section, ours, theirs in pairs for f in dataclasses.fields(ours)
               if getattr(ours, f.name) != getattr(theirs, f.name)]  # fmt: skip
    if changed:
        shown = "; ".join(changed[:3]) + ("; ..." if len(changed) > 3 else "")
        theirs = denoiser_cfg.model.windows
        windows = ("" if theirs == cfg.model.windows else f" (its window lengths: --history "
                   f"{theirs[0]} --future {theirs[1]})")  # fmt: skip
        raise ConfigError(
            f"the generator's config differs from its denoiser checkpoint's ({shown}): train it "
            "with the denoiser's config (its run folder's denoiser_config.yaml, or the "
            f"dataset's --config{windows}); only the generator's own fields "
            "(config.GENERATOR_ONLY) may differ"
        )


def _check_augmentations(model: ModelConfig, data: DataConfig) -> None:
    """Augmentations that would hide what the generator reads: one that sees where its agents
    are (``scene_position``) must train on scenes left in their place (no rotation, mirror,
    time reversal or scaling), and one that reads each agent's slot as its role
    (``agent_roles``) on scenes whose agents are not dropped."""
    moved = data.rotate or data.flip or data.reverse or data.scale_range is not None
    if model.scene_position and moved:
        raise ConfigError("model.scene_position learns from where the agents are in the "
                          "scene's coordinates: train it with data.rotate, data.flip and "
                          "data.reverse false and no scale range")  # fmt: skip
    if model.agent_roles and data.drop_agents > 0:
        raise ConfigError("model.agent_roles reads each agent's slot in its scene as its "
                          "role: train it with data.drop_agents 0 (dropping agents shifts "
                          "the slots)")  # fmt: skip


def build_generator_stage(
    cfg: ExperimentConfig, denoiser_payload: dict[str, Any], val: TrajectoryDataset,
    device: torch.device, train: TrajectoryDataset | None = None,
) -> Stage:  # fmt: skip
    """Stage 2. Validation: minADE_K + minFDE_K of the leapfrog sampler (lower is better).
    ``train``: the training split, whose files' content digests the checkpoint's lineage
    records (``trained_on``; without it, its validation files' are not recorded either)."""
    _check_augmentations(cfg.model, cfg.data)
    torch.manual_seed(cfg.seed)
    denoiser, dcfg = ckpt.build_denoiser(denoiser_payload)
    _check_matches_denoiser(cfg, dcfg)
    generator = Generator(cfg.model).to(device)
    schedule = DDPMSchedule.from_config(cfg.diffusion).to(device)
    sampler = DiffusionPredictor(denoiser.to(device), schedule, denoiser_payload["scale"],
                                 generator, cfg.model.tau,
                                 stochastic=cfg.model.stochastic_steps)  # fmt: skip
    objective = GeneratorObjective(sampler, cfg.generator)
    val_set = val.evenly_spaced(cfg.generator.eval_max_scenes)
    validate = _leapfrog_validation(sampler, val_set, cfg.model.samples, cfg.data.max_agents,
                                    device)  # fmt: skip

    lineage = trained_on(cfg, "generator", denoiser_payload, train, val)
    width = width_meta(train, denoiser_payload["scale"], cfg.model)

    def payload(meta: dict[str, Any]) -> dict[str, Any]:
        return ckpt.generator_payload(generator, denoiser_payload, cfg,
                                      {**meta, "trained_on": lineage, **width})  # fmt: skip

    return Stage("generator", objective, generator, validate, payload,
                 on_progress=objective.set_progress,
                 networks=(generator, sampler.denoiser),
                 nonfinite_hint="lower the learning rate, or cap the samples' spread in "
                 "training with model.max_log_sigma (an outlier agent, such as an annotation "
                 "jump, can drive its log sigma to overflow; docs/pretraining.md, '(sh3)')",
                 context=cfg.model.context_agents)  # fmt: skip


# ----------------------------------------------------------------------------- stage 3


class PolicyAndCritic(nn.Module):
    """What fine-tuning optimises and saves."""

    def __init__(self, policy: Generator, critic: Critic):
        super().__init__()
        self.policy = policy
        self.critic = critic


def build_finetune_stage(
    cfg: ExperimentConfig, start: dict[str, Any], val: TrajectoryDataset, device: torch.device,
    train: TrajectoryDataset | None = None,
) -> Stage:  # fmt: skip
    """Stage 3, from a generator checkpoint payload ``start``. Validation: minADE_K +
    minFDE_K of the policy's leapfrog samples (lower is better), with maxATS/maxFTS,
    meanATS and top-1 recall logged (scored at the paper's every-3 steps). The loop validates
    the start too, once, before the first step (``validate_start``: epoch 0 of the log).
    ``train``: as ``build_generator_stage``'s."""
    if start["kind"] != "generator":
        raise ConfigError("fine-tuning starts from a generator checkpoint")
    torch.manual_seed(cfg.seed)
    sampler = ckpt.predictor_from_payload(start, "leapfrog").to(device)
    assert sampler.generator is not None
    _check_augmentations(sampler.generator.cfg, cfg.data)
    width = cfg.model.generator_encoder_width
    critic = Critic(width, cfg.model.t_fut, cfg.model.generator_width).to(device)
    objective = RLObjective(sampler, critic, cfg.finetune, cfg.generator)
    val_set = val.evenly_spaced(cfg.finetune.eval_max_scenes)
    metric_scorer = TrajectoryScorer(sampler.denoiser, sampler.schedule, sampler.scale)
    keys = ("min_ade", "min_fde", "max_ats", "max_fts", "mean_ats", "top1_recall_ats")
    validate = _leapfrog_validation(sampler, val_set, cfg.model.samples, cfg.data.max_agents,
                                    device, metric_scorer, keys)  # fmt: skip

    lineage = trained_on(cfg, "finetune", start, train, val)
    width = width_meta(train, sampler.scale, sampler.generator.cfg, start)
    preset = finetune_preset(cfg.finetune)

    def payload(meta: dict[str, Any]) -> dict[str, Any]:
        meta = {**meta, "method": cfg.finetune.method, "preset": preset,
                "from": start.get("hash"), "trained_on": lineage, **width}  # fmt: skip
        return ckpt.generator_payload(sampler.generator, start["denoiser"], cfg, meta, critic)

    rl_method = uses_rl(cfg.finetune.method)  # an unknown method is refused
    epochs = cfg.finetune.ppo_epochs if rl_method else 1
    return Stage("finetune", objective, PolicyAndCritic(sampler.generator, critic), validate,
                 payload, objective.collect_frozen if epochs > 1 else None, epochs,
                 networks=(sampler.generator, sampler.denoiser),
                 nonfinite_hint="lower the learning rate or clip the reward",
                 context=sampler.generator.cfg.context_agents, validate_start=True,
                 unused_parameters=not rl_method)  # fmt: skip
