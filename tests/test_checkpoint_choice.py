"""benchmarks/checkpoint_choice.py: which epoch each protocol keeps (hand-written records), and
a whole run of the script on a tiny generator run with every epoch kept."""

import dataclasses
import json

import pytest
import torch
from bench import load_benchmark

from trajpref.data import load_dataset
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.train.run import train_stage


def _epoch(e, val, ade, fde):
    return {"epoch": e, "val_score": val, "val_min_fde": val / 2, "test_min_ade": ade,
            "test_min_fde": fde}  # fmt: skip


def test_each_protocol_keeps_its_own_epoch_and_ties_go_to_the_earlier():
    mod = load_benchmark("checkpoint_choice")
    got = mod.choices([
        _epoch(1, 0.9, 0.30, 0.60),
        _epoch(2, 0.5, 0.25, 0.50),  # best validation
        _epoch(3, 0.6, 0.20, 0.45),  # best test minADE
        _epoch(4, 0.5, 0.22, 0.40),  # ties validation with epoch 2; best test minFDE
    ])  # fmt: skip
    assert got["validation"] == {"epoch": 2, "test_min_ade": 0.25, "test_min_fde": 0.50}
    assert got["test_min_ade"]["epoch"] == 3
    assert got["test_min_ade"]["change_pct"] == pytest.approx(-10.0)
    assert got["test_min_fde"]["epoch"] == 4
    assert got["test_min_fde"]["change_pct"] == pytest.approx(-20.0)
    # the second half: epochs 3 and 4
    assert got["late_test_min_fde"]["mean"] == pytest.approx(0.425)
    assert got["late_test_min_fde"]["std"] == pytest.approx(0.025)
    # validation 0.3 -> 0.25 while the test goes 0.45 -> 0.40: perfectly correlated
    assert got["late_test_min_fde"]["corr_with_val_min_fde"] == pytest.approx(1.0)


def test_validation_against_the_test_correlation_over_the_second_half():
    mod = load_benchmark("checkpoint_choice")
    epochs = [_epoch(e, 1.0, 0.3, 0.6) for e in (1, 2, 3)] + [
        _epoch(4, 0.2, 0.3, 0.5), _epoch(5, 0.4, 0.3, 0.7), _epoch(6, 0.6, 0.3, 0.6),
    ]  # fmt: skip
    # second half: validation 0.1, 0.2, 0.3 against the test 0.5, 0.7, 0.6 -> r = 0.5
    got = mod.choices(epochs)["late_test_min_fde"]
    assert got["corr_with_val_min_fde"] == pytest.approx(0.5)
    assert got["epochs"] == 3


def test_no_epochs_is_an_error():
    mod = load_benchmark("checkpoint_choice")
    with pytest.raises(ValueError, match="no epochs"):
        mod.choices([])


def test_a_run_without_kept_epochs_is_refused(tmp_path, tiny_cfg, tiny_run):
    mod = load_benchmark("checkpoint_choice")
    with pytest.raises(SystemExit, match="keep_checkpoints"):
        mod.main(
            [str(tiny_run), "--out", str(tmp_path / "x.json"), "--plot", str(tmp_path / "x.png")]
        )


def test_the_script_evaluates_every_kept_epoch_with_the_published_settings(
    tmp_path, tiny_cfg, tiny_run, monkeypatch, capsys
):
    mod = load_benchmark("checkpoint_choice")
    generator = dataclasses.replace(tiny_cfg.generator, epochs=3, eval_every=1,
                                    keep_checkpoints=True)  # fmt: skip
    run = tmp_path / "run"
    denoiser = str(tiny_run / "denoiser.safetensors")
    train_stage("generator", dataclasses.replace(tiny_cfg, generator=generator), run,
                device="cpu", progress=False, denoiser=denoiser)  # fmt: skip
    monkeypatch.setattr(mod, "published_settings", lambda dataset, models: {"max_speed": 0.05})
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)  # --device auto: the CPU
    out, png = tmp_path / "choice.json", tmp_path / "choice.png"
    assert mod.main([str(run), "--samples", "4", "--device", "auto", "--out", str(out),
                     "--plot", str(png)]) == 0  # fmt: skip
    study = json.loads(out.read_text())["studies"][0]
    assert [e["epoch"] for e in study["epochs"]] == [1, 2, 3]
    assert png.is_file() and "by test minADE20" in capsys.readouterr().out
    # the validation choice is the epoch the training loop kept
    kept = ckpt.load(run / "generator.safetensors")["meta"]["epoch"]
    assert study["choices"]["validation"]["epoch"] == kept
    # each epoch's test number is that epoch's weights with the published clamp
    payload = ckpt.load(run / "generator_epoch002.safetensors")
    clamped = ckpt.predictor_from_payload(mod.with_settings(payload, {"max_speed": 0.05}))
    test = load_dataset(tiny_cfg.data.dataset, "test")
    want = evaluate(clamped.eval(), test, 4, 0, "cpu", progress=False, collision_radius=None)
    assert study["epochs"][1]["test_min_fde"] == pytest.approx(want["min_fde"])
    unclamped = evaluate(ckpt.predictor_from_payload(payload).eval(), test, 4, 0, "cpu",
                         progress=False, collision_radius=None)  # fmt: skip
    assert unclamped["min_fde"] != pytest.approx(want["min_fde"])  # the setting mattered
