import pytest
import torch
from synthetic import make_scene

from trajpref.data.transforms import (
    augment,
    backward_velocity,
    from_relative,
    observed_pace,
    scene_speeds,
    speed_normaliser,
    to_relative,
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


def test_relative_roundtrip():
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    hist_rel, fut_rel = to_relative(batch)
    assert torch.equal(hist_rel[:, -1], torch.zeros(5, 2))
    torch.testing.assert_close(from_relative(fut_rel, batch), batch.future)


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
