"""benchmarks/speed_clamp.py: the clamp each training split implies, the rule, and the
settings-only variant it publishes."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from bench import load_benchmark
from synthetic import TINY_OVERRIDES, make_scene

from trajpref.config import load_config
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator
from trajpref.types import DatasetInfo, Scene, TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def sc(tmp_path, monkeypatch):
    module = load_benchmark("speed_clamp")
    monkeypatch.setattr(module, "ROOT", tmp_path)
    return module


def test_the_observed_step_is_the_first_to_last_displacement_per_step_in_model_units(sc):
    s = make_scene(2)
    hist = np.zeros((2, 8, 2), np.float32)
    hist[0, -1] = (7.0, 0.0)  # 1 unit per step over 7 steps
    hist[1, -1] = (0.0, 3.5)  # 0.5
    ds = TrajectoryDataset([Scene(hist, s.future, s.agent_type, "x")],
                           DatasetInfo("toy", "train", "m", 0.4))  # fmt: skip
    np.testing.assert_allclose(sc.observed_step(ds, scale=2.0), [0.5, 0.25])


def test_the_rule_refuses_when_one_generator_gets_worse_by_more_than_half_a_percent(sc):
    def row(name, off, on):
        return {"checkpoint": name, "off": {"min_fde": off}, "clamped": {"min_fde": on}}

    ok = [row("a", 1.0, 0.99), row("b", 1.0, 1.004)]
    assert sc.decide(ok)["apply"]
    assert not sc.decide([*ok, row("sdd", 1.0, 1.0095)])["apply"]


def test_a_variant_is_the_defaults_weights_with_the_clamp_and_its_training_records(sc, tmp_path):
    cfg = load_config(None, TINY_OVERRIDES)
    den = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 1.0, {})
    folder = tmp_path / "models" / "walks"
    folder.mkdir(parents=True)
    ckpt.save(folder / "generator.safetensors",
              ckpt.generator_payload(Generator(cfg.model), den, cfg, {}))  # fmt: skip
    meta = tmp_path / "benchmarks" / "results" / "meta"
    meta.mkdir(parents=True)
    (meta / "pretrained_walks.json").write_text(json.dumps({"variant": None, "params": 1}))
    path = sc.publish_variant("walks", 0.3)
    assert path.name == "generator-clamp.safetensors"
    assert ckpt.config_of(ckpt.load(path)).model.max_speed == 0.3
    record = json.loads((meta / "pretrained_walks_clamp.json").read_text())
    assert record == {"variant": "clamp", "params": 1}
    # measured records are kept when the variant is published again
    (meta / "pretrained_walks_clamp.json").write_text(json.dumps({"variant": "clamp", "ms": 9}))
    sc.publish_variant("walks", 0.3)
    assert json.loads((meta / "pretrained_walks_clamp.json").read_text())["ms"] == 9


def _sweep_row(name, off, by_q):
    by_quantile = {
        str(q): {"min_fde": v, "max_speed": q / 2, "share_clamped": {"test": 1 - q}}
        for q, v in by_q.items()
    }
    return {"checkpoint": f"models/{name}/generator.safetensors",
            "off": {"min_ade": 0.5, "min_fde": off}, "by_quantile": by_quantile}  # fmt: skip


def test_the_lower_clamp_rule_takes_the_lowest_quantile_that_no_fold_rejects(sc):
    rows = [_sweep_row("a", 1.0, {0.99: 0.99, 0.9: 1.004, 0.5: 1.02}),
            _sweep_row("b", 2.0, {0.99: 2.0, 0.9: 1.99, 0.5: 1.9})]  # fmt: skip
    decision = sc.decide_sweep(rows)
    assert decision["quantile"] == 0.9  # 0.5 is 2 % worse on a
    assert decision["apply"]
    assert decision["change_min_fde"]["0.5"]["models/a/generator.safetensors"] == pytest.approx(
        0.02
    )
    # a fold worse at every quantile: nothing is chosen, nothing applied
    worse = [*rows, _sweep_row("c", 1.0, {0.99: 1.01, 0.9: 1.01, 0.5: 1.01})]
    assert sc.decide_sweep(worse) == {**sc.decide_sweep(worse), "quantile": None, "apply": False}


def test_the_sweep_table_has_one_column_per_quantile_and_names_the_choice(sc):
    rows = [_sweep_row("a", 1.0, {0.99: 0.99, 0.5: 1.02})]
    table = sc.sweep_table(rows, sc.decide_sweep(rows))
    assert "| q = 0.99 | q = 0.5 |" in table
    assert "-1.00% (test 1% clamped)" in table and "+2.00% (test 50% clamped)" in table
    assert table.endswith("Chosen: q = 0.99")


def test_apply_sweep_writes_the_chosen_quantiles_clamp_into_each_generator(
    sc, tmp_path, monkeypatch
):
    cfg = load_config(None, TINY_OVERRIDES)
    den = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 1.0, {})
    rows = []
    for name in ("a", "b"):
        folder = tmp_path / "models" / name
        folder.mkdir(parents=True)
        ckpt.save(folder / "generator.safetensors",
                  ckpt.generator_payload(Generator(cfg.model), den, cfg, {}))  # fmt: skip
        rows.append(_sweep_row(name, 1.0, {0.99: 0.99, 0.9: 1.0, 0.5: 1.1}))
    sc.SWEEP_OUT = tmp_path / "sweep.json"
    sc.SWEEP_OUT.write_text(json.dumps({"rows": rows, "decision": sc.decide_sweep(rows)}))
    monkeypatch.setattr("sys.argv", ["speed_clamp.py", "--apply-sweep"])
    sc.main()
    for name in ("a", "b"):
        path = tmp_path / "models" / name / "generator.safetensors"
        assert ckpt.config_of(ckpt.load(path)).model.max_speed == pytest.approx(0.45)


def test_a_partial_sweep_replaces_its_generators_rows_and_the_rule_re_decides(sc):
    def named(name, off, by_q):
        return {**_sweep_row(name, off, by_q), "dataset": name}

    stored = [named("a", 1.0, {0.9: 1.0, 0.5: 1.0}), named("b", 1.0, {0.9: 1.0, 0.5: 1.0})]
    new = [named("b", 1.0, {0.9: 1.0, 0.5: 1.2})]
    merged = sc.merge_sweep_rows(stored, new)
    assert [r["dataset"] for r in merged] == ["a", "b"]
    assert sc.decide_sweep(stored)["quantile"] == 0.5
    assert sc.decide_sweep(merged)["quantile"] == 0.9
    with pytest.raises(SystemExit, match="sweep the same quantiles"):
        sc.merge_sweep_rows(stored, [named("b", 1.0, {0.9: 1.0})])


def test_apply_sweep_changes_nothing_when_no_quantile_passed(sc, tmp_path, monkeypatch, capsys):
    rows = [{**_sweep_row("a", 1.0, {0.9: 1.1}), "dataset": "a"}]
    sc.SWEEP_OUT = tmp_path / "sweep.json"
    sc.SWEEP_OUT.write_text(json.dumps({"rows": rows, "decision": sc.decide_sweep(rows)}))
    monkeypatch.setattr("sys.argv", ["speed_clamp.py", "--apply-sweep"])
    sc.main()  # no generator file exists: nothing may be opened
    assert "nothing changed" in capsys.readouterr().out


def test_a_clamp_trained_generator_is_judged_against_the_reference_at_its_own_clamp(sc):
    candidate = _sweep_row("cand", 1.2, {0.9: 0.995, 0.7: 1.009, 0.5: 1.02})
    reference = _sweep_row("ref", 0.9, {0.9: 1.0, 0.5: 0.5})  # its 90 % row is the bar
    decision = sc.decide_trained(candidate, reference)
    assert decision["reference_min_fde"] == 1.0
    assert decision["quantile"] == 0.7  # 0.5 is 2 % worse, beyond the 1 % allowance
    assert decision["change_min_fde"]["0.5"] == pytest.approx(0.02)
    worse = _sweep_row("cand", 1.2, {0.9: 1.02, 0.5: 1.03})
    assert sc.decide_trained(worse, reference) | {"change_min_fde": None} == {
        **decision, "change_min_fde": None, "quantile": None, "apply": False}  # fmt: skip


def test_checkpoints_need_a_sweep_and_a_reference(sc, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["speed_clamp.py", "--sweep", "0.9", "--checkpoints", "a"])
    with pytest.raises(SystemExit) as exc:
        sc.main()
    assert exc.value.code == 2 and "the candidate, then the reference" in capsys.readouterr().err


def test_clamped_metrics_take_the_device_auto(sc, tiny_run, walks, monkeypatch):
    """``--device auto`` went to ``predictor.to`` as it was: a RuntimeError naming 'auto'."""
    import argparse

    import torch

    from trajpref.data import load_dataset

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    args = argparse.Namespace(device="auto", samples=2, seed=0)
    payload = ckpt.load(tiny_run / "generator.safetensors")
    res = sc._clamped_metrics(args, payload, load_dataset(str(walks), "val"), 0.3)
    assert res["min_fde"] > 0
