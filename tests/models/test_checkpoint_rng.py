"""Loading a model leaves torch's global random stream where the caller seeded it
(walkthrough 67, finding 3): building the modules initialises them at random before their
weights are loaded, which moved a planner's ``torch.manual_seed`` stream by when it loaded."""

from __future__ import annotations

import pytest
import torch

from trajpref.models import checkpoint as ckpt
from trajpref.models.registry import load_predictor
from trajpref.score import TrajectoryScorer


def _draws_after(load) -> tuple[torch.Tensor, torch.Tensor]:
    """torch's draws after ``torch.manual_seed(7)``, without and with ``load()`` between."""
    torch.manual_seed(7)
    plain = torch.rand(4)
    torch.manual_seed(7)
    load()
    return plain, torch.rand(4)


@pytest.mark.parametrize(
    "load",
    [
        lambda: load_predictor("zara1/generator"),
        lambda: load_predictor("zara1/generator", sampler="full"),
        lambda: ckpt.load_predictor(ckpt.resolve_path("zara1/denoiser")),
        lambda: TrajectoryScorer.from_checkpoint("zara1/denoiser"),
        lambda: TrajectoryScorer.from_checkpoint("zara1/generator"),  # its embedded denoiser
    ],
    ids=["generator", "full-sampler", "denoiser-file", "scorer", "scorer-of-generator"],
)
def test_loading_draws_nothing_from_the_global_stream(load):
    plain, after = _draws_after(load)
    torch.testing.assert_close(after, plain, rtol=0, atol=0)


def test_loaded_weights_are_the_files_whatever_the_seed(tiny_run):
    path = tiny_run / "generator.safetensors"
    torch.manual_seed(1)
    a = ckpt.load_predictor(path)
    torch.manual_seed(2)
    b = ckpt.load_predictor(path)
    for (name, x), (_, y) in zip(a.state_dict().items(), b.state_dict().items(), strict=True):
        assert torch.equal(x, y), name
    plain, after = _draws_after(lambda: ckpt.load_predictor(path))
    torch.testing.assert_close(after, plain, rtol=0, atol=0)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no GPU")
def test_loading_onto_a_gpu_leaves_its_stream_too():
    torch.manual_seed(7)
    plain = torch.rand(4, device="cuda")
    torch.manual_seed(7)
    load_predictor("zara1/generator", device="cuda")
    TrajectoryScorer.from_checkpoint("zara1/denoiser", "cuda")
    torch.testing.assert_close(torch.rand(4, device="cuda"), plain, rtol=0, atol=0)
