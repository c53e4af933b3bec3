"""DDP's pieces that need no process group: how a batch is shared between ranks, the launcher
read back for the resume advice, each process's threads (two-process runs: test_ddp.py)."""

import numpy as np
import pytest
import torch

from trajpref.data import load_dataset
from trajpref.data.loader import SceneLoader
from trajpref.train.distributed import DistInfo, RankBatches, launcher_from, split_batch
from trajpref.train.run import set_threads


def test_a_batch_is_split_into_contiguous_shares_of_about_equal_agents():
    shares = split_batch(np.array([3, 3, 3, 3]), 2)
    assert [s.tolist() for s in shares] == [[0, 1], [2, 3]]
    shares = split_batch(np.array([1, 1, 1, 1, 1, 6]), 2)  # the big scene alone on rank 1
    assert [s.tolist() for s in shares] == [[0, 1, 2, 3, 4], [5]]
    shares = split_batch(np.array([5, 2]), 3)  # fewer scenes than ranks: one rank gets none
    assert sorted(len(s) for s in shares) == [0, 1, 1]
    for sizes in (np.arange(1, 12), np.array([7]), np.array([2, 9, 4, 4, 1])):
        for world in (1, 2, 3, 8):
            taken = np.concatenate(split_batch(sizes, world))
            assert taken.tolist() == list(range(len(sizes)))  # each scene once, in order


def test_the_ranks_share_each_of_the_one_process_batches(walks):
    """Over the ranks, each batch's shares are the one-process batch's scenes, and each
    rank's weight (its agents over the batch's) sums to 1; a rank without a scene repeats
    one at zero weight."""
    train = load_dataset(str(walks), "train")
    single = SceneLoader(train, max_agents=8, shuffle=True, seed=3)
    single.set_epoch(1)
    ranks = [RankBatches(train, 8, 3, DistInfo(r, 2, r, 2)) for r in range(2)]
    for r in ranks:
        r.set_epoch(1)
        assert len(r) == len(single)
    shares = [list(r.shares()) for r in ranks]
    for b, whole in enumerate(single.batches()):
        (idx0, a0, t0), (idx1, a1, t1) = shares[0][b], shares[1][b]
        taken = [*(idx0 if a0 else []), *(idx1 if a1 else [])]
        assert sorted(taken) == sorted(whole.tolist())
        assert t0 == t1 == a0 + a1 == sum(train.scenes[i].num_agents for i in whole)
    # one process: the loader's own batches, whole
    one = RankBatches(train, 8, 3, DistInfo())
    one.set_epoch(1)
    assert [i.tolist() for i, _, _ in one.shares()] == [b.tolist() for b in single.batches()]
    assert one.idle_batches() == 0
    # batches of a single scene on two ranks: one rank takes it, the other repeats it at
    # zero weight
    big = [RankBatches(train, 1, 3, DistInfo(r, 2, r, 2)) for r in range(2)]
    assert big[0].idle_batches() == len(big[0])
    for (i0, a0, t0), (i1, a1, t1) in zip(big[0].shares(), big[1].shares(), strict=True):
        assert i0.tolist() == i1.tolist() and sorted([a0, a1]) == [0, t0] and t0 == t1 > 0


def test_the_launcher_is_read_back_from_the_parent_command_line():
    own = ["train", "diffusion", "--out", "r"]
    cmd = ["/v/bin/python3", "/v/bin/torchrun", "--standalone", "--nproc_per_node", "2", "-m",
           "trajpref.cli", *own]  # fmt: skip
    assert launcher_from(cmd, own) == cmd[1:7]
    nodes = ["python", "-m", "torch.distributed.run", "--nnodes=2", "--node_rank=0",
             "--rdzv-endpoint=h:29400", "src/trajpref/cli.py", *own]  # fmt: skip
    assert launcher_from(nodes, own) == nodes[:7]
    assert launcher_from(["bash", "-c", "x", *own], own) is None  # not torchrun
    assert launcher_from(cmd, ["train", "generator"]) is None  # not this process's arguments


@pytest.fixture
def threads():
    before = torch.get_num_threads()
    yield
    torch.set_num_threads(before)


def test_an_explicit_omp_num_threads_is_per_process(monkeypatch, threads):
    """torchrun passes OMP_NUM_THREADS to each process (1 when unset): it is not divided
    again by the process count. Without it (another launcher) the threads are shared out."""
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(16)), raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    torch.set_num_threads(2)
    set_threads(DistInfo(0, 2, 0, 2))
    assert torch.get_num_threads() == 2
    monkeypatch.delenv("OMP_NUM_THREADS")
    torch.set_num_threads(8)
    set_threads(DistInfo(0, 4, 0, 4))
    assert torch.get_num_threads() == 2


def test_processes_beyond_the_cores_are_warned_of(monkeypatch, threads):
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    torch.set_num_threads(1)
    with pytest.warns(UserWarning, match="3 processes of 1 thread"):
        set_threads(DistInfo(0, 3, 0, 3))


@pytest.mark.parametrize("rank", [0, 1])
def test_more_processes_than_gpus_is_refused_on_every_rank(monkeypatch, rank):
    """It was raised on ranks above 0 only, which print nothing: torchrun failed without a
    cause."""
    from trajpref.errors import ConfigError
    from trajpref.train.distributed import init_from_env

    for key, value in (("WORLD_SIZE", "2"), ("LOCAL_WORLD_SIZE", "2"), ("RANK", str(rank)),
                       ("LOCAL_RANK", str(rank))):  # fmt: skip
        monkeypatch.setenv(key, value)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(ConfigError, match=r"torchrun started 2 processes on this machine but "
                       r"it has 1 GPU\(s\)"):  # fmt: skip
        init_from_env(torch.device("cuda"))


def test_cleanup_frees_garbage_in_cycles_before_leaving_the_group(monkeypatch):
    """A DDP wrapper left in a reference cycle holds the gloo group: ``cleanup`` collects it
    while the group and the interpreter are whole, before ``destroy_process_group``."""
    import gc
    import weakref

    import torch.distributed as dist

    from trajpref.train import distributed

    class Wrapper:  # stands in for a DDP module caught in a cycle
        pass

    seen = []
    monkeypatch.setattr(dist, "is_initialized", lambda: True)
    monkeypatch.setattr(dist, "destroy_process_group", lambda: seen.append(alive() is None))
    gc.disable()  # no automatic collection from here on: only cleanup's counts
    try:
        held = Wrapper()
        held.self = held  # a cycle: freed by the collector only
        alive = weakref.ref(held)
        del held
        assert alive() is not None
        distributed.cleanup(DistInfo(rank=0, world_size=2))
    finally:
        gc.enable()
    assert seen == [True]
    distributed.cleanup(DistInfo())  # one process: nothing to leave
    assert seen == [True]
