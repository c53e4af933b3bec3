"""predict --format trajnet: K = 2 written (the evaluator then reports Top-1 alone); --rank
writes the samples best first (prediction 0 the diffusion score's top-1)."""

import json

import numpy as np

from trajpref.cli import main


def test_two_predictions_are_written(walks, tmp_path, capsys):
    # TrajNet++'s evaluator reads Top-3 only with more than two predictions: K = 2 gets Top-1
    out = tmp_path / "p.ndjson"
    code = main(["predict", "--dataset", str(walks), "--model", "cv", "--format", "trajnet",
                 "--out", str(out), "--no-progress", "--samples", "2"])  # fmt: skip
    assert code == 0, capsys.readouterr().err
    assert _points(out, 1) and not _points(out, 2)


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
