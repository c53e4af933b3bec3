"""The set-aware reward: it prefers a diverse set to copies of its best sample, and a
sample's gain falls when another sample already covers it."""

import torch

from trajpref.rl.set_reward import marginal_gains, set_log_det


def test_a_diverse_set_beats_copies_of_its_best_sample():
    g = torch.Generator().manual_seed(0)
    ends = torch.randn(6, 3, 2, generator=g)  # [K, N, 2]
    quality = torch.randn(6, 3, generator=g)
    best = quality.argmax(0)  # [N]
    copies = ends[best, torch.arange(3)][None].expand(6, -1, -1)  # K copies of the best
    assert (set_log_det(ends, quality) > set_log_det(copies, quality) + 5).all()


def test_gains_reward_novelty_and_quality():
    ends = torch.tensor([[[0.0, 0.0]], [[0.0, 0.01]], [[3.0, 0.0]], [[0.0, 3.0]]])  # [4, 1, 2]
    flat = torch.zeros(4, 1)
    gain = marginal_gains(ends, flat)[:, 0]
    assert gain[2] > gain[0] and gain[3] > gain[1]  # the near-duplicates add little
    better = torch.tensor([[0.0], [0.0], [2.0], [0.0]])  # sample 2 is more plausible
    assert marginal_gains(ends, better)[2, 0] > gain[2]
