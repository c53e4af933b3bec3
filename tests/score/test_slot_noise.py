"""The score's noise per agent slot does not depend on the batch (docs/score.md, "Common random
numbers"), at any number of score steps."""

import torch

from trajpref.score.scorer import TrajectoryScorer, _join, slot_noise


def test_a_slots_draw_is_the_same_whatever_the_number_of_slots():
    for shape in ((1, 1, 12, 2), (2, 1, 12, 2), (3, 5, 12, 2), (1, 1, 1, 3)):
        gen = lambda: torch.Generator().manual_seed(7)  # noqa: E731
        one, many = slot_noise(1, shape, gen()), slot_noise(6, shape, gen())  # [rows, *shape]
        assert one.shape == (1, *shape) and many.shape == (6, *shape)
        torch.testing.assert_close(many[:1], one, rtol=0, atol=0)


def test_a_multiple_of_16_values_draws_the_plain_numbers():
    shape = (2, 1, 12, 2)  # 48 values: two score steps
    plain = torch.randn((4, *shape), generator=torch.Generator().manual_seed(3))
    assert torch.equal(slot_noise(4, shape, torch.Generator().manual_seed(3)), plain)


@torch.no_grad()
def test_one_step_scores_a_scene_alone_as_beside_a_larger_one():
    scorer = TrajectoryScorer.from_checkpoint("zara1/denoiser")
    gen = torch.Generator().manual_seed(0)
    a = torch.cumsum(0.4 + 0.05 * torch.randn(1, 8, 2, generator=gen), 1)  # [1, T_h, 2]
    b = 50 + torch.cumsum(0.4 + 0.05 * torch.randn(3, 8, 2, generator=gen), 1)  # [3, T_h, 2]
    fa = a[None, :, -1:] + 0.3 * torch.randn(5, 1, 12, 2, generator=gen).cumsum(2)
    fb = b[None, :, -1:] + 0.3 * torch.randn(5, 3, 12, 2, generator=gen).cumsum(2)
    kinds = lambda h: torch.zeros(len(h), dtype=torch.int64)  # noqa: E731
    for steps in ([0], [0, 3], [0, 3, 6]):
        s = scorer.with_steps(steps)
        alone = s.residual(_join([(a, kinds(a), None)], 12), fa)  # [M, 1, T_f]
        both = s.residual(_join([(a, kinds(a), None), (b, kinds(b), None)], 12),
                          torch.cat([fa, fb], 1))[:, :1]  # fmt: skip
        torch.testing.assert_close(both, alone, rtol=1e-4, atol=1e-4)
