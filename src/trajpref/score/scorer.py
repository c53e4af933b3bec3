"""Diffusion residuals and the trajectory score (Eq. 5-8), read as in docs/design.md.

    d(Y; X)[k,p,t] = mean_{s in S_score} || eps_theta(sqrt(abar_s) Y + sqrt(1-abar_s) Z_s, s, X)_t
                                            - Z_{s,t} ||^2                          (Eq. 5)
    r = 1 - d_p / d_g                                                               (Eq. 6)
    ATS(k) = 1 - sum_{p,t} d_p / sum_{p,t} d_g,  FTS(k): the same at t = T_f        (ratio of sums)

S_score = {0, 3, ..., 99}. The same noise Z_s serves all K samples and the ground truth
(common random numbers), so the ranking of samples by sum d_p depends on the predictions alone
and needs no ground truth (Lemma 1). Eq. 7's mean of ratios is offered too, under that name.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from typing import Literal

import numpy as np
import torch

from trajpref.data.transforms import (
    seen_run,
    speed_normaliser,
    to_model_frame,
    transform_positions,
    transform_scenes,
)
from trajpref.device import resolve_device
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import (
    ConfigError,
    DataError,
    IgnoredWarning,
    OutOfRangeWarning,
    TrajprefWarning,
)
from trajpref.metrics import ade_fde, scene_sum
from trajpref.models import checkpoint
from trajpref.models.denoiser import Denoiser, DenoiserShapes
from trajpref.models.encoder import check_neighbour_radius, scene_features
from trajpref.models.predictor import as_integer, check_coordinates, check_seed
from trajpref.models.timing import (
    JUMP_LIMIT,
    attach_timing,
    check_observed_steps,
    check_pace,
    copy_attached,
    observed_jumps,
)
from trajpref.types import AGENT_BALL, AGENT_PERSON, WINDOW, Batch

NOISE_LAYOUT = "scene-slot"
"""How the residual's noise is assigned to agents: ``scene-slot`` (since 2026-12-05), by each
agent's index within its own scene (``scene_slots``); before that, by its index in the batch.
Stored evaluations key on it (benchmarks/reproduce.py), so a change of layout re-measures them.
Since 2026-12-06 each slot's draw is padded to a multiple of 16 values (``slot_noise``): for
the published models' 12 future steps (24 values a step) the numbers of an even number of
score steps (34, 12, 2: those stored evaluations use) are the same as before, while an odd
number's (1, 5, 17, ...) had depended on the batch's largest scene and now do not; the
selection rows of 1 score step were measured again then (validation records of odd step
counts under ``benchmarks/results/meta`` were not)."""


def slot_noise(rows: int, shape: tuple[int, ...], generator: torch.Generator) -> torch.Tensor:
    """[rows, *shape] standard normal draws, row r the same whatever ``rows`` is (a slot's
    noise does not depend on how many slots the batch has). torch fills a draw of 16 values or
    more in blocks of 16 and redraws the last block of a size that is not a multiple of 16, so
    each row is drawn padded to a multiple of 16 values and cut: for a row of such a size (an
    even number of score steps: 24 values a step) the numbers are those of one plain draw."""
    size = math.prod(shape)
    padded = -(-size // 16) * 16  # the row's values, rounded up to a multiple of 16
    # float32 whatever torch's default dtype is: a float64 draw gives other numbers
    z = torch.randn((rows, padded), generator=generator, dtype=torch.float32)  # [rows, padded]
    return z[:, :size].reshape(rows, *shape)


def score_timesteps(num_steps: int = 100, every: int = 3, start: int = 0) -> list[int]:
    """The paper's "every 3 steps": start, start + 3, ..., up to num_steps - 1 (start = 0 is
    the paper's chain from the lowest noise level; a later start keeps only the noisier steps,
    docs/score.md, "Study: score timesteps")."""
    if every < 1:
        raise ConfigError("the score's step spacing must be >= 1")
    if not 0 <= start < num_steps:
        raise ConfigError(f"the score's first step must lie in 0..{num_steps - 1}, got {start}")
    return list(range(start, num_steps, every))


def check_score_steps(steps, num_steps: int) -> list[int]:
    """The score steps ``steps`` (a list, a tuple, a numpy array or a 1-D tensor of integers,
    numpy integers counting: ``np.arange(0, 100, 3)``) as a list of Python ints, each in
    0..``num_steps - 1``; at least one. ``ConfigError`` for anything else (a fraction such as
    0.5, a single number, a string)."""
    want = f"a list of integer diffusion steps in 0..{num_steps - 1}"
    if isinstance(steps, (str, bytes)) or getattr(steps, "ndim", 1) != 1:
        raise ConfigError(f"score steps: {want} (e.g. [0] or range(0, {num_steps}, 3)), got "
                          f"{steps!r}")  # fmt: skip
    try:
        given = list(steps)
    except TypeError:
        raise ConfigError(f"score steps: {want} (e.g. [0] or range(0, {num_steps}, 3)), got "
                          f"{steps!r}") from None  # fmt: skip
    values = [as_integer(s) for s in given]
    bad = [s for s, v in zip(given, values, strict=True) if v is None]
    if bad:
        raise ConfigError(f"score steps must be integers (diffusion steps in "
                          f"0..{num_steps - 1}), got {bad[0]!r}")  # fmt: skip
    if not values or min(values) < 0 or max(values) >= num_steps:
        raise ConfigError(f"score steps must lie in 0..{num_steps - 1} (at least one), got "
                          f"{values}")  # fmt: skip
    return values


def relative_score(d_pred: torch.Tensor, d_gt: torch.Tensor) -> torch.Tensor:
    """Eq. 6, the per-step score r = 1 - d_pred / d_gt: d_pred [..., N, T_f] against the
    ground truth's d_gt [N, T_f]. 1 is perfect; 0 is as typical as the ground truth."""
    return 1 - d_pred / d_gt


@dataclass
class ScoreResult:
    """Scores of K samples of every scene in a batch."""

    d_pred: torch.Tensor
    """[K, N, T_f] residuals of the samples."""
    d_gt: torch.Tensor
    """[N, T_f] residuals of the ground truth."""
    r: torch.Tensor
    """[K, N, T_f] the per-step score 1 - d_pred / d_gt (Eq. 6), unclipped."""
    ats: torch.Tensor
    """[K, B] 1 - sum_{p,t} d_pred / sum_{p,t} d_gt (ratio of sums, Lemma 1's form)."""
    fts: torch.Tensor
    """[K, B] the same at the final step only."""
    ats_mean_of_ratios: torch.Tensor
    """[K, B] Eq. 7 as printed: the mean over p, t of r (depends on the ground truth)."""
    fts_mean_of_ratios: torch.Tensor
    """[K, B] Eq. 8 as printed: the mean over p of r at t = T_f."""

    @property
    def agent_ats(self) -> torch.Tensor:
        """[K, N] each agent's own ATS (its residual summed over time against its ground
        truth's): what the per-agent plots shade by."""
        return relative_score(self.d_pred.sum(-1), self.d_gt.sum(-1))


def score_result(d_pred: torch.Tensor, d_gt: torch.Tensor, scene: torch.Tensor,
                 num_scenes: int) -> ScoreResult:  # fmt: skip
    """The scores of residuals d_pred [K, N, T_f] and d_gt [N, T_f] of the agents of
    ``num_scenes`` scenes (``scene`` [N], each scene's index, every scene with an agent):
    what ``TrajectoryScorer.score`` returns, and the same over a subset of the agents (the
    persons of ``evaluation.evaluate(agents="persons")``)."""
    r = relative_score(d_pred, d_gt)  # [K, N, T_f]
    b = num_scenes
    sum_p = scene_sum(d_pred.sum(-1), scene, b)  # [K, B]
    sum_g = scene_sum(d_gt.sum(-1), scene, b)  # [B]
    fin_p = scene_sum(d_pred[..., -1], scene, b)  # [K, B]
    fin_g = scene_sum(d_gt[..., -1], scene, b)  # [B]
    sizes = torch.bincount(scene, minlength=b).to(r.dtype)  # [B]
    return ScoreResult(
        d_pred=d_pred,
        d_gt=d_gt,
        r=r,
        ats=relative_score(sum_p, sum_g),
        fts=relative_score(fin_p, fin_g),
        ats_mean_of_ratios=scene_sum(r.mean(-1), scene, b) / sizes,
        fts_mean_of_ratios=scene_sum(r[..., -1], scene, b) / sizes,
    )


PRECISIONS = ("fp32", "bf16")
"""Arithmetic of the scorer's denoiser passes (``TrajectoryScorer.precision``)."""


class TrajectoryScorer(DenoiserShapes):
    """Scores futures with a frozen denoiser: lower residual = more human-like."""

    def __init__(
        self,
        denoiser: Denoiser,
        schedule: DDPMSchedule,
        scale: float,
        steps: Sequence[int] | None = None,
        seed: int = 0,
        shared_noise: bool = True,
        speed_ref: float | None = None,
        precision: str = "fp32",
        neighbour_radius: float | None = None,
    ):
        """``speed_ref`` (data units per step; None: off): score a scene that moves faster
        than this as if it were slowed down to it (scene, history and samples scaled together
        about the scene's centre), so that a denoiser trained on slower scenes still ranks
        the samples that keep the scene's own pace as typical (docs/selection.md).
        ``precision``: ``fp32``, or ``bf16`` (the denoiser's passes of ``residual`` under
        bfloat16 autocast, the residuals summed in fp32: about 3x faster on a CPU with
        bfloat16 instructions; docs/selection.md, "Scoring in bfloat16").
        ``neighbour_radius`` (data units; None: off): the denoiser's attention across agents
        reads only the pairs within it (``ModelConfig.neighbour_radius``), measured before
        ``speed_ref`` scales a scene. ``steps`` (None: the paper's 34, ``score_timesteps``)
        are integers in 0..S-1 (``check_score_steps``; numpy integers count) and ``seed`` an
        integer (``models.predictor.check_seed``): anything else is a ``ConfigError``."""
        self.denoiser = denoiser.eval()
        self.schedule = schedule
        self.scale = float(scale)
        self.steps = score_timesteps(schedule.num_steps) if steps is None else steps
        self.seed = seed
        self.shared_noise = shared_noise
        if speed_ref is not None and not speed_ref > 0:
            raise ConfigError(f"speed_ref must be > 0 or None, got {speed_ref}")
        self.speed_ref = speed_ref
        if precision not in PRECISIONS:
            raise ConfigError(f"scorer precision must be one of {PRECISIONS}, got {precision!r}")
        self.precision = precision
        self.timing: dict | None = None
        """What the checkpoint recorded of the training data (``models.timing.model_timing``);
        None when built in code. ``from_checkpoint`` sets it, with the four below."""
        self.frame_interval: float | None = None
        """Seconds per step of the data the denoiser was trained on; None where unknown."""
        self.units: str | None = None
        """Units of the data the denoiser was trained on (``m``, ``px``); None where unknown."""
        self.training_width: float | None = None
        """The widest training scene, in model units (``models.timing.training_width``), which
        sets the wide-scene warning's limit; None where unknown."""
        self.training_width_from: str | None = None
        """Where ``training_width`` comes from (``checkpoint`` or a built-in dataset's name)."""
        self.checkpoint: str | None = None
        """The file it was loaded from (``from_checkpoint``), which the data checks' warnings
        name; None when built in code."""
        self.neighbour_radius = neighbour_radius

    @property
    def steps(self) -> list[int]:
        """The diffusion steps the residual averages over (Eq. 5's S_score), as Python ints.
        Set it to integers in 0..S-1 (``check_score_steps``), or use ``with_steps``."""
        return self._steps

    @steps.setter
    def steps(self, value: Sequence[int]) -> None:
        self._steps = check_score_steps(value, self.schedule.num_steps)

    @property
    def seed(self) -> int:
        """The seed of the residual's noise (common random numbers: the same call gives the
        same numbers). Set it to an integer (``models.predictor.check_seed``; numpy integers
        count); anything else is a ``ConfigError``."""
        return self._seed

    @seed.setter
    def seed(self, value: int) -> None:
        self._seed = check_seed(value)

    @property
    def neighbour_radius(self) -> float | None:
        """Agents whose last observed positions are farther apart than this (data units) do
        not attend to each other in the denoiser's encoder (``ModelConfig.neighbour_radius``;
        ``from_checkpoint`` takes it from the file's config); None: every pair of a scene.
        Set it to a number > 0 or None; anything else is a ``ConfigError``."""
        return self._neighbour_radius

    @neighbour_radius.setter
    def neighbour_radius(self, value: float | None) -> None:
        self._neighbour_radius = check_neighbour_radius(value, "scorer.neighbour_radius")

    @classmethod
    def from_checkpoint(
        cls,
        path: str | PathLike,
        device: str | torch.device = "cpu",
        *,
        steps: Sequence[int] | None = None,
        seed: int = 0,
        shared_noise: bool = True,
        speed_ref: float | None = None,
        precision: str = "fp32",
        neighbour_radius: float | None | Literal["checkpoint"] = "checkpoint",
    ) -> TrajectoryScorer:
        """From a denoiser checkpoint, or the denoiser embedded in a generator checkpoint
        (``path``: a published name such as ``zara1/denoiser``, or a file); it carries the
        checkpoint's training step and units (``frame_interval``, ``units``), and its
        ``model.neighbour_radius`` (a generator file's own, as the predictor loaded from it
        uses) unless ``neighbour_radius`` is given (None: off). ``device``: ``auto``, ``cpu``,
        ``cuda[:i]`` or a ``torch.device``. The other arguments are ``__init__``'s. Building
        it draws nothing from torch's global random stream, nor saves and restores it (the
        denoiser is built without random initialisation: ``checkpoint.built_for_loading``),
        so it is safe beside threads that draw from that stream."""
        checkpoint.check_spec(path, "TrajectoryScorer.from_checkpoint")  # None: ConfigError
        device = resolve_device(device)  # "auto" as the CLI reads it; a missing GPU in one line
        header = checkpoint.load(path)
        payload = checkpoint.denoiser_of(header)
        denoiser, cfg = checkpoint.build_denoiser(payload, loading=True)  # no random init
        denoiser = checkpoint.as_float32(denoiser)  # float32 under any default dtype
        schedule = DDPMSchedule.from_config(cfg.diffusion)
        if isinstance(neighbour_radius, str) and neighbour_radius == "checkpoint":
            neighbour_radius = checkpoint.config_of(header).model.neighbour_radius
        scorer = cls(denoiser.to(device), schedule.to(device), payload["scale"], steps, seed,
                     shared_noise, speed_ref, precision, neighbour_radius)  # fmt: skip
        scorer.checkpoint = str(path)  # named by the data checks' warnings
        return attach_timing(scorer, header, payload)  # the training width: its denoiser's

    def with_steps(self, steps: Sequence[int], precision: str | None = None) -> TrajectoryScorer:
        """This scorer at other score steps (and ``precision``; None: its own), sharing its
        denoiser and schedule; itself when nothing changes. ``steps`` are checked as
        ``__init__``'s (``check_score_steps``)."""
        steps = check_score_steps(steps, self.schedule.num_steps)
        precision = self.precision if precision is None else precision
        if steps == self.steps and precision == self.precision:
            return self
        other = TrajectoryScorer(self.denoiser, self.schedule, self.scale, steps,
                                 self.seed, self.shared_noise, self.speed_ref,
                                 precision, self.neighbour_radius)  # fmt: skip
        copy_attached(self, other)  # the checkpoint's record: timing, units, training width
        other.checkpoint = self.checkpoint  # the warnings name the same file
        return other

    def check_shapes(self, batch: Batch, futures: torch.Tensor) -> None:
        """DataError unless the batch's histories are [N, T_h, 2] and futures [M, N, T_f, 2]
        with this scorer's T_h and T_f."""
        n = batch.history.shape[0]
        if batch.history.ndim != 3 or tuple(batch.history.shape[1:]) != (self.t_hist, 2):
            raise DataError(
                f"history: expected [N, {self.t_hist}, 2] (this scorer's T_h = {self.t_hist}), "
                f"got {list(batch.history.shape)}"
            )
        if futures.ndim != 4 or tuple(futures.shape[1:]) != (n, self.t_fut, 2):
            raise DataError(
                f"futures: expected [M, {n}, {self.t_fut}, 2] (N = {n} agents, this scorer's "
                f"T_f = {self.t_fut}), got {list(futures.shape)}"
            )

    @torch.no_grad()
    def residual(self, batch: Batch, futures: torch.Tensor) -> torch.Tensor:
        """d for absolute futures [M, N, T_f, 2] of the batch's agents -> [M, N, T_f].

        Uses only the histories of ``batch`` (its ``future`` is never read). The noise is
        drawn from a generator seeded with ``seed``: the same call gives the same numbers,
        and an agent's noise depends on its place in its own scene only, so a scene scores the
        same alone (``rank_samples``) as among other scenes (``evaluate``, ``--keep``).
        """
        self.check_shapes(batch, futures)
        radius = self.neighbour_radius
        # [B, P, P] who attends to whom, from the scene as given (before speed_ref scales it)
        pairs = None if radius is None else scene_features(batch, self.scale, radius=radius).pairs
        if self.speed_ref is not None:
            mats = speed_normaliser(batch, self.speed_ref)  # [B, 2, 2]
            futures = transform_positions(futures, batch, mats)  # [M, N, T_f, 2]
            batch = transform_scenes(batch, mats)
        low = torch.autocast(self.device.type, torch.bfloat16, enabled=self.precision == "bf16")
        with low:
            features = scene_features(batch, self.scale)
            if pairs is not None:
                features = dataclasses.replace(features, pairs=pairs)
            context = self.denoiser.context(features)  # [N, H]
            y = to_model_frame(futures, batch, self.scale)  # [M, N, T_f, 2]
            return self.residual_normalised(context, y, scene_slots(batch.scene)).float()

    @torch.no_grad()
    def residual_normalised(self, context: torch.Tensor, y: torch.Tensor,
                            slots: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
        """d for futures already in the denoiser's frame (relative, divided by the data
        scale): y [M, N, T_f, 2], context [N, H] from this scorer's denoiser -> [M, N, T_f].
        ``slots`` [N]: each agent's index within its scene (``scene_slots``), which picks its
        noise; None: its index in the batch (the same for a batch of one scene)."""
        return self.residual_differentiable(context, y, slots)

    def residual_differentiable(self, context: torch.Tensor, y: torch.Tensor,
                                slots: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
        """``residual_normalised`` with autograd on: gradients flow from d into y (and into
        whatever made y), never into the frozen denoiser's weights unless they require it."""
        m, n, t_f, _ = y.shape
        gen = torch.Generator().manual_seed(self.seed)
        # slot-major draw: an agent's noise depends on its slot only (its index in its scene,
        # or in the batch without slots), not on the batch's size or other scenes
        slots = torch.arange(n) if slots is None else slots.cpu()  # [N]
        rows = int(slots.max()) + 1 if n else 0
        shape = (len(self.steps), 1 if self.shared_noise else m, t_f, 2)  # one slot's draw
        z = slot_noise(rows, shape, gen)[slots]  # [N, S', 1|M, T_f, 2]
        z = z.permute(1, 2, 0, 3, 4).to(y)  # [S', 1|M, N, T_f, 2]
        d = y.new_zeros(m, n, t_f)
        # one step at a time: the denoiser's conditioning on (step, agent) is then computed
        # once per agent and shared by the M samples (about half the cost of a pass)
        for i, s in enumerate(self.steps):
            y_s = self.schedule.add_noise(y, z[i], torch.tensor(s))  # [M, N, T_f, 2]
            eps = self.denoiser(y_s, s, context)  # [M, N, T_f, 2]
            d += (eps.to(d.dtype) - z[i]).pow(2).sum(-1)  # fp32 even under autocast
        return d / len(self.steps)  # [M, N, T_f]

    @torch.no_grad()
    def step_scores(
        self, context: torch.Tensor, futures: torch.Tensor, target: torch.Tensor
    ) -> torch.Tensor:
        """Eq. 6 for futures [M, N, T_f, 2] against the ground truth target [N, T_f, 2], both
        in the denoiser's frame, with context [N, H] -> r [M, N, T_f]. One residual call
        serves both, so they share the noise."""
        d = self.residual_normalised(context, torch.cat([futures, target[None]]))  # [M+1,N,T]
        return relative_score(d[:-1], d[-1])

    @torch.no_grad()
    def score(self, batch: Batch, pred: torch.Tensor) -> ScoreResult:
        """Score K samples pred [K, N, T_f, 2] against the batch's ground truth."""
        self.check_shapes(batch, pred)
        k = pred.shape[0]
        d = self.residual(batch, torch.cat([pred, batch.future[None]], 0))  # [K+1, N, T_f]
        return score_result(d[:k], d[k], batch.scene, batch.num_scenes)

    @torch.no_grad()
    def scene_residual(self, batch: Batch, pred: torch.Tensor, final: bool = False):
        """Each sample's residual summed over a scene's agents and all steps (or the final
        step only): [K, B]. Lower is more human-like; no ground truth is read."""
        d = self.residual(batch, pred)  # [K, N, T_f]
        return scene_sum(d[..., -1] if final else d.sum(-1), batch.scene, batch.num_scenes)

    @torch.no_grad()
    def rank(self, batch: Batch, pred: torch.Tensor, final: bool = False) -> torch.Tensor:
        """Ground-truth-free ranking: [K, B] sample indices per scene, best first, by the
        scene's summed residual over all steps (ATS order) or the final step (FTS order)."""
        return self.scene_residual(batch, pred, final).argsort(0)  # [K, B]


ArrayLike = np.ndarray | torch.Tensor
"""What the public API accepts: a numpy array (or anything ``np.asarray`` reads) or a tensor."""


HALF_PRECISION = (
    "half precision ({dtype}) rounds positions too coarsely for trajectories: its 8 "
    "(bfloat16) or 11 (float16) significant bits hold positions near 100 m only to 0.5 m "
    "or 0.06 m, so a walker's 0.5 m steps read as 0 or 1 m and the futures move by metres; "
    "pass float32 or float64 (x.float(), np.asarray(x, np.float32))"
)
"""Why ``_float_tensor`` refuses float16 and bfloat16 input (``{dtype}``: the input's)."""


def _input_dtype_problem(dtype) -> str | None:
    """Why positions of ``dtype`` (a torch or numpy dtype) cannot be read as coordinates,
    None when they can: booleans (True would read as 1), complex numbers (the imaginary part
    would be dropped), half precision (``HALF_PRECISION``). The same for tensors and arrays."""
    if isinstance(dtype, torch.dtype):
        if dtype == torch.bool or dtype.is_complex:
            return f"expected real numbers, got a {dtype} tensor"
        half = dtype in (torch.float16, torch.bfloat16)
        return HALF_PRECISION.format(dtype=dtype) if half else None
    if dtype.kind in "bc":
        return f"expected real numbers, got a numpy {dtype} array"
    half = dtype.kind == "f" and dtype.itemsize < 4
    return HALF_PRECISION.format(dtype=f"numpy {dtype}") if half else None


def _refuse_dtype(name: str, dtype) -> None:
    """DataError when ``_input_dtype_problem`` finds a problem with ``dtype``."""
    problem = _input_dtype_problem(dtype)
    if problem is not None:
        raise DataError(f"{name}: {problem}")


def _refuse_meta(name: str, value) -> None:
    """DataError for a tensor on the ``meta`` device (a shape without values, as
    ``torch.device("meta")`` or deferred module initialisation make): torch cannot copy it
    anywhere, so there are no positions to read."""
    if isinstance(value, torch.Tensor) and value.is_meta:
        raise DataError(f"{name}: a tensor on the meta device holds no values (only a shape "
                        f"{list(value.shape)}); pass the values themselves, a tensor on the "
                        "CPU or a GPU or a numpy array")  # fmt: skip


def _float_tensor(name: str, value, device: torch.device, unseen: bool = False) -> torch.Tensor:
    """``value`` as float32 on ``device``; DataError for non-numbers, booleans, complex numbers
    and half precision (float16, bfloat16: ``_input_dtype_problem``; a tensor's dtype or the
    dtype numpy reads a list or array as), and for values that are not finite after the
    float32 conversion (NaN, inf, or beyond float32's range; with ``unseen``, NaN is let
    through: a frame where a neighbour was not seen). Any numpy view (reversed, strided) is
    read as its values. A tensor on the ``meta`` device is a DataError (``_refuse_meta``)."""
    if isinstance(value, torch.Tensor):
        _refuse_meta(name, value)
        _refuse_dtype(name, value.dtype)
        tensor = value.detach().to(device=device, dtype=torch.float32)
    else:
        try:
            value = np.asarray(value)  # its own dtype, judged before the conversion
        except (TypeError, ValueError) as exc:
            raise DataError(f"{name}: expected an array of numbers ({exc})") from None
        _refuse_dtype(name, value.dtype)
        try:
            with np.errstate(over="ignore"):  # overflow becomes inf, reported below
                array = value.astype(np.float32, copy=False)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{name}: expected an array of numbers ({exc})") from None
        if any(stride < 0 for stride in array.strides):  # h[::-1]: torch cannot wrap it
            array = array.copy()
        tensor = torch.from_numpy(array).to(device)
    finite = torch.isfinite(tensor) | (tensor.isnan() if unseen else False)
    if not bool(finite.all()):
        bad = (~finite).nonzero()
        what = "inf or beyond +-3.4e38; NaN marks an unseen frame" if unseen else (
            "NaN, inf or beyond +-3.4e38")  # fmt: skip
        raise DataError(
            f"{name}: {len(bad)} value(s) not finite after conversion to float32 ({what}), "
            f"the first at index {bad[0].tolist()}"
        )
    return tensor


def _require_array(name: str, value, shape: str) -> None:
    """DataError for None or a single value (a number, a string, a 0-d array) where an array
    of ``shape`` is needed, before the conversion reads it as one NaN or number."""
    single = (value is None or isinstance(value, (numbers.Number, str, bytes))
              or getattr(value, "ndim", None) == 0)  # fmt: skip
    if single:
        shown = repr(value) if isinstance(value, (str, bytes)) else str(value)  # 3.0, not np's
        got = "None" if value is None else f"a single value ({shown})"
        raise DataError(f"{name} must be an array {shape}, got {got}")


def _agent_types(value, p: int, device: torch.device, name: str = "agent_type") -> torch.Tensor:
    """``value`` [P] as int64 flags on ``device`` (None: every agent a person). Integers, and
    floats that are whole numbers (0.0 / 1.0: a pandas column read as float64), are flags;
    booleans, other floats and non-numbers are a DataError naming the input's own dtype
    (numpy's for an array or list, torch's for a tensor)."""
    if value is None:
        return torch.full((p,), AGENT_PERSON, dtype=torch.int64, device=device)
    flags = f"{AGENT_PERSON} (person) or {AGENT_BALL} (ball)"
    _refuse_meta(name, value)
    try:
        tensor = isinstance(value, torch.Tensor)
        array = value.detach().cpu().numpy().copy() if tensor else np.array(value)  # a copy
        types = torch.as_tensor(array)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name}: expected {p} integer flags [P] ({exc})") from None
    dtype = value.dtype if isinstance(value, torch.Tensor) else array.dtype  # the input's own
    if types.dtype == torch.bool:  # True would read as 1, a ball
        raise DataError(f"{name}: expected integer flags {flags}, got booleans")
    if tuple(types.shape) != (p,) or types.is_complex():
        raise DataError(f"{name}: expected {p} integer flags [P], got {list(types.shape)} "
                        f"of {dtype}")  # fmt: skip
    if types.is_floating_point():  # 0.0 / 1.0 are flags; 0.5 or NaN is no type
        whole = torch.isfinite(types) & (types == types.round())
        if not bool(whole.all()):
            bad = types[~whole][0].item()
            raise DataError(f"{name}: expected {p} integer flags [P], {flags}; got {dtype} "
                            f"values that are not whole numbers (the first, {bad:g}, at index "
                            f"{int((~whole).nonzero()[0])})")  # fmt: skip
    if bool(((types != AGENT_PERSON) & (types != AGENT_BALL)).any()):  # floats compared too
        raise DataError(f"{name}: flags must be {flags}, got {sorted(set(types.tolist()))}")
    return types.to(device=device, dtype=torch.int64)


TYPED_DATASETS = frozenset({"nba"})
"""Built-in datasets whose reader flags each agent's type (the ball ``AGENT_BALL``, players
``AGENT_PERSON``): a model trained on one reads the flags (its encoder's ``type_embed``), so
its futures and scores change with them (``reads_agent_types``)."""


def reads_agent_types(obj) -> bool:
    """Whether ``obj`` (a predictor or scorer carrying ``models.timing.attach_timing``'s
    record) was trained on data whose agents were flagged by type (nba's ball is
    ``agent_type`` 1): such a model given no ``agent_type`` takes every agent as a person, the
    ball included. Read from the flags its checkpoint recorded (``agent_types``, since
    2026-12-06: a folder with a BALL column counts), else from the dataset
    (``TYPED_DATASETS``); False for models without a record (built in code, ``cv``)."""
    timing = getattr(obj, "timing", None)
    if not isinstance(timing, dict):
        return False
    types = timing.get("agent_types")
    if types is not None:
        return any(int(t) != AGENT_PERSON for t in types)
    return timing.get("trained_on") in TYPED_DATASETS


def warn_untyped(obj, call: str, stacklevel: int) -> None:
    """An ``OutOfRangeWarning`` that ``call`` (``predict_scene``, ``predict_scenes``,
    ``rank_samples``, ``select_for_scene``) got no agent types for a model or scorer trained
    with typed agents (``reads_agent_types``). Its text is the same at every call, so Python
    shows it once per call site."""
    scenes = call == "predict_scenes"
    model = call.startswith("predict")
    how = ("agent_types=[one [P] integer array per scene]" if scenes
           else "agent_type=[P] integers")  # fmt: skip
    warnings.warn(f"{call}: no {'agent_types' if scenes else 'agent_type'} given, so every "
                  f"agent is taken as a person (agent_type {AGENT_PERSON}), a ball included; "
                  f"this {'model' if model else 'scorer'} was trained on "
                  f"{obj.timing['trained_on']} with the ball flagged (agent_type {AGENT_BALL}) "
                  f"and its {'futures' if model else 'scores'} change with the flags: pass "
                  f"{how}, {AGENT_BALL} for the ball, {AGENT_PERSON} for a player",
                  OutOfRangeWarning, stacklevel=stacklevel)  # fmt: skip


def warn_ball_count(obj, call: str, counts: list[tuple[int, int]], stacklevel: int) -> None:
    """An ``OutOfRangeWarning`` that ``call`` (``predict_scene``, ``predict_scenes``,
    ``rank_samples``, ``select_for_scene``) was given agent types that flag no ball, or more
    than one, in a scene, for a model or scorer trained with the ball flagged
    (``reads_agent_types``: every scene of NBA's splits flags exactly one). ``counts``:
    ``(scene index, balls flagged)`` of each scene with agents whose types were given;
    nothing is said when each has one ball."""
    odd = [(i, n) for i, n in counts if n != 1]
    if not odd or not reads_agent_types(obj):
        return
    model = call.startswith("predict")
    what = "model" if model else "scorer"
    tail = (f"this {what} was trained on {obj.timing['trained_on']} with the ball flagged "
            f"(agent_type {AGENT_BALL}; one in every scene of NBA's splits), so its "
            f"{'futures' if model else 'scores'} of such a scene are of one it never saw: "
            f"flag the ball {AGENT_BALL} and each player {AGENT_PERSON}")  # fmt: skip
    if call != "predict_scenes":
        n = odd[0][1]
        found = "no ball" if n == 0 else f"{n} balls"
        warnings.warn(f"{call}: agent_type flags {found} (agent_type {AGENT_BALL}) in this "
                      f"scene; {tail}", OutOfRangeWarning, stacklevel=stacklevel)  # fmt: skip
        return
    none = [i for i, n in odd if n == 0]
    many = [i for i, n in odd if n > 1]
    parts = [f"no ball in {len(none)}" if none else "",
             f"two or more balls in {len(many)}" if many else ""]  # fmt: skip
    first = ", ".join(f"histories[{i}]" for i, _ in odd[:3]) + (", ..." if len(odd) > 3 else "")
    warnings.warn(f"{call}: agent_types flag {' and '.join(p for p in parts if p)} of the "
                  f"{len(counts)} scenes given types ({first}); {tail}", OutOfRangeWarning,
                  stacklevel=stacklevel)  # fmt: skip


def scene_slots(scene: torch.Tensor) -> torch.Tensor:
    """Each agent's index within its scene, [N] int64, from the batch's non-decreasing scene
    index [N] (``Batch.scene``): 0, 1, ... for the first scene's agents, 0, 1, ... again for
    the next."""
    first = torch.searchsorted(scene, scene)  # [N] where each agent's scene begins
    return torch.arange(len(scene), device=scene.device) - first  # [N]


def rank_samples(
    scorer: TrajectoryScorer,
    history: ArrayLike,
    samples: ArrayLike,
    agent_type: ArrayLike | None = None,
    final: bool = False,
    *,
    frame_interval: float | None = None,
    units: str | None = None,
) -> tuple[ArrayLike, ArrayLike]:
    """Rank sampled futures of ONE scene given only its history (the planning use).

    history [P, T_h, 2] and samples [K, P, T_f, 2], absolute coordinates in the units the
    scorer's data had (``scorer.units``: metres for the published ETH/UCY and Robo models),
    with T_h and T_f the scorer's (``scorer.t_hist``, ``scorer.t_fut``: 8 and 12 for the
    published models), one position every ``scorer.frame_interval`` seconds. Each may be a
    numpy array (what ``trajpref predict`` exports) or a torch tensor. ``agent_type`` [P]: 0
    person (the default), 1 ball; a scorer trained with the ball flagged (``reads_agent_types``:
    nba/denoiser) given none scores the ball as a player, with a ``UserWarning``. ``final``:
    rank by the last step only (FTS order) instead of all steps (ATS order).
    ``frame_interval`` (seconds between the positions) and ``units``, when given, are compared
    with the scorer's, with a warning where they differ (as ``predict_scene``); so is the
    observed pace (``models.timing.check_observed_steps``: data in centimetres for a metre
    scorer ranks nonsense).

    Returns ``(order [K] int64, residual [K] float32)``: sample indices best first, and each
    sample's residual summed over agents and steps (lower is more human-like). Both are numpy
    arrays when neither ``history`` nor ``samples`` is a tensor, else tensors on the scorer's
    device. The score is computed at the scorer's steps (``scorer.steps``; 34 from
    ``from_checkpoint``: ``scorer.with_steps([0])`` is 10-25x cheaper). The order depends
    on the scorer's ``seed`` and on the order the agents are listed in (docs/score.md).
    Wrong shapes, non-numbers, non-finite values and coordinates too large for float32 raise
    ``DataError``; so do samples that do not continue the history (``check_samples_continue``:
    an agent whose first future position is, in every sample, a jump above
    ``models.timing.JUMP_LIMIT`` model units from its last observed position: samples in
    another frame than the history, or given as offsets from the last position). A scene
    without agents (history [0, T_h, 2], samples [K, 0, T_f, 2]: an empty view) has nothing
    to tell the samples apart: order ``0..K-1`` and residuals 0.
    """
    batch, futs = scene_batch(scorer, history, samples, agent_type, frame_interval=frame_interval,
                              units=units, allow_empty=True)  # fmt: skip
    if agent_type is None and batch.num_agents and reads_agent_types(scorer):
        warn_untyped(scorer, "rank_samples", stacklevel=3)  # the ball would rank as a player
    if agent_type is not None and batch.num_agents:  # NBA's scorer: one ball a scene
        balls = int((batch.agent_type == AGENT_BALL).sum())
        warn_ball_count(scorer, "rank_samples", [(0, balls)], stacklevel=3)
    if batch.num_agents == 0:  # an empty view: every sample alike, a residual summed over none
        total = futs.new_zeros(futs.shape[0])  # [K]
        order = torch.arange(futs.shape[0], device=futs.device)  # [K] as they came
    else:
        d = scorer.residual(batch, futs)  # [K, P, T_f]
        total = (d[..., -1] if final else d.sum(-1)).sum(-1)  # [K]
        order = total.argsort()  # [K]
    if isinstance(history, torch.Tensor) or isinstance(samples, torch.Tensor):
        return order, total
    return order.cpu().numpy(), total.cpu().numpy()


def predict_scene(model, history: ArrayLike, num_samples: int = 20,
                  agent_type: ArrayLike | None = None, seed: int = 0, *,
                  frame_interval: float | None = None, units: str | None = None,
                  context: ArrayLike | None = None) -> ArrayLike:  # fmt: skip
    """Sample the futures of ONE scene from its agents' histories (the planning use, beside
    ``rank_samples``): history [P, T_h, 2] absolute positions -> [K, P, T_f, 2] absolute
    future positions, in the model's units (``model.units``: metres for the published
    ETH/UCY and Robo models, pixels for sdd) and at its step (``model.frame_interval``
    seconds between positions: 0.4 for ETH/UCY and sdd, 0.5 for robo and robo-mix, 0.12 for
    nba), histories and futures alike.

    ``model`` is what ``models.registry.load_predictor`` returns (a published name, a
    checkpoint or ``cv``). ``agent_type`` [P]: 0 person (the default), 1 ball; a model trained
    with the ball flagged (``reads_agent_types``: nba/generator) given none takes the ball for a
    player, with a ``UserWarning`` (once per call site). ``seed`` (an integer, numpy integers
    included; ``models.predictor.check_seed``) seeds the sampling (the published generators
    draw no noise: every seed gives the same).
    ``num_samples`` below a generator's fixed set (``model.generator.samples``: 20 for the
    published ones, trained best-of-20) takes the first of its set, an arbitrary subset, with
    a ``UserWarning``: to keep a few, predict all 20 and choose with
    ``score.selection.select_for_scene``. A scene without agents (history [0, T_h, 2], an
    empty view) gives [K, 0, T_f, 2] without running the model.

    Agents far apart: the published models never saw two agents of a scene more than about
    16 m apart, and a scene holding agents much farther apart moves every agent's futures;
    ``model.neighbour_radius = 12.0`` (data units; ``ModelConfig.neighbour_radius``) keeps
    each agent's attention to the agents within it.

    ``frame_interval`` (seconds between the history's positions) and ``units``, when given,
    are compared with the model's, with an ``OutOfRangeWarning`` where they differ (the CLI's
    check): a model trained on 0.5 s steps reads 0.4 s tracks as slower agents, and its 12
    steps then span 6 s, not 4.8. Positions in other units than the model's (centimetres for
    metres) get an ``OutOfRangeWarning`` too, once per call, when the scene's agents move far faster
    than its training data (``models.timing.check_observed_steps``); so do agents faster than
    training on a model without an input speed clamp (``timing.FAST_LIMIT``: set
    ``model.generator.cfg.max_speed``) and a scene wider than any training scene on a model
    without a neighbour radius (``timing.wide_limit`` of the model's training width: set
    ``model.neighbour_radius``).
    float16 / bfloat16, bool and complex positions are a ``DataError`` (half precision holds a
    position of 100 m only to 0.06-0.5 m).

    Agent order: a model with agent roles (``model.agent_roles`` > 0: robo/generator and
    robo-mix/generator, 3 roles) reads each agent's place in ``history`` as its role, so the
    agents must be listed in its training data's order (robo: leader, follower,
    approacher); listed otherwise its futures are about constant velocity, with no error
    (at most ``agent_roles`` agents, else a DataError). Other models give each agent the same
    futures whatever the order.

    ``context`` [C, T_h, 2]: neighbours that are seen but not predicted, NaN at the frames
    where they were not seen; read only by a model with ``model.reads_context`` (the
    published zara1, zara2, univ and eth generators), and only those seen in the last
    ``model.context_frames`` frames without a break (all 8 for the published ones): others
    are ignored, with a ``UserWarning`` (one text, shown once per call site; so with the
    published models, whose rule is all 8 frames, every context row of
    ``trajpref.data.tracks_to_history`` is ignored, and a
    neighbour seen over part of the history changes nothing unless its missing frames are
    filled in, e.g. its first seen position held). Every target in ``history`` needs all
    T_h positions (docs/score.md, "Python: the planning calls").

    A numpy array (or anything ``np.asarray`` reads) gives a numpy array back, a tensor a
    tensor on the model's device. Wrong shapes (None or a single number for ``history``
    included), non-numbers, non-finite values and coordinates too large for float32 raise
    ``DataError``; a model name or a scorer in place of the model, or a bad ``num_samples``
    or ``seed``, ``ConfigError``. Several scenes at once:
    ``predict_scenes``."""
    return _predict(model, [history], num_samples, [agent_type], seed, frame_interval, units,
                    [context], single=True)[0]  # fmt: skip


def predict_scenes(model, histories, num_samples: int = 20, agent_types=None, seed: int = 0, *,
                   frame_interval: float | None = None, units: str | None = None,
                   contexts=None) -> list[ArrayLike]:  # fmt: skip
    """``predict_scene`` for several scenes in one batch (one pass of the networks instead of
    one per scene): ``histories`` a list of [P_b, T_h, 2] (the scenes may differ in P) ->
    a list of [K, P_b, T_f, 2], in the same order. ``agent_types`` and ``contexts``: None, or
    one entry (None or an array) per scene. For a model that draws no noise (every published
    generator) each scene's futures equal ``predict_scene``'s for it alone, to float32
    rounding (about 1e-5 m); a model that draws noise draws it across the batch, so the
    numbers differ from the loop's (with the same spread). Each result is a tensor when its
    history was one, else a numpy array. A scene without agents gets [K, 0, T_f, 2] and
    leaves the others as they are. The checks and the warnings are ``predict_scene``'s,
    naming ``histories[b]``."""
    if isinstance(histories, (np.ndarray, torch.Tensor)) and histories.ndim == 3:
        raise DataError("histories: expected a list of scenes' histories [P, T_h, 2]; got "
                        f"one array {list(histories.shape)}: predict_scene takes one "
                        "scene")  # fmt: skip
    if histories is None or isinstance(histories, (numbers.Number, str, bytes)):
        raise DataError(f"histories must be a list of scenes' histories [P, T_h, 2], got "
                        f"{histories!r}")  # fmt: skip
    histories = list(histories)
    b = len(histories)
    agent_types = [None] * b if agent_types is None else list(agent_types)
    contexts = [None] * b if contexts is None else list(contexts)
    for name, value in (("agent_types", agent_types), ("contexts", contexts)):
        if len(value) != b:
            raise DataError(f"{name}: expected one entry per scene ({b}), got {len(value)}")
    return _predict(model, histories, num_samples, agent_types, seed, frame_interval, units,
                    contexts, single=False)  # fmt: skip


def _check_model(model) -> None:
    """ConfigError unless ``model`` predicts (a name or a scorer in its place says what to do)."""
    if isinstance(model, (str, PathLike)):
        raise ConfigError(f"model: got the name {str(model)!r}, not a model: load it once "
                          f"with trajpref.models.registry.load_predictor({str(model)!r}) and "
                          "pass what it returns (loading reads the file: not in the "
                          "loop)")  # fmt: skip
    if isinstance(model, TrajectoryScorer):
        raise ConfigError("model: got a TrajectoryScorer, which ranks futures but does not "
                          "sample them: predict with trajpref.models.registry.load_predictor("
                          "'DATASET/generator') and rank with the scorer "
                          "(rank_samples)")  # fmt: skip
    if not callable(getattr(model, "predict", None)):
        raise ConfigError(f"model: expected a predictor (trajpref.models.registry."
                          f"load_predictor), got a {type(model).__name__}")  # fmt: skip


def _check_scorer(scorer) -> None:
    """ConfigError unless ``scorer`` is a TrajectoryScorer (a name or a predictor in its place
    says what to do)."""
    if isinstance(scorer, TrajectoryScorer):
        return
    if isinstance(scorer, (str, PathLike)):
        raise ConfigError(f"scorer: got the name {str(scorer)!r}, not a scorer: build it once "
                          f"with TrajectoryScorer.from_checkpoint({str(scorer)!r})")  # fmt: skip
    if hasattr(scorer, "denoiser") and hasattr(scorer, "predict"):
        raise ConfigError("scorer: got a predictor, which samples futures; rank them with "
                          "TrajectoryScorer.from_checkpoint('DATASET/denoiser') (or "
                          "TrajectoryScorer(model.denoiser, model.schedule, "
                          "model.scale))")  # fmt: skip
    raise ConfigError(f"scorer: expected a TrajectoryScorer, got a {type(scorer).__name__}")


def _predict(model, histories: list, num_samples, agent_types: list, seed, frame_interval,
             units, contexts: list, single: bool) -> list[ArrayLike]:  # fmt: skip
    """``predict_scene`` (``single``) and ``predict_scenes``: one batch of every scene."""
    _check_model(model)
    check_pace(model, frame_interval, units, stacklevel=4)  # the user's line
    count = as_integer(num_samples)  # numpy integers count too
    if count is None or count < 1:
        raise ConfigError(f"num_samples must be an integer >= 1, got {num_samples!r}")
    seed = check_seed(seed)  # np.int64(3) counts; None, 0.5 or 2**70 is a ConfigError
    if not histories:
        raise DataError("histories: no scenes to predict")
    _warn_fixed_set(model, count)
    device = getattr(model, "device", torch.device("cpu"))
    t_h = getattr(model, "t_hist", None)  # None: any length (the constant-velocity baseline)
    t_f = getattr(model, "t_fut", None) or getattr(model, "horizon", WINDOW[1])  # cv: horizon
    scenes = []
    given = zip(histories, agent_types, contexts, strict=True)
    for i, (history, agent_type, context) in enumerate(given):
        name = "history" if single else f"histories[{i}]"
        _require_array(name, history, f"[P, {t_h or 'T_h'}, 2] (agents, observed steps, x/y)")
        hist = _float_tensor(name, history, device)  # [P, T_h, 2]
        if hist.ndim != 3 or hist.shape[2] != 2 or hist.shape[1] != (t_h or hist.shape[1]):
            want = (
                f"[P, {t_h}, 2] (agents, observed steps, x/y; this model's T_h = {t_h})"
                if t_h
                else "[P, T_h, 2] (agents, observed steps, x/y)"
            )
            raise DataError(f"{name}: expected {want}, got {list(hist.shape)}")
        types = _agent_types(agent_type, hist.shape[0], device,
                             "agent_type" if single else f"agent_types[{i}]")  # fmt: skip
        ctx = None
        if context is not None:
            what = "context" if single else f"contexts[{i}]"
            ctx = _float_tensor(what, context, device, unseen=True)  # [C, T_h, 2]
            if ctx.ndim != 3 or tuple(ctx.shape[1:]) != tuple(hist.shape[1:]):
                raise DataError(f"{what}: expected [C, {hist.shape[1]}, 2] (neighbours, the "
                                f"history's observed steps, x/y; NaN where not seen), got "
                                f"{list(ctx.shape)}")  # fmt: skip
        if scenes and hist.shape[1] != scenes[0][0].shape[1]:  # one batch, one T_h
            raise DataError(f"{name}: {hist.shape[1]} observed steps, but histories[0] has "
                            f"{scenes[0][0].shape[1]}: the scenes of one call need the same "
                            "number")  # fmt: skip
        scenes.append((hist, types, ctx))
    untyped = any(t is None and len(h) for t, (h, _, _) in zip(agent_types, scenes, strict=True))
    if untyped and reads_agent_types(model):  # the ball would be read as a player
        warn_untyped(model, "predict_scene" if single else "predict_scenes", stacklevel=4)
    if reads_agent_types(model):  # NBA's: one ball a scene
        given = zip(agent_types, scenes, strict=True)
        counts = [(i, int((t == AGENT_BALL).sum())) for i, (flags, (h, t, _)) in
                  enumerate(given) if flags is not None and len(h)]  # fmt: skip
        warn_ball_count(model, "predict_scene" if single else "predict_scenes", counts,
                        stacklevel=4)  # fmt: skip
    if any(c is not None and len(c) for _, _, c in scenes) and not getattr(
            model, "reads_context", False):  # fmt: skip
        warnings.warn("this model reads no context-only neighbours (model.reads_context is "
                      "False): the context changes nothing; a neighbour seen over the whole "
                      "history can be listed as an agent instead", IgnoredWarning,
                      stacklevel=3)  # fmt: skip
    elif getattr(model, "reads_context", False):
        _warn_unread_context(model, [c for h, _, c in scenes if len(h)])
    present = [scene for scene in scenes if len(scene[0])]  # a scene without agents: no pass
    pred = None
    if present:  # one warning per call: cm for m (the speed clamp would hide it)
        joined = torch.cat([h for h, _, _ in present])  # [N, T_h, 2]
        # other units, an id switch, agents faster or a scene wider than training
        check_observed_steps(model, joined, stacklevel=4,
                             agent_type=torch.cat([t for _, t, _ in present]),
                             scenes=[len(h) for h, _, _ in present])  # fmt: skip
        batch = _join(present, t_f)
        pred = model.predict(batch, count, torch.Generator().manual_seed(seed))  # [K, N, T_f, 2]
    elif callable(getattr(model, "check_samples", None)):  # predict's refusal, without a pass
        model.check_samples(count)  # more than a generator's fixed set
    out, start = [], 0
    for history, (hist, _, _) in zip(histories, scenes, strict=True):
        if pred is None:  # no agent in any scene: K empty futures each
            part = hist.new_zeros(count, 0, t_f, 2)  # [K, 0, T_f, 2]
        else:
            part = pred[:, start : start + hist.shape[0]]  # [K, P_b, T_f, 2], P_b may be 0
        start += hist.shape[0]
        out.append(part if isinstance(history, torch.Tensor) else part.cpu().numpy())
    return out


def _warn_fixed_set(model, count: int) -> None:
    """A warning when ``count`` samples are asked of a leapfrog generator that emits a fixed
    set of more (trained best-of-K): it takes the first of its set (the CLI's ``--samples``
    warning, in Python's words)."""
    generator = getattr(model, "generator", None)
    if getattr(model, "sampler", None) != "leapfrog" or generator is None:
        return
    fixed = int(generator.samples)
    if count < fixed:
        warnings.warn(f"this model emits a set of K = {fixed} samples (trained best-of-"
                      f"{fixed}), and num_samples={count} takes its first {count}, an "
                      f"arbitrary subset: to keep {count} chosen from all {fixed}, predict "
                      f"all {fixed} and keep {count} with trajpref.score.selection."
                      f"select_for_scene (chosen_selection(model, keep={count}) gives the "
                      "published models' score-guided setting; docs/selection.md), or load "
                      "it with sampler='full' for independent draws", TrajprefWarning,
                      stacklevel=4)  # fmt: skip


def _warn_unread_context(model, contexts: list) -> None:
    """A warning when a context-reading model ignores some of the context rows [C_b, T_h, 2]:
    those not seen in each of its last ``model.context_frames`` frames (a NaN among them).
    Its text is the same at every call (Python then shows it once per place in the code)."""
    frames = int(model.context_frames)
    rows = [c for c in contexts if c is not None and len(c)]
    if not rows:
        return
    ignored = int((seen_run(torch.cat(rows)) < frames).sum())  # observed_context's rule
    if ignored:  # the same text every call, so a planner's loop is warned once
        warnings.warn("context rows ignored: this model reads a "
                      f"context-only neighbour only if it was seen in each of the last "
                      f"{frames} frames (model.context_frames), and these were seen in fewer "
                      "(a NaN among them); fill in their missing frames (e.g. the first seen "
                      "position held) for the model to read them", IgnoredWarning,
                      stacklevel=4)  # fmt: skip


def scene_batch(scorer: TrajectoryScorer, history: ArrayLike, samples: ArrayLike,
                agent_type: ArrayLike | None = None, *, frame_interval: float | None = None,
                units: str | None = None,
                allow_empty: bool = False) -> tuple[Batch, torch.Tensor]:  # fmt: skip
    """One scene's history [P, T_h, 2] and samples [K, P, T_f, 2] (arrays or tensors, the
    scorer's units and lengths) as a one-scene Batch with an unknown (NaN) future, and the
    samples as a float32 tensor on the scorer's device. DataError for wrong shapes,
    non-finite values and coordinates too large for float32 (``predict_scene``'s check,
    ``models.predictor.check_coordinates``) and for samples that do not continue the history
    (``check_samples_continue``); ConfigError for something other than a scorer;
    a warning where ``frame_interval`` or ``units`` differ from the scorer's (``rank_samples``
    documents the conventions). A scene without agents (P = 0) is a DataError, unless
    ``allow_empty``: then its (empty) Batch comes back, which the caller must not run the
    networks on (``rank_samples`` answers it without them)."""
    _check_scorer(scorer)
    check_pace(scorer, frame_interval, units, name="this scorer", stacklevel=4)
    device = scorer.device
    t_h, t_f = scorer.t_hist, scorer.t_fut
    _require_array("history", history, f"[P, {t_h}, 2] (agents, observed steps, x/y)")
    _require_array("samples", samples, f"[K, P, {t_f}, 2] (samples, agents, future steps, x/y)")
    hist = _float_tensor("history", history, device)  # [P, T_h, 2]
    futs = _float_tensor("samples", samples, device)  # [K, P, T_f, 2]
    if hist.ndim == 3 and hist.shape[0] == 0 and not allow_empty:
        raise DataError("history: the scene has no agents (P = 0): nothing to rank")
    if futs.ndim == 4 and futs.shape[0] == 0:
        raise DataError("samples: no samples (K = 0): nothing to rank")
    if hist.ndim != 3 or tuple(hist.shape[1:]) != (t_h, 2):
        raise DataError(
            f"history: expected [P, {t_h}, 2] (agents, observed steps, x/y; this scorer's "
            f"T_h = {t_h}), got {list(hist.shape)}"
        )
    p = hist.shape[0]
    if futs.ndim != 4 or tuple(futs.shape[1:]) != (p, t_f, 2):
        hint = " (one sample? add a leading axis: samples[None])" if futs.ndim == 3 else ""
        raise DataError(
            f"samples: expected [K, {p}, {t_f}, 2] (samples, the history's {p} agents, "
            f"future steps, x/y; this scorer's T_f = {t_f}), got {list(futs.shape)}{hint}"
        )
    # map coordinates rank differently in float32: predict's rule, at the scorer's scale
    check_coordinates(hist, scorer.scale)
    types = _agent_types(agent_type, p, device)
    if p:  # cm given to a metre scorer scrambles its ranking without an error; or an id
        # switch, agents faster or a scene wider than training (one scene: scenes=None)
        check_observed_steps(scorer, hist, name="this scorer", stacklevel=4, agent_type=types)
        check_samples_continue(scorer, hist, futs, types)
    return _join([(hist, types, None)], t_f), futs


def check_samples_continue(scorer: TrajectoryScorer, hist: torch.Tensor, futs: torch.Tensor,
                           types: torch.Tensor | None = None) -> None:  # fmt: skip
    """DataError when an agent's samples do not continue its history: in every one of the
    K samples futs [K, P, T_f, 2], the step from the agent's last observed position
    (hist [P, T_h, 2]) to its first future position is a jump (``models.timing.observed_jumps``:
    above ``JUMP_LIMIT`` model units of ``scorer``, the history's own rule; balls in ``types``
    [P] are not checked). Samples in another frame than the history (a robot's frame and the
    map's) or given as offsets from the last position are ranked without any error otherwise,
    and their order means nothing. A frame offset below the limit (7.4 m at zara1's scale) is
    not caught; one stray sample of K > 1 is not an error; an agent whose history itself steps above
    the limit is left to ``check_observed_steps``' warning (data in other units moves every
    step that far; a tracker id switch). The published generators' samples start at most
    0.75 model units from the last observed position (200 test scenes of each published
    dataset, walkthrough 67)."""
    k, p = futs.shape[:2]
    if not k or not p:
        return
    scale = float(scorer.scale)
    last = hist[None, :, -1].expand(k, -1, -1)  # [K, P, 2]
    pairs = torch.stack([last, futs[:, :, 0]], dim=2).reshape(k * p, 2, 2)  # [K*P, 2, 2]
    kinds = None if types is None else types.reshape(1, -1).expand(k, -1).reshape(-1)  # [K*P]
    far = observed_jumps(pairs, scale, kinds).reshape(k, p).all(0)  # [P]
    far &= ~observed_jumps(hist, scale, types)  # its history's own jump: already warned of
    if not bool(far.any()):
        return
    agents = far.nonzero().flatten().tolist()
    gap = (futs[:, :, 0] - last).norm(dim=-1).min(0).values  # [P] the nearest sample's
    shown = ", ".join(f"{i} ({float(gap[i]):.4g})" for i in agents[:5])
    more = f" and {len(agents) - 5} more" if len(agents) > 5 else ""
    units = getattr(scorer, "units", None) or "data units"
    raise DataError(
        f"samples do not continue the history: the first future position of agent(s) "
        f"{shown}{more} is, in every sample, more than {JUMP_LIMIT * scale:.4g} {units} "
        f"({JUMP_LIMIT:g} model units at this scorer's data scale {scale:g}; the nearest "
        f"sample's distance in brackets) from its last observed position. Samples in another "
        f"frame than the history (e.g. a robot's frame and the map's), or given as offsets "
        f"from the last position? Give both as absolute positions in one frame (offsets o: "
        f"history[None, :, -1:] + o)"
    )


def _join(scenes: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]],
          t_f: int) -> Batch:  # fmt: skip
    """Checked scenes (history [P_b, T_h, 2], agent types [P_b], context [C_b, T_h, 2] or
    None) as one Batch on their device, with an unknown (NaN) future of T_f steps, never
    read."""
    hist = torch.cat([h for h, _, _ in scenes])  # [N, T_h, 2]
    device = hist.device
    sizes = torch.tensor([len(h) for h, _, _ in scenes], device=device)  # [B]
    b = len(scenes)
    ctx = [(i, c) for i, (_, _, c) in enumerate(scenes) if c is not None and len(c)]
    context = torch.cat([c for _, c in ctx]) if ctx else None  # [M, T_h, 2]
    context_scene = (torch.cat([torch.full((len(c),), i, dtype=torch.int64, device=device)
                                for i, c in ctx]) if ctx else None)  # [M]  # fmt: skip
    return Batch(
        history=hist,
        future=hist.new_full((len(hist), t_f, 2), float("nan")),  # [N, T_f, 2]
        scene=torch.repeat_interleave(torch.arange(b, device=device), sizes),  # [N]
        agent_type=torch.cat([t for _, t, _ in scenes]),
        num_scenes=b,
        context=context,
        context_scene=context_scene,
    )


# Two samples with the same joint error tie for best. Identical samples give equal errors on
# the CPU; on a GPU, index_add_ sums a scene's agents in no fixed order, so they may differ in
# the last bits of a float32 (relative error at most about n * 6e-8 for n agents). A sample
# within this relative distance of the least error counts as best: 1e-5 covers scenes of
# over a hundred agents and is far below any difference the metric means to tell apart.
RECALL_TIE_RTOL = 1e-5


def recall_hits(
    pred: torch.Tensor, batch: Batch, order_ats: torch.Tensor, order_fts: torch.Tensor,
    ks: tuple[int, ...] = (1, 5),
) -> dict[str, torch.Tensor]:  # fmt: skip
    """Per scene, is a sample with the least joint ADE (FDE) among the top-k by ATS (FTS)?

    Samples that tie for the least error (within ``RECALL_TIE_RTOL``) are all best: ranking
    either of two identical best samples first is a hit.
    Returns {"top{k}_recall_ats": [B] bool, "top{k}_recall_fts": [B] bool}.
    """
    ade, fde = ade_fde(pred, batch.future)  # [K, N]
    out = {}
    for name, err, order in (("ats", ade, order_ats), ("fts", fde, order_fts)):
        total = scene_sum(err, batch.scene, batch.num_scenes)  # [K, B]
        least = total.min(0).values  # [B]
        best = total <= least + RECALL_TIE_RTOL * least  # [K, B] every sample tied for best
        for k in ks:
            out[f"top{k}_recall_{name}"] = best.gather(0, order[:k]).any(0)  # [B]
    return out


class ScoreAccumulator:
    """Running maxATS_K / maxFTS_K, meanATS_K (the average sample's ATS: what fine-tuning's
    reward sees) and top-k recall over batches (means over scenes)."""

    KEYS = ("max_ats", "max_fts", "mean_ats", "top1_recall_ats", "top5_recall_ats",
            "top1_recall_fts", "top5_recall_fts")  # fmt: skip

    def __init__(self) -> None:
        self.sums = dict.fromkeys(self.KEYS, 0.0)
        self.scenes = 0

    def update(self, scorer: TrajectoryScorer, batch: Batch, pred: torch.Tensor,
               result: ScoreResult | None = None) -> None:  # fmt: skip
        """One batch; ``result``: ``scorer.score(batch, pred)`` when the caller has it."""
        res = scorer.score(batch, pred) if result is None else result
        self.sums["max_ats"] += float(res.ats.max(0).values.sum())
        self.sums["max_fts"] += float(res.fts.max(0).values.sum())
        self.sums["mean_ats"] += float(res.ats.mean(0).sum())
        # the ranking comes from the residuals alone (Lemma 1): highest ATS first, by a stable
        # sort: samples of equal score (identical samples share their noise) keep their drawn
        # order, so the ranking does not depend on the sort's implementation
        hits = recall_hits(pred, batch, res.ats.argsort(dim=0, descending=True, stable=True),
                           res.fts.argsort(dim=0, descending=True, stable=True))  # fmt: skip
        for key, value in hits.items():
            self.sums[key] += float(value.sum())
        self.scenes += batch.num_scenes

    def compute(self) -> dict[str, float]:
        return {k: v / max(1, self.scenes) for k, v in self.sums.items()}
