import math

import pytest
import torch

from trajpref.config import GeneratorTrainConfig
from trajpref.errors import ConfigError
from trajpref.models.generator import GeneratorOutput
from trajpref.models.losses import generator_loss, soft_best, wta_temperature


def _case():
    """One agent, T_f = 2, K = 2 samples; the target stays at the origin.

    Sample 0 is off by 1 m at both steps (ADE 1, FDE 1); sample 1 is exact at the first
    step and off by 3 m at the last (ADE 1.5, FDE 3)."""
    target = torch.zeros(1, 2, 2)  # [N, T_f, 2]
    y = torch.tensor([[[1.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [0.0, 3.0]]])[:, None]  # [K,N,T_f,2]
    out = GeneratorOutput(
        mean=torch.zeros(1, 2, 2), log_sigma=torch.zeros(2, 1), shifts=torch.zeros(2, 1, 2, 2),
        context=torch.zeros(1, 4),
    )  # fmt: skip
    return out, y, target


def test_best_of_k_term_is_hand_computable():
    out, y, target = _case()
    only_best = dict(mean_weight=0.0, uncertainty_weight=0.0)
    loss, logs = generator_loss(out, y, target, GeneratorTrainConfig(**only_best))
    assert loss.item() == pytest.approx(2.0)  # min(1 + 1, 1.5 + 3)
    assert logs["best_of_k"] == pytest.approx(2.0)
    # a heavier endpoint: sample 0 still wins with 1 + 3 * 1 = 4 against 1.5 + 9
    loss, _ = generator_loss(out, y, target, GeneratorTrainConfig(fde_weight=3.0, **only_best))
    assert loss.item() == pytest.approx(4.0)
    # ADE alone: 1 against 1.5
    loss, _ = generator_loss(out, y, target, GeneratorTrainConfig(fde_weight=0.0, **only_best))
    assert loss.item() == pytest.approx(1.0)


def test_fde_weight_moves_the_choice_of_the_best_sample():
    out, _, target = _case()
    # sample 0: ADE 2, FDE 0 (back at the target); sample 1: ADE 0.5, FDE 1
    y = torch.tensor([[[4.0, 0.0], [0.0, 0.0]], [[0.0, 0.0], [1.0, 0.0]]])[:, None]
    y = y.requires_grad_(True)
    cfg = GeneratorTrainConfig(fde_weight=3.0, mean_weight=0.0, uncertainty_weight=0.0)
    loss, _ = generator_loss(out, y, target, cfg)
    assert loss.item() == pytest.approx(2.0)  # sample 0: 2 + 0 beats 0.5 + 3
    loss.backward()
    assert y.grad[1].abs().sum() == 0 and y.grad[0].abs().sum() > 0  # only the best learns


def test_fde_weight_must_not_be_negative():
    with pytest.raises(ConfigError, match="fde_weight must be >= 0"):
        GeneratorTrainConfig(fde_weight=-1.0)


def test_decreasing_time_weights_favour_the_sample_right_at_first():
    out, y, target = _case()
    # T_f = 2: weights (2, 1) / 1.5. Sample 0: (2*1 + 1*1) / 3 = 1; sample 1: (2*0 + 1*3) / 3 = 1
    cfg = GeneratorTrainConfig(time_weights="decreasing", fde_weight=0.0, mean_weight=0.0,
                               uncertainty_weight=0.0)  # fmt: skip
    loss, _ = generator_loss(out, y, target, cfg)
    assert loss.item() == pytest.approx(1.0)
    # a sample exact at the first step and off by 2 m at the last: uniform 1.0, decreasing 2/3
    y2 = torch.tensor([[[1.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [0.0, 2.0]]])[:, None]
    loss, _ = generator_loss(out, y2, target, cfg)
    assert loss.item() == pytest.approx(2.0 / 3.0)
    uniform = GeneratorTrainConfig(fde_weight=0.0, mean_weight=0.0, uncertainty_weight=0.0)
    assert generator_loss(out, y2, target, uniform)[0].item() == pytest.approx(1.0)
    with pytest.raises(ConfigError, match="time_weights"):
        GeneratorTrainConfig(time_weights="increasing")


def test_annealed_best_of_k_is_hand_computable_and_reaches_every_sample():
    out, y, target = _case()
    y = y.clone().requires_grad_(True)
    only_best = GeneratorTrainConfig(mean_weight=0.0, uncertainty_weight=0.0)
    # distances 2 and 4.5; at temperature 1 the softmin weights are 1 / (1 + e^-2.5) and the rest
    w0 = 1.0 / (1.0 + math.exp(-2.5))
    loss, _ = generator_loss(out, y, target, only_best, temperature=1.0)
    assert loss.item() == pytest.approx(w0 * 2.0 + (1.0 - w0) * 4.5)
    loss.backward()
    assert y.grad[1].abs().sum() > 0  # the losing sample learns too
    # temperature 0 is the hard minimum, where only the winner learns
    y.grad = None
    loss, _ = generator_loss(out, y, target, only_best, temperature=0.0)
    assert loss.item() == pytest.approx(2.0)
    loss.backward()
    assert y.grad[1].abs().sum() == 0


def test_soft_best_tends_to_the_minimum_and_to_the_mean():
    d = torch.tensor([[1.0, 5.0], [3.0, 2.0], [2.0, 8.0]])  # [K, N]
    assert torch.allclose(soft_best(d, 0.0), torch.tensor([1.0, 2.0]))
    assert torch.allclose(soft_best(d, 1e-3), torch.tensor([1.0, 2.0]))
    assert torch.allclose(soft_best(d, 1e6), d.mean(0), atol=1e-4)


def test_wta_temperature_decays_geometrically_then_is_hard():
    c = GeneratorTrainConfig(wta_temperature=2.0, wta_anneal=0.5)
    assert wta_temperature(c, 0.0) == pytest.approx(2.0)
    assert wta_temperature(c, 0.25) == pytest.approx(2.0 * 1e-3**0.5)  # halfway: sqrt(1e-3)
    assert wta_temperature(c, 0.5) == 0.0 and wta_temperature(c, 0.9) == 0.0
    assert wta_temperature(GeneratorTrainConfig(), 0.0) == 0.0  # off by default


@pytest.mark.parametrize("field, value, match", [
    ("wta_temperature", -1.0, "wta_temperature must be >= 0"),
    ("wta_anneal", 0.0, "wta_anneal must lie in"),
    ("wta_anneal", 1.5, "wta_anneal must lie in"),
])  # fmt: skip
def test_wta_settings_are_checked(field, value, match):
    with pytest.raises(ConfigError, match=match):
        GeneratorTrainConfig(**{field: value})


def test_separate_winners_train_the_path_and_the_endpoint_on_different_samples():
    out, _, target = _case()
    # sample 0: ADE 2.25, FDE 0.5; sample 1: ADE 0.5, FDE 1
    y = torch.tensor([[[4.0, 0.0], [0.5, 0.0]], [[0.0, 0.0], [1.0, 0.0]]])[:, None]
    y = y.requires_grad_(True)
    cfg = GeneratorTrainConfig(winner="separate", mean_weight=0.0, uncertainty_weight=0.0)
    loss, _ = generator_loss(out, y, target, cfg)
    assert loss.item() == pytest.approx(0.5 + 0.5)  # min ADE (sample 1) + min FDE (sample 0)
    loss.backward()
    assert y.grad[1, 0, 1].abs().sum() > 0  # the path's winner learns its path
    assert y.grad[0, 0, 1].abs().sum() > 0  # the endpoint's winner learns its endpoint ...
    assert y.grad[0, 0, 0].abs().sum() == 0  # ... and nothing before it
    joint = GeneratorTrainConfig(mean_weight=0.0, uncertainty_weight=0.0)
    assert generator_loss(out, y, target, joint)[0].item() == pytest.approx(1.5)  # 0.5 + 1
    cfg3 = GeneratorTrainConfig(winner="separate", fde_weight=3.0, mean_weight=0.0,
                                uncertainty_weight=0.0)  # fmt: skip
    assert generator_loss(out, y, target, cfg3)[0].item() == pytest.approx(0.5 + 1.5)
    with pytest.raises(ConfigError, match="winner"):
        GeneratorTrainConfig(winner="both")


def _partial_case():
    """Two agents, T_f = 3, K = 2. Agent 0 is seen at all 3 steps; agent 1 left the view
    after 2 steps (NaN at step 3). The targets stay at the origin."""
    target = torch.zeros(2, 3, 2)  # [N, T_f, 2]
    target[1, 2] = float("nan")
    y = torch.zeros(2, 2, 3, 2)  # [K, N, T_f, 2]
    y[0, :, :, 0] = 1.0  # sample 0: 1 m off at every step, both agents
    y[1, :, 1, 1] = 2.0  # sample 1: exact at step 1, 2 m off at step 2 ...
    y[1, :, 2, 1] = 9.0  # ... and 9 m off at step 3 (agent 1 was not seen there)
    out = GeneratorOutput(mean=torch.zeros(2, 3, 2), log_sigma=torch.zeros(2, 2),
                          shifts=torch.zeros(2, 2, 3, 2), context=torch.zeros(2, 4))  # fmt: skip
    return out, y, target


def test_a_target_that_left_the_view_is_scored_on_its_seen_steps():
    out, y, target = _partial_case()
    cfg = GeneratorTrainConfig(mean_weight=0.0, uncertainty_weight=0.0)
    y = y.requires_grad_(True)
    loss, logs = generator_loss(out, y, target, cfg)
    # agent 0: sample 0 ADE 1 + FDE 1 = 2 against (0 + 2 + 9) / 3 + 9; agent 1 over its two
    # seen steps: sample 0 gives 1 + 1 (endpoint: step 2) = 2, sample 1 (0 + 2) / 2 + 2 = 3
    assert loss.item() == pytest.approx(2.0)
    assert logs["best_of_k"] == pytest.approx(2.0)
    loss.backward()
    assert torch.isfinite(y.grad).all()
    assert y.grad[:, 1, 2].abs().sum() == 0  # the unseen step teaches nothing
    # the same as the loss of agent 1 alone, cut to its two seen steps
    alone, _ = generator_loss(GeneratorOutput(out.mean[1:, :2], out.log_sigma[:, 1:],
                                              out.shifts[:, 1:, :2], out.context[1:]),
                              y.detach()[:, 1:, :2], target[1:, :2], cfg)  # fmt: skip
    assert alone.item() == pytest.approx(2.0)


def test_the_mean_and_eq4_terms_average_over_seen_steps_only():
    out, y, target = _partial_case()
    cfg = GeneratorTrainConfig(best_of_k_weight=0.0, mean_weight=0.0, uncertainty_weight=0.0,
                               reg_weight=1.0)  # fmt: skip
    _, logs = generator_loss(out, y, target, cfg)
    # squared errors per seen (sample, agent, step): sample 0 1 at each of 5 seen steps;
    # sample 1 0, 4, 81 (agent 0) and 0, 4 (agent 1): (5 + 89) / 10
    assert logs["eq4"] == pytest.approx(9.4)
    assert logs["mean_ade"] == pytest.approx(0.0)
    full = target.clone()
    full[1, 2] = 0.0
    _, logs_full = generator_loss(out, y, full, cfg)
    assert logs_full["eq4"] == pytest.approx((6 + 85 + 85) / 12)  # step 3 counted when seen


def test_unseen_steps_must_come_after_the_seen_ones():
    out, y, target = _partial_case()
    target[1] = 0.0
    target[1, 1] = float("nan")  # seen, unseen, seen: not an agent that left the view
    with pytest.raises(ValueError, match="seen steps must be its first ones"):
        generator_loss(out, y, target, GeneratorTrainConfig())
    target[1] = float("nan")  # never seen
    with pytest.raises(ValueError, match="at least one"):
        generator_loss(out, y, target, GeneratorTrainConfig())
