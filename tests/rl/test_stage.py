"""The fine-tuning stage on tiny synthetic data."""

import pytest
import torch

from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.models import checkpoint as ckpt
from trajpref.rl.objective import best_sample, take_sample
from trajpref.rl.presets import preset_overrides
from trajpref.train.run import finetune
from trajpref.train.stages import build_finetune_stage
from trajpref.types import collate


def _cfg(start, *overrides):
    return load_config(None, list(overrides), base=start["config"])


def _stage(start, train, *overrides):
    return build_finetune_stage(_cfg(start, *overrides), start, train, torch.device("cpu"))


def _state(module):
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def test_best_sample_is_the_argmax_of_the_summed_score():
    r = torch.zeros(3, 3, 2)  # [K, N, T]; agents 0, 1 in scene 0, agent 2 in scene 1
    r[1, 0] = 1.0  # scene 0: k = 1 sums to 2
    r[2, 1] = 0.6  # scene 0: k = 2 sums to 1.2
    r[0, 2] = -1.0  # scene 1: k = 0 is worst; k = 1 and 2 tie at 0 -> first, k = 1
    r[2, 2] = 0.1  # scene 1: k = 2 best
    scene = torch.tensor([0, 0, 1])
    k_star = best_sample(r, scene, 2)
    assert k_star.tolist() == [1, 2]
    x = torch.arange(9.0).view(3, 3)  # x[k, n] = 3k + n
    assert take_sample(x, k_star, scene).tolist() == [[3.0, 4.0, 8.0]]


def test_steps_change_policy_and_critic_only(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    for method in ("rlhf", "rlhf-res"):
        cfg = _cfg(start, *preset_overrides("paper", method))
        stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
        obj = stage.objective
        ref, den = _state(obj.reference), _state(obj.denoiser)
        pol, cri = _state(obj.policy), _state(obj.critic)
        opt = torch.optim.Adam(stage.trainable.parameters(), lr=1e-2)
        gen = torch.Generator().manual_seed(0)
        for i in range(3):
            loss, logs = obj(collate(train.scenes[i * 3 : i * 3 + 3]), gen)
            opt.zero_grad()
            loss.backward()
            opt.step()
        for name, before, module in (("reference", ref, obj.reference),
                                     ("denoiser", den, obj.denoiser)):  # fmt: skip
            for k, v in module.state_dict().items():
                assert torch.equal(before[k], v), f"{method}: frozen {name}.{k} changed"
        assert any(not torch.equal(pol[k], v) for k, v in obj.policy.state_dict().items())
        assert any(not torch.equal(cri[k], v) for k, v in obj.critic.state_dict().items())
        assert {"reward", "kl_div", "clip_fraction", "approx_kl", "value_loss",
                "explained_variance"} <= set(logs)  # fmt: skip


def test_kl_term_is_zero_before_the_first_update(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    for form in ("paper", "logratio"):
        cfg = _cfg(start, f"finetune.kl_form={form}", "finetune.kl_coef=1.0")
        stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
        _, logs = stage.objective(collate(train.scenes[:4]), torch.Generator().manual_seed(0))
        assert logs["kl_div"] == 0.0 and logs["approx_kl"] == 0.0
        assert logs["reward_total"] == logs["reward"]


def _mean_reward(stage, scenes) -> float:
    obj = stage.objective.eval()
    with torch.no_grad():
        _, logs = obj(collate(scenes), torch.Generator().manual_seed(0))
    return logs["reward"]


@pytest.mark.parametrize("baseline", ["critic", "antithetic"])
def test_tiny_finetune_raises_the_mean_reward(tiny_run, walks, tmp_path, baseline):
    """A smoke test of the whole run, not of the gradient: with random advantages in place of
    the real ones its critic variant still passed in 3 of 6 draws. The wiring it cannot
    catch (per-scene whitening, the twin's -A, the value clip's centre) is checked by hand in
    test_objective.py."""
    start_path = tiny_run / "generator.safetensors"
    start = ckpt.load(start_path)
    train = load_dataset(str(walks), "train")
    cfg = _cfg(start, "finetune.method=rlhf", "finetune.reg_weight=0", "finetune.lr=3e-3",
               "finetune.policy_weight=1", "finetune.epochs=8", "finetune.warmup_steps=1",
               "finetune.adv_norm=scene", "finetune.eval_every=8",
               "finetune.ratio_against=rollout", "finetune.likelihood=sample",
               "finetune.explore_std=0.1", f"finetune.baseline={baseline}")  # fmt: skip
    before = _mean_reward(build_finetune_stage(cfg, start, train, torch.device("cpu")),
                          train.scenes)  # fmt: skip
    finetune(cfg, start_path, tmp_path, device="cpu", progress=False)
    last = torch.load(tmp_path / "finetune_last.pt", weights_only=True)
    stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
    stage.trainable.load_state_dict(last["trainable"])
    after = _mean_reward(stage, train.scenes)
    assert after > before, (before, after)
    # the result loads like any model
    assert ckpt.load_predictor(tmp_path / "finetune.safetensors").generator is not None


def test_finetune_config_takes_todays_defaults_not_the_checkpoints_section(tiny_run, tmp_path):
    from trajpref.config import FinetuneConfig
    from trajpref.rl.presets import finetune_config

    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["finetune"] = {**payload["config"]["finetune"], "epochs": 99,
                                     "kl_form": "paper"}  # fmt: skip
    path = tmp_path / "old.safetensors"
    ckpt.save(path, payload)
    cfg = finetune_config(str(path), "rlhf", None, None, ["finetune.lr=0.01"], 3)
    want = FinetuneConfig(method="rlhf", lr=0.01)
    assert cfg.finetune == want and cfg.seed == 3
    assert cfg.model == load_config(None, [], base=payload["config"]).model
    paper = finetune_config(str(path), "rlhf-res", "paper", None, [], None).finetune
    assert (paper.kl_form, paper.likelihood, paper.score_every) == ("paper", "mean", 3)


def test_antithetic_needs_the_sample_likelihood(tiny_run):
    from trajpref.config import ConfigError

    start = ckpt.load(tiny_run / "generator.safetensors")
    with pytest.raises(ConfigError, match="antithetic needs"):
        _cfg(start, "finetune.baseline=antithetic", "finetune.likelihood=mean")
    with pytest.raises(ConfigError, match="baseline must be"):
        _cfg(start, "finetune.baseline=none")


def test_antithetic_steps_move_the_policy_and_keep_the_reference(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    for method in ("rlhf", "rlhf-res"):
        cfg = _cfg(start, f"finetune.method={method}", "finetune.baseline=antithetic")
        obj = build_finetune_stage(cfg, start, train, torch.device("cpu")).objective
        ref, pol = _state(obj.reference), _state(obj.policy)
        loss, logs = obj(collate(train.scenes[:3]))  # no generator: one is made per step
        loss.backward()
        torch.optim.SGD(obj.policy.parameters(), lr=1e-2).step()
        assert all(torch.equal(ref[k], v) for k, v in obj.reference.state_dict().items())
        assert any(not torch.equal(pol[k], v) for k, v in obj.policy.state_dict().items())
        assert torch.isfinite(loss) and logs["kl_div"] == 0.0


def test_ppo_epochs_move_the_ratio_away_from_one_and_clip(tiny_run, walks):
    """Several update epochs on one collected rollout: the first sees ratio 1 (nothing
    clipped, approx-KL 0), later ones a moved policy (ratio != 1, some ratios clipped)."""
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    cfg = _cfg(start, "finetune.ppo_epochs=4", "finetune.ratio_against=rollout",
               "finetune.likelihood=sample", "finetune.explore_std=0.05",
               "finetune.policy_weight=1", "finetune.clip=0.05")  # fmt: skip
    stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
    assert stage.updates == 4 and stage.collect is not None
    obj = stage.objective
    batch = collate(train.scenes[:6])
    gen = torch.Generator().manual_seed(0)
    memo = stage.collect(batch, gen)
    opt = torch.optim.SGD(stage.trainable.parameters(), lr=0.5)
    seen = []
    for _ in range(4):
        loss, logs = obj(batch, gen, memo)
        opt.zero_grad()
        loss.backward()
        opt.step()
        seen.append((logs["approx_kl"], logs["clip_fraction"]))
    assert seen[0] == (0.0, 0.0)  # the rollout policy itself
    assert any(kl > 0 for kl, _ in seen[1:])
    assert any(frac > 0 for _, frac in seen[1:])


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_the_loops_first_ppo_epoch_sees_ratio_one_in_every_precision(
    tiny_run, walks, tmp_path, monkeypatch, precision
):
    """The loop collects the rollout in the update's precision: in bf16 too, the first update
    epoch on each rollout compares the policy with itself (ratio exactly 1, nothing clipped);
    collected in fp32 and updated under bf16 autocast, rounding alone clipped a third."""
    from trajpref.rl.objective import RLObjective

    seen = []  # (rollout, approx-KL, clip fraction) per update; the rollouts kept alive
    update = RLObjective.update

    def recording(self, batch, memo, generator=None):
        loss, logs = update(self, batch, memo, generator)
        seen.append((memo, logs["approx_kl"], logs["clip_fraction"]))
        return loss, logs

    monkeypatch.setattr(RLObjective, "update", recording)
    start_path = tiny_run / "generator.safetensors"
    cfg = _cfg(ckpt.load(start_path), "finetune.ppo_epochs=2", "finetune.epochs=1",
               "finetune.steps_per_epoch=2", "finetune.eval_max_scenes=2",
               "finetune.ratio_against=rollout", "finetune.likelihood=sample",
               "finetune.explore_std=0.05", "finetune.clip=0.05",
               f"finetune.precision={precision}")  # fmt: skip
    finetune(cfg, start_path, tmp_path, device="cpu", progress=False)
    memos = [memo for memo, _, _ in seen]
    assert len(seen) == 4 and memos[0] is memos[1] and memos[2] is memos[3]
    assert memos[0] is not memos[2]  # two rollouts, two update epochs on each
    assert [(kl, frac) for _, kl, frac in seen[::2]] == [(0.0, 0.0)] * 2


def test_clean_l_reg_ignores_the_exploration(tiny_run, walks):
    """reg_on=clean: L_reg does not depend on the exploration noise's size."""
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:4])
    reg = {}
    for on in ("clean", "explored"):
        for std in (0.01, 1.0):
            obj = _stage(start, train, f"finetune.reg_on={on}",
                         f"finetune.explore_std={std}").objective  # fmt: skip
            reg[on, std] = obj(batch, torch.Generator().manual_seed(0))[1]["reg_loss"]
    assert reg["clean", 0.01] == pytest.approx(reg["clean", 1.0], rel=1e-6)
    assert reg["explored", 1.0] > reg["explored", 0.01]


def test_the_control_trains_the_policy_on_the_supervised_loss_only(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    stage = _stage(start, train, "finetune.method=control")
    obj = stage.objective
    pol, cri = _state(obj.policy), _state(obj.critic)
    loss, logs = obj(collate(train.scenes[:4]), torch.Generator().manual_seed(0))
    assert "reward" not in logs and logs["reg_loss"] == pytest.approx(float(loss.detach()))
    loss.backward()
    torch.optim.SGD(stage.trainable.parameters(), lr=1e-2).step()
    assert any(not torch.equal(pol[k], v) for k, v in obj.policy.state_dict().items())
    assert all(torch.equal(cri[k], v) for k, v in obj.critic.state_dict().items())


def test_the_set_reward_steps_and_differs_from_the_score(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:4])
    logs = {}
    for reward in ("score", "set"):
        stage = _stage(start, train, f"finetune.reward={reward}")
        loss, logs[reward] = stage.objective(batch, torch.Generator().manual_seed(0))
        loss.backward()
        assert all(torch.isfinite(p.grad).all() for p in stage.objective.policy.parameters()
                   if p.grad is not None)  # fmt: skip
    assert logs["set"]["reward"] == logs["score"]["reward"]  # the same samples, same score
    assert logs["set"]["reward_total"] != logs["score"]["reward_total"]


def test_smooth_exploration_explores_in_the_smooth_span_and_steps(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    stage = _stage(start, train, "finetune.explore=smooth", "finetune.explore_std=0.2")
    obj = stage.objective
    batch = collate(train.scenes[:4])
    policy, _, _ = obj.rollouts(
        batch, obj.sampler.condition(batch), torch.Generator().manual_seed(0)
    )
    q = obj.basis  # [T, 2]
    xi = policy.explore  # [K, N, T, 2]
    inside = torch.einsum("tj,sj,knsd->kntd", q, q, xi)
    assert torch.allclose(inside, xi, atol=1e-5) and float(xi.abs().max()) > 0.05
    before = _state(obj.policy)
    opt = torch.optim.Adam(stage.trainable.parameters(), lr=1e-2)
    loss, logs = obj(batch, torch.Generator().manual_seed(0))
    opt.zero_grad()
    loss.backward()
    opt.step()
    assert torch.isfinite(loss) and any(not torch.equal(before[k], v)
                                        for k, v in obj.policy.state_dict().items())  # fmt: skip


def test_a_policy_trained_with_dropout_fine_tunes_without_it(tiny_run, walks):
    """The PPO ratio of the first update epoch is exactly 1 even when the start was trained
    with dropout: the loop's ``train()`` leaves the policy's dropout layers off."""
    start = ckpt.load(tiny_run / "generator.safetensors")
    start["config"]["model"]["generator_dropout"] = 0.5  # same parameter names, so it loads
    train = load_dataset(str(walks), "train")
    cfg = _cfg(start, "finetune.ppo_epochs=2", "finetune.ratio_against=rollout",
               "finetune.likelihood=sample", "finetune.explore_std=0.05")  # fmt: skip
    stage = build_finetune_stage(cfg, start, train, torch.device("cpu"))
    obj = stage.objective.train()
    drops = [m for m in obj.policy.modules() if isinstance(m, torch.nn.Dropout)]
    assert drops and not any(m.training for m in drops)
    assert obj.policy.training  # the rest of the policy trains
    batch = collate(train.scenes[:6])
    gen = torch.Generator().manual_seed(0)
    _, logs = obj(batch, gen, stage.collect(batch, gen))
    assert logs["approx_kl"] == 0.0 and logs["clip_fraction"] == 0.0


def test_validation_samples_without_dropout_whatever_mode_the_caller_left(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    start["config"]["model"]["generator_dropout"] = 0.5  # as if trained with dropout
    val = load_dataset(str(walks), "val")
    stage = _stage(start, val, "finetune.eval_max_scenes=4")
    drops = [m for m in stage.objective.policy.modules() if isinstance(m, torch.nn.Dropout)]
    assert drops and not any(m.training for m in drops)  # built for prediction: eval mode
    stage.objective.policy.train()  # a caller that leaves dropout on
    first, second = stage.validate(), stage.validate()
    assert first == second  # no dropout noise: the same seed gives the same samples
    assert all(m.training for m in drops)  # the caller's modes are restored
    stage.objective.eval()
    assert stage.validate() == first  # as the training loop validates


def test_a_finetuned_checkpoint_records_its_method_reward_and_start(tiny_run, tmp_path):
    from trajpref.io import read_checkpoint_header
    from trajpref.rl.presets import finetune_config

    start_path = tiny_run / "generator.safetensors"
    cfg = finetune_config(str(start_path), "rlhf-res", overrides=[
        "finetune.reward=sda", "finetune.epochs=1", "finetune.steps_per_epoch=1",
        "finetune.eval_max_scenes=2"])  # fmt: skip
    finetune(cfg, start_path, tmp_path, device="cpu", progress=False)
    meta = read_checkpoint_header(tmp_path / "finetune.safetensors")["meta"]
    start_hash = read_checkpoint_header(start_path)["hash"]
    assert (meta["method"], meta["reward"], meta["from"]) == ("rlhf-res", "sda", start_hash)
