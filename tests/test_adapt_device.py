"""In-context evaluation takes a device as the rest of the library does
(``trajpref.device.resolve_device``): ``auto`` was a raw RuntimeError from ``torch.device``."""

import pytest
import torch

from trajpref.adapt import AdaptConfig, evaluate_in_context
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.models.registry import load_predictor


def test_auto_and_a_missing_gpu(tiny_run, walks, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    model = load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")
    data = load_dataset(str(walks), "test")
    cfg = AdaptConfig(ctx_frames=40, steps=0)
    ref = evaluate_in_context(model, data, cfg, num_samples=2, indices=[0, 1])
    got = evaluate_in_context(model, data, cfg, num_samples=2, indices=[0, 1], device="auto")
    assert got["min_ade"] == ref["min_ade"]
    with pytest.raises(ConfigError, match="device 'cuda' requested but no CUDA GPU"):
        evaluate_in_context(model, data, cfg, num_samples=2, indices=[0], device="cuda")
