"""The hand-crafted SDA reward (rl/sda.py) and its use as finetune.reward=sda."""

import dataclasses
import math

import numpy as np
import pytest
import torch

from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.rl.presets import finetune_config
from trajpref.rl.sda import LONE_REWARD, sda_reward, social_groups
from trajpref.train.stages import build_finetune_stage
from trajpref.types import AGENT_BALL, Scene, collate

T_H, T_F = 8, 12
RADIUS, DRIFT, TOL = 1.5, 0.5, 0.2


def _walk(start, step, frames):
    """[frames, 2] a straight walk from ``start`` by ``step`` per frame."""
    return np.asarray(start, np.float32) + np.arange(frames, dtype=np.float32)[:, None] * step


def _scene(tracks, name="s", types=None):
    track = np.stack(tracks).astype(np.float32)  # [P, T_h + T_f, 2]
    types = np.zeros(len(tracks), np.int64) if types is None else np.asarray(types)
    return Scene(track[:, :T_H], track[:, T_H:], types, name)


def _pair_and_stranger():
    """A and B walk side by side 0.8 m apart at 0.4 m per frame; C walks the other way 1.2 m
    beside B (within the radius at the crossing, never for the whole history)."""
    n = T_H + T_F
    a = _walk([0.0, 0.0], np.array([0.4, 0.0]), n)
    b = _walk([0.0, 0.8], np.array([0.4, 0.0]), n)
    c = _walk([3.0, 2.0], np.array([-0.4, 0.0]), n)
    return _scene([a, b, c], "pair+stranger")


def test_side_by_side_walkers_are_one_group_and_the_stranger_is_alone():
    batch = collate([_pair_and_stranger(), _pair_and_stranger()])
    labels = social_groups(batch.history, batch.scene, RADIUS, DRIFT, batch.agent_type)
    # groups never cross scenes, though scene 1 repeats scene 0's positions exactly
    assert labels.tolist() == [0, 0, 2, 3, 3, 5]


def test_velocities_must_agree_not_only_positions():
    """B walks past a standing A: always within 0.86 m (< radius), but the offset between
    them moves by 7 x 0.2 = 1.4 m over the history: a group only once drift >= 1.4."""
    a = np.zeros((T_H + T_F, 2), np.float32)
    b = _walk([-0.7, 0.5], np.array([0.2, 0.0]), T_H + T_F)
    batch = collate([_scene([a, b])])
    assert social_groups(batch.history, batch.scene, RADIUS, DRIFT).tolist() == [0, 1]
    assert social_groups(batch.history, batch.scene, RADIUS, 1.41).tolist() == [0, 0]
    assert social_groups(batch.history, batch.scene, 0.8, 1.41).tolist() == [0, 1]


def test_groups_chain_through_mates_and_skip_the_ball():
    """Three abreast 1.2 m apart: the outer two (2.4 m) are one group through the middle one.
    The same walk flagged as the ball stays alone."""
    step = np.array([0.4, 0.0])
    tracks = [_walk([0.0, 1.2 * i], step, T_H + T_F) for i in range(3)]
    batch = collate([_scene(tracks), _scene(tracks, types=[0, 0, AGENT_BALL])])
    labels = social_groups(batch.history, batch.scene, RADIUS, DRIFT, batch.agent_type)
    assert labels.tolist() == [0, 0, 0, 3, 3, 5]


def _futures(batch):
    """K = 2 joint samples: k = 0 continues every walk (the pair keeps 0.8 m); k = 1 makes B
    veer away by 0.1 m more per step (the pair's distance is 0.8 + 0.1 (t + 1))."""
    step = batch.history[:, -1] - batch.history[:, -2]  # [N, 2]
    t = torch.arange(1, T_F + 1, dtype=torch.float32)[:, None]  # [T_f, 1]
    keep = batch.history[:, -1:] + t * step[:, None]  # [N, T_f, 2]
    split = keep.clone()
    split[1, :, 1] += 0.1 * t[:, 0]
    return torch.stack([keep, split])  # [2, N, T_f, 2]


def test_keeping_the_pair_together_scores_higher_than_splitting_it():
    batch = collate([_pair_and_stranger()])
    r = sda_reward(batch.history, batch.scene, _futures(batch), RADIUS, DRIFT, TOL)  # [2,3,T_f]
    assert r.shape == (2, 3, T_F)
    assert torch.allclose(r[0], torch.ones(3, T_F), atol=1e-5)  # formation kept: 1
    want = 1 - 0.1 * torch.arange(1, T_F + 1) / TOL  # hand-computed: 1 - e / tol
    assert torch.allclose(r[1, 0], want, atol=1e-4) and torch.allclose(r[1, 1], want, atol=1e-4)
    assert (r[0, :2].sum() > r[1, :2].sum()).item()


def test_a_lone_agent_gets_the_same_neutral_reward_whatever_its_sample():
    batch = collate([_pair_and_stranger()])
    futures = _futures(batch)
    futures[1, 2] += torch.randn(T_F, 2) * 5  # the stranger's sample k = 1 goes anywhere
    r = sda_reward(batch.history, batch.scene, futures, RADIUS, DRIFT, TOL)
    assert LONE_REWARD == 1.0 and torch.equal(r[:, 2], torch.full((2, T_F), LONE_REWARD))


def test_the_mates_of_a_chain_are_averaged():
    """Three abreast 1.2 m apart; the top one (agent 2) drifts 0.3 m further out in every step
    of the future. Its errors: 0.3 to the middle, 0.3 to the bottom -> r = 1 - 0.3 / tol; the
    middle and bottom ones each have one of two mates off by 0.3 -> r = 1 - 0.15 / tol."""
    step = np.array([0.4, 0.0])
    tracks = [_walk([0.0, 1.2 * i], step, T_H + T_F) for i in range(3)]
    batch = collate([_scene(tracks)])
    futures = _futures(batch)[:1].clone()  # k = 0: everyone keeps formation
    futures[0, 2, :, 1] += 0.3
    r = sda_reward(batch.history, batch.scene, futures, RADIUS, DRIFT, TOL)[0]  # [3, T_f]
    assert torch.allclose(r[2], torch.full((T_F,), 1 - 0.3 / TOL), atol=1e-4)
    assert torch.allclose(r[:2], torch.full((2, T_F), 1 - 0.15 / TOL), atol=1e-4)


# --- the plug-in in the fine-tuning objective ---


def _stage(start, train, *overrides):
    cfg = load_config(None, list(overrides), base=start["config"])
    return build_finetune_stage(cfg, start, train, torch.device("cpu"))


def _batch(train):
    """Synthetic walks plus the pair-and-stranger scene, so that a group is present."""
    return collate([*train.scenes[:3], _pair_and_stranger()])


def test_the_objective_never_reads_the_ground_truth_future(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = _batch(train)
    blind = dataclasses.replace(batch, future=torch.full_like(batch.future, math.nan))
    for reward in ("sda", "score"):
        obj = _stage(start, train, f"finetune.reward={reward}").objective
        memo = {}
        for name, b in (("real", batch), ("nan", blind)):
            memo[name] = obj.collect_frozen(b, torch.Generator().manual_seed(0))
        real, nan = memo["real"].acts[0], memo["nan"].acts[0]
        if reward == "sda":  # the same rewards, advantages and value targets, bit for bit
            assert torch.isfinite(real.reward).all() and torch.equal(real.score, nan.score)
            assert torch.equal(real.reward, nan.reward)
            assert torch.equal(memo["real"].adv, memo["nan"].adv)
            assert torch.equal(memo["real"].v_target, memo["nan"].v_target)
        else:  # the contrast: the diffusion score's r does read it (Eq. 6's d_gt)
            assert torch.isfinite(real.score).all() and torch.isnan(nan.score).all()


@pytest.mark.parametrize("method", ["rlhf", "rlhf-res"])
def test_a_finetune_step_with_the_sda_reward_changes_the_policy(tiny_run, walks, method):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    stage = _stage(start, train, "finetune.reward=sda", f"finetune.method={method}")
    obj = stage.objective

    def no_score(*args, **kwargs):
        raise AssertionError("the sda reward must not call the diffusion score")

    obj.scorer.step_scores = no_score
    before = {k: v.detach().clone() for k, v in obj.policy.state_dict().items()}
    opt = torch.optim.Adam(stage.trainable.parameters(), lr=1e-2)
    gen = torch.Generator().manual_seed(0)
    for _ in range(2):
        loss, logs = obj(_batch(train), gen)
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert torch.isfinite(loss) and -5.0 <= logs["reward"] < LONE_REWARD  # a group was scored
    assert any(not torch.equal(before[k], v) for k, v in obj.policy.state_dict().items())


def test_sda_thresholds_are_checked(tiny_run):
    start = ckpt.load(tiny_run / "generator.safetensors")
    for key in ("sda_radius", "sda_drift", "sda_tolerance"):
        with pytest.raises(ConfigError, match=key):
            load_config(None, [f"finetune.{key}=0"], base=start["config"])
    # any name is a config's reward; fine-tuning refuses one that is not a reward here
    assert load_config(None, ["finetune.reward=groups"], base=start["config"]).finetune.reward
    with pytest.raises(ConfigError, match=r"^finetune\.reward=groups: no such reward .*sda"):
        finetune_config(str(tiny_run / "generator.safetensors"), "rlhf",
                        overrides=["finetune.reward=groups"])  # fmt: skip
