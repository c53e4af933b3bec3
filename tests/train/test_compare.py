"""Runs compared side by side: kept epochs, seed means and spreads, curves at equal shares."""

from __future__ import annotations

import dataclasses
import json
import statistics
from pathlib import Path

import pytest

from trajpref.cli import main
from trajpref.config import ExperimentConfig, save_config
from trajpref.errors import TrajprefError
from trajpref.train import compare


def _run(path: Path, epochs: int, curve: dict[int, tuple[float, float]], config=True) -> Path:
    """A run folder: a training row every epoch, validation at ``curve``'s epochs, whose
    ``val_score`` is minADE + minFDE as the generator stage logs it."""
    path.mkdir(parents=True)
    rows = []
    for epoch in range(1, epochs + 1):
        row = {"epoch": epoch, "train_loss": 1.0 / epoch}
        if epoch in curve:
            ade, fde = curve[epoch]
            row |= {"val_min_ade": ade, "val_min_fde": fde, "val_score": ade + fde}
        rows.append(json.dumps(row))
    (path / "generator_metrics.jsonl").write_text("\n".join(rows) + "\n")
    if config:
        cfg = ExperimentConfig()
        cfg.generator.epochs = epochs
        save_config(cfg, path / "config.yaml")
    return path


def test_the_kept_epoch_is_the_lowest_validation_score_not_the_lowest_fde(tmp_path):
    curve = {2: (0.30, 0.50), 4: (0.20, 0.45), 6: (0.25, 0.44), 8: (0.22, 0.46)}
    run = _run(tmp_path / "a", 8, curve)
    curve = compare.read_curve(run, "generator", ("val_min_ade", "val_min_fde"))
    assert curve.kept == 4  # 0.65 < 0.68 (epoch 8) < 0.69 (epoch 6), though 6 has the lower FDE
    assert curve.epochs == 8 and list(curve.points) == [2, 4, 6, 8]
    assert curve.at(6) == {"val_min_ade": 0.25, "val_min_fde": 0.44}


def test_group_means_spreads_and_changes_are_the_hand_computed_ones(tmp_path):
    a = _run(tmp_path / "a", 4, {2: (0.20, 0.40), 4: (0.21, 0.41)})
    b = _run(tmp_path / "b", 4, {2: (0.22, 0.44), 4: (0.23, 0.46)})
    c = _run(tmp_path / "c", 4, {2: (0.25, 0.42), 4: (0.19, 0.38)})
    metrics = ("val_min_ade", "val_min_fde")
    groups = {
        "control": [compare.read_curve(r, "generator", metrics) for r in (a, b)],
        "candidate": [compare.read_curve(c, "generator", metrics)],
    }
    out = compare.summarise(groups, metrics)
    control = out["control"]
    assert control["mean"]["val_min_fde"] == pytest.approx(0.42)  # kept epochs 2 and 2
    assert control["sd"]["val_min_fde"] == pytest.approx(statistics.stdev([0.40, 0.44]))
    assert control["change"]["val_min_fde"] == pytest.approx(0.0)
    candidate = out["candidate"]
    assert candidate["runs"][0]["kept_epoch"] == 4 and candidate["sd"]["val_min_fde"] is None
    assert candidate["change"]["val_min_fde"] == pytest.approx(0.38 / 0.42 - 1)
    assert candidate["change"]["val_min_ade"] == pytest.approx(0.19 / 0.21 - 1)


def test_curves_meet_at_equal_shares_of_schedules_of_different_lengths(tmp_path):
    long = _run(tmp_path / "long", 160, {e: (0.2, 0.3 + e / 1000) for e in range(8, 161, 8)})
    short = _run(tmp_path / "short", 80, {e: (0.2, 0.3 + e / 1000) for e in range(4, 81, 4)})
    metrics = ("val_min_fde",)
    groups = {"160": [compare.read_curve(long, "generator", metrics)],
              "80": [compare.read_curve(short, "generator", metrics)]}  # fmt: skip
    rows = compare.curve_rows(groups, metrics, (0.25, 0.5, 1.0))
    assert [[r["epoch"] for r in row["runs"]] for row in rows] == [[40, 20], [80, 40], [160, 80]]
    assert rows[1]["runs"][1]["val_min_fde"] == pytest.approx(0.34)
    # between two validations the earlier one is shown on a tie, the nearer one otherwise
    assert groups["160"][0].nearest(0.275) == 40 and groups["160"][0].nearest(0.29) == 48


def test_a_run_without_its_config_takes_its_last_logged_epoch_as_the_schedule(tmp_path):
    run = _run(tmp_path / "a", 12, {6: (0.2, 0.3), 12: (0.2, 0.31)}, config=False)
    assert compare.read_curve(run, "generator", ("val_min_fde",)).epochs == 12


def test_missing_logs_metrics_and_bad_groups_are_clear_errors(tmp_path):
    with pytest.raises(TrajprefError, match=r"no generator_metrics.jsonl \(is it a run folder"):
        compare.read_curve(tmp_path, "generator", ("val_min_fde",))
    with pytest.raises(TrajprefError, match="nope: no such run folder"):
        compare.read_curve(tmp_path / "nope", "generator", ("val_min_fde",))
    (tmp_path / "ft").mkdir()
    (tmp_path / "ft" / "finetune_metrics.jsonl").write_text('{"epoch": 1}\n')
    with pytest.raises(TrajprefError, match="it holds finetune logs: --stage finetune"):
        compare.read_curve(tmp_path / "ft", "generator", ("val_min_fde",))
    run = _run(tmp_path / "a", 2, {})
    with pytest.raises(TrajprefError, match="has not validated yet"):
        compare.read_curve(run, "generator", ("val_min_fde",))
    run = _run(tmp_path / "b", 2, {2: (0.2, 0.3)})
    with pytest.raises(TrajprefError, match=r"no metric 'val_ade'.*val_min_ade, val_min_fde"):
        compare.read_curve(run, "generator", ("val_ade",))
    with pytest.raises(TrajprefError, match="stage must be one of"):
        compare.read_curve(run, "diffusion", ("val_min_fde",))
    with pytest.raises(TrajprefError, match="NAME=DIR"):
        compare.parse_group("name=")
    assert compare.parse_group("c=r/a,r/b") == ("c", ["r/a", "r/b"])
    assert compare.parse_group("r/a") == ("r/a", ["r/a"])
    curve = compare.read_curve(run, "generator", ("val_min_fde",))
    with pytest.raises(TrajprefError, match=r"shares lie in \(0, 1\]"):
        compare.curve_rows({"a": [curve]}, ("val_min_fde",), (0.0,))


def test_the_command_prints_the_tables_and_the_same_numbers_as_json(tmp_path, capsys):
    a = _run(tmp_path / "a", 4, {2: (0.20, 0.40), 4: (0.21, 0.41)})
    b = _run(tmp_path / "b", 4, {2: (0.22, 0.44), 4: (0.19, 0.37)})
    assert main(["compare", f"control={a}", str(b)]) == 0
    text = capsys.readouterr().out
    assert f"| control | {a} | 2 of 4 | 0.2000 / 0.4000 |" in text
    assert f"| {b} | 1 | 0.1900 / 0.3700 | - / - | -5.0 % / -7.5 % |" in text
    assert "| 0.50 | 0.2000 / 0.4000 (2) | 0.2200 / 0.4400 (2) |" in text
    assert main(["compare", f"control={a}", str(b), "--json", "--shares", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["groups"][str(b)]["change"]["val_min_fde"] == pytest.approx(0.37 / 0.40 - 1)
    assert [r["epoch"] for r in out["curves"][0]["runs"]] == [4, 4]


def test_the_command_refuses_a_group_named_twice(tmp_path, capsys):
    a = _run(tmp_path / "a", 2, {2: (0.2, 0.3)})
    assert main(["compare", f"x={a}", f"x={a}"]) == 2
    assert "group 'x' is given twice" in capsys.readouterr().err


def test_each_stage_reads_its_own_config_not_the_last_stages(tmp_path, capsys):
    # a denoiser trained for 3 epochs, then a generator into the same folder: the generator's
    # config.yaml holds the default denoiser schedule, denoiser_config.yaml the one it ran
    run = tmp_path / "run"
    run.mkdir()
    rows = [{"epoch": e, "val_denoise_loss": 1.0 / e, "val_score": 1.0 / e} for e in (1, 2, 3)]
    (run / "denoiser_metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    trained = ExperimentConfig()
    trained.denoiser.epochs = 3
    save_config(trained, run / "denoiser_config.yaml")
    save_config(ExperimentConfig(), run / "config.yaml")  # the later stage's: 60 epochs
    assert compare.stage_config_path(run, "denoiser") == run / "denoiser_config.yaml"
    assert compare.stage_config_path(run, "generator") == run / "config.yaml"  # older folders
    curve = compare.read_curve(run, "denoiser", compare.default_metrics("denoiser"))
    assert (curve.epochs, curve.kept) == (3, 3)
    # and the command shows the denoiser's own metric without --metrics
    assert main(["compare", f"a={run}", "--stage", "denoiser"]) == 0
    assert f"| a | {run} | 3 of 3 |" in capsys.readouterr().out
    assert compare.default_metrics("generator") == ("val_min_ade", "val_min_fde")


def _budget_run(path: Path, seconds: list[float], fde: list[float], minutes: float | None,
                start_fde: float | None = None) -> Path:  # fmt: skip
    """A fine-tuning run folder validated at each epoch, logged at ``seconds`` of the cpu
    budget clock, with ``epochs=100000`` and ``max_minutes=minutes`` (a budget that ended it
    when the last seconds reach it); with ``start_fde``, the start's validation first."""
    path.mkdir(parents=True)
    rows = []
    if start_fde is not None:  # the loop's epoch 0: the start, validated before training
        rows.append({"epoch": 0, "step": 0, "start": True, "val_min_ade": 0.1,
                     "val_min_fde": start_fde, "val_score": 0.1 + start_fde})  # fmt: skip
    for epoch, (s, f) in enumerate(zip(seconds, fde, strict=True), 1):
        rows.append({"epoch": epoch, "budget_cpu_seconds": s, "val_min_ade": 0.2,
                     "val_min_fde": f, "val_score": 0.2 + f})  # fmt: skip
    (path / "finetune_metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    cfg = ExperimentConfig()
    cfg.finetune.epochs, cfg.finetune.max_minutes = 100000, minutes
    cfg.finetune.budget_clock = "cpu"
    save_config(cfg, path / "finetune_config.yaml")
    return path


def test_a_run_its_budget_ended_is_compared_at_shares_of_the_budget(tmp_path, capsys):
    metrics = ("val_min_ade", "val_min_fde")
    # cheap epochs (validated at 6, 12, 18, 24 s of a 24 s budget) and dear ones (7, 13, 24 s):
    # at equal shares of the budget, not of their 100000 epochs (where all are the last)
    cheap = _budget_run(tmp_path / "c", [6, 12, 18, 24.01], [0.4, 0.3, 0.35, 0.32], 0.4)
    dear = _budget_run(tmp_path / "d", [7, 13, 24.2], [0.5, 0.45, 0.44], 0.4)
    curves = [compare.read_curve(r, "finetune", metrics) for r in (cheap, dear)]
    assert [c.budget for c in curves] == [0.4, 0.4] and curves[0].kept == 2
    rows = compare.curve_rows({"c": curves[:1], "d": curves[1:]}, metrics, (0.25, 0.5, 1.0))
    assert [[r["epoch"] for r in row["runs"]] for row in rows] == [[1, 1], [2, 2], [4, 3]]
    assert curves[0].schedule(2) == "2 (0.2 of 0.4 min, cpu budget)"
    assert main(["compare", "--stage", "finetune", f"c={cheap}", f"d={dear}"]) == 0
    text = capsys.readouterr().out
    assert f"| c | {cheap} | 2 (0.2 of 0.4 min, cpu budget) | 0.2000 / 0.3000 |" in text
    assert (
        "| share of the schedule (epochs; of the time budget where it ended the run) | "
        f"c: {cheap} (of its 0.4 min budget) | d: {dear} (of its 0.4 min budget) |" in text
    )
    assert "| 0.50 | 0.2000 / 0.3000 (2) | 0.2000 / 0.4500 (2) |" in text
    # a budget that has not ended the run (stopped early, or not reached): its epochs
    short = compare.read_curve(_budget_run(tmp_path / "s", [6, 12], [0.4, 0.3], 0.4),
                               "finetune", metrics)  # fmt: skip
    unbudgeted = compare.read_curve(_budget_run(tmp_path / "u", [6, 12], [0.4, 0.3], None),
                                    "finetune", metrics)  # fmt: skip
    assert short.budget is None and unbudgeted.budget is None
    assert short.schedule(2) == "2 of 100000"


def test_the_start_row_of_fine_tuning_is_no_epoch_and_never_kept(tmp_path, capsys):
    # a start better than every epoch: the kept checkpoint is still an epoch's, as the loop
    # saved it, and the log's epochs are those of a run without the start row
    metrics = ("val_min_ade", "val_min_fde")
    run = _budget_run(tmp_path / "a", [6, 12], [0.4, 0.3], None, start_fde=0.1)
    without = _budget_run(tmp_path / "b", [6, 12], [0.4, 0.3], None)
    curve = compare.read_curve(run, "finetune", metrics)
    assert list(curve.points) == [1, 2] and curve.kept == 2
    assert curve == dataclasses.replace(compare.read_curve(without, "finetune", metrics),
                                        run=str(run))  # fmt: skip
    assert compare.curve_rows({"a": [curve]}, metrics, (1e-5,))[0]["runs"][0]["epoch"] == 1
    # a run stopped in its first epoch has validated its start only
    alone = _budget_run(tmp_path / "c", [], [], None, start_fde=0.1)
    with pytest.raises(TrajprefError, match="has not validated an epoch yet .*start's validation"):
        compare.read_curve(alone, "finetune", metrics)


def test_the_whole_schedule_is_the_runs_final_validation_past_its_budget(tmp_path, capsys):
    """The step that crosses a time budget overshoots it: a set-aware run of 0.2 minutes
    (12 s) validated at 11.5 s and, after its last step, at 12.6 s. The 1.00 row matched the
    nearest validation, 11.5 s, and so showed epoch 2 where the run ended (and kept) epoch 3
    (walkthrough, 2026-12-06)."""
    metrics = ("val_min_ade", "val_min_fde")
    run = _budget_run(tmp_path / "set", [4.0, 11.5, 12.6], [0.40, 0.35, 0.30], 0.2)
    curve = compare.read_curve(run, "finetune", metrics)
    assert curve.budget == 0.2 and curve.kept == 3
    rows = compare.curve_rows({"set": [curve]}, metrics, (0.5, 0.75, 1.0))
    assert [row["runs"][0]["epoch"] for row in rows] == [1, 2, 3]  # 6 s -> 4 s, 9 s -> 11.5 s
    assert main(["compare", "--stage", "finetune", f"set={run}"]) == 0
    assert "| 1.00 | 0.2000 / 0.3000 (3) |" in capsys.readouterr().out
    # a run its epochs ended: the last epoch, as before
    ended = _run(tmp_path / "e", 8, {3: (0.2, 0.3), 7: (0.2, 0.3), 8: (0.2, 0.3)})
    epochs = compare.read_curve(ended, "generator", metrics)
    assert epochs.nearest(1.0) == 8
