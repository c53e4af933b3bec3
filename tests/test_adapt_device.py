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


def test_a_model_on_another_device_is_the_clear_error_evaluate_gives(tiny_run, walks,
                                                                     monkeypatch):  # fmt: skip
    """The batches went to ``device`` wherever the model was: a crash inside the first
    prediction (or torch's 'not compiled with CUDA') instead of evaluate's one line."""
    from trajpref.adapt import adapt_and_predict

    model = load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")
    data = load_dataset(str(walks), "test")
    cfg = AdaptConfig(ctx_frames=40, steps=0)
    # a GPU this CPU machine pretends to have: the model stayed on the CPU
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(ConfigError, match=r"^adapt_and_predict\(device='cuda'\): the model's "
                       r"weights are on cpu: move it first, model\.to\('cuda'\)"):  # fmt: skip
        adapt_and_predict(model, data, cfg, num_samples=2, indices=[0], device="cuda")
    monkeypatch.undo()
    model.to("meta")  # weights nowhere this machine computes
    with pytest.raises(ConfigError, match=r"^adapt_and_predict\(device='cpu'\): the model's "
                       r"weights are on meta: move it first"):  # fmt: skip
        adapt_and_predict(model, data, cfg, num_samples=2, indices=[0], device="cpu")
    with pytest.raises(ConfigError, match=r"^adapt_and_predict: the model's weights are on "
                       r"meta, where it cannot run"):  # fmt: skip
        adapt_and_predict(model, data, cfg, num_samples=2, indices=[0])
