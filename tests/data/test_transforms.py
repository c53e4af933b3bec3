import dataclasses

import numpy as np
import pytest
import torch
from synthetic import make_scene

from trajpref.data.transforms import (
    augment,
    backward_velocity,
    drop_agents_at_random,
    from_model_frame,
    observed_pace,
    reverse_time,
    scene_speeds,
    speed_normaliser,
    to_model_frame,
    transform_scenes,
)
from trajpref.types import Batch, collate


def test_backward_velocity_never_looks_ahead():
    x = torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [100.0, 0.0]])  # [T, 2]
    v = backward_velocity(x)
    assert v[:, 0].tolist() == [0.0, 1.0, 2.0, 97.0]
    # changing the last frame leaves every earlier velocity unchanged
    y = x.clone()
    y[-1, 0] = -5
    assert torch.equal(backward_velocity(y)[:-1], v[:-1])


def test_model_frame_is_relative_to_the_last_observed_position_and_roundtrips():
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    for scale in (1.0, 2.5):
        hist_rel = to_model_frame(batch.history, batch, scale)  # [N, T_h, 2]
        fut_rel = to_model_frame(batch.future, batch, scale)  # [N, T_f, 2]
        assert torch.equal(hist_rel[:, -1], torch.zeros(5, 2))
        origin = batch.history[:, -1:]  # [N, 1, 2]
        torch.testing.assert_close(fut_rel, (batch.future - origin) / scale)
        torch.testing.assert_close(from_model_frame(fut_rel, batch, scale), batch.future)
    samples = to_model_frame(batch.future, batch, 2.0).expand(4, -1, -1, -1)  # [K, N, T_f, 2]
    torch.testing.assert_close(from_model_frame(samples, batch, 2.0)[3], batch.future)


def _pairwise(x):  # [N, T, 2] -> [N, N, T]
    return torch.linalg.vector_norm(x[:, None] - x[None], dim=-1)


def test_augment_is_rigid_per_scene_and_seeded():
    batch = collate([make_scene(3), make_scene(4, seed=1)])
    g = torch.Generator().manual_seed(0)
    out = augment(batch, g, rotate=True, flip=True)
    same = batch.same_scene()
    d_in = _pairwise(torch.cat([batch.history, batch.future], 1))
    d_out = _pairwise(torch.cat([out.history, out.future], 1))
    torch.testing.assert_close(d_out[same], d_in[same], atol=1e-4, rtol=1e-4)
    assert not torch.allclose(out.history, batch.history)
    again = augment(batch, torch.Generator().manual_seed(0), rotate=True, flip=True)
    assert torch.equal(out.history, again.history)


def test_augment_scale():
    batch = collate([make_scene(2)])
    out = augment(batch, torch.Generator().manual_seed(0), rotate=False, scale_range=(2.0, 2.0))
    step_in = batch.future[:, 1] - batch.future[:, 0]
    step_out = out.future[:, 1] - out.future[:, 0]
    torch.testing.assert_close(step_out, 2 * step_in)


def test_scene_speeds_is_the_median_agent_step_length():
    # scene 0: agents stepping 1, 2 and 6 units per step -> median 2; scene 1: one agent at 0.5
    steps = torch.tensor([1.0, 2.0, 6.0, 0.5])  # [N]
    t = torch.arange(8, dtype=torch.float32)  # [T_h]
    history = torch.stack([t[:, None] * torch.stack([s, torch.tensor(0.0)]) for s in steps])
    batch = Batch(history=history, future=torch.zeros(4, 12, 2),
                  scene=torch.tensor([0, 0, 0, 1]), agent_type=torch.zeros(4, dtype=torch.int64),
                  num_scenes=2)  # fmt: skip
    assert torch.allclose(scene_speeds(batch), torch.tensor([2.0, 0.5]))
    mats = speed_normaliser(batch, speed_ref=1.0)  # scene 0 halved, scene 1 (slower) kept
    assert torch.allclose(mats[:, 0, 0], torch.tensor([0.5, 1.0]))
    scaled = transform_scenes(batch, mats)
    centre = batch.history[:3, -1].mean(0)  # scene 0's mean last observed position
    assert torch.allclose(scaled.history[:3], (batch.history[:3] - centre) * 0.5 + centre)
    assert torch.equal(scaled.history[3], batch.history[3])


def test_observed_pace_is_first_to_last_displacement_per_step_over_the_scale():
    hist = torch.zeros(2, 8, 2)
    hist[0, :, 0] = torch.arange(8.0) * 0.5  # 0.5 per step
    hist[1, 0] = torch.tensor([3.0, 4.0])  # 5 units back to the origin over 7 steps
    hist[1, 3] = torch.tensor([100.0, 0.0])  # the path between does not count
    torch.testing.assert_close(observed_pace(hist), torch.tensor([0.5, 5 / 7]))
    torch.testing.assert_close(observed_pace(hist, scale=2.0), torch.tensor([0.25, 5 / 14]))
    assert observed_pace(hist[None].expand(3, -1, -1, -1)).shape == (3, 2)


def test_observed_pace_needs_two_steps():
    with pytest.raises(ValueError, match="two observed steps"):
        observed_pace(torch.zeros(3, 1, 2))


def _window_batch():
    # scene 0: two agents, scene 1: one agent; agent i's position at step t is (t, i)
    t = torch.arange(20, dtype=torch.float32)  # [T_h + T_f]
    window = torch.stack([torch.stack([t, torch.full_like(t, i)], -1) for i in range(3)])
    return Batch(history=window[:, :8], future=window[:, 8:], scene=torch.tensor([0, 0, 1]),
                 agent_type=torch.zeros(3, dtype=torch.int64), num_scenes=2)  # fmt: skip


def test_reverse_time_plays_flagged_scenes_backwards():
    batch = _window_batch()
    out = reverse_time(batch, torch.tensor([True, False]))
    # scene 0: history is steps 19..12, future 11..0; scene 1 untouched
    assert out.history[0, :, 0].tolist() == [19.0, 18, 17, 16, 15, 14, 13, 12]
    assert out.future[1, :, 0].tolist() == [11.0, 10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0]
    assert torch.equal(out.history[:, :, 1], batch.history[:, :, 1])  # agents keep their rows
    assert torch.equal(out.history[2], batch.history[2])
    assert torch.equal(out.future[2], batch.future[2])
    twice = reverse_time(out, torch.tensor([True, False]))
    assert torch.equal(twice.history, batch.history) and torch.equal(twice.future, batch.future)


def test_reverse_time_needs_one_flag_per_scene():
    with pytest.raises(ValueError, match="one flag per scene"):
        reverse_time(_window_batch(), torch.tensor([True]))


def test_augment_reverse_flips_whole_scenes_and_leaves_other_draws_alone():
    scenes = [make_scene(2, seed=s) for s in range(40)]
    batch = collate(scenes)
    plain = augment(batch, torch.Generator().manual_seed(3), rotate=True, flip=True)
    out = augment(batch, torch.Generator().manual_seed(3), rotate=True, flip=True, reverse=True)
    first = torch.cat([batch.history, batch.future], 1)  # [N, T, 2]
    reversed_agents = []
    for i in range(batch.num_agents):
        # the rotation and mirror are the same draws: a kept agent matches the plain run, a
        # reversed one keeps its step lengths in reverse order
        steps = (first[i, 1:] - first[i, :-1]).norm(dim=-1)  # [T - 1]
        got = torch.cat([out.history[i], out.future[i]], 0)  # [T, 2]
        got_steps = (got[1:] - got[:-1]).norm(dim=-1)  # [T - 1]
        if torch.allclose(
            out.history[i] - out.history[i, -1], plain.history[i] - plain.history[i, -1], atol=1e-5
        ):
            torch.testing.assert_close(got_steps, steps, atol=1e-4, rtol=1e-4)
            reversed_agents.append(False)
        else:
            torch.testing.assert_close(got_steps, steps.flip(0), atol=1e-4, rtol=1e-4)
            reversed_agents.append(True)
    flags = torch.tensor(reversed_agents)
    for b in range(batch.num_scenes):  # a scene is reversed as a whole
        assert flags[batch.scene == b].unique().numel() == 1
    assert 5 < int(flags.sum()) < 75  # about half of the 80 agents


def test_history_noise_jitters_all_observed_positions_but_the_last_and_no_other_draw():
    batch = collate([make_scene(3, seed=s) for s in range(200)])  # N = 600
    plain = augment(batch, torch.Generator().manual_seed(5), rotate=True, flip=True)
    out = augment(batch, torch.Generator().manual_seed(5), rotate=True, flip=True,
                  history_noise=0.1)  # fmt: skip
    # the rotation and mirror are the same draws; the last observation and the future exact
    assert torch.equal(out.history[:, -1], plain.history[:, -1])
    assert torch.equal(out.future, plain.future)
    jitter = out.history[:, :-1] - plain.history[:, :-1]  # [N, T_h - 1, 2]
    assert abs(float(jitter.std()) - 0.1) < 0.005
    assert abs(float(jitter.mean())) < 0.005


def test_dropping_agents_keeps_whole_rows_and_at_least_one_agent_per_scene():
    scenes = [make_scene(size, seed=s) for s, size in enumerate([1, 2, 5, 3, 8] * 40)]
    batch = collate(scenes)  # B = 200, N = 760
    out = drop_agents_at_random(batch, 0.6, torch.Generator().manual_seed(3))
    assert out.num_scenes == batch.num_scenes
    assert torch.equal(out.scene_sizes() >= 1, torch.ones(200, dtype=torch.bool))
    assert bool((out.scene[1:] >= out.scene[:-1]).all())  # still packed scene by scene
    assert 0.3 < out.num_agents / batch.num_agents < 0.55  # about 40 % kept, plus the rescued
    # every kept agent is one of the batch's rows, unchanged, with its own scene and type
    rows = torch.cat([batch.history.flatten(1), batch.future.flatten(1)], 1)  # [N, 40]
    kept = torch.cat([out.history.flatten(1), out.future.flatten(1)], 1)  # [N', 40]
    match = (kept[:, None] == rows[None]).all(-1)  # [N', N]
    assert bool((match.sum(1) == 1).all())
    src = match.float().argmax(1)  # [N']
    assert torch.equal(batch.scene[src], out.scene)
    assert torch.equal(batch.agent_type[src], out.agent_type)
    assert bool((src[1:] > src[:-1]).all())  # order kept


def test_dropping_agents_is_seeded_and_off_at_zero():
    batch = collate([make_scene(4, seed=s) for s in range(50)])
    a = drop_agents_at_random(batch, 0.3, torch.Generator().manual_seed(1))
    b = drop_agents_at_random(batch, 0.3, torch.Generator().manual_seed(1))
    assert torch.equal(a.history, b.history) and a.num_agents < batch.num_agents
    c = drop_agents_at_random(batch, 0.3, torch.Generator().manual_seed(3))
    assert not torch.equal(c.history, a.history)  # another seed leaves out other agents
    gen = torch.Generator().manual_seed(2)
    plain = augment(batch, torch.Generator().manual_seed(2), flip=True)
    same = augment(batch, gen, flip=True, drop_agents=0.0)
    assert torch.equal(plain.history, same.history)
    # dropping is drawn last: the kept agents have the transform of the run without it
    dropped = augment(batch, torch.Generator().manual_seed(2), flip=True, drop_agents=0.3)
    rows = plain.history.flatten(1)
    assert bool((dropped.history.flatten(1)[:, None] == rows[None]).all(-1).any(1).all())
    with pytest.raises(ValueError, match=r"drop_agents needs a rate in \[0, 1\)"):
        drop_agents_at_random(batch, 1.0)


def _context_batch() -> Batch:
    a = make_scene(2)
    b = make_scene(3, seed=1)
    rng = np.random.default_rng(5)
    a = dataclasses.replace(a, context=rng.normal(size=(2, 8, 2)).astype(np.float32))
    b = dataclasses.replace(b, context=rng.normal(size=(1, 8, 2)).astype(np.float32))
    return collate([a, b])


def test_context_agents_move_with_their_scene():
    batch = _context_batch()
    mats = torch.tensor([[[0.0, -1.0], [1.0, 0.0]], [[2.0, 0.0], [0.0, 2.0]]])  # [B, 2, 2]
    moved = transform_scenes(batch, mats)
    # as if each context agent were one more target of its scene (the centroid stays the
    # targets')
    from trajpref.data.transforms import scene_centroids

    c = scene_centroids(batch)[batch.context_scene][:, None]  # [M, 1, 2]
    expected = (batch.context - c) @ mats[batch.context_scene].transpose(-1, -2) + c
    torch.testing.assert_close(moved.context, expected)
    torch.testing.assert_close(moved.history, transform_scenes(batch.without_context(),
                                                               mats).history)  # fmt: skip


def test_reversed_scenes_lose_their_context_agents():
    batch = _context_batch()
    out = reverse_time(batch, torch.tensor([True, False]))
    assert out.context_scene.tolist() == [1]
    torch.testing.assert_close(out.context, batch.context[2:])
    assert reverse_time(batch, torch.tensor([True, True])).context is None


def test_augment_without_context_draws_as_before():
    # the targets' draws do not depend on the context agents, which are drawn after them
    batch = _context_batch()
    kw = dict(flip=True, history_noise=0.05, drop_agents=0.3)
    with_ctx = augment(batch, torch.Generator().manual_seed(3), **kw)
    without = augment(batch.without_context(), torch.Generator().manual_seed(3), **kw)
    torch.testing.assert_close(with_ctx.history, without.history)
    torch.testing.assert_close(with_ctx.scene, without.scene)


def test_observed_context_keeps_agents_seen_long_enough_and_holds_them_still_before():
    import dataclasses

    import numpy as np

    from trajpref.data.transforms import observed_context

    track = np.stack([np.arange(8.0), np.zeros(8)], -1).astype(np.float32)  # [T_h, 2]
    ctx = np.stack([track] * 4)  # [4, T_h, 2]
    ctx[1, :2] = np.nan  # seen from frame 2: a run of 6
    ctx[2, 3] = np.nan  # a break at frame 3: a run of 4 (frames 4..7)
    ctx[3, :7] = np.nan  # seen at the last frame only
    batch = collate([dataclasses.replace(make_scene(1), context=ctx)])
    assert observed_context(batch, 8).context_scene.tolist() == [0]
    torch.testing.assert_close(observed_context(batch, 8).context, batch.context[:1])
    six = observed_context(batch, 6).context  # rows 0 and 1
    assert six.shape == (2, 8, 2)
    torch.testing.assert_close(six[1, :, 0], torch.tensor([2.0, 2, 2, 3, 4, 5, 6, 7]))
    four = observed_context(batch, 4).context  # rows 0, 1 and 2; row 2 holds frame 4 before
    torch.testing.assert_close(four[2, :, 0], torch.tensor([4.0, 4, 4, 4, 4, 5, 6, 7]))
    assert observed_context(batch, 1).num_context == 4
    with pytest.raises(ValueError, match="min_frames"):
        observed_context(batch, 9)


def _two_way_context_batch():
    a, b = make_scene(2), make_scene(3, seed=1)
    rng = np.random.default_rng(6)
    a = dataclasses.replace(
        a,
        context=rng.normal(size=(2, 8, 2)).astype(np.float32),
        context_reverse=rng.normal(size=(3, 8, 2)).astype(np.float32),
    )
    b = dataclasses.replace(
        b,
        context=rng.normal(size=(1, 8, 2)).astype(np.float32),
        context_reverse=rng.normal(size=(2, 8, 2)).astype(np.float32),
    )
    return collate([a, b])  # fmt: skip


def test_reversed_scenes_can_keep_the_reversed_windows_context():
    batch = _two_way_context_batch()
    assert batch.context_reverse_scene.tolist() == [0, 0, 0, 1, 1]
    out = reverse_time(batch, torch.tensor([False, True]), keep_context=True)
    # scene 0 keeps its own context; scene 1 takes its reversed window's
    assert out.context_scene.tolist() == [0, 0, 1, 1]
    torch.testing.assert_close(out.context[:2], batch.context[:2])
    torch.testing.assert_close(out.context[2:], batch.context_reverse[3:])
    assert out.context_reverse is None and out.context_reverse_scene is None
    both = reverse_time(batch, torch.tensor([True, True]), keep_context=True)
    torch.testing.assert_close(both.context, batch.context_reverse)
    # without keep_context a reversed scene has none, as before
    lost = reverse_time(batch, torch.tensor([False, True]))
    assert lost.context_scene.tolist() == [0, 0] and lost.context_reverse is None


def test_augment_hands_back_no_reversed_context_and_draws_as_before():
    batch = _two_way_context_batch()
    kw = dict(flip=True, history_noise=0.05, drop_agents=0.3, reverse=True)
    kept = augment(batch, torch.Generator().manual_seed(4), reverse_context=True, **kw)
    plain = augment(batch.without_context(), torch.Generator().manual_seed(4), **kw)
    torch.testing.assert_close(kept.history, plain.history)  # the targets' draws unchanged
    torch.testing.assert_close(kept.future, plain.future)
    assert kept.context_reverse is None
    assert augment(batch, torch.Generator().manual_seed(4)).context_reverse is None
