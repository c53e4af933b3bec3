"""The weights' moving average: hand-computed updates, an exact swap, and a training run that
validates and checkpoints the average while the optimiser keeps the raw weights."""

import dataclasses
import json
import math

import pytest
import torch
from torch import nn

from trajpref.config import OptimConfig
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.train.ema import WeightAverage, ema_decay, warmed_decay
from trajpref.train.run import train_stage


def _linear(value: float) -> nn.Linear:
    layer = nn.Linear(1, 1)
    with torch.no_grad():
        layer.weight.fill_(value)
        layer.bias.fill_(0.0)
    return layer


def test_decay_from_a_time_constant_in_epochs():
    assert ema_decay(2.0, 50) == pytest.approx(math.exp(-1 / 100))
    with pytest.raises(ConfigError, match="time constant"):
        ema_decay(0.0, 50)


def test_the_first_updates_use_a_warmed_up_decay():
    assert warmed_decay(0.99, 1) == pytest.approx(2 / 11)
    assert warmed_decay(0.99, 10) == pytest.approx(11 / 20)
    assert warmed_decay(0.99, 10_000) == 0.99


def test_update_matches_a_hand_computed_average():
    layer = _linear(1.0)
    average = WeightAverage(layer, decay=0.5)
    with torch.no_grad():
        layer.weight.fill_(3.0)
    assert average.update() == pytest.approx(2 / 11)  # warm-up: min(0.5, 2/11)
    first = 2 / 11 * 1.0 + 9 / 11 * 3.0
    assert average.shadow["weight"].item() == pytest.approx(first)
    with torch.no_grad():
        layer.weight.fill_(5.0)
    assert average.update() == pytest.approx(3 / 12)
    assert average.shadow["weight"].item() == pytest.approx(0.25 * first + 0.75 * 5.0)


def test_swapped_in_holds_the_average_then_restores_the_raw_weights_even_on_error():
    layer = _linear(1.0)
    average = WeightAverage(layer, decay=0.5)
    with torch.no_grad():
        layer.weight.fill_(7.0)
    with average.swapped_in():
        assert layer.weight.item() == 1.0
    assert layer.weight.item() == 7.0
    with pytest.raises(RuntimeError), average.swapped_in():
        raise RuntimeError("validation failed")
    assert layer.weight.item() == 7.0


def test_a_bad_decay_and_a_negative_time_constant_are_config_errors():
    with pytest.raises(ConfigError, match="decay"):
        WeightAverage(_linear(0.0), decay=1.0)
    with pytest.raises(ConfigError, match="ema_epochs"):
        OptimConfig(ema_epochs=-1.0)


def _with_ema(cfg, epochs=3):
    generator = dataclasses.replace(cfg.generator, ema_epochs=1.0, epochs=epochs)
    return dataclasses.replace(cfg, generator=generator)


def test_a_run_with_an_average_checkpoints_the_average_and_logs_both(tmp_path, tiny_cfg,
                                                                     tiny_run):  # fmt: skip
    cfg = _with_ema(tiny_cfg)
    train_stage("generator", cfg, tmp_path, device="cpu", progress=False,
                denoiser=str(tiny_run / "denoiser.safetensors"))  # fmt: skip
    records = [json.loads(line) for line in (tmp_path / "generator_metrics.jsonl").open()]
    assert all("val_raw_score" in r and "val_score" in r for r in records)
    # the average is not the raw weights, so the two validations differ
    assert any(r["val_raw_score"] != r["val_score"] for r in records)
    assert ckpt.load(tmp_path / "generator.safetensors")["meta"]["ema_epochs"] == 1.0
    last = torch.load(tmp_path / "generator_last.pt", weights_only=True)
    assert last["ema"]["updates"] == last["step"]


def test_the_checkpoint_holds_the_average_and_training_continues_from_the_raw_weights(
    tmp_path, tiny_cfg, tiny_run
):
    from trajpref.data import load_dataset
    from trajpref.train.loop import fit
    from trajpref.train.stages import build_generator_stage

    cfg = _with_ema(tiny_cfg, epochs=2)
    train = load_dataset(cfg.data.dataset, "train")
    stage = build_generator_stage(cfg, ckpt.load(tiny_run / "denoiser.safetensors"), train,
                                  torch.device("cpu"))  # fmt: skip
    calls = []

    def improving(progress=False):  # each validation beats the last: the last one is kept
        calls.append(1)
        return {"score": -float(len(calls))}

    stage.validate = improving
    fit(stage, train, cfg.data, cfg.generator, tmp_path, torch.device("cpu"), progress=False)
    assert len(calls) == 2 * cfg.generator.epochs  # raw and average, every epoch
    saved = ckpt.load(tmp_path / "generator.safetensors")["state_dict"]
    last = torch.load(tmp_path / "generator_last.pt", weights_only=True)
    shadow, raw = last["ema"]["shadow"], last["trainable"]
    for key, value in shadow.items():
        torch.testing.assert_close(saved[key].float(), value)
    assert any(not torch.equal(raw[k].float(), v) for k, v in shadow.items())
    for key, value in stage.trainable.state_dict().items():  # the raw weights came back
        torch.testing.assert_close(value, raw[key])
    # the raw weights' own best (here the last epoch's) is kept beside it: the run's control
    control = ckpt.load(tmp_path / "generator_raw.safetensors")
    assert control["meta"]["epoch"] == cfg.generator.epochs
    assert control["meta"]["weights"].startswith("raw")
    for key, value in raw.items():
        torch.testing.assert_close(control["state_dict"][key].float(), value.float())
    assert last["best_raw"]["epoch"] == cfg.generator.epochs


def test_a_resumed_run_continues_the_same_average(tmp_path, tiny_cfg, tiny_run):
    cfg = _with_ema(tiny_cfg)
    denoiser = str(tiny_run / "denoiser.safetensors")
    full = tmp_path / "full"
    train_stage("generator", cfg, full, device="cpu", progress=False, denoiser=denoiser)
    steps = json.loads((full / "generator_metrics.jsonl").open().readline())["step"]
    stop = tmp_path / "stop"
    train_stage("generator", cfg, stop, device="cpu", progress=False, denoiser=denoiser,
                max_steps=steps)  # fmt: skip
    train_stage("generator", cfg, stop, device="cpu", progress=False, denoiser=denoiser,
                resume=str(stop / "generator_last.pt"))  # fmt: skip
    a = torch.load(full / "generator_last.pt", weights_only=True)["ema"]
    b = torch.load(stop / "generator_last.pt", weights_only=True)["ema"]
    assert a["updates"] == b["updates"]
    for key, value in a["shadow"].items():
        torch.testing.assert_close(b["shadow"][key], value)


def test_resuming_an_averaging_run_from_a_state_without_average_is_refused(tmp_path, tiny_cfg,
                                                                          tiny_run):  # fmt: skip
    denoiser = str(tiny_run / "denoiser.safetensors")
    plain = dataclasses.replace(tiny_cfg, generator=dataclasses.replace(tiny_cfg.generator,
                                                                        epochs=3))  # fmt: skip
    train_stage("generator", plain, tmp_path, device="cpu", progress=False, denoiser=denoiser,
                max_steps=1)  # fmt: skip
    last = tmp_path / "generator_last.pt"
    config = (tmp_path / "generator_config.yaml").read_text()
    with pytest.raises(ConfigError, match=r"differs .*generator\.ema_epochs: 0\.0 -> 1\.0"):
        train_stage("generator", _with_ema(tiny_cfg), tmp_path, device="cpu", progress=False,
                    denoiser=denoiser, resume=str(last))  # fmt: skip
    # a state written before states recorded their run: the missing average is still caught,
    # before the run's config files are rewritten
    state = torch.load(last, weights_only=True)
    state.pop("identity")
    torch.save(state, last)
    with pytest.raises(ConfigError, match="no average"):
        train_stage("generator", _with_ema(tiny_cfg), tmp_path, device="cpu", progress=False,
                    denoiser=denoiser, resume=str(last))  # fmt: skip
    assert (tmp_path / "generator_config.yaml").read_text() == config


def test_only_trained_parameters_are_averaged():
    layer = _linear(1.0)
    layer.bias.requires_grad_(False)
    layer.register_buffer("table", torch.tensor([0.1, 0.2]))
    average = WeightAverage(layer, decay=0.5)
    assert set(average.shadow) == {"weight"}
    with torch.no_grad():
        layer.bias.fill_(4.0)
    with average.swapped_in():
        assert layer.bias.item() == 4.0 and layer.table.tolist() == pytest.approx([0.1, 0.2])
