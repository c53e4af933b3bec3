"""benchmarks/gpu_sweep/ and benchmarks/sweep_summary.py: the leave-one-out folders rebuilt from
the pool of distinct files, and the validation summary of a sweep's runs."""

import json
import shutil
import subprocess
from pathlib import Path

import pytest
from bench import load_benchmark

ROOT = Path(__file__).resolve().parent.parent


def _summary_module():
    module = load_benchmark("sweep_summary")
    return module


def _log(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))


def test_summary_keeps_the_best_kept_and_last_validation_and_marks_skipped_jobs(tmp_path):
    runs = tmp_path / "runs"
    (runs).mkdir()
    (runs / "jobs.txt").write_text(
        "# name fold epochs every seed\n"
        "A zara1 8 4 0\n"
        "B hotel 8 4 1 generator.lr=0.002 data.max_agents=256\n"
    )
    _log(runs / "A" / "generator_metrics.jsonl", [
        {"epoch": 4, "train_seconds": 10.0, "val_min_ade": 0.3, "val_min_fde": 0.5,
         "val_score": 0.8},
        {"epoch": 6, "train_seconds": 15.0},
        {"epoch": 8, "train_seconds": 20.0, "val_min_ade": 0.31, "val_min_fde": 0.55,
         "val_score": 0.86},
        {"epoch": 12, "train_seconds": 30.0, "val_min_ade": 0.2, "val_min_fde": 0.52,
         "val_score": 0.72},
    ])  # fmt: skip
    out = tmp_path / "sweep.json"
    assert _summary_module().main([str(runs), "--gpu", "a GPU", "--out", str(out)]) == 0
    meta = json.loads(out.read_text())
    a, b = meta["runs"]
    assert meta["train_machine"] == "a GPU" and meta["split"] == "val"
    assert a["best"] == {"epoch": 4, "min_ade": 0.3, "min_fde": 0.5}  # the lowest minFDE
    assert a["kept"] == {"epoch": 12, "min_ade": 0.2, "min_fde": 0.52}  # the lowest sum
    assert a["last"]["epoch"] == 12 and a["train_seconds"] == 30.0 and a["epochs_done"] == 12
    assert b["skipped"] is True and b["seed"] == 1
    assert b["overrides"] == ["generator.lr=0.002", "data.max_agents=256"]


def test_summary_says_where_the_jobs_file_should_be(tmp_path, capsys):
    with pytest.raises(SystemExit):
        _summary_module().main([str(tmp_path), "--gpu", "g", "--out", str(tmp_path / "o.json")])
    assert "unpack the sweep's meta.tgz" in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash")
def test_unpack_rebuilds_each_fold_without_its_own_scenes(tmp_path):
    repo = tmp_path / "repo"
    (repo / "benchmarks" / "gpu_sweep").mkdir(parents=True)
    shutil.copy(
        ROOT / "benchmarks" / "gpu_sweep" / "unpack_data.sh", repo / "benchmarks" / "gpu_sweep"
    )
    pool = repo / ".gpu" / "pool"
    pool.mkdir(parents=True)
    (repo / ".gpu" / "sdd").mkdir()
    (repo / ".gpu" / "sdd" / "train.npz").write_bytes(b"x")
    (repo / ".gpu" / "robo").mkdir()
    (repo / ".gpu" / "robo" / "val.npz").write_bytes(b"x")  # Robo's test split never travels
    scenes = ("biwi_eth", "biwi_hotel", "students001", "students003", "uni_examples",
              "crowds_zara01", "crowds_zara02", "crowds_zara03")  # fmt: skip
    for s in scenes:
        for split in ("train", "val"):
            (pool / f"{s}_{split}.txt").write_text("0 1 0.0 0.0\n")
    out = tmp_path / "data"
    subprocess.run(["bash", str(repo / "benchmarks" / "gpu_sweep" / "unpack_data.sh"), str(out)],
                   check=True)  # fmt: skip
    univ = sorted(p.name for p in (out / "eth_ucy" / "univ" / "train").iterdir())
    assert "students001_train.txt" not in univ and "students003_train.txt" not in univ
    assert len(univ) == 6 and "uni_examples_train.txt" in univ
    eth_val = sorted(p.name for p in (out / "eth_ucy" / "eth" / "val").iterdir())
    assert len(eth_val) == 7 and "biwi_eth_val.txt" not in eth_val
    assert (out / "sdd" / "train.npz").is_file()
    assert [p.name for p in (out / "robo").iterdir()] == ["val.npz"]
