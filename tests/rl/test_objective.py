"""The objective's glue around the PPO pieces (rl/objective.py), by hand: what ``advantages``
whitens, what ``collect`` gives the antithetic twin, and what ``update`` clips the value loss
around. The pieces themselves are tested in test_ppo.py; these catch a wrong wiring of them,
which the end-to-end test (test_stage.py) is too noisy to catch."""

import math
from types import SimpleNamespace

import pytest
import torch
from helpers import NEW

from trajpref import config
from trajpref.config import FinetuneConfig, load_config
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.rl.objective import Actions, RLObjective
from trajpref.rl.ppo import whiten_per_group
from trajpref.train.stages import build_finetune_stage
from trajpref.types import collate


def _objective(tiny_run, walks, *overrides):
    start = ckpt.load(tiny_run / "generator.safetensors")
    cfg = load_config(None, list(overrides), base=start["config"])
    train = load_dataset(str(walks), "train")
    stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
    return stage.objective.train(), collate(train.scenes[:4])


def _actions(reward: torch.Tensor) -> Actions:
    """Actions [K, N, T] with only a reward (what ``advantages`` reads)."""
    k, n, t = reward.shape
    zeros = torch.zeros(k, n, t)
    return Actions(zeros, zeros, torch.zeros(k, n, t, 2), torch.zeros(k, n, t, 2),
                   reward=reward)  # fmt: skip


# K = 1 sample, agents 0 and 1 in scene 0, agent 2 in scene 1, T = 2 steps
SCENES = SimpleNamespace(scene=torch.tensor([0, 0, 1]), num_scenes=2)
REWARD = torch.tensor([[[1.0, 3.0], [5.0, 7.0], [2.0, 4.0]]])  # [1, 3, 2]


@pytest.mark.parametrize("baseline", ["critic", "antithetic"])
def test_advantages_are_whitened_per_scene_by_default(tiny_run, walks, baseline):
    """``adv_norm=scene`` is the default and is applied: by hand, with V = 0 (so the one-step
    advantage is R), scene 0's rewards 1, 3, 5, 7 (mean 4, std sqrt 5) become
    (-3, -1, 1, 3) / sqrt 5 and scene 1's 2, 4 become -1, 1; ``adv_norm=none`` keeps them.
    With the antithetic baseline the twin's reward is -R, so (R - (-R)) / 2 = R again."""
    assert FinetuneConfig().adv_norm == "scene"
    acts = [_actions(REWARD)] + ([_actions(-REWARD)] if baseline == "antithetic" else [])
    values = torch.zeros_like(REWARD)
    whitened = torch.tensor([[[-3.0, -1.0], [1.0, 3.0], [-math.sqrt(5), math.sqrt(5)]]])
    whitened = whitened / math.sqrt(5)
    for norm, expected in (("scene", whitened), ("none", REWARD)):
        obj, _ = _objective(tiny_run, walks, f"finetune.adv_norm={norm}",
                            f"finetune.baseline={baseline}")  # fmt: skip
        adv, _ = obj.advantages(acts, values, SCENES)
        torch.testing.assert_close(adv, expected)
    obj, _ = _objective(tiny_run, walks, f"finetune.baseline={baseline}")  # the default
    torch.testing.assert_close(obj.advantages(acts, values, SCENES)[0], whitened)


@pytest.mark.parametrize("method", ["rlhf", "rlhf-res"])
def test_the_antithetic_twins_advantage_is_minus_the_samples(tiny_run, walks, method):
    """``collect`` gives the -xi twin the advantage -A of its +xi sample (A = the whitened
    (R(+xi) - R(-xi)) / 2, of all K samples or of each scene's k*): the twin's gradient then
    adds to its sample's, where the same sign for both would cancel the policy gradient."""
    obj, batch = _objective(tiny_run, walks, f"finetune.method={method}",
                            "finetune.baseline=antithetic", "finetune.likelihood=sample",
                            "finetune.explore_std=0.1")  # fmt: skip
    memo = obj.collect_frozen(batch, torch.Generator().manual_seed(0))
    main, twin = memo.acts
    a = whiten_per_group((main.reward - twin.reward) / 2, batch.scene, batch.num_scenes)
    a = memo.select(a)  # [K or 1, N, T_f]
    assert memo.adv.shape[0] == 2 * a.shape[0]
    torch.testing.assert_close(memo.adv[: a.shape[0]], a)
    assert torch.equal(memo.adv[a.shape[0] :], -memo.adv[: a.shape[0]])
    assert bool(a.abs().gt(0.1).any())


@pytest.mark.parametrize("ppo_epochs", [1, 2])
def test_the_value_loss_is_clipped_around_the_references_value(tiny_run, walks, ppo_epochs):
    """Eq. 16's clip centre is V_0, the critic's value of the reference prediction
    (``memo.values_ref``), not V itself (which would clip nothing). By hand: with V_0 put
    100 above the value target R and clip 0.2, clip(V, V_0 - 0.2, V_0 + 0.2) = R + 99.8 for
    any V within 99.8 of R, so the loss is 99.8^2 exactly; centred on V it would be
    (V - R)^2, a few units at most."""
    obj, batch = _objective(tiny_run, walks, "finetune.value_clip=0.2",
                            f"finetune.ppo_epochs={ppo_epochs}")  # fmt: skip
    gen = torch.Generator().manual_seed(0)
    memo = obj.collect(batch, gen, live=ppo_epochs == 1)
    memo.values_ref = memo.select(memo.v_target) + 100.0
    _, logs = obj.update(batch, memo, gen)
    assert logs["value_loss"] == pytest.approx(99.8**2, rel=1e-4)


# One table of fine-tuning methods (config.FinetuneMethod, config.USES_RL,
# rl.objective.LOSS_SAMPLES): the CLI offers its names, and a name that reaches a dispatch
# without an entry there is an error, never trained as RLHF-ReS (the walkthrough's finding: a
# new method's name took the k* path of ``RLObjective.selection``).


def test_every_method_has_its_entries():
    from trajpref.rl.objective import LOSS_SAMPLES

    assert set(config.USES_RL) == set(config.FINETUNE_METHODS)
    assert set(LOSS_SAMPLES) == {m for m in config.FINETUNE_METHODS if config.USES_RL[m]}


def test_an_rl_method_without_its_loss_samples_is_refused_by_selection(monkeypatch):
    """``RLObjective.selection`` (the walkthrough's case): a name other than ``rlhf`` got
    k* whatever it was; now a method without a ``LOSS_SAMPLES`` entry is an error."""
    monkeypatch.setitem(config.USES_RL, NEW, True)
    rl = FinetuneConfig()
    object.__setattr__(rl, "method", NEW)
    batch = SimpleNamespace(scene=torch.tensor([0, 0, 1]), num_scenes=2)
    score = torch.zeros(3, 3, 2)  # [K, N, T]
    with pytest.raises(ConfigError, match=r"'rlhf-new'.*LOSS_SAMPLES"):
        RLObjective.selection(SimpleNamespace(rl=rl), score, batch)
