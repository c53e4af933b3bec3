"""predict --format trajnet: K = 2 refused before any model or data is read, naming the option
that set it; --rank writes the samples best first (prediction 0 the diffusion score's top-1)."""

import json

import numpy as np
import pytest

from trajpref.cli import main


@pytest.mark.parametrize(
    ("flags", "named"),
    [(["--samples", "2"], "--samples 2"), (["--samples", "5", "--keep", "2"], "--keep 2")],
)
def test_two_predictions_are_refused_before_the_model_is_read(tmp_path, capsys, flags, named):
    out = tmp_path / "p.ndjson"
    code = main(["predict", "--dataset", str(tmp_path / "no-data"), "--model",
                 str(tmp_path / "no-model.safetensors"), "--format", "trajnet", "--out", str(out),
                 *flags])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and named in err and "1 or at least 3 predictions" in err
    assert "no-model" not in err and "no-data" not in err  # neither was reached
    assert not out.exists()


def _points(path, k: int) -> set[tuple[float, float]]:
    """Every predicted (x, y) of prediction_number k in a TrajNet++ file, as float32."""
    found = set()
    for line in path.read_text().splitlines():
        row = json.loads(line).get("track")
        if row is not None and row.get("prediction_number") == k:
            found.add((float(np.float32(row["x"])), float(np.float32(row["y"]))))
    return found


def test_rank_writes_the_samples_best_first(tiny_run, walks, tmp_path, capsys):
    den = str(tiny_run / "denoiser.safetensors")
    common = ["predict", "--dataset", str(walks), "--model", "cv", "--scorer", den,
              "--samples", "5", "--no-progress"]  # fmt: skip
    ranked, plain = tmp_path / "r.ndjson", tmp_path / "u.ndjson"
    assert main([*common, "--rank", "--format", "trajnet", "--out", str(ranked)]) == 0
    assert "prediction_number 0 (TrajNet++'s Top-1) is its top-1" in capsys.readouterr().err
    assert main([*common, "--format", "trajnet", "--out", str(plain)]) == 0
    assert capsys.readouterr().err == ""  # no note without --rank
    assert main([*common, "--rank", "--out", str(tmp_path / "r.npz")]) == 0
    with np.load(tmp_path / "r.npz") as z:
        pred = z["pred"]  # [K, N, T_f, 2] each scene's samples best first
    for k in range(5):
        want = {(float(x), float(y)) for x, y in pred[k].reshape(-1, 2)}
        assert _points(ranked, k) == want
    assert _points(plain, 0) != _points(ranked, 0)  # the ranking moved some sample first
