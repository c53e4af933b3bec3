"""benchmarks/train_cost.py: the warm probe times a second epoch and books the first one's extra
time once; estimates of other settings never overwrite the defaults' file, whose entries say
how and where each was probed."""

import json

import pytest
from bench import load_benchmark


def test_a_warm_probe_times_the_second_epoch_and_books_the_first_ones_extra_time(tiny_cfg):
    cost = load_benchmark("train_cost")
    cold = cost.probe(tiny_cfg, "diffusion", None, steps=2, denoiser=None)
    warm = cost.probe(tiny_cfg, "diffusion", None, steps=2, denoiser=None, warm=1)
    warmer = cost.probe(tiny_cfg, "diffusion", None, steps=2, denoiser=None, warm=2)
    assert "warmup_seconds" not in cold and warm["warmup_seconds"] >= 0.0
    assert warmer["warmup_seconds"] >= 0.0
    for p in (cold, warm, warmer):
        assert p["rate"] > 0 and p["val_seconds"] > 0 and p["train_agents"] > 0


def test_a_budget_caps_the_estimate_and_its_validations_share_the_cut():
    cost = load_benchmark("train_cost")
    assert cost.guarded(1200.0, 60.0, None) == (1260.0, 1.0)  # no budget
    assert cost.guarded(1200.0, 60.0, 30.0) == (1260.0, 1.0)  # 20 of 30 minutes: not reached
    # 40 minutes of steps against 30: three quarters of the schedule, and of its validations
    assert cost.guarded(2400.0, 60.0, 30.0) == pytest.approx((1800.0 + 45.0, 0.75))


def test_evaluations_count_every_nth_epoch_and_the_last():
    cost = load_benchmark("train_cost")
    assert cost.evaluations(40, 5) == 8
    assert cost.evaluations(42, 5) == 9  # and once more after the last epoch


def test_other_settings_into_the_defaults_file_are_refused_before_anything_is_timed(
    monkeypatch, capsys
):
    cost = load_benchmark("train_cost")
    monkeypatch.setattr(cost, "estimate", lambda *a: pytest.fail("timed a stage"))
    monkeypatch.setattr("sys.argv", ["train_cost.py", "--datasets", "eth", "--set",
                                     "generator.epochs=80"])  # fmt: skip
    with pytest.raises(SystemExit, match="name --out"):
        cost.main()


def test_the_defaults_file_records_each_entrys_probe_and_machine_and_keeps_the_others(
    monkeypatch, capsys, tmp_path
):
    """The warm probe (the default) writes the defaults' file; a subset keeps the other
    datasets' entries with the date and machine of the run that measured them."""
    cost = load_benchmark("train_cost")
    out = tmp_path / "train_cost.json"
    monkeypatch.setattr(cost, "OUT", out)
    seen = []

    def fake(cfg, dataset, data_root, steps, warm):
        seen.append((dataset, tuple(steps), warm))
        return {"denoiser": {"minutes": 1.0}, "generator": {"minutes": 2.0}, "minutes": 3.0}

    monkeypatch.setattr(cost, "estimate", fake)
    out.write_text(json.dumps({"machine": "an older host", "date": "2026-11-01", "datasets": {
        "nba": {"minutes": 9.0}, "eth": {"minutes": 8.0}}}))  # fmt: skip
    monkeypatch.setattr("sys.argv", ["train_cost.py", "--datasets", "eth"])
    cost.main()
    assert seen == [("eth", (20, 60), 3)]  # the warm probe by default
    written = json.loads(out.read_text())["datasets"]
    assert written["eth"]["probe"] == {"warm": 3, "steps": [20, 60]}
    assert written["eth"]["machine"] == cost.machine() and "settings" not in written["eth"]
    assert written["nba"] == {"date": "2026-11-01", "machine": "an older host", "minutes": 9.0}


def test_the_printed_line_of_an_estimate_with_other_settings_names_only_the_stages():
    cost = load_benchmark("train_cost")
    entry = {"denoiser": {"minutes": 7.5}, "generator": {"minutes": 26.6}, "minutes": 34.1,
             "settings": {"set": ["data.reverse=true"], "warm": False}}  # fmt: skip
    assert cost._line(entry) == "D 7.5 + G 26.6 = 34.1 min"


def test_a_warmer_probe_times_the_last_epoch_and_books_every_earlier_ones_extra(
    monkeypatch, tiny_cfg
):
    cost = load_benchmark("train_cost")
    # three epochs of 5, 3 and 2 s of training (cumulative 5, 8, 10), validations 1.5, 1, 1 s
    records = [{"train_seconds": 5.0, "val_seconds": 1.5},
               {"train_seconds": 8.0, "val_seconds": 1.0},
               {"train_seconds": 10.0, "val_seconds": 1.0}]  # fmt: skip
    summary = {"samples_per_second": 100.0, "train_agents": 40}
    monkeypatch.setattr(cost, "train_stage", lambda *a, **k: summary)
    monkeypatch.setattr(cost, "read_metrics", lambda *a: records)
    p = cost.probe(tiny_cfg, "diffusion", None, steps=2, denoiser=None, warm=2)
    assert p["val_seconds"] == 1.0
    assert p["warmup_seconds"] == (5 - 2) + (1.5 - 1) + (3 - 2)  # 4.5 s, booked once
