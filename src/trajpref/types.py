"""Typed containers for trajectory data.

Shape vocabulary: B scenes, P agents in one scene, N agents packed across a batch,
K samples, T_h history steps, T_f future steps, D = 2 coordinates.
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass, field

import numpy as np
import torch

from trajpref.errors import ConfigError, DataError

AGENT_PERSON = 0
"""Agent-type flag: a person, a player or a robot."""
AGENT_BALL = 1
"""Agent-type flag: the ball (NBA)."""


@dataclass
class Scene:
    """One window of one scene: every agent observed over all T_h + T_f frames.

    Coordinates are absolute, in the dataset's units.
    """

    history: np.ndarray
    """[P, T_h, 2] observed positions."""
    future: np.ndarray
    """[P, T_f, 2] ground-truth future positions; NaN where the data hides them (the
    observation-only scenes of TrajNet++ test files, ``data.trajnet.read_trajnet``: predict
    only)."""
    agent_type: np.ndarray
    """[P] int64 agent-type flags (AGENT_PERSON or AGENT_BALL)."""
    scene_id: str
    """Where the window comes from, e.g. ``crowds_zara01.txt@frame=120``."""
    context: np.ndarray | None = None
    """[C, T_h, 2] positions of the other agents seen at the last observed frame but not in
    all T_h + T_f frames (they entered during the history or leave before the window ends),
    NaN at the history frames where they were not seen; None where the data gives none
    (``.npz`` splits). They are neighbours only: no future, no prediction, no metric; only a
    model built with ``ModelConfig.context_agents`` reads them
    (``data.transforms.observed_context`` keeps those seen long enough)."""
    context_reverse: np.ndarray | None = None
    """[C', T_h, 2] the context-only agents of the window played backwards
    (``data.transforms.reverse_time``): the other agents seen at the first of the window's last
    T_h frames but not in all of its frames, their positions over those T_h frames in reverse
    order (NaN where not seen); None where the data gives none. Training only: a reversed
    scene's history is the window's end, so these are its neighbours."""
    agent_id: np.ndarray | None = None
    """[P] each target agent's id in its source file, in the order of ``history``'s agents
    (int64 where they are whole numbers, else float64 or str, e.g. the exact text of an id
    float64 cannot hold); None where the source has none, e.g. ``.npz`` splits and
    simulations. Metadata only: no model reads it and ``collate`` does not pack it;
    ``trajpref predict`` saves it (the .npz's ``agent_id``, docs/data_format.md)."""
    frames: np.ndarray | None = None
    """[T_h + T_f] the window's frame numbers in its source file (int64, or Python ints in an
    object array beyond int64); None where the reader does not keep them (text track files,
    ``.npz`` splits, simulations). Set by the TrajNet++ reader: ``predict --format trajnet``
    writes the predictions at the source's own future frames. Metadata only, like
    ``agent_id``."""
    source_row: str | None = None
    """The line of the source file that defines this window, as it is there (a TrajNet++
    ``{"scene": {...}}`` row: id, primary, start, end, fps, tag); None for other data.
    ``predict --format trajnet`` writes it unchanged. Metadata only."""

    def __post_init__(self) -> None:
        if self.history.ndim != 3 or self.history.shape[-1] != 2:
            shape = self.history.shape
            raise DataError(f"{self.scene_id}: history must be [P, T_h, 2], got {shape}")
        if self.future.ndim != 3 or self.future.shape[-1] != 2:
            shape = self.future.shape
            raise DataError(f"{self.scene_id}: future must be [P, T_f, 2], got {shape}")
        if self.future.shape[0] != self.history.shape[0]:
            raise DataError(f"{self.scene_id}: history and future disagree on the agent count")
        if self.agent_type.shape != (self.history.shape[0],):
            raise DataError(f"{self.scene_id}: agent_type must be [P]")
        if self.context is not None and (
            self.context.ndim != 3 or self.context.shape[1:] != self.history.shape[1:]
        ):
            shape = self.context.shape
            raise DataError(f"{self.scene_id}: context must be [C, T_h, 2], got {shape}")
        if self.context_reverse is not None and (
            self.context_reverse.ndim != 3
            or self.context_reverse.shape[1:] != self.history.shape[1:]
        ):
            shape = self.context_reverse.shape
            raise DataError(f"{self.scene_id}: context_reverse must be [C', T_h, 2], got {shape}")
        if self.agent_id is not None:
            self.agent_id = _checked_ids(self.agent_id, self.history.shape[0], self.scene_id)
        t_total = self.history.shape[1] + self.future.shape[1]
        if self.frames is not None and np.shape(self.frames) != (t_total,):
            shape = list(np.shape(self.frames))
            raise DataError(f"{self.scene_id}: frames must be [T_h + T_f] = [{t_total}], got "
                            f"{shape}")  # fmt: skip

    @property
    def num_agents(self) -> int:
        """P, the scene's agents (targets; context-only agents not counted)."""
        return int(self.history.shape[0])


def _checked_ids(agent_id, agents: int, scene_id: str) -> np.ndarray:
    """``agent_id`` as a [P] array of numbers or strings (``Scene.agent_id``), else
    ``DataError``."""
    ids = np.asarray(agent_id)
    if ids.shape != (agents,):
        raise DataError(f"{scene_id}: agent_id must be [P] with P = {agents} (one id per agent "
                        f"of history, in its order), got {list(ids.shape)}")  # fmt: skip
    if ids.dtype.kind not in "iufUSO":
        raise DataError(f"{scene_id}: agent_id must hold numbers or strings, got {ids.dtype}")
    return ids


INTERVAL_SOURCES = ("dataset", "given", "declared", "timestamps", "default")
"""Where a split's frame interval comes from (``DatasetInfo.interval_from``, which refuses any
other); ``train.run.INTERVAL_NOTES`` and ``models.zoo.INTERVAL_FROM`` word each of them."""


WINDOW = (8, 12)
"""Observed and future frames per window (T_h, T_f) of every built-in dataset and published
model: what data are read as unless a model or ``ReadOptions`` asks for other lengths (a
folder of text track files, ETH/UCY, NBA and TrajNet++ files can be cut into any)."""


@dataclass
class DatasetInfo:
    """What a split is and how to read its numbers."""

    name: str
    """Dataset name, e.g. ``zara1`` or a folder path."""
    split: str
    """``train``, ``val`` or ``test``."""
    units: str
    """Units of the coordinates: ``m`` or ``px`` (or ``unknown`` for user folders)."""
    frame_interval: float
    """Seconds between two consecutive frames of a window."""
    t_hist: int = WINDOW[0]
    """Observed frames per window (T_h)."""
    t_fut: int = WINDOW[1]
    """Future frames per window (T_f)."""
    source: str = ""
    """Where the data was read from (path) or how it was made (simulator seed)."""
    protocol: str = "all"
    """Which windows count: ``all`` (every window with a fully observed agent) or ``sgan``
    (only windows with at least two, as the Social-GAN loader counts them; docs/data.md)."""
    interval_from: str = "given"
    """Where ``frame_interval`` comes from (``INTERVAL_SOURCES``): ``dataset`` (a built-in
    dataset's own), ``given`` (by the caller: ``--frame-interval``, ``data.frame_interval``),
    ``declared`` (the fps of TrajNet++ scenes), ``timestamps`` (the step of text files whose
    frame column is named as a time: in seconds, ``time``, ``timestamp`` and the like
    (``data.text.SECONDS_COLUMNS``), or in milliseconds, ``time_ms`` or ``timestamp_ms``
    (``data.text.MILLISECONDS_COLUMNS``, their step divided by 1000); ``frame_interval`` is in
    seconds either way) or ``default`` (none of these: 0.4 s assumed, so the seconds are a
    guess)."""
    time_step: float = 1.0
    """The ``--time-step`` the data was read with (``frame_interval`` already includes it)."""
    text_tracks: bool = False
    """Read from text track files, which ``--time-step`` can resample (ETH/UCY, NBA, a folder
    of text files); windows cut already (SDD, Robo, TrajNet++ scenes, simulations) cannot be."""

    def __post_init__(self) -> None:
        if self.interval_from not in INTERVAL_SOURCES:
            known = ", ".join(INTERVAL_SOURCES)
            raise ValueError(f"DatasetInfo.interval_from must be one of {known}, "
                             f"got {self.interval_from!r}")  # fmt: skip


@dataclass
class TrajectoryDataset:
    """A list of scenes plus what they are. Indexable; items are ``Scene``."""

    scenes: list[Scene]
    info: DatasetInfo

    def __len__(self) -> int:
        return len(self.scenes)

    def __getitem__(self, i: int) -> Scene:
        return self.scenes[i]

    @property
    def num_agents(self) -> int:
        """The agent-windows of every scene of the split."""
        return sum(s.num_agents for s in self.scenes)

    def evenly_spaced(self, max_scenes: int | None) -> TrajectoryDataset:
        """At most ``max_scenes`` scenes, evenly spread over the split (all when None): the
        subset that validation during training, timing and the studies' ``--max-scenes`` read.
        ``ConfigError`` (a ``ValueError``) for anything but None or an integer >= 1."""
        if max_scenes is None:
            return self
        whole = isinstance(max_scenes, numbers.Integral) and not isinstance(max_scenes, bool)
        if not whole or max_scenes < 1:
            raise ConfigError(f"max_scenes, the scenes to keep, must be an integer, at least 1 "
                              f"(or None for all {len(self)}), got {max_scenes!r}")  # fmt: skip
        if len(self) <= max_scenes:
            return self
        max_scenes = int(max_scenes)
        idx = torch.linspace(0, len(self) - 1, max_scenes).long().tolist()
        return TrajectoryDataset([self.scenes[i] for i in idx], self.info)


@dataclass
class Batch:
    """Many scenes packed agent-wise, with a scene index per agent.

    Agents of different scenes never interact: models build per-scene padded views
    (``padded_index``) whose attention mask only covers agents of one scene, so the cost
    is B * P_max^2 rather than N^2 over the whole batch.
    """

    history: torch.Tensor
    """[N, T_h, 2] absolute observed positions."""
    future: torch.Tensor
    """[N, T_f, 2] absolute future positions."""
    scene: torch.Tensor
    """[N] int64 batch-local scene index in 0..B-1, non-decreasing."""
    agent_type: torch.Tensor
    """[N] int64 agent-type flags."""
    num_scenes: int
    """B, the number of scenes in the batch."""
    scene_ids: list[str] = field(default_factory=list)
    """[B] where each scene comes from."""
    context: torch.Tensor | None = None
    """[M, T_h, 2] absolute observed positions of context-only agents (``Scene.context``, NaN
    where not seen), packed across the batch; None when there are none."""
    context_scene: torch.Tensor | None = None
    """[M] int64 scene index of each context-only agent, non-decreasing; None with ``context``."""
    context_reverse: torch.Tensor | None = None
    """[M', T_h, 2] the context-only agents of each scene played backwards
    (``Scene.context_reverse``), packed across the batch; read by ``reverse_time`` only, which
    hands back a batch without them. None when there are none."""
    context_reverse_scene: torch.Tensor | None = None
    """[M'] int64 scene index of each of them, non-decreasing; None with ``context_reverse``."""

    def __post_init__(self) -> None:
        for name in ("context", "context_reverse"):
            value, scene = getattr(self, name), getattr(self, f"{name}_scene")
            if (value is None) != (scene is None):
                raise DataError(f"Batch: {name} and {name}_scene go together")
            if value is not None and scene.shape != value.shape[:1]:
                raise DataError(f"Batch: {name}_scene must be [M] for {name} [M, T_h, 2]")

    @property
    def num_agents(self) -> int:
        """N, the agents of every scene packed in the batch (context-only agents not counted)."""
        return self.history.shape[0]  # an int; symbolic while exporting, so no int()

    @property
    def num_context(self) -> int:
        """M, the number of context-only agents (0 without any)."""
        return 0 if self.context is None else int(self.context.shape[0])

    @property
    def origin(self) -> torch.Tensor:
        """[N, 2] each agent's last observed position (the origin of relative coordinates)."""
        return self.history[:, -1]

    def to(self, device: torch.device | str) -> Batch:
        """The same batch with every tensor on ``device``."""
        return Batch(
            history=self.history.to(device),
            future=self.future.to(device),
            scene=self.scene.to(device),
            agent_type=self.agent_type.to(device),
            num_scenes=self.num_scenes,
            scene_ids=self.scene_ids,
            context=None if self.context is None else self.context.to(device),
            context_scene=None if self.context_scene is None else self.context_scene.to(device),
            context_reverse=_to(self.context_reverse, device),
            context_reverse_scene=_to(self.context_reverse_scene, device),
        )

    def without_context(self) -> Batch:
        """The same batch with no context-only agents (of either time direction)."""
        return dataclasses.replace(self, context=None, context_scene=None,
                                   context_reverse=None, context_reverse_scene=None)  # fmt: skip

    def scene_sizes(self) -> torch.Tensor:
        """[B] number of agents in each scene."""
        return torch.bincount(self.scene, minlength=self.num_scenes)

    def padded_index(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Where each agent sits in a per-scene padded layout.

        Returns ``(slot, mask)``: ``slot`` [N] is the agent's position within its scene,
        and ``mask`` [B, P_max] is True where a slot holds a real agent. Scatter a flat
        tensor x [N, ...] with ``padded = x.new_zeros(B, P_max, ...);
        padded[batch.scene, slot] = x``.
        """
        sizes = self.scene_sizes()  # [B]
        starts = torch.cumsum(sizes, 0) - sizes  # [B]
        slot = torch.arange(self.num_agents, device=self.scene.device) - starts[self.scene]  # [N]
        if self.num_scenes == 1:  # from the shape, not the data: one scene holds them all
            p_max = self.num_agents  # (an exported one-scene predictor keeps P symbolic)
        else:
            p_max = int(sizes.max().item()) if self.num_scenes else 0
        mask = torch.arange(p_max, device=self.scene.device)[None, :] < sizes[:, None]  # [B, P]
        return slot, mask

    def same_scene(self) -> torch.Tensor:
        """[N, N] bool: True where two agents belong to the same scene. For tests and tiny
        batches only; models use ``padded_index``."""
        return self.scene[:, None] == self.scene[None, :]


def collate(scenes: list[Scene]) -> Batch:
    """Pack scenes agent-wise into a ``Batch`` (float32 tensors)."""
    if not scenes:
        raise DataError("cannot collate an empty list of scenes")
    hist = np.concatenate([s.history for s in scenes], 0)  # [N, T_h, 2]
    fut = np.concatenate([s.future for s in scenes], 0)  # [N, T_f, 2]
    types = np.concatenate([s.agent_type for s in scenes], 0)  # [N]
    scene = np.repeat(np.arange(len(scenes)), [s.num_agents for s in scenes])  # [N]
    context, context_scene = _pack([s.context for s in scenes])  # [M, T_h, 2], [M]
    context_reverse, context_reverse_scene = _pack([s.context_reverse for s in scenes])
    return Batch(
        history=torch.as_tensor(hist, dtype=torch.float32),
        future=torch.as_tensor(fut, dtype=torch.float32),
        scene=torch.as_tensor(scene, dtype=torch.int64),
        agent_type=torch.as_tensor(types, dtype=torch.int64),
        num_scenes=len(scenes),
        scene_ids=[s.scene_id for s in scenes],
        context=context,
        context_scene=context_scene,
        context_reverse=context_reverse,
        context_reverse_scene=context_reverse_scene,
    )


def _pack(parts: list[np.ndarray | None]) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """Per-scene agent arrays [C_b, T_h, 2] (or None) packed into one [M, T_h, 2] float32
    tensor and its [M] scene index; (None, None) when no scene has any."""
    extra = [c for c in parts if c is not None and len(c)]
    if not extra:
        return None, None
    counts = [0 if c is None else len(c) for c in parts]  # [B]
    packed = torch.as_tensor(np.concatenate(extra, 0), dtype=torch.float32)  # [M, T_h, 2]
    return packed, torch.as_tensor(np.repeat(np.arange(len(parts)), counts))  # [M]


def _to(x: torch.Tensor | None, device: torch.device | str) -> torch.Tensor | None:
    return None if x is None else x.to(device)
