"""A reward of the user's own (rl/rewards.py): registered by name from Python, trained on by
both RL methods, blind to the ground truth, checked, recorded in the checkpoint by name only,
refused where it is not registered (the CLI, a resuming process). docs/rlhf.md's example runs
here on the tiny fixtures."""

import re
from pathlib import Path

import pytest
import torch

from trajpref.cli import main
from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.data.transforms import from_model_frame
from trajpref.errors import ConfigError
from trajpref.io import read_checkpoint_header
from trajpref.models import checkpoint as ckpt
from trajpref.rl import register_reward, registered_reward, registered_rewards, unregister_reward
from trajpref.rl.presets import finetune_config
from trajpref.rl.rewards import RewardError
from trajpref.train import finetune, read_metrics
from trajpref.train.stages import build_finetune_stage
from trajpref.types import collate

RLHF_MD = Path(__file__).resolve().parents[2] / "docs" / "rlhf.md"
TINY = ["finetune.epochs=1", "finetune.steps_per_epoch=1", "finetune.eval_max_scenes=2"]


def slowness(batch, futures, cfg):
    """Minus the length of each future step (the first from the last observed position):
    prefers slower futures. [M, N, T_f, 2] -> [M, N, T_f]."""
    start = batch.history[:, -1].expand(futures.shape[0], -1, -1)[:, :, None]  # [M, N, 1, 2]
    return -torch.diff(futures, dim=2, prepend=start).norm(dim=-1)


class Recorder:
    """A reward that keeps what it was given and what it returned."""

    def __init__(self, fn=slowness):
        self.fn, self.calls = fn, []

    def __call__(self, batch, futures, cfg):
        r = self.fn(batch, futures, cfg)
        self.calls.append({"batch": batch, "futures": futures.clone(), "r": r.clone(),
                           "cfg": cfg})  # fmt: skip
        return r


def _stage(start, train, *overrides):
    cfg = load_config(None, list(overrides), base=start["config"])
    return build_finetune_stage(cfg, start, train, torch.device("cpu"))


def _state(module):
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def _files(folder: Path) -> dict[str, float]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*")}


# --- registration ---


def test_registration_refuses_builtin_names_bad_names_and_non_callables():
    for name in ("score", "set", "sda"):
        with pytest.raises(ConfigError, match=rf"^register_reward: '{name}' is a built-in reward "
                           r"\(score, set, sda\); register yours under another name$"):  # fmt: skip
            register_reward(name, slowness)
    for name in ("", "9lives", "two words", "café", "a.b", None, 3):
        with pytest.raises(ConfigError, match=r"^register_reward: a reward's name is an ASCII "
                           r"letter, then letters, digits, '_' or '-'"):  # fmt: skip
            register_reward(name, slowness)
    with pytest.raises(TypeError, match=r"^register_reward\('comfort', fn\): fn must be a callable "
                       r"\(batch, futures, cfg\) -> reward \[M, N, T_f\], got int$"):  # fmt: skip
        register_reward("comfort", 3)
    with pytest.raises(TypeError, match=r"fn must take three arguments \(batch, futures, cfg\), "
                       r"and .*<lambda> does not"):  # fmt: skip
        register_reward("comfort", lambda batch, futures: futures[..., 0])
    assert registered_rewards() == ()  # nothing refused was registered


def test_register_unregister_and_the_context_manager():
    register_reward("comfort", slowness)
    register_reward("comfort", slowness)  # the same function again: fine
    assert registered_rewards() == ("comfort",)
    other = Recorder()
    with pytest.raises(ConfigError, match=r"^register_reward: 'comfort' is registered already "
                       r"\(to slowness\); unregister_reward\('comfort'\) first, or pass "
                       r"replace=True$"):  # fmt: skip
        register_reward("comfort", other)
    register_reward("comfort", other, replace=True)
    with pytest.raises(ConfigError, match="'comfort' is registered already"):
        with registered_reward("comfort", slowness):
            pass
    unregister_reward("comfort")
    assert registered_rewards() == ()
    with pytest.raises(ConfigError, match=r"^unregister_reward: no reward 'comfort' is "
                       r"registered \(the built-in rewards are score, set, sda; registered in "
                       r"this process: none\)$"):  # fmt: skip
        unregister_reward("comfort")
    with pytest.raises(ConfigError, match=r"^unregister_reward: 'sda' is a built-in reward"):
        unregister_reward("sda")
    with pytest.raises(RuntimeError, match="inside"):
        with registered_reward("comfort", slowness) as fn:
            assert fn is slowness and registered_rewards() == ("comfort",)
            raise RuntimeError("inside")
    assert registered_rewards() == ()  # taken back whatever the block raised


# --- refused where it is not registered ---


def test_an_unregistered_reward_is_refused_naming_the_registered_ones(tiny_run, walks):
    start = str(tiny_run / "generator.safetensors")
    how = (r"A reward of your own is registered from Python before fine-tuning, and again in a "
           r"process that resumes its run: trajpref\.rl\.register_reward\('comfort', fn\), then "
           r"rl\.presets\.finetune_config and train\.finetune \(docs/rlhf\.md, \"A reward of "
           r"your own\"\); the trajpref command cannot register Python code")  # fmt: skip
    with pytest.raises(ConfigError, match=r"^finetune\.reward=comfort: no such reward in this "
                       r"process; the built-in rewards are score, set, sda; registered in this "
                       r"process: none\. " + how):  # fmt: skip
        finetune_config(start, "rlhf", overrides=["finetune.reward=comfort"])
    with registered_reward("slow", slowness), registered_reward("quiet", slowness):
        with pytest.raises(ConfigError, match=r"^finetune\.reward=comfort: .*registered in this "
                           r"process: quiet, slow\. "):  # fmt: skip
            finetune_config(start, "rlhf-res", overrides=["finetune.reward=comfort"])
        with pytest.raises(ConfigError, match=r"^finetune\.reward=slwo: no such reward in this "
                           r"process \(did you mean slow\?\)"):  # fmt: skip
            finetune_config(start, "rlhf-res", overrides=["finetune.reward=slwo"])
    # a config built without finetune_config: the objective refuses it, before any step
    payload = ckpt.load(start)
    train = load_dataset(str(walks), "train")
    with pytest.raises(ConfigError, match=r"^finetune\.reward=comfort: no such reward"):
        _stage(payload, train, "finetune.method=rlhf", "finetune.reward=comfort")
    # the control reads no reward: its name is not looked up
    _stage(payload, train, "finetune.method=control", "finetune.reward=comfort")


def test_the_cli_refuses_a_reward_it_cannot_register_with_a_pointer_to_python(
    capsys, tiny_run, tmp_path
):
    argv = ["finetune", "--method", "rlhf", "--from", tiny_run / "generator.safetensors",
            "--out", tmp_path / "ft", "--set", "finetune.reward=comfort", "--device", "cpu",
            "--no-progress"]  # fmt: skip
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("trajpref: error: finetune.reward=comfort: no such reward")
    assert "trajpref.rl.register_reward('comfort', fn)" in err
    assert "the trajpref command cannot register Python code" in err
    assert not (tmp_path / "ft").exists()


# --- what the objective does with it ---


@pytest.mark.parametrize("method", ["rlhf", "rlhf-res"])
def test_a_step_trains_on_the_registered_reward_blind_to_the_future(tiny_run, walks, method):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:4])
    reward = Recorder()
    with registered_reward("slow", reward):
        stage = _stage(start, train, f"finetune.method={method}", "finetune.reward=slow",
                       "finetune.reward_clip=null")  # fmt: skip
    obj = stage.objective  # the callable was looked up when the objective was built

    def no_score(*args, **kwargs):
        raise AssertionError("a registered reward must not call the diffusion score")

    obj.scorer.step_scores = no_score
    before = _state(obj.policy)
    memo = obj.collect_frozen(batch, torch.Generator().manual_seed(0))
    (call,) = reward.calls
    k, n, t_f = obj.policy.samples, batch.num_agents, batch.future.shape[1]
    # the futures in absolute coordinates, the future hidden, the run's config
    assert call["futures"].shape == (k, n, t_f, 2)
    absolute = from_model_frame(memo.acts[0].action, batch, obj.sampler.scale)
    assert torch.allclose(call["futures"], absolute)
    assert torch.isnan(call["batch"].future).all() and torch.isfinite(batch.future).all()
    assert torch.equal(call["batch"].history, batch.history) and call["cfg"] is obj.rl
    assert torch.equal(memo.acts[0].score, call["r"])  # the reward is the callable's
    if method == "rlhf-res":  # k*: each scene's sample of the highest summed reward
        scenes = batch.scene
        best = [int(call["r"][:, scenes == b].sum((1, 2)).argmax()) for b in range(4)]
        chosen = torch.stack([call["r"][best[s], i] for i, s in enumerate(scenes)])  # [N, T_f]
        assert torch.equal(memo.select(memo.acts[0].score)[0], chosen)
    # one step: the reward it logs is the callable's mean, and the policy moves
    loss, logs = obj(batch, torch.Generator().manual_seed(0))
    assert logs["reward"] == pytest.approx(float(reward.calls[-1]["r"].mean()), rel=1e-6)
    opt = torch.optim.Adam(stage.trainable.parameters(), lr=1e-2)
    loss.backward()
    opt.step()
    assert torch.isfinite(loss)
    assert any(not torch.equal(before[k], v) for k, v in obj.policy.state_dict().items())


def test_reward_clip_applies_to_a_registered_reward(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:3])

    def big(batch, futures, cfg):
        return torch.full(futures.shape[:-1], 100.0).to(futures)

    with registered_reward("big", big):
        for clip, want in (("2", 2.0), ("null", 100.0)):
            obj = _stage(start, train, "finetune.method=rlhf", "finetune.reward=big",
                         f"finetune.reward_clip={clip}").objective  # fmt: skip
            _, logs = obj(batch, torch.Generator().manual_seed(0))
            assert logs["reward"] == want


def test_a_reward_that_reads_the_ground_truth_gets_nan_and_bad_returns_are_named(tiny_run, walks):
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:3])

    def cheat(batch, futures, cfg):  # the distance to the ground truth: it cannot see it
        return -(futures - batch.future).norm(dim=-1)

    def one_per_agent(batch, futures, cfg):
        return futures.norm(dim=-1).sum(-1)  # [M, N]: not per step

    def a_float(batch, futures, cfg):
        return 1.0

    def infinite(batch, futures, cfg):
        r = slowness(batch, futures, cfg)
        r[0, 0, 0] = float("inf")
        return r

    cases = {
        cheat: r"^reward 'bad' returned \d+ non-finite values of \d+ \(NaN or inf\); it must be "
               r"finite everywhere \(the batch's future is NaN: a reward that reads it gets NaN\)$",
        one_per_agent: r"^reward 'bad' returned shape \[\d+, \d+\]; it must return \[M, N, T_f\] "
                       r"= \[\d+, \d+, \d+\]",
        a_float: r"^reward 'bad' returned a float; it must return a tensor \[M, N, T_f\]",
        infinite: r"^reward 'bad' returned 1 non-finite values of ",
    }  # fmt: skip
    for fn, message in cases.items():
        with registered_reward("bad", fn):
            obj = _stage(start, train, "finetune.method=rlhf", "finetune.reward=bad").objective
            with pytest.raises(RewardError, match=message):
                obj(batch, torch.Generator().manual_seed(0))


def test_a_reward_that_changes_the_batch_does_not_change_the_update(tiny_run, walks):
    """The callable gets copies: a reward that writes into them leaves the step as it was."""
    start = ckpt.load(tiny_run / "generator.safetensors")
    train = load_dataset(str(walks), "train")
    batch = collate(train.scenes[:3])

    def vandal(batch, futures, cfg):
        r = slowness(batch, futures, cfg)
        batch.history.zero_()
        batch.scene.zero_()
        return r

    losses = {}
    for name, fn in (("clean", slowness), ("vandal", vandal)):
        with registered_reward(name, fn):
            obj = _stage(start, train, "finetune.method=rlhf", f"finetune.reward={name}").objective
            losses[name] = obj(batch, torch.Generator().manual_seed(0))[0].detach()
    assert torch.equal(losses["clean"], losses["vandal"])


def test_a_registered_reward_reads_no_score_setting_and_its_run_refuses_them(tiny_run, walks):
    start = str(tiny_run / "generator.safetensors")
    with registered_reward("slow", slowness):
        for key, value in (("score_every", 3), ("sda_radius", 3), ("set_alpha", 2)):
            with pytest.raises(ConfigError, match=rf"^finetune\.{key}: .* this run's reward is "
                               r"slow"):  # fmt: skip
                finetune_config(start, "rlhf", overrides=["finetune.reward=slow",
                                                         f"finetune.{key}={value}"])  # fmt: skip
        with pytest.raises(ConfigError, match=r"reward is slow, which computes no diffusion"):
            finetune_config(start, "rlhf", overrides=["finetune.reward=slow",
                                                     "finetune.score_every=3"])  # fmt: skip
        for method in ("rlhf", "rlhf-res"):  # reward_clip is read; the paper preset is fine
            finetune_config(start, method, overrides=["finetune.reward=slow",
                                                     "finetune.reward_clip=2"])  # fmt: skip
            finetune_config(start, method, "paper", overrides=["finetune.reward=slow"])
        # what the refusal claims: score_every leaves the loss bit for bit as it was
        payload, train = ckpt.load(start), load_dataset(str(walks), "train")
        batch = collate(train.scenes[:3])
        losses = []
        for every in (9, 3):
            obj = _stage(payload, train, "finetune.method=rlhf", "finetune.reward=slow",
                         f"finetune.score_every={every}").objective  # fmt: skip
            with torch.no_grad():  # the policy leaves the reference: KL and ratios are not 0, 1
                for p in obj.policy.parameters():
                    p.add_(0.005 * torch.randn(p.shape, generator=torch.Generator().manual_seed(1)))
            losses.append(obj(batch, torch.Generator().manual_seed(0))[0].detach())
        assert torch.equal(losses[0], losses[1])


# --- a whole run: log, checkpoint, resume ---


def test_a_tiny_finetune_logs_the_reward_records_its_name_and_resumes_only_registered(
    capsys, tiny_run, walks, tmp_path
):
    start = tiny_run / "generator.safetensors"
    out = tmp_path / "slow"
    reward = Recorder()
    with registered_reward("slow", reward):
        cfg = finetune_config(str(start), "rlhf-res", overrides=["finetune.reward=slow", *TINY])
        longer = ["finetune.reward=slow", *TINY, "finetune.epochs=2"]
        again = finetune_config(str(start), "rlhf-res", overrides=longer)
        finetune(cfg, start, out, device="cpu", progress=False)
    (row,) = read_metrics(out, "finetune")
    (call,) = reward.calls  # one step, one call (validation does not call the reward)
    clipped = call["r"].clamp(-cfg.finetune.reward_clip, cfg.finetune.reward_clip)  # 5
    assert row["train_reward"] == pytest.approx(float(clipped.mean()), rel=1e-6)
    tuned = out / "finetune.safetensors"
    header = read_checkpoint_header(tuned)
    assert (header["meta"]["method"], header["meta"]["reward"]) == ("rlhf-res", "slow")
    assert ckpt.finetune_reward(header) == "slow"
    # unregistered now: the checkpoint loads and evaluates all the same (no code is run)
    assert ckpt.load_predictor(tuned).generator is not None
    code = main(["evaluate", "--dataset", str(walks), "--model", str(tuned), "--samples", "2",
                 "--json", "--no-progress", "--device", "cpu"])  # fmt: skip
    assert code == 0 and '"finetune_reward": "slow"' in capsys.readouterr().out
    # a resume in a process without the reward is refused, before anything is written
    files = _files(out)
    with pytest.raises(ConfigError, match=r"^finetune\.reward=slow: no such reward in this "
                       r"process; .* and again in a process that resumes its run"):  # fmt: skip
        finetune(again, start, out, device="cpu", progress=False,
                 resume=str(out / "finetune_last.pt"))  # fmt: skip
    assert _files(out) == files
    with registered_reward("slow", reward):  # registered again: it resumes
        finetune(again, start, out, device="cpu", progress=False,
                 resume=str(out / "finetune_last.pt"))  # fmt: skip
    assert [r["epoch"] for r in read_metrics(out, "finetune")] == [1, 2]
    assert len(reward.calls) == 2


def test_a_registered_reward_sees_the_datasets_own_coordinates(capsys, tiny_run, walks,
                                                                tmp_path):  # fmt: skip
    """The start's augmentation asked for (rotation, mirror, jitter, scaling): a registered
    reward is still given each scene as the dataset has it (its histories are the dataset's
    own, not rotated or mirrored ones), and its run says why it trains without augmentation.
    The built-in ``sda`` keeps rotation and mirror, and trains without scaled scenes (its
    thresholds are distances)."""
    start = tiny_run / "generator.safetensors"
    aug = ["data.rotate=true", "data.flip=true", "data.history_noise=0.05",
           "data.scale_min=0.8", "data.scale_max=1.2"]  # fmt: skip
    reward = Recorder()
    with registered_reward("slow", reward):
        cfg = finetune_config(str(start), "rlhf", overrides=[
            "finetune.reward=slow", "finetune.epochs=1", "finetune.steps_per_epoch=3",
            "finetune.eval_max_scenes=2", *aug])  # fmt: skip
        assert cfg.data.rotate and cfg.data.flip  # asked for; the run turns them off
        finetune(cfg, start, tmp_path / "slow", device="cpu", progress=False)
    train = load_dataset(str(walks), "train")
    own = torch.cat([torch.as_tensor(s.history).float() for s in train.scenes])  # [A, T_h, 2]
    assert len(reward.calls) == 3
    for call in reward.calls:
        seen = call["batch"].history  # [N, T_h, 2]
        gap = (seen[:, None] - own[None]).abs().amax((-2, -1)).min(1).values  # [N]
        assert float(gap.max()) < 1e-5, gap  # each agent's history is one of the dataset's
    saved = load_config(tmp_path / "slow" / "finetune_config.yaml", [])
    assert not (saved.data.rotate or saved.data.flip or saved.data.history_noise)
    assert "trains without augmentation (data.rotate, data.flip" in capsys.readouterr().err
    sda = finetune_config(str(start), "rlhf", overrides=["finetune.reward=sda", *TINY, *aug])
    finetune(sda, start, tmp_path / "sda", device="cpu", progress=False)
    err = capsys.readouterr().err
    assert "without augmentation" not in err
    assert "thresholds are distances" in err and "(data.scale_min, data.scale_max off)" in err
    saved = load_config(tmp_path / "sda" / "finetune_config.yaml", [])
    assert saved.data.rotate and saved.data.flip  # distances unchanged: kept
    assert (saved.data.scale_min, saved.data.scale_max) == (1.0, 1.0)  # stretched them: off


# --- the documented example ---


def test_the_docs_example_runs(tiny_run, tmp_path, monkeypatch):
    """docs/rlhf.md's block, as written but for the start (the tiny generator for the
    published one), the run's length, and the run folder (under tmp_path)."""
    section = RLHF_MD.read_text().split("## A reward of your own (Python API)", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    swaps = {
        '"zara1/generator"': repr(str(tiny_run / "generator.safetensors")),
        'overrides=["finetune.reward=slow"]': f'overrides=["finetune.reward=slow", *{TINY}]',
    }
    for old, new in swaps.items():
        assert code.count(old) == 1, old
        code = code.replace(old, new)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, str(RLHF_MD), "exec"), namespace)  # noqa: S102 - our own docs
    assert registered_rewards() == ()  # the with block took it back
    assert "min_fde" in namespace["summary"]["best"]
    header = read_checkpoint_header(tmp_path / "runs" / "zara1-slow" / "finetune.safetensors")
    assert header["meta"]["reward"] == "slow"
    # and the example's reward prefers slower futures: half the speed, a higher reward
    history = torch.zeros(1, 8, 2)
    fast = torch.stack([torch.arange(1.0, 13.0), torch.zeros(12)], -1)[None, None]  # [1,1,12,2]
    slow, observed = namespace["slow"], _Observed(history)
    assert bool((slow(observed, fast / 2, None) > slow(observed, fast, None)).all())


class _Observed:
    """A stand-in batch: what the example's reward reads (the history)."""

    def __init__(self, history):
        self.history = history
