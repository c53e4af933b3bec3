import pytest
import torch

from trajpref.metrics import (
    MetricAccumulator,
    joint_min_ade_fde,
    min_ade_fde,
)


def _pred_with_x_errors(errors: list[list[list[float]]]) -> tuple[torch.Tensor, torch.Tensor]:
    """errors [K][N][T_f] along x on a zero ground truth -> (pred [K,N,T_f,2], future)."""
    e = torch.tensor(errors)  # [K, N, T_f]
    pred = torch.stack([e, torch.zeros_like(e)], -1)  # [K, N, T_f, 2]
    return pred, torch.zeros(pred.shape[1:])


def test_per_agent_ade_and_fde_pick_their_own_best_sample():
    # one agent, K=2: sample 0 errors (0, 4) -> ADE 2, FDE 4; sample 1 (3, 2) -> ADE 2.5, FDE 2
    pred, fut = _pred_with_x_errors([[[0.0, 4.0]], [[3.0, 2.0]]])
    ade, fde = min_ade_fde(pred, fut)
    assert ade.tolist() == [2.0]
    assert fde.tolist() == [2.0]


def test_joint_differs_from_per_agent():
    # two agents in one scene. sample 0: agent0 exact, agent1 off by 2.
    # sample 1: agent0 off by 1, agent1 exact.
    pred, fut = _pred_with_x_errors([[[0, 0], [2, 2]], [[1, 1], [0, 0]]])
    ade, fde = min_ade_fde(pred, fut)
    assert ade.tolist() == [0.0, 0.0] and fde.tolist() == [0.0, 0.0]
    scene = torch.tensor([0, 0])
    jade, jfde = joint_min_ade_fde(pred, fut, scene, 1)
    assert jade.tolist() == [0.5]  # min over k of (0+2)/2 and (1+0)/2
    assert jfde.tolist() == [0.5]


def test_joint_equals_per_agent_when_every_scene_has_one_agent():
    pred, fut = _pred_with_x_errors([[[0, 4], [1, 1]], [[3, 2], [0.5, 0.5]]])
    scene = torch.tensor([0, 1])
    ade, fde = min_ade_fde(pred, fut)
    jade, jfde = joint_min_ade_fde(pred, fut, scene, 2)
    assert torch.equal(ade, jade) and torch.equal(fde, jfde)


def test_euclidean_not_squared():
    pred = torch.tensor([[[[3.0, 4.0]]]])  # [1, 1, 1, 2]
    ade, fde = min_ade_fde(pred, torch.zeros(1, 1, 2))
    assert ade.item() == pytest.approx(5.0) and fde.item() == pytest.approx(5.0)


def test_accumulator_averages_agents_and_scenes_separately():
    acc = MetricAccumulator()
    # batch 1: one scene of two agents (per-agent min 0, joint 0.5)
    pred, fut = _pred_with_x_errors([[[0, 0], [2, 2]], [[1, 1], [0, 0]]])
    acc.update(pred, fut, torch.tensor([0, 0]), 1)
    # batch 2: one scene of one agent with error 3 everywhere
    pred, fut = _pred_with_x_errors([[[3, 3]], [[3, 3]]])
    acc.update(pred, fut, torch.tensor([0]), 1)
    out = acc.compute()
    assert out["agents"] == 3 and out["scenes"] == 2
    assert out["min_ade"] == pytest.approx(1.0)  # (0 + 0 + 3) / 3 agents
    assert out["joint_min_ade"] == pytest.approx(1.75)  # (0.5 + 3) / 2 scenes


def test_bad_shapes_raise_clear_errors():
    with pytest.raises(ValueError, match=r"\[K, N, T_f, 2\]"):
        min_ade_fde(torch.zeros(3, 12, 2), torch.zeros(3, 12, 2))
    with pytest.raises(ValueError, match="does not match"):
        min_ade_fde(torch.zeros(2, 3, 12, 2), torch.zeros(3, 8, 2))
    with pytest.raises(ValueError, match="at least one agent"):
        joint_min_ade_fde(torch.zeros(2, 1, 12, 2), torch.zeros(1, 12, 2), torch.tensor([1]), 2)
