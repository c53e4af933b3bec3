"""Collision rates (Col-I, Col-II, TrajNet++'s test) and scene-size bins."""

import json

import numpy as np
import pytest
import torch
import trajnetplusplustools as tnt
from helpers import _run
from synthetic import make_scene
from trajnetplusplustools.metrics import collision as tnt_collision

from trajpref.data import load_dataset
from trajpref.evaluation import evaluate, predict_dataset
from trajpref.metrics import (
    BinnedMetrics,
    CollisionAccumulator,
    bin_labels,
    collides,
    collision_flags,
    default_collision_radius,
    interpolate_steps,
    neighbour_pairs,
    size_bin,
)
from trajpref.models.baseline import ConstantVelocity
from trajpref.types import AGENT_BALL, AGENT_PERSON, DatasetInfo, Scene, TrajectoryDataset, collate


def _path(*points) -> torch.Tensor:
    return torch.tensor(points, dtype=torch.float64)  # [T, 2]


def _rows(path: np.ndarray, ped: int) -> list:
    return [tnt.TrackRow(f, ped, float(x), float(y)) for f, (x, y) in enumerate(path)]


# ----------------------------------------------------------------------------- collides


def test_crossing_paths_collide_only_between_steps():
    # a walks along x and b along y; both pass the origin at the midpoint of their first step
    a = _path((-1, 0), (1, 0), (3, 0))
    b = _path((0, -1), (0, 1), (0, 3))
    assert torch.linalg.vector_norm(a - b, dim=-1).min() > 1.4  # never close at a step
    assert collides(a, b)  # the midpoint check (TrajNet++'s inter_parts=2) sees it
    assert not collides(a, b, parts=1)  # steps only: missed
    assert tnt_collision(_rows(a.numpy(), 1), _rows(b.numpy(), 2), n_predictions=3)
    assert not tnt_collision(_rows(a.numpy(), 1), _rows(b.numpy(), 2), 3, inter_parts=1)


def test_a_crossing_off_the_checked_points_needs_more_parts():
    # b reaches the origin a quarter of the way through the step: the midpoint misses it
    a = _path((-1, 0), (3, 0))
    b = _path((0, -1), (0, 3))
    assert not collides(a, b)  # positions checked: t = 0, 0.5, 1 (at 0.5 they are 1.41 apart)
    assert collides(a, b, parts=4)  # t = 0.25 is checked


@pytest.mark.parametrize(("gap", "radius", "expected"), [
    (0.19, 0.1, True), (0.21, 0.1, False),  # TrajNet++: centres within 2 * 0.1 m
    (0.09, 0.05, True), (0.11, 0.05, False),  # a radius of 0.05: within 0.1 m
    (0.5, 0.25, True),  # exactly 2 * radius (both exact in binary): inclusive, as TrajNet++
])  # fmt: skip
def test_parallel_paths_collide_within_twice_the_radius(gap, radius, expected):
    t = torch.arange(12, dtype=torch.float64)
    a = torch.stack([0.4 * t, torch.zeros_like(t)], -1)  # [12, 2]
    b = a + torch.tensor([0.0, gap], dtype=torch.float64)
    assert bool(collides(a, b, radius)) is expected
    assert tnt_collision(_rows(a.numpy(), 1), _rows(b.numpy(), 2), 12, radius) is expected


@pytest.mark.parametrize("parts", [1, 2, 3, 5])
def test_collides_equals_trajnetplusplustools_on_random_paths(parts):
    rng = np.random.default_rng(parts)
    a = np.cumsum(rng.normal(0, 0.15, (400, 12, 2)), 1)  # [M, T, 2] random walks
    b = a + rng.normal(0, 0.3, (400, 1, 2)) + np.cumsum(rng.normal(0, 0.1, (400, 12, 2)), 1)
    ours = collides(torch.from_numpy(a), torch.from_numpy(b), parts=parts).tolist()  # [M]
    ref = [tnt_collision(_rows(p, 1), _rows(q, 2), 12, inter_parts=parts)
           for p, q in zip(a, b, strict=True)]  # fmt: skip
    assert 50 < sum(ref) < 350  # both outcomes are well represented
    assert ours == ref


def test_interpolated_points_are_evenly_spaced():
    dense = interpolate_steps(_path((0, 0), (4, 0), (4, 8)), parts=4)
    xs, ys = dense[:, 0].tolist(), dense[:, 1].tolist()
    assert xs == [0, 1, 2, 3, 4, 4, 4, 4, 4]
    assert ys == [0, 0, 0, 0, 0, 2, 4, 6, 8]


def test_bad_collision_arguments_raise():
    with pytest.raises(ValueError, match="radius"):
        collides(torch.zeros(3, 2), torch.zeros(3, 2), radius=0.0)
    with pytest.raises(ValueError, match="radius"):
        collides(torch.zeros(3, 2), torch.zeros(3, 2), radius=float("nan"))
    with pytest.raises(ValueError, match=r"\[\.\.\., T, 2\]"):
        collides(torch.zeros(3, 2), torch.zeros(4, 2))
    with pytest.raises(ValueError, match="parts"):
        collides(torch.zeros(3, 2), torch.zeros(3, 2), parts=0)


def test_collision_radius_is_off_for_data_not_in_metres():
    assert default_collision_radius("m") == 0.1
    assert default_collision_radius("px") is None  # SDD
    assert default_collision_radius("unknown") is None  # a user folder without --units


# ----------------------------------------------------------------------------- Col-I / Col-II


def test_neighbour_pairs_are_ordered_pairs_within_a_scene():
    i, j = neighbour_pairs(torch.tensor([1, 0, 1, 1, 2]))  # need not be sorted
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == [
        (0, 2), (0, 3), (2, 0), (2, 3), (3, 0), (3, 2)
    ]  # fmt: skip


def _two_agent_case(close_to: str):
    """K=2, T_f=2: agents 0 and 1 share scene 0, agent 2 is alone in scene 1 with agent 0's
    exact ground truth and samples. Agent 0's best sample is k=0, agent 1's is k=1 (exact).
    close_to='sample': agent 0's k=0 passes 0.05 m from agent 1's k=0 sample (Col-I only);
    close_to='truth': it passes 0.15 m from agent 1's ground truth (Col-II only)."""
    future = torch.tensor([[[0, 0], [1, 0]], [[0, 1], [1, 1]], [[0, 0], [1, 0]]], dtype=torch.float)
    y0 = 0.0 if close_to == "sample" else 0.85
    k0 = [[[0, y0], [1, y0]], [[0, 0.05], [1, 0.05]], [[0, y0], [1, y0]]]  # [N, T, 2]
    k1 = [[[5, 5], [6, 5]], [[0, 1], [1, 1]], [[5, 5], [6, 5]]]
    pred = torch.tensor([k0, k1], dtype=torch.float)  # [2, 3, 2, 2]
    return pred, future, torch.tensor([0, 0, 1])


def test_col_i_tests_the_best_sample_against_the_neighbours_same_index_sample():
    pred, future, scene = _two_agent_case("sample")
    flags = collision_flags(pred, future, scene)
    assert flags.col_i.tolist() == [True, False, False]
    assert flags.col_ii.tolist() == [False, False, False]
    assert flags.has_neighbour.tolist() == [True, True, False]
    assert flags.col_gt.tolist() == [False, False, False]  # agent 2 overlaps agent 0: other scene


def test_col_ii_tests_the_best_sample_against_the_neighbours_ground_truth():
    pred, future, scene = _two_agent_case("truth")
    flags = collision_flags(pred, future, scene)
    assert flags.col_i.tolist() == [False, False, False]
    assert flags.col_ii.tolist() == [True, False, False]


def test_rates_count_agents_with_a_neighbour_only():
    acc = CollisionAccumulator()
    acc.update(*_two_agent_case("sample"))  # 2 agents with a neighbour, 1 alone
    acc.update(*_two_agent_case("truth"))
    out = acc.compute()
    assert out["col_agents"] == 4
    assert out["col_i_pct"] == pytest.approx(25.0) and out["col_ii_pct"] == pytest.approx(25.0)
    assert out["col_gt_pct"] == 0.0 and out["col_radius"] == 0.1
    alone = CollisionAccumulator()
    alone.update(torch.zeros(2, 1, 12, 2), torch.zeros(1, 12, 2), torch.tensor([0]))
    assert alone.compute()["col_agents"] == 0 and np.isnan(alone.compute()["col_i_pct"])


def test_collision_flags_equal_a_loop_over_trajnetplusplustools():
    rng = np.random.default_rng(0)
    k, sizes = 3, [1, 4, 7]
    scene = torch.tensor(np.repeat(np.arange(len(sizes)), sizes))  # [N]
    n = len(scene)
    start = rng.uniform(-1, 1, (1, n, 1, 2))
    pred = start + np.cumsum(rng.normal(0, 0.2, (k, n, 12, 2)), 2)  # [K, N, 12, 2]
    future = start[0] + np.cumsum(rng.normal(0, 0.2, (n, 12, 2)), 1)  # [N, 12, 2]
    flags = collision_flags(torch.from_numpy(pred), torch.from_numpy(future), scene)
    best = np.linalg.norm(pred - future[None], axis=-1).mean(-1).argmin(0)  # [N]
    col_i, col_ii = [], []
    for i in range(n):
        own = _rows(pred[best[i], i], i)
        mates = [j for j in range(n) if j != i and scene[j] == scene[i]]
        col_i.append(any(tnt_collision(own, _rows(pred[best[i], j], j), 12) for j in mates))
        col_ii.append(any(tnt_collision(own, _rows(future[j], j), 12) for j in mates))
    assert flags.col_i.tolist() == col_i and flags.col_ii.tolist() == col_ii
    assert 0 < sum(col_i) < n - 1 and 0 < sum(col_ii) < n - 1  # informative case


def test_collision_flags_follow_the_agents_not_their_order():
    pred, future, scene = _two_agent_case("sample")
    perm = torch.tensor([2, 1, 0])
    flags = collision_flags(pred[:, perm], future[perm], scene[perm])
    assert flags.col_i.tolist() == [False, False, True]
    again = collision_flags(pred[:, perm], future[perm], scene[perm])  # no state kept
    assert torch.equal(flags.col_i, again.col_i) and torch.equal(flags.col_ii, again.col_ii)


def test_evaluate_collisions_come_from_predictions_and_ground_truth_only(walks):
    test = load_dataset(str(walks), "test")
    # the walks start metres apart: a radius of 3 (data units) gives some collisions, not all
    res = evaluate(ConstantVelocity(), test, 4, seed=0, progress=False, collision_radius=3.0)
    arrays = predict_dataset(ConstantVelocity(), test, 4, seed=0, progress=False)
    acc = CollisionAccumulator(3.0)
    acc.update(*(torch.from_numpy(arrays[k]) for k in ("pred", "future", "scene")))
    assert {k: res[k] for k in acc.compute()} == acc.compute()
    assert res["col_agents"] == res["agents"] and 0 < res["col_ii_pct"] < 100
    off = evaluate(ConstantVelocity(), test, 4, seed=0, progress=False)  # units unknown: off
    assert off["col_i_pct"] is None and off["col_radius"] is None


# ----------------------------------------------------------------------------- bins


def test_bin_labels_and_assignment():
    assert bin_labels() == ["<=5", "6-10", "11-20", ">20"]
    assert bin_labels((1, 2, 4)) == ["<=1", "2", "3-4", ">4"]
    sizes = torch.tensor([1, 5, 6, 10, 11, 20, 21, 100])
    assert size_bin(sizes).tolist() == [0, 0, 1, 1, 2, 2, 3, 3]
    with pytest.raises(ValueError, match="increasing"):
        bin_labels((10, 5))


def _x_errors(errors: list[float], t_f: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    """One sample per agent, off its zero ground truth by errors[i] along x at every step."""
    e = torch.tensor(errors)[None, :, None].expand(1, len(errors), t_f)  # [1, N, T_f]
    return torch.stack([e, torch.zeros_like(e)], -1), torch.zeros(len(errors), t_f, 2)


def test_binned_metrics_by_hand():
    # scene sizes 1, 2, 6: the first two fall in <=5, the third in 6-10
    pred, fut = _x_errors([1, 2, 4, 1, 1, 1, 1, 1, 7])
    scene = torch.tensor([0, 1, 1, 2, 2, 2, 2, 2, 2])
    acc = BinnedMetrics()
    acc.update(pred, fut, scene, 3, {"max_ats": torch.tensor([0.5, 0.1, 0.9])})
    out = acc.compute()
    assert list(out) == ["<=5", "6-10", "11-20", ">20"]
    small, mid = out["<=5"], out["6-10"]
    assert (small["scenes"], small["agents"], mid["scenes"], mid["agents"]) == (2, 3, 1, 6)
    assert small["min_ade"] == pytest.approx(7 / 3) and small["joint_min_ade"] == pytest.approx(2)
    assert mid["min_fde"] == pytest.approx(2) and mid["joint_min_fde"] == pytest.approx(2)
    assert small["max_ats"] == pytest.approx(0.3) and mid["max_ats"] == pytest.approx(0.9)
    # every ground truth sits at the origin (all overlap); the five samples at x = 1 collide
    assert small["col_agents"] == 2 and small["col_i_pct"] == 0 and small["col_gt_pct"] == 100
    assert mid["col_i_pct"] == pytest.approx(500 / 6) and mid["col_ii_pct"] == 0
    assert out["11-20"] == {"scenes": 0, "agents": 0} and out[">20"] == {"scenes": 0, "agents": 0}


def test_bins_add_up_to_the_whole_split():
    acc, whole = BinnedMetrics((2, 4)), CollisionAccumulator()
    scenes = [make_scene(n, seed=n) for n in (1, 2, 3, 4, 5, 6, 2, 5)]
    for part in (scenes[:5], scenes[5:]):
        batch = collate(part)
        pred = batch.future[None] + 0.3 * torch.randn(3, *batch.future.shape)  # [3, N, T_f, 2]
        acc.update(pred, batch.future, batch.scene, batch.num_scenes)
        whole.update(pred, batch.future, batch.scene)
    out = acc.compute()
    assert [out[k]["scenes"] for k in ("<=2", "3-4", ">4")] == [3, 2, 3]
    assert sum(r["agents"] for r in out.values()) == sum(s.num_agents for s in scenes)
    total = whole.compute()
    assert sum(r["col_agents"] for r in out.values()) == total["col_agents"]
    hits = sum(r["col_i_pct"] * r["col_agents"] / 100 for r in out.values())
    assert hits == pytest.approx(total["col_i_pct"] * total["col_agents"] / 100)


# ----------------------------------------------------------------------------- evaluate --json


def test_evaluate_json_has_collisions_and_bins(capsys, walks, tiny_run):
    scorer = tiny_run / "denoiser.safetensors"
    argv = ["evaluate", "--dataset", walks, "--units", "m", "--model", "cv", "--samples", "4",
            "--no-progress", "--device", "cpu", "--scorer", scorer]  # fmt: skip
    code, out, _ = _run(capsys, *argv, "--json", "--bins", "--collision-radius", "3")
    assert code == 0
    res = json.loads(out)  # strict JSON
    assert {"col_i_pct", "col_ii_pct", "col_gt_pct", "col_agents"} <= set(res)
    assert res["col_radius"] == 3 and res["col_agents"] == res["agents"]  # 3 agents a scene
    assert 0 < res["col_i_pct"] < 100
    assert list(res["bins"]) == ["<=5", "6-10", "11-20", ">20"]
    small = res["bins"]["<=5"]  # every scene has 3 agents: this bin is the whole split
    for key in ("min_ade", "min_fde", "joint_min_fde", "col_i_pct", "col_ii_pct", "max_ats"):
        assert small[key] == pytest.approx(res[key]), key
    code, text, _ = _run(capsys, *argv, "--bins", "--collision-radius", "3")
    assert code == 0 and f"Col-I {res['col_i_pct']:.2f} %" in text and "<=5" in text
    code, out, _ = _run(capsys, *argv[:-2], "--json")  # metres: TrajNet++'s radius by default
    assert json.loads(out)["col_radius"] == 0.1 and "bins" not in json.loads(out)


def test_evaluate_collisions_are_off_without_metres(capsys, walks):
    argv = ["evaluate", "--dataset", walks, "--model", "cv", "--no-progress", "--device", "cpu"]
    code, out, _ = _run(capsys, *argv, "--json")
    assert code == 0 and json.loads(out)["col_i_pct"] is None
    code, text, _ = _run(capsys, *argv)
    assert "collisions off (units unknown" in text


BAD = [["--bins", "10,5"], ["--bins", "a"], ["--bins", "0,3"], ["--collision-radius", "0"],
       ["--collision-radius", "nan"]]  # fmt: skip


@pytest.mark.parametrize("bad", BAD)
def test_bad_bins_or_radius_give_one_line_errors(capsys, walks, bad):
    code, out, err = _run(capsys, "evaluate", "--dataset", walks, "--no-progress", *bad)
    assert code == 2 and out == ""
    assert err.startswith("trajpref: error: ") and len(err.strip().splitlines()) == 1


# ----------------------------------------------------------------------------- the ball


def _ball_case() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Scene 0: a player with the ball on top of it and a far player; scene 1: two players on
    top of each other. Ground truth and every sample follow the same paths."""
    walk = [[0.0, 0.0], [1.0, 0.0]]  # [T, 2]
    far = [[5.0, 5.0], [6.0, 5.0]]
    future = torch.tensor([walk, walk, far, walk, walk])  # [N = 5, T, 2]
    pred = future.expand(2, -1, -1, -1).clone()  # [K = 2, N, T, 2] every sample exact
    scene = torch.tensor([0, 0, 0, 1, 1])
    agent_type = torch.tensor([AGENT_PERSON, AGENT_BALL, AGENT_PERSON, AGENT_PERSON,
                               AGENT_PERSON])  # fmt: skip
    return pred, future, scene, agent_type


def test_the_ball_is_no_collider_but_two_players_are():
    pred, future, scene, agent_type = _ball_case()
    flags = collision_flags(pred, future, scene, bodies=agent_type != AGENT_BALL)
    for key in ("col_i", "col_ii", "col_gt"):  # the ball-holder does not collide; players do
        assert getattr(flags, key).tolist() == [False, False, False, True, True], key
    assert flags.has_neighbour.tolist() == [True, False, True, True, True]  # the ball: no rate
    untyped = collision_flags(pred, future, scene)  # without the mask the ball is a body
    assert untyped.col_gt.tolist() == [True, True, False, True, True]
    acc = CollisionAccumulator()
    acc.update(pred, future, scene, agent_type != AGENT_BALL)
    out = acc.compute()
    assert out["col_agents"] == 4 and out["col_gt_pct"] == pytest.approx(50.0)
    with pytest.raises(ValueError, match="bodies must be"):
        collision_flags(pred, future, scene, bodies=agent_type[:3] != AGENT_BALL)


def test_a_ball_alone_with_one_player_leaves_no_agent_with_a_neighbour():
    future = torch.zeros(2, 3, 2)  # [N, T, 2] the ball in the player's hands
    flags = collision_flags(
        future[None], future, torch.tensor([0, 0]), bodies=torch.tensor([False, True])
    )  # the ball, the player
    assert not flags.has_neighbour.any() and not flags.col_gt.any()


def test_evaluate_does_not_count_the_ball_as_a_collider():
    pred, future, scene, agent_type = _ball_case()
    hist = future[:, :1].expand(-1, 8, -1).numpy()  # [N, 8, 2] standing still
    scenes = [Scene(hist[a:b], future[a:b].numpy(), agent_type[a:b].numpy(), f"s{a}")
              for a, b in ((0, 3), (3, 5))]  # fmt: skip
    info = DatasetInfo("ball", "test", "m", 0.12, t_fut=2)
    res = evaluate(ConstantVelocity(), TrajectoryDataset(scenes, info), 1, progress=False)
    assert res["col_agents"] == 4  # the 4 players
    assert res["col_gt_pct"] == pytest.approx(50.0)  # scene 1's two players, not the ball-holder
    binned = BinnedMetrics(collision_radius=0.1)
    binned.update(pred, future, scene, 2, bodies=agent_type != AGENT_BALL)
    assert binned.compute()["<=5"]["col_gt_pct"] == pytest.approx(50.0)
