"""benchmarks/speed_clamp.py: the clamp each training split implies, the rule, and the
settings-only variant it publishes."""

import json
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
