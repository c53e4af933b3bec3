"""benchmarks/ema_test_check.py: a run's two checkpoints get the published default's sampling
settings with their weights untouched, and the paired change is taken raw -> averaged."""

import pytest
import torch
from bench import load_benchmark
from synthetic import TINY_OVERRIDES

from trajpref.config import load_config
from trajpref.io import read_checkpoint_header
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator


def _generator(path, seed, **settings):
    cfg = load_config(None, TINY_OVERRIDES)
    torch.manual_seed(0)
    den = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 0.7, {})
    torch.manual_seed(seed)
    ckpt.save(path, ckpt.generator_payload(Generator(cfg.model), den, cfg, {}))
    for name, value in settings.items():
        ckpt.set_generator_setting(path, name, value, note="test")


def test_match_settings_copies_the_published_clamp_and_keeps_the_weights(tmp_path):
    mod = load_benchmark("ema_test_check")
    published, run = tmp_path / "published.safetensors", tmp_path / "run.safetensors"
    _generator(published, 1, max_speed=0.32, spread_scale=0.9, neighbour_radius=8.0)
    _generator(run, 2)
    weights = read_checkpoint_header(run)["hash"]
    got = mod.match_settings(run, published)
    assert got == {"stochastic_steps": False, "max_speed": 0.32, "spread_scale": 0.9,
                   "max_log_sigma": None, "neighbour_radius": 8.0}  # fmt: skip
    model = read_checkpoint_header(run)["config"]["model"]
    assert (model["max_speed"], model["spread_scale"]) == (0.32, 0.9)
    assert model["neighbour_radius"] == 8.0  # the published file's radius, copied
    assert read_checkpoint_header(run)["hash"] == weights


def test_match_settings_reads_a_file_published_before_the_radius(tmp_path):
    mod = load_benchmark("ema_test_check")
    run = tmp_path / "run.safetensors"
    _generator(run, 2)
    published = ckpt.resolve_path("zara1/generator")  # its header predates the setting
    assert "neighbour_radius" not in read_checkpoint_header(published)["config"]["model"]
    assert mod.match_settings(run, published)["neighbour_radius"] is None


def test_change_is_raw_to_averaged_in_percent():
    mod = load_benchmark("ema_test_check")
    pair = {
        "raw": {"min_fde": 0.40, "min_ade": 0.20},
        "averaged": {"min_fde": 0.38, "min_ade": 0.21},
    }
    assert mod.change(pair, "min_fde") == pytest.approx(-5.0)
    assert mod.change(pair, "min_ade") == pytest.approx(5.0)


def test_the_published_pair_of_an_adopted_fold_is_found():
    mod = load_benchmark("ema_test_check")
    pair = mod.published_pair("zara1")  # the repository's own rows
    assert pair["averaged"]["min_fde"] < pair["raw"]["min_fde"]
    with pytest.raises(SystemExit, match="no pretrained-raw test row"):
        mod.published_pair("hotel")  # hotel never adopted the average
