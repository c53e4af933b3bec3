"""Tests of the core containers (trajpref.types)."""

import pytest
from synthetic import make_scene

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
