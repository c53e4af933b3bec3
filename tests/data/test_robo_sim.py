"""Tests of robo-sim (trajpref.data.robo_sim)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from trajpref.data.registry import stacked_arrays
from trajpref.data.robo_sim import (
    FRAME_DT,
    N_FUTURE,
    N_HISTORY,
    RoboSimConfig,
    scene_statistics,
    simulate,
)


@pytest.fixture(scope="module")
def sample() -> tuple[np.ndarray, np.ndarray]:
    return simulate(300, seed=7)


def test_same_seed_is_bit_identical(sample: tuple[np.ndarray, np.ndarray]) -> None:
    hist, fut = simulate(300, seed=7)
    assert hist.tobytes() == sample[0].tobytes()
    assert fut.tobytes() == sample[1].tobytes()


def test_different_seeds_differ(sample: tuple[np.ndarray, np.ndarray]) -> None:
    hist, fut = simulate(300, seed=8)
    assert not np.array_equal(hist, sample[0])
    assert not np.array_equal(fut, sample[1])


def test_shapes_dtypes_finite(sample: tuple[np.ndarray, np.ndarray]) -> None:
    hist, fut = sample
    assert hist.shape == (300, 3, N_HISTORY, 2) == (300, 3, 8, 2)
    assert fut.shape == (300, 3, N_FUTURE, 2) == (300, 3, 12, 2)
    assert hist.dtype == np.float32 and fut.dtype == np.float32
    assert np.isfinite(hist).all() and np.isfinite(fut).all()
    size = RoboSimConfig().arena_size
    xy = np.concatenate([hist, fut], axis=2)
    assert xy.min() >= 0.0 and xy.max() <= size + 1e-4


def test_zero_episodes() -> None:
    hist, fut = simulate(0, seed=0)
    assert hist.shape == (0, 3, 8, 2) and fut.shape == (0, 3, 12, 2)


def test_steps_consistent_with_half_second_frames(sample: tuple[np.ndarray, np.ndarray]) -> None:
    xy = np.concatenate(sample, axis=2).astype(np.float64)  # E,P,T,D
    speed = np.linalg.norm(np.diff(xy, axis=2), axis=-1) / FRAME_DT  # E,P,T-1
    # robots walk at roughly 0.3-0.9 m/s; frame-interval jitter allows up to ~1.8x
    assert 0.5 < speed.mean() < 0.9
    assert np.percentile(speed, 50) > 0.4
    assert speed.max() < 2.0
    # the history/future split is continuous: no jump between frame 7 and frame 8
    gap = np.linalg.norm(sample[1][:, :, 0] - sample[0][:, :, -1], axis=-1) / FRAME_DT  # E,P
    assert gap.max() < 2.0


def _approach_min(hist: np.ndarray, fut: np.ndarray) -> np.ndarray:
    xy = np.concatenate([hist, fut], axis=2).astype(np.float64)  # E,P,T,D
    d = np.linalg.norm(xy[:, :2] - xy[:, 2:3], axis=-1)  # E,2,T
    return d.min(axis=(1, 2))  # E


def test_avoidance_increases_clearance() -> None:
    on = simulate(400, seed=11)
    off = simulate(400, seed=11, config=RoboSimConfig(avoid_strength=0.0))
    d_on, d_off = _approach_min(*on), _approach_min(*off)
    assert d_on.mean() > d_off.mean()
    assert (d_on < 0.5).mean() < (d_off < 0.5).mean()


@pytest.mark.parametrize(
    "changes",
    [
        {"arena_size": -1.0},
        {"arena_size": float("nan")},
        {"substeps": 0},
        {"substeps": 2.5},
        {"leader_speed": 0.0},
        {"follower_turn_speed": 5.0},  # > follower_speed
        {"approacher_turn_rate": -0.1},
        {"avoid_strength": -1.0},
        {"avoid_range": 0.0},
        {"speed_noise": 0.9},
        {"frame_interval_tail_prob": 1.5},
        {"leader_left_y": (9.0, 5.0)},
        {"leader_right_y": (0.0, 50.0)},
        {"approacher_x": "bad"},
        {"max_start_frame": -1},
        {"turn_threshold": 4.0},
    ],
)
def test_bad_config_raises(changes: dict[str, object]) -> None:
    (name,) = changes  # the error names the field given
    with pytest.raises(ValueError, match=rf"^RoboSimConfig\.{name} must "):
        RoboSimConfig(**changes)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match=r"^n_episodes must be an int >= 0, got -1$"):
        simulate(-1)
    cfg = RoboSimConfig()
    with pytest.raises(ValueError, match=r"^RoboSimConfig\.accel must be a finite number > 0\.0 "
                       r"and <= inf, got 0\.0$"):  # fmt: skip
        dataclasses.replace(cfg, accel=0.0)


def test_every_config_field_has_a_docstring() -> None:
    import inspect

    import trajpref.data.robo_sim as mod

    source = inspect.getsource(mod.RoboSimConfig)
    lines = source.splitlines()
    for field in dataclasses.fields(RoboSimConfig):
        idx = next(i for i, line in enumerate(lines) if line.strip().startswith(f"{field.name}:"))
        assert lines[idx + 1].strip().startswith('"""'), field.name


def test_scene_statistics_keys(sample: tuple[np.ndarray, np.ndarray]) -> None:
    stats = scene_statistics(*sample)
    for key in (
        "speed_mean",
        "closest_p50",
        "pair_dist_mean",
        "turn_total_mean_deg",
        "approach_min_mean",
    ):
        assert np.isfinite(stats[key])


@pytest.mark.realdata
def test_matches_val_statistics(data_root) -> None:
    val = scene_statistics(*stacked_arrays("robo", "val", str(data_root)))
    sim = scene_statistics(*simulate(2000, seed=0))

    def close(key: str, rel: float) -> None:
        assert abs(sim[key] - val[key]) <= rel * abs(val[key]), (key, sim[key], val[key])

    close("speed_mean", 0.15)
    for a in range(3):
        close(f"speed_mean_a{a}", 0.15)
    close("speed_std", 0.3)
    close("pair_dist_mean", 0.25)
    close("closest_p50", 0.3)
    close("approach_min_lt1m_frac", 0.6)
    close("turn_total_mean_deg", 0.3)
    close("on_wall_frac", 0.4)
    assert abs(sim["x_max"] - val["x_max"]) < 0.2 and abs(sim["y_p01"] - val["y_p01"]) < 0.5
