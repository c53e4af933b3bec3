"""Scale-out with PyTorch's own DDP under ``torchrun`` (gloo on CPU, nccl on GPU).

A run on N processes trains the one-process run's schedule: every optimiser step takes the
batch one process would take (``data.max_agents`` agents, summed over the ranks), split into
N shares of about equal agents (``RankBatches``), and the ranks' gradients are weighted by
their shares' agents, so that DDP's average is the gradient of the whole batch's loss.
"""

from __future__ import annotations

import gc
import os
import sys
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from trajpref.data.loader import SceneLoader
from trajpref.errors import ConfigError, IgnoredWarning
from trajpref.errors import EveryRankError as EveryRankError  # its older place
from trajpref.types import Batch, TrajectoryDataset, collate

TIMEOUT = timedelta(minutes=60)
"""How long a collective waits for every rank before it fails the run. Only rank 0 validates
and saves; the other ranks wait meanwhile in the next step's all-reduce, and nccl's default
(10 min) is shorter than gloo's (30 min). The longest validation pass logged in this
repository took 47.6 s (a fine-tuning validation on two CPU cores, runs/ac_57), so 60 min
leaves a 75-fold margin and still ends a hung run within the hour."""


@dataclass
class DistInfo:
    rank: int = 0
    """This process's rank."""
    world_size: int = 1
    """Number of processes."""
    local_rank: int = 0
    """Rank on this machine (selects the GPU)."""
    local_world_size: int = 1
    """Processes on this machine (torchrun's ``--nproc_per_node``)."""
    nodes: int = 1
    """Machines the run spans (torchrun's ``--nnodes``)."""

    @property
    def enabled(self) -> bool:
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def env_info() -> DistInfo:
    """The process's place in a torchrun launch, read from torchrun's environment variables
    (one process, rank 0, without them); joins nothing."""
    world = int(os.environ.get("WORLD_SIZE", "1") or 1)
    if world <= 1:
        return DistInfo()
    local_world = int(os.environ.get("LOCAL_WORLD_SIZE", str(world)) or world)
    return DistInfo(int(os.environ.get("RANK", "0")), world,
                    int(os.environ.get("LOCAL_RANK", "0")), local_world,
                    int(os.environ.get("GROUP_WORLD_SIZE", "1") or 1))  # fmt: skip


def init_from_env(device: torch.device) -> tuple[DistInfo, torch.device]:
    """Join the process group when launched by torchrun (``WORLD_SIZE`` > 1), with the
    collective timeout ``TIMEOUT``.

    Returns the rank info and this process's device (``cuda:LOCAL_RANK`` on GPUs; more
    processes on a machine than it has GPUs is a ``ConfigError``)."""
    info = env_info()
    if not info.enabled:
        return info, device
    if device.type == "cuda":
        count = torch.cuda.device_count()
        if info.local_world_size > count:  # every rank says so: rank 0 is the one that prints
            raise ConfigError(f"torchrun started {info.local_world_size} processes on this machine "
                              f"but it has {count} GPU(s): start at most {count} "
                              "(--nproc_per_node), or train on the CPU (--device cpu)")  # fmt: skip
        if device.index is not None and device.index != info.local_rank and info.is_main:
            warnings.warn(f"--device {device}: under torchrun each process takes the GPU of its "
                          "local rank (cuda:LOCAL_RANK); choose GPUs with CUDA_VISIBLE_DEVICES",
                          category=IgnoredWarning, stacklevel=2)  # fmt: skip
        device = torch.device("cuda", info.local_rank)
        torch.cuda.set_device(device)
    if not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo", timeout=TIMEOUT)
    return info, device


def barrier(info: DistInfo) -> None:
    if info.enabled and dist.is_initialized():
        dist.barrier()


def cleanup(info: DistInfo) -> None:
    """Leave the process group. Call ``barrier`` first on the normal path: a rank that tears
    gloo down while another is still writing files can abort in gloo's threads ("terminate
    called without an active exception", seen once in CI); on an error path no barrier is
    taken, so that a failed rank does not wait for one that will never come.

    Garbage is collected first: a DDP wrapper left in a reference cycle holds the gloo group
    through its reducer, and freed only at interpreter exit it would tear gloo's threads down
    while the interpreter is half gone (the same abort; pytorch/pytorch#179291 describes it)."""
    if info.enabled and dist.is_initialized():
        gc.collect()
        dist.destroy_process_group()


def split_batch(sizes: np.ndarray, world_size: int) -> list[np.ndarray]:
    """Which scenes of a batch each rank takes: positions into ``sizes`` (the scenes' agent
    counts, [S]), one array per rank, in order. Contiguous runs of about equal agents: a scene
    goes to the rank whose equal share of the agents holds the scene's middle agent. A rank
    gets none when the batch has fewer scenes than ranks (or one scene holds most agents)."""
    cum = np.cumsum(sizes)  # [S]
    middle = cum - np.asarray(sizes) / 2  # [S] each scene's middle agent
    owner = np.minimum(world_size - 1, (middle * world_size // cum[-1]).astype(np.int64))
    return [np.flatnonzero(owner == r) for r in range(world_size)]


class RankBatches:
    """A training split's batches as one process takes them (``SceneLoader``: at most
    ``max_agents`` agents each, reshuffled each epoch), each split among the ranks
    (``split_batch``). Iterating yields ``(batch, agents, total)``: this rank's share of the
    next batch, its agents, and the whole batch's agents (a rank's gradient weighs
    ``world_size * agents / total``). A rank whose share is empty takes the batch's first
    scene with ``agents`` 0 (DDP needs every rank's gradient; this one weighs nothing). With
    one process the batches are the loader's own."""

    def __init__(self, dataset: TrajectoryDataset, max_agents: int, seed: int,
                 info: DistInfo) -> None:  # fmt: skip
        self.loader = SceneLoader(dataset, max_agents=max_agents, shuffle=True, seed=seed)
        self.scenes = dataset.scenes
        self.sizes = np.array([s.num_agents for s in dataset.scenes])  # [S]
        self.info = info

    def set_epoch(self, epoch: int) -> None:
        self.loader.set_epoch(epoch)

    def __len__(self) -> int:
        return len(self.loader)

    def shares(self) -> Iterator[tuple[np.ndarray, int, int]]:
        """``(scene indices, agents, total)`` of this rank's share of each batch."""
        for idx in self.loader.batches():
            sizes = self.sizes[idx]  # [S_b]
            total = int(sizes.sum())
            if not self.info.enabled:
                yield idx, total, total
                continue
            mine = split_batch(sizes, self.info.world_size)[self.info.rank]
            if len(mine) == 0:
                yield idx[:1], 0, total
            else:
                yield idx[mine], int(sizes[mine].sum()), total

    def idle_batches(self, epoch: int = 0, limit: int | None = None) -> int:
        """How many of epoch ``epoch``'s batches leave some rank without a scene: of its first
        ``limit`` (the steps a stage takes of an epoch), or of all of them. Each epoch's
        shuffle makes its own batches, so the count is that epoch's."""
        if not self.info.enabled:
            return 0
        before = self.loader.epoch
        self.loader.set_epoch(epoch)
        try:
            batches = self.loader.batches()[:limit]
        finally:
            self.loader.set_epoch(before)
        return sum(
            any(len(s) == 0 for s in split_batch(self.sizes[idx], self.info.world_size))
            for idx in batches
        )

    def __iter__(self) -> Iterator[tuple[Batch, int, int]]:
        for idx, agents, total in self.shares():
            yield collate([self.scenes[i] for i in idx]), agents, total


def gather_objects(value: Any, info: DistInfo) -> list[Any]:
    """Every rank's ``value`` (anything picklable, small), in rank order: a collective (every
    rank calls it); with one process, ``[value]``."""
    if not info.enabled:
        return [value]
    gathered: list[Any] = [None] * info.world_size
    dist.all_gather_object(gathered, value)
    return gathered


def largest(value: float, info: DistInfo, device: torch.device) -> float:
    """The largest of the ranks' ``value``: a collective (every rank calls it); with one
    process, ``value``."""
    if not info.enabled:
        return value
    t = torch.tensor(value, dtype=torch.float64, device=device)
    dist.all_reduce(t, op=dist.ReduceOp.MAX)
    return float(t)


def gather_generators(generators: dict[str, torch.Generator],
                      info: DistInfo) -> list[dict[str, torch.Tensor]]:  # fmt: skip
    """Every rank's states of its random ``generators`` (name -> generator), in rank order:
    a collective (every rank calls it); with one process, its own."""
    return gather_objects({name: g.get_state() for name, g in generators.items()}, info)


def launcher_command() -> list[str] | None:
    """The launcher's options of this torchrun launch, as it was started on this machine
    (``launcher_from`` the parent process's command line, read from Linux's ``/proc``); None
    when that cannot be read (another system, another launcher) or outside torchrun."""
    if not env_info().enabled:
        return None
    try:
        raw = Path(f"/proc/{os.getppid()}/cmdline").read_bytes()
    except OSError:
        return None
    parent = [a.decode(errors="replace") for a in raw.split(b"\0")[:-1]]
    return launcher_from(parent, sys.argv[1:])


def launcher_from(parent: list[str], own: list[str]) -> list[str] | None:
    """The launcher's part of the command line ``parent`` that started a process with the
    arguments ``own``: what comes before them, when ``parent`` ends with them and runs torchrun
    (``torchrun`` or ``python -m torch.distributed.run``); the interpreter in front of a
    ``torchrun`` script is left out. ``[".venv/bin/torchrun", "--standalone",
    "--nproc_per_node", "2", "-m", "trajpref.cli"]``; None otherwise."""
    if len(parent) <= len(own) or (own and parent[len(parent) - len(own) :] != own):
        return None
    launcher = parent[: len(parent) - len(own)]
    if not any(Path(a).name == "torchrun" or a == "torch.distributed.run" for a in launcher):
        return None
    if len(launcher) > 1 and Path(launcher[1]).name == "torchrun":  # python .../bin/torchrun
        launcher = launcher[1:]
    return launcher


def fallback_launcher(info: DistInfo) -> list[str]:
    """A torchrun command with this launch's counts, when its own options cannot be read."""
    nodes = [f"--nnodes={info.nodes}"] if info.nodes > 1 else []
    return ["torchrun", *nodes, f"--nproc_per_node={info.local_world_size}", "-m", "trajpref.cli"]


def launcher_note(info: DistInfo, known: bool) -> str:
    """What to add to a resume command for a launch over several machines, or when the
    launcher's own options could not be read ("" otherwise)."""
    if info.nodes > 1:
        which = "; this is the command of rank 0's machine" if known else ": rendezvous, rank"
        return (f"\n  (on each of the {info.nodes} machines, with the launcher options it was "
                f"started with there{which})")  # fmt: skip
    if not known:
        return "\n  (with the launcher options the run was started with)"
    return ""
