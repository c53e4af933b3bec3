"""benchmarks/kernel_cache.py: each run's child gets its capacity; the ratio skips epoch 1."""

import json
import subprocess

import pytest
from bench import load_benchmark

import trajpref


def test_each_setting_reaches_its_child_and_the_ratio_uses_the_later_epochs(
    monkeypatch, tmp_path, capsys
):
    kc = load_benchmark("kernel_cache")
    seen = []

    def fake_run(cmd, env, **kwargs):
        capacity = int(env["ONEDNN_PRIMITIVE_CACHE_CAPACITY"])
        seen.append((cmd[-4], capacity))  # the stage argument, and the capacity
        # the first epoch is as slow under both; the later ones are 2 s against 1 s
        epochs = [9.0, 2.0, 2.0] if capacity == 1024 else [9.0, 1.0, 1.0]
        return subprocess.CompletedProcess(cmd, 0, stdout=f"log\n{json.dumps(epochs)}\n")

    monkeypatch.setattr(kc.subprocess, "run", fake_run)
    out = tmp_path / "kc.json"
    monkeypatch.setattr("sys.argv", ["kernel_cache.py", "--runs", "hotel:generator",
                                     "--repeats", "2", "--out", str(out)])  # fmt: skip
    kc.main()
    assert sorted(seen) == sorted([("generator", 1024), ("generator", 1024),
                                   ("generator", trajpref.ONEDNN_CACHE_CAPACITY),
                                   ("generator", trajpref.ONEDNN_CACHE_CAPACITY)])  # fmt: skip
    record = json.loads(out.read_text())
    assert record["runs"]["hotel:generator"]["speedup"] == 2.0
    assert "2.0x" in capsys.readouterr().out


def test_a_run_without_a_known_stage_is_refused(monkeypatch):
    kc = load_benchmark("kernel_cache")
    monkeypatch.setattr(kc.subprocess, "run", lambda *a, **k: pytest.fail("trained"))
    monkeypatch.setattr("sys.argv", ["kernel_cache.py", "--runs", "hotel:denoiser"])
    with pytest.raises(SystemExit, match="DATASET:diffusion"):
        kc.main()
