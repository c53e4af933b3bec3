"""benchmarks/winner_shares.py: which sample index is nearest the truth, and how often."""

import numpy as np
import pytest
from bench import load_benchmark


def test_shares_count_the_nearest_sample_and_skip_unobserved_futures():
    shares = load_benchmark("winner_shares")
    future = np.zeros((4, 3, 2))  # [N, T_f, 2]: every agent stays at the origin
    future[3, 1] = np.nan  # a future with a gap: not counted
    pred = np.ones((2, 4, 3, 2))  # [K, N, T_f, 2], both samples off by sqrt(2)
    pred[0, :2] = 0.0  # sample 0 is exact for agents 0 and 1
    pred[1, 2] = 0.0  # sample 1 for agent 2
    res = shares.winner_shares(pred, future)
    assert res["agents"] == 3
    assert np.allclose(res["fde_share"], [2 / 3, 1 / 3]) and np.allclose(
        res["ade_share"], [2 / 3, 1 / 3]
    )
    assert res["min_fde"] == pytest.approx(0.0)
    expected = -(2 / 3 * np.log2(2 / 3) + 1 / 3 * np.log2(1 / 3))
    assert res["fde_entropy_bits"] == pytest.approx(expected)
    # the shares do not depend on how far the losers are
    pred[1, :2] *= 10.0
    assert np.allclose(shares.winner_shares(pred, future)["fde_share"], [2 / 3, 1 / 3])


def test_the_study_takes_the_device_auto(tiny_run, tmp_path, monkeypatch, capsys):
    """``--device auto`` went to ``predictor.to`` as it was: a RuntimeError naming 'auto'."""
    import json
    import sys

    import torch

    shares = load_benchmark("winner_shares")
    monkeypatch.setattr(shares, "OUT", tmp_path)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    model = str(tiny_run / "generator.safetensors")
    monkeypatch.setattr(sys, "argv", ["winner_shares.py", "--models", model, "--device", "auto",
                                      "--samples", "2"])  # fmt: skip
    shares.main()
    rows = json.loads((tmp_path / "winner_shares_val.json").read_text())["rows"]
    assert [r["model"] for r in rows] == [model] and rows[0]["agents"] > 0
