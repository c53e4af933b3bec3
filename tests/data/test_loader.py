import numpy as np
import pytest
import torch
from synthetic import make_scene

from trajpref.data.loader import SceneLoader
from trajpref.types import DatasetInfo, TrajectoryDataset, collate


def _dataset(sizes):
    scenes = [make_scene(n, seed=i) for i, n in enumerate(sizes)]
    return TrajectoryDataset(scenes, DatasetInfo("synthetic", "train", "m", 0.4))


def test_collate_packs_agents_and_scene_index():
    batch = collate([make_scene(2), make_scene(3, seed=1)])
    assert batch.history.shape == (5, 8, 2) and batch.future.shape == (5, 12, 2)
    assert batch.scene.tolist() == [0, 0, 1, 1, 1]
    assert batch.num_scenes == 2


def test_padded_layout_never_mixes_scenes():
    batch = collate([make_scene(2), make_scene(4, seed=1), make_scene(1, seed=2)])
    slot, mask = batch.padded_index()
    assert slot.tolist() == [0, 1, 0, 1, 2, 3, 0]
    assert mask.shape == (3, 4)
    assert mask.sum(1).tolist() == [2, 4, 1]
    padded = torch.full((3, 4), -1)
    padded[batch.scene, slot] = torch.arange(batch.num_agents)
    # every real slot of scene b holds an agent of scene b; padding stays empty
    for b in range(3):
        members = padded[b][mask[b]]
        assert (batch.scene[members] == b).all()
        assert (padded[b][~mask[b]] == -1).all()
    # the attention mask of agent i (its scene's row of ``mask``) equals same_scene()[i]
    same = batch.same_scene()
    for i in range(batch.num_agents):
        attends = torch.zeros(batch.num_agents, dtype=torch.bool)
        row = padded[batch.scene[i]][mask[batch.scene[i]]]
        attends[row] = True
        assert torch.equal(attends, same[i])


def test_loader_covers_every_scene_once_and_respects_budget():
    sizes = [1, 60, 3, 2, 7, 55, 1, 4] * 5
    loader = SceneLoader(_dataset(sizes), max_agents=64, shuffle=True, seed=0)
    seen = np.concatenate(loader.batches())
    assert sorted(seen.tolist()) == list(range(len(sizes)))
    for batch in loader:
        assert batch.num_agents <= 64
        _, mask = batch.padded_index()
        # grouping by size keeps padding small: a crowded scene rarely shares a batch
        assert mask.numel() <= 4 * batch.num_agents + 64


def test_shuffle_is_seeded_and_changes_with_epoch():
    loader = SceneLoader(_dataset(list(range(1, 30))), max_agents=20, shuffle=True, seed=1)
    a = [b.tolist() for b in loader.batches()]
    assert a == [
        b.tolist() for b in SceneLoader(loader.dataset, 20, shuffle=True, seed=1).batches()
    ]
    loader.set_epoch(1)
    assert a != [b.tolist() for b in loader.batches()]
    assert a != [
        b.tolist() for b in SceneLoader(loader.dataset, 20, shuffle=True, seed=2).batches()
    ]


def test_the_seed_decides_which_scenes_share_a_batch():
    """Equal sizes, four scenes a batch and a pool of one batch: the batches are runs of the
    shuffled order, so what they hold (not only their order) comes from the seed and epoch."""

    def groups(seed, epoch=0):
        loader = SceneLoader(_dataset([3] * 12), max_agents=100, max_scenes=4, shuffle=True,
                             seed=seed, pool=1)  # fmt: skip
        loader.set_epoch(epoch)
        return {frozenset(b.tolist()) for b in loader.batches()}

    assert groups(1) == groups(1) and len(groups(1)) == 3
    assert groups(1) != groups(2) and groups(1) != groups(1, epoch=1)


def test_bad_loader_args():
    with pytest.raises(ValueError, match=r"^max_agents and max_scenes must be positive$"):
        SceneLoader(_dataset([1]), max_agents=0)
