"""benchmarks/ema_seeds.py: the paired raw-vs-averaged change of each run and its spread over
seeds, from hand-written metrics logs."""

import json
from pathlib import Path

import pytest
import yaml
from bench import load_benchmark


def _run(folder: Path, dataset: str, seed: int, rows: list[dict]) -> Path:
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(
        yaml.safe_dump({"data": {"dataset": dataset}, "seed": seed})
    )
    (folder / "generator_metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return folder


def _eval(epoch, raw_ade, raw_fde, ade, fde):
    return {"epoch": epoch, "val_raw_min_ade": raw_ade, "val_raw_min_fde": raw_fde,
            "val_min_ade": ade, "val_min_fde": fde}  # fmt: skip


def test_each_weight_set_keeps_its_own_best_epoch_by_ade_plus_fde(tmp_path):
    mod = load_benchmark("ema_seeds")
    run = _run(tmp_path / "a", "zara1", 0, [
        _eval(4, 0.20, 0.40, 0.19, 0.38),
        {"epoch": 5, "train_loss": 1.0},  # no validation this epoch
        # raw best here by ADE + FDE (0.55), though epoch 12 has the lower raw FDE
        _eval(8, 0.15, 0.40, 0.18, 0.37),
        _eval(12, 0.30, 0.30, 0.16, 0.36),
    ])  # fmt: skip
    got = mod.paired(run)
    assert got["raw"] == {"epoch": 8, "min_ade": 0.15, "min_fde": 0.40}
    assert got["averaged"] == {"epoch": 12, "min_ade": 0.16, "min_fde": 0.36}
    assert got["change_fde_pct"] == pytest.approx(-10.0)
    assert got["change_ade_pct"] == pytest.approx(100 * (0.16 / 0.15 - 1))
    assert (got["dataset"], got["seed"], got["epochs_done"]) == ("zara1", 0, 12)


def test_fold_mean_and_spread_and_the_keep_bar(tmp_path):
    mod = load_benchmark("ema_seeds")
    runs = [
        {"dataset": "zara1", "seed": 1, "change_fde_pct": -1.0, "change_ade_pct": -2.0},
        {"dataset": "zara1", "seed": 0, "change_fde_pct": -3.0, "change_ade_pct": 0.0},
        {"dataset": "eth", "seed": 0, "change_fde_pct": -0.4, "change_ade_pct": 1.0},
    ]
    folds = mod.by_fold(runs)
    assert folds["zara1"]["seeds"] == [0, 1]
    assert folds["zara1"]["change_fde_pct"] == [-3.0, -1.0]
    assert folds["zara1"]["mean_fde_pct"] == pytest.approx(-2.0)
    assert folds["zara1"]["std_fde_pct"] == pytest.approx(1.0)
    assert folds["zara1"]["replicates"] is True
    assert folds["eth"]["std_fde_pct"] == 0.0 and folds["eth"]["replicates"] is False


def test_a_run_without_raw_validation_or_a_repeated_seed_is_a_clear_error(tmp_path):
    mod = load_benchmark("ema_seeds")
    plain = _run(
        tmp_path / "plain", "eth", 0, [{"epoch": 4, "val_min_ade": 0.2, "val_min_fde": 0.3}]
    )
    with pytest.raises(SystemExit, match="ema_epochs > 0"):
        mod.paired(plain)
    with pytest.raises(SystemExit, match="no config.yaml"):
        mod.paired(tmp_path)
    twice = [{"dataset": "eth", "seed": 0, "change_fde_pct": 0.0, "change_ade_pct": 0.0}] * 2
    with pytest.raises(SystemExit, match="seed given twice"):
        mod.by_fold(twice)


def test_main_writes_the_record_with_each_runs_machine(tmp_path, capsys):
    mod = load_benchmark("ema_seeds")
    _run(tmp_path / "cpu" / "zara1", "zara1", 0, [_eval(4, 0.2, 0.4, 0.2, 0.38)])
    _run(tmp_path / "gpu" / "R-zara1-s1", "zara1", 1, [_eval(4, 0.2, 0.4, 0.2, 0.42)])
    out = tmp_path / "seeds.json"
    argv = [str(tmp_path / "cpu" / "zara1"), str(tmp_path / "gpu" / "R-zara1-s1"),
            "--machine", f"{tmp_path / 'cpu'}=a CPU", "--out", str(out)]  # fmt: skip
    assert mod.main(argv) == 0
    meta = json.loads(out.read_text())
    assert [r["train_machine"] for r in meta["runs"]] == ["a CPU", "not stated"]
    assert meta["folds"]["zara1"]["mean_fde_pct"] == pytest.approx(0.0)
    assert "| zara1 | 0: -5.00 %, 1: +5.00 % |" in capsys.readouterr().out
