"""In-context adaptation (the paper's Sec. 8.4): before predicting a test window, adapt a copy
of the generator by a few gradient steps on the earlier windows of the same recording.

Leak-free by construction. A window starting at frame f observes frames f .. f + (T_h - 1)
(its last observed frame, f + 7 with T_h = 8). Its *context* is every window of the same
recording whose T_h + T_f frames all lie in the ``ctx_frames`` frames that end at that last
observed frame: start >= last - (ctx_frames - 1) steps and start + (T_h + T_f - 1) steps <= last.
Adaptation reads only those windows (history and future, both observed by then), never the
test window's own future nor any later frame. Each window adapts its own copy of the generator,
starting from the given weights; the copy is dropped after the prediction, so nothing is carried
from one window to the next. Windows without context are predicted by the unadapted model.

A window knows its recording and start frame only through ``Scene.scene_id``
(``<file>@frame=<number>``, written by the text reader); ``window_origin`` parses it. Frame
numbers are raw (ETH/UCY step by 10): the frame step of a recording is the smallest positive
gap between its windows' start frames, unless ``AdaptConfig.frame_step`` gives it.
"""

from __future__ import annotations

import copy
import dataclasses
import re
import time
import typing
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Literal

import torch
from tqdm.auto import tqdm

from trajpref.config import GeneratorTrainConfig
from trajpref.data.trajnet import require_future
from trajpref.data.transforms import to_model_frame
from trajpref.errors import ConfigError, DataError
from trajpref.evaluation import pass_device
from trajpref.io import bar_options
from trajpref.metrics import MetricAccumulator
from trajpref.models.generator import Generator
from trajpref.models.losses import generator_loss
from trajpref.models.predictor import DiffusionPredictor
from trajpref.score.scorer import TrajectoryScorer, relative_score, score_timesteps
from trajpref.types import Batch, TrajectoryDataset, collate

AdaptParams = Literal["heads", "sigma", "all"]
ADAPT_PARAMS: tuple[str, ...] = typing.get_args(AdaptParams)
AdaptObjective = Literal["supervised", "score", "both"]
ADAPT_OBJECTIVES: tuple[str, ...] = typing.get_args(AdaptObjective)
PARAM_PREFIXES: dict[str, tuple[str, ...]] = {
    "heads": ("mean_head.", "sigma_head.", "shift_head."),
    "sigma": ("sigma_head.",),
    "all": ("",),
}
"""Which generator parameters adapt: names starting with one of these prefixes."""

_ORIGIN = re.compile(r"^(?P<name>.+)@frame=(?P<frame>[-+0-9.eE]+)$")


@dataclass
class AdaptConfig:
    """How each test window adapts its copy of the generator."""

    ctx_frames: int = 40
    """Frames before (and including) the window's last observed frame that context windows
    must lie in (40 frames = 16 s at 0.4 s); at least T_h + T_f."""
    steps: int = 5
    """Gradient steps per window (0: no adaptation)."""
    lr: float = 1e-4
    """Adam learning rate of the adaptation."""
    params: AdaptParams = "heads"
    """Which generator parameters adapt: ``heads`` (mean, sigma and shift heads), ``sigma``
    (the sigma head only) or ``all``."""
    trust: float = 0.0
    """Weight of the trust region: trust * sum ||theta - theta_start||^2 is added to the loss."""
    objective: AdaptObjective = "supervised"
    """The adaptation loss on the context windows: ``supervised`` is the generator's best-of-K
    loss (``models.losses.generator_loss``); ``score`` maximises the fine-tuning's reward, the
    diffusion score of Eq. 6 (r = 1 - d_pred / d_gt, averaged over samples, agents and steps),
    by its pathwise gradient through the tau denoising steps instead of a policy gradient;
    ``both`` adds ``score_weight`` times the score loss to the supervised one."""
    score_weight: float = 1.0
    """Weight of the score loss when ``objective`` is ``both``."""
    score_every: int = 9
    """Spacing of the diffusion steps the score is computed at (9: 12 of 100 steps)."""
    grad_clip: float = 1.0
    """Gradient-norm clip per step."""
    frame_step: float | None = None
    """Raw frame numbers between consecutive frames (None: per recording, the smallest positive
    gap between its window start frames)."""
    loss: GeneratorTrainConfig = field(default_factory=GeneratorTrainConfig)
    """The weights of the supervised loss's terms."""

    def __post_init__(self) -> None:
        if self.ctx_frames < 1:
            raise ConfigError(f"AdaptConfig.ctx_frames must be >= 1, got {self.ctx_frames}")
        if self.steps < 0:
            raise ConfigError(f"AdaptConfig.steps must be >= 0, got {self.steps}")
        if not self.lr > 0:
            raise ConfigError(f"AdaptConfig.lr must be > 0, got {self.lr}")
        if self.params not in ADAPT_PARAMS:
            raise ConfigError(f"AdaptConfig.params must be one of {', '.join(ADAPT_PARAMS)}, "
                              f"got {self.params!r}")  # fmt: skip
        if not self.trust >= 0:
            raise ConfigError(f"AdaptConfig.trust must be >= 0, got {self.trust}")
        if self.objective not in ADAPT_OBJECTIVES:
            raise ConfigError(f"AdaptConfig.objective must be one of "
                              f"{', '.join(ADAPT_OBJECTIVES)}, got {self.objective!r}")  # fmt: skip
        if not self.score_weight >= 0:
            raise ConfigError(f"AdaptConfig.score_weight must be >= 0, got {self.score_weight}")
        if self.score_every < 1:
            raise ConfigError(f"AdaptConfig.score_every must be >= 1, got {self.score_every}")
        if not self.grad_clip > 0:
            raise ConfigError(f"AdaptConfig.grad_clip must be > 0, got {self.grad_clip}")
        if self.frame_step is not None and not self.frame_step > 0:
            raise ConfigError(f"AdaptConfig.frame_step must be > 0, got {self.frame_step}")


def window_origin(scene_id: str) -> tuple[str, float]:
    """``'crowds_zara01.txt@frame=120'`` -> ``('crowds_zara01.txt', 120.0)``: the recording
    and the raw start frame of a window. DataError for ids without ``@frame=``."""
    m = _ORIGIN.match(scene_id)
    if m is None:
        raise DataError(f"scene {scene_id!r} has no '<file>@frame=<n>' id: in-context "
                        "adaptation needs windows read from track files")  # fmt: skip
    try:
        return m["name"], float(m["frame"])
    except ValueError:
        raise DataError(f"scene {scene_id!r}: frame {m['frame']!r} is not a number") from None


def context_windows(dataset: TrajectoryDataset, cfg: AdaptConfig) -> list[list[int]]:
    """For every window of the dataset, the indices of its context windows (see the module
    docstring), in dataset order."""
    t_hist, t_total = dataset.info.t_hist, dataset.info.t_hist + dataset.info.t_fut
    if cfg.ctx_frames < t_total:
        raise ConfigError(f"--in-context {cfg.ctx_frames} frames cannot hold a whole window "
                          f"of {t_total} frames")  # fmt: skip
    recordings: dict[str, list[tuple[float, int]]] = defaultdict(list)
    for i, scene in enumerate(dataset.scenes):
        name, frame = window_origin(scene.scene_id)
        recordings[name].append((frame, i))
    out: list[list[int]] = [[] for _ in dataset.scenes]
    for windows in recordings.values():
        starts = sorted({f for f, _ in windows})
        gaps = [b - a for a, b in zip(starts[:-1], starts[1:], strict=True)]
        step = cfg.frame_step or (min(gaps) if gaps else 1.0)
        # window starts lie a whole number of steps apart, but frames that are Unix seconds
        # carry float64's rounding (0.39999986 s for 0.4 at 1.7e9 s): a quarter step of slack
        # tells the two apart at any magnitude (1e-6 of a step found no context there)
        tol = 0.25 * step
        for f, i in windows:
            last = f + (t_hist - 1) * step  # the last observed frame
            lo = last - (cfg.ctx_frames - 1) * step
            out[i] = [j for g, j in windows
                      if g >= lo - tol and g + (t_total - 1) * step <= last + tol]  # fmt: skip
            out[i].sort()
    return out


def window_seed(seed: int, index: int) -> int:
    """The seed of window ``index``'s random draws (adaptation, then prediction)."""
    return (seed * 1_000_003 + index) % (2**63)


def _with_generator(model: DiffusionPredictor, generator: Generator) -> DiffusionPredictor:
    """A predictor sharing ``model``'s denoiser, schedule and sampling settings (its
    ``neighbour_radius`` included), with another generator."""
    return DiffusionPredictor(model.denoiser, model.schedule, model.scale, generator, model.tau,
                              model.sampler, model.stochastic,
                              neighbour_radius=model.neighbour_radius)  # fmt: skip


def _check_model(model) -> None:
    if not isinstance(model, DiffusionPredictor) or model.generator is None:
        raise ConfigError("in-context adaptation needs a diffusion model with a generator "
                          "(a generator or fine-tuned checkpoint)")  # fmt: skip
    if model.sampler != "leapfrog":
        raise ConfigError("in-context adaptation adapts the generator: use --sampler leapfrog")


def adapt_generator(
    model: DiffusionPredictor, context: Batch, cfg: AdaptConfig,
    rng: torch.Generator | None = None,
) -> Generator:  # fmt: skip
    """A copy of ``model.generator`` after ``cfg.steps`` Adam steps of ``cfg.objective`` on
    the ``context`` batch; ``model`` itself is left unchanged."""
    gen = copy.deepcopy(model.generator)
    gen.eval()
    prefixes = PARAM_PREFIXES[cfg.params]
    named = [(n, p) for n, p in gen.named_parameters()]
    chosen = [p for n, p in named if n.startswith(prefixes)]
    for n, p in named:
        p.requires_grad_(n.startswith(prefixes))
    start = [p.detach().clone() for p in chosen]
    view = _with_generator(model, gen)
    cond = view.condition(context)
    target = to_model_frame(context.future, context, model.scale)  # [N, T_f, 2]
    scorer = None
    if cfg.objective != "supervised":
        steps = score_timesteps(model.schedule.num_steps, cfg.score_every)
        scorer = TrajectoryScorer(model.denoiser, model.schedule, model.scale, steps,
                                  neighbour_radius=model.neighbour_radius)  # fmt: skip
    opt = torch.optim.Adam(chosen, lr=cfg.lr)
    for _ in range(cfg.steps):
        roll = view.rollout(context, rng, cond=cond)
        loss = torch.zeros((), device=target.device)
        if cfg.objective in ("supervised", "both"):
            loss = loss + generator_loss(roll.out, roll.y, target, cfg.loss)[0]
        if scorer is not None:
            # the ground truth shares the samples' noise (one call); its d is a constant
            d = scorer.residual_differentiable(cond.context, torch.cat([roll.y, target[None]]))
            r = relative_score(d[:-1], d[-1].detach())  # [K, N, T_f]
            weight = cfg.score_weight if cfg.objective == "both" else 1.0
            loss = loss - weight * r.mean()
        if cfg.trust > 0:
            loss = loss + cfg.trust * sum((p - s).pow(2).sum() for p, s in
                                          zip(chosen, start, strict=True))  # fmt: skip
        grads = torch.autograd.grad(loss, chosen)
        for p, g in zip(chosen, grads, strict=True):
            p.grad = g
        torch.nn.utils.clip_grad_norm_(chosen, cfg.grad_clip)
        opt.step()
    gen.requires_grad_(False)
    return gen


@dataclass
class InContextPrediction:
    """What ``adapt_and_predict`` returns, one entry per predicted window."""

    indices: list[int]
    """The predicted windows' indices in the dataset."""
    pred: list[torch.Tensor]
    """[K, P, T_f, 2] absolute samples of each window (after adaptation when it had context)."""
    context: list[list[int]]
    """Each window's context windows (dataset indices; empty: predicted unadapted)."""
    seconds: float
    """Wall time of the whole call."""

    @property
    def windows_with_context(self) -> int:
        return sum(1 for c in self.context if c)


def adapt_and_predict(
    model: DiffusionPredictor, dataset: TrajectoryDataset, cfg: AdaptConfig | None = None,
    num_samples: int = 20, seed: int = 0, indices: list[int] | None = None,
    device: torch.device | str | None = None, progress: bool | str = False,
) -> InContextPrediction:  # fmt: skip
    """Predict the windows ``indices`` (default: all) of ``dataset``, each by its own copy of
    the generator adapted on its context windows (``context_windows``); windows without
    context are predicted by ``model`` unchanged. Window i's draws come from
    ``torch.Generator().manual_seed(window_seed(seed, i))``, so a window's prediction does not
    depend on which other windows are predicted. ``progress``: a progress bar over the
    windows (a string: its label). ``device``: None, the model's; else as
    ``trajpref.device.resolve_device`` takes it (``auto``, ``cpu``, ``cuda[:i]``). A model
    whose weights are on another device than that (or on one this machine cannot compute on)
    is a ``ConfigError`` before any work, as in ``evaluate`` (``evaluation.pass_device``)."""
    cfg = cfg or AdaptConfig()
    _check_model(model)
    device = pass_device(model, device, call="adapt_and_predict")
    ctx = context_windows(dataset, cfg)
    indices = list(range(len(dataset))) if indices is None else list(indices)
    for i in indices:
        if not 0 <= i < len(dataset):
            raise ConfigError(f"window index {i} outside 0..{len(dataset) - 1}")
    start = time.perf_counter()
    preds, contexts = [], []
    label = progress if isinstance(progress, str) else f"in-context {dataset.info.name}"
    for i in tqdm(indices, desc=label, unit="window", leave=False, **bar_options(progress)):
        rng = torch.Generator().manual_seed(window_seed(seed, i))
        batch = collate([dataset[i]]).to(device)
        use = ctx[i] if cfg.steps > 0 else []
        predictor = model
        if use:
            context = collate([dataset[j] for j in use]).to(device)
            with torch.enable_grad():
                predictor = _with_generator(model, adapt_generator(model, context, cfg, rng))
        preds.append(predictor.predict(batch, num_samples, rng))
        contexts.append(ctx[i])
    return InContextPrediction(indices, preds, contexts, time.perf_counter() - start)


def _metrics(dataset: TrajectoryDataset, indices: list[int], preds: list[torch.Tensor]) -> dict:
    acc = MetricAccumulator()
    for i, pred in zip(indices, preds, strict=True):
        future = torch.as_tensor(dataset[i].future).to(pred)  # [P, T_f, 2]
        scene = torch.zeros(future.shape[0], dtype=torch.long, device=pred.device)  # [P]
        acc.update(pred, future, scene, 1)
    return acc.compute()


def evaluate_in_context(
    model: DiffusionPredictor, dataset: TrajectoryDataset, cfg: AdaptConfig | None = None,
    num_samples: int = 20, seed: int = 0, indices: list[int] | None = None,
    device: torch.device | str | None = None, progress: bool = False,
) -> dict:  # fmt: skip
    """The usual metrics (minADE/minFDE per agent and joint) of ``adapt_and_predict`` over the
    windows ``indices``, plus ``windows``, ``windows_with_context``, ``seconds_per_window`` and,
    on the windows that have context, ``before`` and ``after``: the metrics of the unadapted
    model (same draws' seed) and of the adapted copies (None when no window has context; with
    ``cfg.steps`` 0 the two are the same predictions, and equal). ``progress``: progress bars
    over the windows (the adapted pass, then the unadapted one on the windows with context)."""
    require_future(dataset, "evaluate_in_context")  # TrajNet++ test files: NaN metrics otherwise
    cfg = cfg or AdaptConfig()
    name = dataset.info.name
    res = adapt_and_predict(model, dataset, cfg, num_samples, seed, indices, device,
                            progress and f"in-context {name}")  # fmt: skip
    out = _metrics(dataset, res.indices, res.pred)
    out.update(windows=len(res.indices), windows_with_context=res.windows_with_context,
               seconds_per_window=res.seconds / max(len(res.indices), 1))  # fmt: skip
    with_ctx = [(i, p) for i, p, c in zip(res.indices, res.pred, res.context, strict=True) if c]
    out["before"] = out["after"] = None
    if with_ctx:
        idx = [i for i, _ in with_ctx]
        out["after"] = _metrics(dataset, idx, [p for _, p in with_ctx])
        if cfg.steps == 0:  # nothing adapted: the predictions are the unadapted ones already
            out["before"] = dict(out["after"])
        else:
            unadapted = dataclasses.replace(cfg, steps=0)  # same per-window seeds, no steps
            base = adapt_and_predict(model, dataset, unadapted, num_samples, seed, idx, device,
                                     progress and f"before {name}")  # fmt: skip
            out["before"] = _metrics(dataset, idx, base.pred)
    return out
