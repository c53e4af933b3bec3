"""What the evaluation pass checks of a predictor's output (``check_prediction``) and which
devices it takes (``resolve_device``): a researcher's own predictor that returns another number
of samples than asked, NaN, a numpy array, ... is refused with its class named, and never
scored in silence (minADE over 100 samples reported as minADE_20)."""

import numpy as np
import pytest
import torch
from synthetic import make_scene

from trajpref.errors import ConfigError, DataError, TrajprefError
from trajpref.evaluation import PredictionError, evaluate, predict_dataset, sampled_batches
from trajpref.models.baseline import ConstantVelocity
from trajpref.score.selection import SelectingPredictor, SelectionConfig
from trajpref.types import DatasetInfo, TrajectoryDataset

DATA = TrajectoryDataset([make_scene(3, seed=i) for i in range(4)],
                         DatasetInfo("toy", "test", "m", 0.4))  # fmt: skip


class Mangled:
    """Constant velocity's samples, passed through ``fn(pred, batch, k)``."""

    name = "mangled"

    def __init__(self, fn) -> None:
        self.fn, self.base = fn, ConstantVelocity()

    def predict(self, batch, num_samples, generator=None):
        return self.fn(self.base.predict(batch, num_samples, generator), batch, num_samples)


def _nan(p, b, k):
    p[1, 4, 7, 0] = float("nan")  # sample 1 of agent 4: scene 1's second agent
    return p


CASES = {
    "more samples": (lambda p, b, k: torch.cat([p, p]),
                     r"Mangled\.predict returned shape \[6, 12, 12, 2\] .* it gave 6 samples "
                     r"where evaluate asked for K = 3"),
    "fewer samples": (lambda p, b, k: p[:1], r"it gave 1 samples where evaluate asked for K = 3"),
    "[N, K, T_f, 2]": (lambda p, b, k: p.transpose(0, 1),
                       r"looks like \[N, K, T_f, 2\]: put the samples first"),
    "no sample axis": (lambda p, b, k: p[0], r"the sample axis is missing"),
    "T_f 8": (lambda p, b, k: p[:, :, :8], r"gave 8 future steps where the batch's future has 12"),
    "xyz": (lambda p, b, k: torch.cat([p, p[..., :1]], -1), r"last axis holds 3 coordinates"),
    "numpy": (lambda p, b, k: p.numpy(), r"returned a numpy array.*torch\.from_numpy"),
    "list": (lambda p, b, k: p.tolist(), r"returned list, not a torch tensor"),
    "None": (lambda p, b, k: None, r"returned NoneType, not a torch tensor"),
    "int64": (lambda p, b, k: p.long(), r"dtype int64: positions must be floating point"),
    "meta": (lambda p, b, k: p.to("meta"), r"tensor on meta, the batch is on cpu"),
    "NaN": (_nan, r"returned NaN values \(1 of 36 agent-samples; the first: sample 1 of agent 4 "
                  r"in this batch, of scene synthetic#1\)"),
    "inf": (lambda p, b, k: p.index_fill_(1, torch.tensor([0]), float("inf")),
            r"returned infinite values"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(CASES))
def test_a_wrong_prediction_is_refused_naming_the_predictors_class(case):
    fn, message = CASES[case]
    with pytest.raises(PredictionError, match=message) as err:
        evaluate(Mangled(fn), DATA, num_samples=3, progress=False)
    assert isinstance(err.value, DataError) and isinstance(err.value, TrajprefError)
    assert str(err.value).startswith("Mangled.predict returned")


def test_predict_dataset_and_the_pass_itself_check_it_too():
    more = Mangled(lambda p, b, k: torch.cat([p, p]))
    with pytest.raises(PredictionError, match="gave 6 samples"):
        predict_dataset(more, DATA, num_samples=3, progress=False)
    with pytest.raises(PredictionError, match="gave 6 samples"):
        next(sampled_batches(more, DATA, 3, progress=False))


def test_what_the_interface_allows_still_passes():
    """Another floating dtype is scored; the library's own predictors pass, a selector's K'
    samples included (evaluate asks it for K' = cfg.keep, as the CLI's --keep does)."""
    ref = evaluate(ConstantVelocity(), DATA, num_samples=3, progress=False)
    double = evaluate(Mangled(lambda p, b, k: p.double()), DATA, num_samples=3, progress=False)
    assert double["min_ade"] == pytest.approx(ref["min_ade"], rel=1e-6)
    for method in ("first", "random", "facility"):
        sel = SelectingPredictor(ConstantVelocity(), SelectionConfig(keep=2, method=method), 5)
        out = evaluate(sel, DATA, num_samples=2, progress=False)
        assert np.isfinite(out["min_ade"])
        arrays = predict_dataset(sel, DATA, num_samples=2, progress=False)
        assert arrays["pred"].shape == (2, 12, 12, 2)


def test_the_trained_generator_passes_with_and_without_a_selection(tiny_run, walks):
    from trajpref.data import load_dataset
    from trajpref.models.checkpoint import load_predictor

    model = load_predictor(tiny_run / "generator.safetensors")
    data = load_dataset(str(walks), "test")
    assert np.isfinite(evaluate(model, data, num_samples=4, progress=False)["min_ade"])
    sel = SelectingPredictor(model, SelectionConfig(keep=2, method="facility"), 4)
    assert np.isfinite(evaluate(sel, data, num_samples=2, progress=False)["min_ade"])


def test_device_names_are_resolved_as_load_predictor_resolves_them(monkeypatch):
    """device='auto' crashed in Batch.to with a raw RuntimeError; 'cuda' on a machine without
    a GPU raised torch's own error from inside a predictor."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    ref = evaluate(ConstantVelocity(), DATA, num_samples=3, progress=False)
    for device in ("auto", "cpu", torch.device("cpu")):
        assert evaluate(ConstantVelocity(), DATA, 3, device=device, progress=False) == ref
    got = predict_dataset(ConstantVelocity(), DATA, 3, device="auto", progress=False)
    assert got["pred"].shape == (3, 12, 12, 2)
    for call in (evaluate, predict_dataset):
        with pytest.raises(ConfigError, match="device 'cuda' requested but no CUDA GPU"):
            call(ConstantVelocity(), DATA, 3, device="cuda", progress=False)
        with pytest.raises(ConfigError, match="unknown device 'gpu'"):
            call(ConstantVelocity(), DATA, 3, device="gpu", progress=False)
