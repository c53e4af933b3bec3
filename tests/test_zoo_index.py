"""benchmarks/zoo_index.py: what a model card says about where it was trained."""

from pathlib import Path

from bench import load_benchmark

ROOT = Path(__file__).resolve().parent.parent


def test_a_card_names_the_training_process_machine_before_the_publishing_one(monkeypatch):
    """pretrain.py records the machine (threads included) the checkpoint was trained on
    (``trained_on``, from the checkpoint's meta since 2026-11-27); the card prefers it to the
    machine of the process that evaluated the test row."""
    zoo = load_benchmark("zoo_index")
    path = ROOT / "models" / "zara2" / "generator.safetensors"
    rows = [{"dataset": "zara2", "method": "pretrained", "seed": 0, "split": "test",
             "protocol": "all", "checkpoint": "models/zara2/generator.safetensors",
             "machine": "publisher, 2 threads", "min_ade": 0.1, "min_fde": 0.2,
             "joint_min_ade": 0.3, "joint_min_fde": 0.4, "date": "2026-11-27"}]  # fmt: skip
    meta = {"stage_seconds": {"generator": 60.0}}
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: meta)
    assert zoo.describe("zara2/generator", path, rows)["train"]["machine"] == "publisher, 2 threads"
    meta["trained_on"] = "trainer, 1 threads"
    assert zoo.describe("zara2/generator", path, rows)["train"]["machine"] == "trainer, 1 threads"
    meta["train_machine"] = "1x H100"  # stated by hand for a run trained elsewhere
    assert zoo.describe("zara2/generator", path, rows)["train"]["machine"] == "1x H100"
