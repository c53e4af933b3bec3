"""``trajpref models FILE`` of a run's own checkpoint (walkthrough 66): the card showed
``Data: <path>`` alone, its ``trajpref evaluate`` line failed on a K = 4 generator (evaluate
asks for 20 samples), and it claimed a run folder a file handed over alone does not have."""

from __future__ import annotations

import subprocess
import sys

from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo


def _relabelled(src, dst, *, samples=4, method=None, preset=None):
    payload = ckpt.load(src)
    payload["config"]["data"]["time_step"] = 4.0
    payload["config"]["model"]["samples"] = samples
    timing = {"frame_interval": 0.4, "interval_from": "timestamps", "time_step": 4.0,
              "units": "m", "agent_types": [0]}  # fmt: skip
    payload["meta"]["data_timing"] = timing
    if method:
        payload["meta"].update(method=method, preset=preset)
    ckpt.save(dst, payload)
    return dst


def test_the_card_shows_how_to_read_data_its_lineage_and_a_command_that_runs(tiny_run, tmp_path):
    path = _relabelled(tiny_run / "generator.safetensors", tmp_path / "generator.safetensors")
    card = zoo.file_card(path)
    dataset = ckpt.load(path)["config"]["data"]["dataset"]
    assert "read with `--time-step 4 --units m`: 0.4 s per step (its files' time column)." in card
    assert f"- Lineage: denoiser on `{dataset}`, then generator on `{dataset}`." in card
    assert "- Denoiser: weights hash `" in card
    command = (f"`trajpref evaluate --model {path} --dataset {dataset} --split test "
               "--time-step 4 --units m --samples 4` tests it")  # fmt: skip
    assert command in card
    assert "Its run folder holds" not in card
    assert "The run folder it came from holds" in card and "the file alone rebuilds" in card
    # K = 20 needs no --samples
    plain = _relabelled(tiny_run / "generator.safetensors", tmp_path / "k20.safetensors",
                        samples=20)  # fmt: skip
    assert "--samples" not in zoo.file_card(plain)


def test_a_fine_tunes_card_names_its_preset(tiny_run, tmp_path):
    path = _relabelled(tiny_run / "generator.safetensors", tmp_path / "finetune.safetensors",
                       method="rlhf", preset="paper")  # fmt: skip
    assert "- Preset: `paper`." in zoo.file_card(path)
    path = _relabelled(tiny_run / "generator.safetensors", tmp_path / "finetune2.safetensors",
                       method="rlhf")  # fmt: skip
    assert "- Preset: none" in zoo.file_card(path)


def test_the_cards_evaluate_command_runs(tiny_run):
    """The command the card prints evaluates the file (K = the generator's own)."""
    samples = ckpt.load(tiny_run / "generator.safetensors")["config"]["model"]["samples"]
    card = zoo.file_card(tiny_run / "generator.safetensors")
    line = card.split("`trajpref evaluate ", 1)[1].split("` tests it", 1)[0]
    assert ("--samples" in line) == (samples != 20)
    args = ["evaluate", *line.split(), "--device", "cpu", "--no-progress", "--max-scenes", "2"]
    run = subprocess.run([sys.executable, "-m", "trajpref.cli", *args], capture_output=True,
                         text=True, timeout=300)  # fmt: skip
    assert run.returncode == 0, run.stderr


def test_a_run_validated_on_another_dataset_is_tested_on_that_ones_test_split(tiny_run, tmp_path):
    """robo.yaml trains on robo-sim and chooses its epoch on robo: its card pointed at
    robo-sim's simulated test split, not robo's real one the published cards test on."""
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["data"]["dataset"] = "robo-sim"
    payload["config"]["data"]["val_dataset"] = "robo"
    payload["meta"].pop("dataset", None)
    path = tmp_path / "generator.safetensors"
    ckpt.save(path, payload)
    card = zoo.file_card(path)
    assert "--dataset robo --split test" in card and "--dataset robo-sim --split" not in card
