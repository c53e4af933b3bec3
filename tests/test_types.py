"""Tests of the core containers (trajpref.types)."""

import numpy as np
import pytest
from synthetic import make_scene

from trajpref.errors import ConfigError
from trajpref.types import TrajectoryDataset


def _dataset(n: int) -> TrajectoryDataset:
    return TrajectoryDataset([make_scene(2, seed=i) for i in range(n)], None)


def test_evenly_spaced_keeps_both_ends_and_floors_the_interior():
    data = _dataset(10)
    picked = data.evenly_spaced(3)
    # linspace(0, 9, 3) = 0, 4.5, 9 -> scenes 0, 4, 9
    assert all(s is data.scenes[i] for s, i in zip(picked.scenes, (0, 4, 9), strict=True))
    assert len(data.evenly_spaced(4)) == 4


def test_evenly_spaced_returns_the_split_itself_when_it_is_small_enough():
    data = _dataset(5)
    assert data.evenly_spaced(None) is data
    assert data.evenly_spaced(5) is data
    assert data.evenly_spaced(50) is data


def test_evenly_spaced_rejects_a_count_below_one():
    with pytest.raises(ValueError, match="at least 1"):
        _dataset(5).evenly_spaced(0)


@pytest.mark.parametrize("count", [0, -2, 2.5, True, "3"])
@pytest.mark.parametrize("scenes", [0, 1, 5])
def test_evenly_spaced_refuses_a_count_below_one_or_no_integer_as_a_config_error(count, scenes):
    """A ``ConfigError``, which is a ``ValueError`` as the bare error was (walkthrough 69), and
    whatever the split's size (a split no bigger than the count was returned whole, so 0 on an
    empty split or 2.5 on a split of one passed)."""
    with pytest.raises(ConfigError, match="at least 1") as caught:
        _dataset(scenes).evenly_spaced(count)
    assert isinstance(caught.value, ValueError)


def test_evenly_spaced_takes_numpy_integers():
    data = _dataset(10)
    assert [s.scene_id for s in data.evenly_spaced(np.int64(3)).scenes] == [
        s.scene_id for s in data.evenly_spaced(3).scenes
    ]


def _with_context(scene, context):
    import dataclasses

    return dataclasses.replace(scene, context=context)


def test_collate_packs_context_agents_with_their_scene_index():
    import numpy as np

    from trajpref.types import collate

    a = _with_context(make_scene(2), np.ones((3, 8, 2), np.float32))
    b = make_scene(1, seed=1)  # no context
    c = _with_context(make_scene(2, seed=2), np.full((1, 8, 2), 2.0, np.float32))
    batch = collate([a, b, c])
    assert batch.num_agents == 5 and batch.num_context == 4
    assert batch.context_scene.tolist() == [0, 0, 0, 2]
    assert batch.context[3, 0, 0].item() == 2.0
    assert batch.without_context().num_context == 0
    assert collate([b]).context is None


def test_bad_context_gives_a_clear_error():
    import numpy as np
    import torch

    from trajpref.errors import DataError
    from trajpref.types import collate

    with pytest.raises(DataError, match=r"context must be \[C, T_h, 2\]"):
        _with_context(make_scene(2), np.ones((3, 5, 2), np.float32))
    batch = collate([make_scene(2)])
    with pytest.raises(DataError, match="go together"):
        type(batch)(batch.history, batch.future, batch.scene, batch.agent_type, 1,
                    context=torch.zeros(1, 8, 2))  # fmt: skip


def test_agent_ids_are_checked_against_the_agents():
    import dataclasses

    import numpy as np

    from trajpref.errors import DataError

    scene = make_scene(3)
    assert scene.agent_id is None  # a source without ids (.npz splits, simulations)
    kept = dataclasses.replace(scene, agent_id=[17, 42, 9])  # a list is taken as an array
    assert isinstance(kept.agent_id, np.ndarray) and kept.agent_id.tolist() == [17, 42, 9]
    names = dataclasses.replace(scene, agent_id=np.array(["a", "b", "18446744073709551617"]))
    assert names.agent_id.dtype.kind == "U"
    for bad, shape in (([17, 42], r"\[2\]"), (np.zeros((3, 1)), r"\[3, 1\]"), (5, r"\[\]")):
        with pytest.raises(DataError, match=r"agent_id must be \[P\] with P = 3 .* got " + shape):
            dataclasses.replace(scene, agent_id=bad)
    with pytest.raises(DataError, match="agent_id must hold numbers or strings, got bool"):
        dataclasses.replace(scene, agent_id=np.array([True, False, True]))


def test_dataset_info_refuses_an_interval_source_it_does_not_know():
    import dataclasses

    from trajpref.types import INTERVAL_SOURCES, DatasetInfo

    for source in INTERVAL_SOURCES:
        assert DatasetInfo("x", "test", "m", 0.4, interval_from=source).interval_from == source
    info = DatasetInfo("x", "test", "m", 0.4)  # "given" by default
    with pytest.raises(ValueError, match="interval_from must be one of dataset, .*'guessed'"):
        DatasetInfo("x", "test", "m", 0.4, interval_from="guessed")
    with pytest.raises(ValueError, match="got None"):
        dataclasses.replace(info, interval_from=None)


def test_every_interval_source_is_worded_where_it_is_shown():
    """``data stats``, a training run's split lines and a checkpoint's card say where a frame
    interval comes from: each wording table covers exactly ``INTERVAL_SOURCES``."""
    from trajpref.models.zoo import INTERVAL_FROM
    from trajpref.train.run import INTERVAL_NOTES
    from trajpref.types import INTERVAL_SOURCES

    assert set(INTERVAL_NOTES) == set(INTERVAL_SOURCES)
    assert set(INTERVAL_FROM) == set(INTERVAL_SOURCES)
