"""benchmarks/score_step_profile.py: its two rewrites of a denoiser pass compute that pass."""

import torch
from bench import load_benchmark

from trajpref.config import ModelConfig
from trajpref.models.denoiser import Denoiser

TINY = ModelConfig(hidden=16, heads=2, encoder_layers=1, denoiser_width=32, denoiser_blocks=2)


def _case():
    torch.manual_seed(0)
    den = Denoiser(TINY).eval()
    for p in den.parameters():  # away from LayerNorm's (1, 0) init, so the fold is exercised
        p.data.add_(0.1 * torch.randn_like(p))
    y = torch.randn(7, 5, TINY.t_fut, 2)  # [M, N, T_f, 2]
    context = torch.randn(5, TINY.hidden)  # [N, H]
    return den, y, context


@torch.no_grad()
def test_the_fused_pass_is_the_denoisers_up_to_rounding():
    profile = load_benchmark("score_step_profile")
    den, y, context = _case()
    for s in (0, 7):
        ref = den(y, s, context)
        fused = profile.fused_pass(den, y, s, context)
        assert fused.shape == ref.shape
        torch.testing.assert_close(fused, ref, rtol=1e-5, atol=1e-5)
    assert not torch.equal(profile.fused_pass(den, y, 0, context), den(y, 7, context))


@torch.no_grad()
def test_the_chunked_pass_is_the_denoisers():
    profile = load_benchmark("score_step_profile")
    den, y, context = _case()
    ref = den(y, 3, context)
    assert torch.equal(profile.chunked_pass(den, y, 3, context, 10), ref)  # one chunk: itself
    for chunk in (1, 3, 7):  # equal up to the kernel's blocking of few rows
        torch.testing.assert_close(profile.chunked_pass(den, y, 3, context, chunk), ref,
                                   rtol=1e-6, atol=1e-6)  # fmt: skip
