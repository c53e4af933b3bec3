"""benchmarks/optimizer_speed.py: its two arms step from the same start on the same batches,
with the default and the fused AdamW, and end equal up to float rounding."""

import copy
import itertools

import torch
from bench import load_benchmark

from trajpref.data import load_dataset
from trajpref.data.loader import SceneLoader
from trajpref.models import checkpoint as ckpt
from trajpref.train.stages import build_generator_stage


def test_both_arms_are_timed_and_end_at_the_same_weights_up_to_rounding(tiny_cfg, tiny_run):
    speed = load_benchmark("optimizer_speed")
    train = load_dataset(tiny_cfg.data.dataset, "train")
    loader = SceneLoader(train, max_agents=tiny_cfg.data.max_agents, shuffle=True, seed=0)
    batches = list(itertools.islice(loader, 2))
    denoiser = ckpt.load(tiny_run / "denoiser.safetensors")
    stage = build_generator_stage(tiny_cfg, denoiser, train, torch.device("cpu"))
    start = {k: v.clone() for k, v in stage.trainable.state_dict().items()}
    arms = {arm: copy.deepcopy(stage) for arm in speed.ARMS}
    out = speed.time_arms(arms, tiny_cfg.generator, batches, 1, torch.device("cpu"))
    assert set(out["seconds"]) == {"default", "fused"}
    assert all(s > 0 for s in out["seconds"].values())
    assert out["max_weight_difference"] < 1e-5  # fp32: rounding only
    moved = arms["fused"].trainable.state_dict()
    assert any(not torch.equal(start[k], v) for k, v in moved.items())  # the arms trained
    assert all(torch.equal(start[k], v) for k, v in stage.trainable.state_dict().items())
