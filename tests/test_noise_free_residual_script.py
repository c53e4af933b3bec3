"""benchmarks/noise_free_residual.py: the probe's settings each give a rank correlation and a
minFDE_5; a noise-free step draws no noise, so its residual does not depend on the seed."""

import torch
from bench import load_benchmark

from trajpref.data import load_dataset
from trajpref.data.loader import collate
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import TrajectoryScorer


def test_the_probe_reports_every_setting_and_the_score_free_selections(tiny_run, walks, capsys):
    probe = load_benchmark("noise_free_residual")
    out = probe.main(["--dataset", str(walks), "--model", str(tiny_run / "generator.safetensors"),
                      "--scenes", "6", "--samples", "4"])  # fmt: skip
    assert set(out) == {*probe.settings(), "facility", "first"}
    for key in probe.settings():
        assert -1 <= out[key]["rho"] <= 1 and out[key]["fde5"] > 0
    assert "n34" in capsys.readouterr().out


def test_a_noise_free_residual_ignores_the_scorers_seed(tiny_run, walks):
    probe = load_benchmark("noise_free_residual")
    model = load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")
    batch = collate(load_dataset(str(walks), "val").scenes[:3])
    pred = model.predict(batch, 4, torch.Generator().manual_seed(0))
    a, b = (TrajectoryScorer.from_checkpoint(tiny_run / "generator.safetensors", seed=s)
            for s in (0, 1))  # fmt: skip
    torch.testing.assert_close(probe.zero_residual(a, batch, pred, [5]),
                               probe.zero_residual(b, batch, pred, [5]))  # fmt: skip
    assert not torch.equal(a.with_steps([5]).residual(batch, pred),
                           b.with_steps([5]).residual(batch, pred))  # fmt: skip
