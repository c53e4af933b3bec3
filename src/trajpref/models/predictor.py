"""A trained diffusion predictor: denoiser (+ generator) + schedule, behind ``predict``.

``DiffusionPredictor.rollout`` is the one leapfrog rollout (generator -> Y^tau -> tau
denoising steps, Eq. 1 and 3). Prediction, the generator stage, fine-tuning and the benchmarks
all call it; the networks' coordinate frame is ``data.transforms.to_model_frame``.
"""

from __future__ import annotations

import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import torch
from torch import nn

from trajpref.data.text import PRECISION_STEP_FLOOR, float32_precision_loss
from trajpref.data.transforms import from_model_frame
from trajpref.diffusion.samplers import denoise, sample_full
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import ConfigError, DataError
from trajpref.metrics import as_integer  # one definition for every layer above metrics
from trajpref.models.denoiser import Denoiser, DenoiserShapes
from trajpref.models.encoder import SceneFeatures, check_neighbour_radius, scene_features
from trajpref.models.generator import Generator, GeneratorOutput
from trajpref.types import Batch

Sampler = Literal["leapfrog", "full"]
SAMPLERS: tuple[str, ...] = typing.get_args(Sampler)


class Condition:
    """What the networks see of a batch, computed once and shared by every rollout on it.

    The denoiser's context is computed on first use: a leapfrog rollout with tau = 0 never
    runs the denoiser, so it never pays for its encoder."""

    def __init__(self, features: SceneFeatures, denoiser: Denoiser,
                 denoiser_features: SceneFeatures | None = None):  # fmt: skip
        self.features = features
        """The normalised history features the generator reads."""
        self.denoiser_features = features if denoiser_features is None else denoiser_features
        """The denoiser's: the same, less any context-only agents."""
        self._denoiser = denoiser
        self._context: torch.Tensor | None = None

    @property
    def context(self) -> torch.Tensor:
        """[N, H] the denoiser's social encoding (never differentiated: the denoiser is frozen
        wherever a rollout is trained through)."""
        if self._context is None:
            with torch.no_grad():
                self._context = self._denoiser.context(self.denoiser_features)  # [N, H]
        return self._context


@dataclass
class Rollout:
    """One leapfrog rollout, in the networks' frame (relative, divided by the data scale)."""

    out: GeneratorOutput
    """mu, sigma, S of the generator (differentiable when the rollout was)."""
    initial: torch.Tensor
    """[K, N, T_f, 2] the generator's initial sample mu + sigma S (Eq. 1)."""
    y_tau: torch.Tensor
    """[K, N, T_f, 2] what entered the denoiser: ``initial`` plus the exploration, if any."""
    y: torch.Tensor
    """[K, N, T_f, 2] the denoised samples after tau steps."""
    explore: torch.Tensor | None
    """[K, N, T_f, 2] the exploration noise added to Y^tau, or None."""


SEED_RANGE = (-(2**63), 2**64 - 1)
"""The seeds ``torch.Generator.manual_seed`` takes (a negative one counts modulo 2**64)."""


def check_seed(value, name: str = "seed") -> int:
    """``value`` as a Python int seed (``as_integer``: a numpy integer from a planner's arrays
    counts), else ``ConfigError``: for None, a float, a string, a bool, or an integer outside
    ``SEED_RANGE``. The one check of the seeds the public API takes (``predict_scene``,
    ``TrajectoryScorer``, ``SelectionConfig``), before torch reads them."""
    seed = as_integer(value)
    if seed is None or not SEED_RANGE[0] <= seed <= SEED_RANGE[1]:
        raise ConfigError(f"{name} must be an integer (a Python or numpy int) from -2**63 to "
                          f"2**64 - 1, the seeds torch.Generator takes, got {value!r}")  # fmt: skip
    return seed


def check_histories(history: torch.Tensor, t_hist: int, scale: float | None = None) -> None:
    """``DataError`` unless ``history`` is [N, T_h, 2] with this ``t_hist``, finite, and in
    coordinates float32 can hold for a model of data scale ``scale`` (``check_coordinates``)."""
    if history.ndim != 3 or tuple(history.shape[1:]) != (t_hist, 2):
        raise DataError(f"history: expected [N, {t_hist}, 2] (agents, observed steps, x/y; this "
                        f"model's T_h = {t_hist}), got {list(history.shape)}")  # fmt: skip
    bad = ~torch.isfinite(history).all(dim=(1, 2))  # [N]
    if bad.any():
        first = int(bad.nonzero()[0, 0])
        raise DataError(
            f"history: {int(bad.sum())} agent(s) with non-finite positions, the first at index "
            f"{first}; every target needs all {t_hist} observed positions (an agent seen for "
            "only part of the history can be a neighbour: Scene.context)"
        )
    check_coordinates(history, scale)


def check_coordinates(history: torch.Tensor, scale: float | None = None) -> None:
    """``DataError`` unless the finite histories [N, T_h, 2] are in coordinates whose float32
    rounding stays within a small share of a step (the text reader's rule,
    ``data.text.float32_precision_loss``; map coordinates such as UTM eastings are not within
    it: subtract an origin first). With the model's data ``scale`` (data units per model
    unit), the step compared with is the median moving step or ``PRECISION_STEP_FLOOR`` model
    units, whichever is larger, so that a crowd standing with tracker jitter is judged as one
    walking is (up to 16,777 model units from the origin, 24.7 km at zara1's scale); without
    it, the median moving step alone. The one check of the prediction (``predict``) and of the
    one-scene scoring calls (``score.scene_batch``: ``rank_samples``, ``select_for_scene``),
    with one advice."""
    if history.numel() == 0:
        return
    steps = (history[:, 1:] - history[:, :-1]).norm(dim=-1).flatten()  # [N * (T_h - 1)]
    largest = float(history.abs().max())
    rounding = float(torch.finfo(torch.float32).eps) * largest / 2  # half a float32 spacing
    floor = 0.0 if scale is None else PRECISION_STEP_FLOOR * float(scale)  # data units
    problem = float32_precision_loss(largest, rounding, steps.cpu().numpy(), floor)
    if problem is not None:
        raise DataError(f"history: {problem}: subtract an origin from x and y (from the history "
                        "and any samples alike) before predicting or ranking, and add it back "
                        "to the predictions")  # fmt: skip


class DiffusionPredictor(DenoiserShapes, nn.Module):
    """Samples futures with the leapfrog sampler (generator + tau denoising steps) or the full
    S-step sampler from noise, both with the same denoiser.

    ``scale`` is the data scale: networks see coordinates divided by it. ``neighbour_radius``
    (data units; None: off): the attention across agents of both networks reads only the
    pairs within it (``ModelConfig.neighbour_radius``; ``load_predictor`` takes it from the
    checkpoint's config, and it may be set afterwards: ``model.neighbour_radius = 12.0``).
    """

    def __init__(
        self,
        denoiser: Denoiser,
        schedule: DDPMSchedule,
        scale: float,
        generator: Generator | None = None,
        tau: int = 5,
        sampler: Sampler = "leapfrog",
        stochastic: bool = True,
        neighbour_radius: float | None = None,
    ):
        super().__init__()
        if sampler not in SAMPLERS:
            raise ConfigError(f"unknown sampler {sampler!r}; choose {' or '.join(SAMPLERS)}")
        if sampler == "leapfrog" and generator is None:
            raise ConfigError("the leapfrog sampler needs a generator checkpoint")
        if not 0 <= tau <= schedule.num_steps:
            raise ConfigError(f"tau must lie in 0..{schedule.num_steps}, got {tau}")
        self.schedule = schedule
        self.scale = float(scale)
        self.denoiser = denoiser
        self.generator = generator
        self.tau = tau
        self.sampler = sampler
        self.stochastic = stochastic
        self.name = f"diffusion-{sampler}"
        self.timing: dict | None = None
        """What the checkpoint recorded of the training data (``models.timing.model_timing``:
        ``trained_on``, ``step``, ``known``, ``time_step``, ``units``); None when built in code
        or when the header says nothing of it. ``checkpoint.load_predictor`` sets it."""
        self.frame_interval: float | None = None
        """Seconds per step of the data the model was trained on (its histories and futures
        step at this pace), from the checkpoint; None where unknown."""
        self.units: str | None = None
        """Units of the data the model was trained on (``m``, ``px``), from the checkpoint;
        None where unknown."""
        self.neighbour_radius = neighbour_radius

    @property
    def neighbour_radius(self) -> float | None:
        """Agents whose last observed positions are farther apart than this (data units: the
        model's ``units``) do not attend to each other, in the generator's attention and the
        denoiser's (``ModelConfig.neighbour_radius``); None: every pair of a scene, as
        trained. Set it to a number > 0 or None; anything else is a ``ConfigError``."""
        return self._neighbour_radius

    @neighbour_radius.setter
    def neighbour_radius(self, value: float | None) -> None:
        self._neighbour_radius = check_neighbour_radius(value, "model.neighbour_radius")

    @property
    def agent_roles(self) -> int:
        """How many agent roles the sampling network knows (``ModelConfig.agent_roles``; 0:
        none). A model with roles reads each agent's place in the list as its role: the
        agents must be listed in its training data's order (robo: leader, follower,
        approacher), at most this many."""
        net = self.generator if self.sampler == "leapfrog" else self.denoiser
        return int(net.cfg.agent_roles)

    @property
    def reads_context(self) -> bool:
        """Whether the model reads context-only neighbours (``Batch.context``,
        ``predict_scene(context=...)``): a leapfrog generator built with
        ``ModelConfig.context_agents``."""
        gen = self.generator
        return self.sampler == "leapfrog" and gen is not None and bool(gen.cfg.context_agents)

    @property
    def context_frames(self) -> int:
        """The last history frames a context-only neighbour must be seen in, without a break,
        to be read (``ModelConfig.context_frames``; 0 there means all T_h)."""
        frames = self.generator.cfg.context_frames if self.generator is not None else 0
        return int(frames) or self.t_hist

    def condition(self, batch: Batch) -> Condition:
        """Features and (on first use) the denoiser's context of a batch (no gradient into
        the denoiser). A generator built with ``ModelConfig.context_agents`` also sees the
        batch's context-only agents; the denoiser never does."""
        radius = self.neighbour_radius
        plain = scene_features(batch, self.scale, radius=radius)
        if self.generator is None or not self.generator.cfg.context_agents or not batch.num_context:
            return Condition(plain, self.denoiser)
        frames = self.generator.cfg.context_frames or None  # 0: the whole history
        features = scene_features(batch, self.scale, context=True, context_frames=frames,
                                  radius=radius)  # fmt: skip
        return Condition(features, self.denoiser, plain)

    def denoise(
        self, cond: Condition, y_tau: torch.Tensor, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """tau ancestral steps of the denoiser from y_tau [K, N, T_f, 2] (differentiable in
        y_tau); without noise when the predictor is not ``stochastic``. With ``tau = 0``
        the generator's samples are returned as they are."""
        if self.tau == 0:
            return y_tau
        return denoise(self.schedule, lambda y, s: self.denoiser(y, s, cond.context), y_tau,
                       self.tau, generator, self.stochastic)  # fmt: skip

    def rollout(
        self,
        batch: Batch,
        generator: torch.Generator | None = None,
        num_samples: int | None = None,
        explore_std: float = 0.0,
        explore_sign: float = 1.0,
        cond: Condition | None = None,
        explore_noise: Callable[[torch.Size, torch.Generator | None], torch.Tensor] | None = None,
    ) -> Rollout:
        """Generator -> Y^tau (+ exploration) -> tau denoising steps.

        Gradients flow into the generator unless the caller disables them. With
        ``explore_std`` > 0, Gaussian noise xi of that std (drawn from ``generator`` before
        the denoising noise) is added to Y^tau; ``explore_sign = -1`` adds -xi instead, so a
        rollout from a copy of the same generator state is xi's antithetic twin under the same
        denoising noise. ``explore_noise(shape, generator)`` draws the noise instead of
        ``explore_std`` white noise (e.g. the RL objective's smooth exploration).
        """
        if self.generator is None:
            raise ConfigError("a leapfrog rollout needs a generator checkpoint")
        k = self.generator.samples if num_samples is None else num_samples
        self._check_generator_samples(k)
        cond = cond if cond is not None else self.condition(batch)
        out = self.generator(cond.features)
        initial = y_tau = out.initial_sample()[:k]  # [K, N, T_f, 2]
        explore = None
        if explore_noise is not None:
            explore = explore_sign * explore_noise(initial.shape, generator).to(initial)
            y_tau = initial + explore  # [K, N, T_f, 2]
        elif explore_std > 0:
            noise = torch.randn(initial.shape, generator=generator, dtype=torch.float32).to(initial)
            explore = explore_sign * explore_std * noise  # [K, N, T_f, 2]
            y_tau = initial + explore
        return Rollout(out, initial, y_tau, self.denoise(cond, y_tau, generator), explore)

    def check_samples(self, k: int) -> None:
        """``ConfigError`` when the leapfrog sampler is asked for more samples than its
        generator emits (its fixed set of K); the full sampler draws any number."""
        if self.sampler == "leapfrog" and self.generator is not None:
            self._check_generator_samples(k)

    def _check_generator_samples(self, k: int) -> None:
        if k > self.generator.samples:
            raise ConfigError(
                f"this generator emits K = {self.generator.samples} samples; "
                f"asked for {k} (for more, the full sampler: --sampler full, or "
                "sampler='full' when loading in Python)"
            )

    def sample_normalised(
        self, batch: Batch, num_samples: int, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """[K, N, T_f, 2] samples in the networks' frame."""
        if self.sampler == "leapfrog":
            return self.rollout(batch, generator, num_samples).y
        cond = self.condition(batch)
        shape = (num_samples, batch.num_agents, self.denoiser.cfg.t_fut, 2)
        return sample_full(self.schedule, lambda y, s: self.denoiser(y, s, cond.context), shape,
                           generator, batch.history.device)  # fmt: skip

    @torch.no_grad()
    def predict(
        self, batch: Batch, num_samples: int = 20, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Absolute future positions [K, N, T_f, 2]. The batch's histories must be [N, T_h, 2]
        with this model's T_h, finite, and in coordinates float32 can hold to within a small
        share of a step (``check_histories``); ``num_samples`` >= 1."""
        count = as_integer(num_samples)  # numpy integers count too
        if count is None or count < 1:
            raise ConfigError(f"num_samples must be an integer >= 1, got {num_samples!r}")
        num_samples = count
        check_histories(batch.history, self.denoiser.cfg.t_hist, self.scale)
        y = self.sample_normalised(batch, num_samples, generator)  # [K, N, T_f, 2]
        return from_model_frame(y, batch, self.scale)
