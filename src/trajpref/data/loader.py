"""Batching: many scenes per batch, grouped by size so padding stays small."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from trajpref.errors import ConfigError
from trajpref.types import Batch, TrajectoryDataset, collate


class SceneLoader:
    """Iterate over a dataset in batches of whole scenes.

    A batch holds at most ``max_agents`` agents (a scene larger than that is a batch of its own)
    and at most ``max_scenes`` scenes. Scenes are sorted by size inside shuffled pools, so a
    batch's scenes have similar agent counts and the padded per-scene attention
    (B * P_max^2) never grows with the whole batch (N^2), even on UNIV's 50+ agent scenes.

    Under DDP every rank builds the same batches (the same seed and epoch) and takes a share
    of each (``train.distributed.RankBatches``), so N processes train the one-process schedule.
    """

    def __init__(
        self,
        dataset: TrajectoryDataset,
        max_agents: int = 512,
        max_scenes: int = 256,
        shuffle: bool = False,
        seed: int = 0,
        pool: int = 64,
    ):
        if max_agents < 1 or max_scenes < 1:
            raise ConfigError("max_agents and max_scenes must be positive")
        self.dataset = dataset
        self.max_agents = max_agents
        self.max_scenes = max_scenes
        self.shuffle = shuffle
        self.seed = seed
        self.pool = pool
        self.epoch = 0
        self._sizes = np.array([s.num_agents for s in dataset.scenes])  # [S]

    def set_epoch(self, epoch: int) -> None:
        """Reshuffle differently each epoch (same order on every rank)."""
        self.epoch = epoch

    def batches(self) -> list[np.ndarray]:
        """Scene indices of every batch, in order (the same on every rank)."""
        n = len(self._sizes)
        if self.shuffle:
            rng = np.random.default_rng((self.seed, self.epoch))
            order = rng.permutation(n)
            chunk = self.pool * self.max_scenes
            # sort by size inside pools: similar sizes share a batch, randomness is kept
            order = np.concatenate(
                [
                    c[np.argsort(self._sizes[c], kind="stable")]
                    for c in np.array_split(order, max(1, -(-n // chunk)))
                ]
            )
        else:
            order = np.arange(n)
        groups: list[np.ndarray] = []
        current: list[int] = []
        agents = 0
        for i in order:
            size = int(self._sizes[i])
            if current and (agents + size > self.max_agents or len(current) >= self.max_scenes):
                groups.append(np.asarray(current))
                current, agents = [], 0
            current.append(int(i))
            agents += size
        if current:
            groups.append(np.asarray(current))
        if self.shuffle:
            rng = np.random.default_rng((self.seed, self.epoch, 1))
            groups = [groups[j] for j in rng.permutation(len(groups))]
        return groups

    def __iter__(self) -> Iterator[Batch]:
        for idx in self.batches():
            yield collate([self.dataset.scenes[i] for i in idx])

    def __len__(self) -> int:
        return len(self.batches())
