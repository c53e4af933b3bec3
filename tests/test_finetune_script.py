"""benchmarks/finetune.py: a run folder is never resumed or reused from another start."""

from pathlib import Path

import pytest
from bench import load_benchmark

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def ft(monkeypatch):
    module = load_benchmark("finetune")
    hashes = {"a.safetensors": "aaaa", "b.safetensors": "bbbb"}
    monkeypatch.setattr(module.ckpt, "load", lambda path: {"hash": hashes[Path(path).name]})
    return module


def test_a_run_folder_remembers_its_start_and_refuses_another(ft, tmp_path):
    run = tmp_path / "zara1-rlhf-s0"
    ft.check_start(run, tmp_path / "a.safetensors")  # a new run: records its start
    (run / "finetune_last.pt").write_text("state")
    ft.check_start(run, tmp_path / "a.safetensors")  # resuming from the same start is fine
    with pytest.raises(SystemExit, match="was started from"):
        ft.check_start(run, tmp_path / "b.safetensors")


def test_an_unrecorded_old_run_folder_is_not_reused(ft, tmp_path):
    run = tmp_path / "zara1-rlhf-s0"
    run.mkdir()
    (run / "finetune.safetensors").write_text("old model")
    with pytest.raises(SystemExit, match="no record of its start"):
        ft.check_start(run, tmp_path / "a.safetensors")
