"""train/loop.py's learning-rate schedule: a linear warm-up, then a cosine decay from lr to
``final_lr * lr``; a line when the warm-up lasts the whole run."""

import dataclasses
import math

import pytest
import torch

from trajpref.config import OptimConfig
from trajpref.errors import ConfigError
from trajpref.train.loop import _lr_lambda, make_optimizer, warmup_note


def test_the_default_schedule_is_the_published_one_warm_up_then_cosine_to_a_tenth():
    f = _lr_lambda(OptimConfig(warmup_steps=4), total=104)
    assert [f(s) for s in range(4)] == pytest.approx([0.25, 0.5, 0.75, 1.0])
    assert f(4) == pytest.approx(1.0)  # the decay starts at the peak
    assert f(54) == pytest.approx(0.55)  # half-way: 0.1 + 0.9 * 0.5
    assert f(104) == pytest.approx(0.1)
    assert f(500) == pytest.approx(0.1)  # past the end it stays at the floor
    # a golden value a quarter of the way: 0.1 + 0.45 * (1 + cos(pi / 4))
    assert f(29) == pytest.approx(0.1 + 0.45 * (1 + math.cos(math.pi / 4)))


@pytest.mark.parametrize("final", [0.0, 0.01, 0.5, 1.0])
def test_final_lr_sets_where_the_cosine_ends_and_nothing_before_its_decay(final):
    f = _lr_lambda(OptimConfig(warmup_steps=0, final_lr=final), total=100)
    assert f(0) == pytest.approx(1.0)
    assert f(50) == pytest.approx((1 + final) / 2)
    assert f(100) == pytest.approx(final)
    values = [f(s) for s in range(101)]
    assert all(a >= b - 1e-12 for a, b in zip(values[:-1], values[1:], strict=True))  # never rises


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_a_final_lr_outside_zero_to_one_is_a_clear_error(bad):
    with pytest.raises(ConfigError, match="final_lr"):
        OptimConfig(final_lr=bad)


def test_a_budget_schedule_decays_by_the_larger_of_the_steps_and_the_budgets_share():
    share = {"value": 0.0}
    cfg = OptimConfig(warmup_steps=0, max_minutes=10.0, budget_schedule=True)
    f = _lr_lambda(cfg, total=100, budget_share=lambda: share["value"])
    assert f(50) == pytest.approx(0.55)  # no time spent: the steps' own schedule
    share["value"] = 0.75  # three quarters of the budget, a quarter of the steps
    assert f(25) == pytest.approx(0.1 + 0.45 * (1 + math.cos(0.75 * math.pi)))
    assert f(90) == pytest.approx(0.1 + 0.45 * (1 + math.cos(0.9 * math.pi)))  # steps lead
    share["value"] = 1.3  # past the budget: the floor, not a rise
    assert f(10) == pytest.approx(0.1)


def test_without_a_budget_schedule_the_time_spent_does_not_touch_the_rate():
    f = _lr_lambda(OptimConfig(warmup_steps=0, max_minutes=10.0), total=100,
                   budget_share=lambda: 0.9)  # fmt: skip
    assert f(50) == pytest.approx(0.55)


def test_the_warm_up_is_by_steps_even_with_a_budget_schedule():
    cfg = OptimConfig(warmup_steps=4, max_minutes=1.0, budget_schedule=True)
    f = _lr_lambda(cfg, total=104, budget_share=lambda: 0.5)
    assert [f(s) for s in range(4)] == pytest.approx([0.25, 0.5, 0.75, 1.0])
    # then the step the budget's half stands for: 52 of 104, 48 of the 100 decay steps
    assert f(4) == pytest.approx(0.1 + 0.45 * (1 + math.cos(0.48 * math.pi)))


def test_a_budget_schedule_without_a_budget_is_a_clear_error():
    with pytest.raises(ConfigError, match="budget_schedule .* needs the same stage.s max_minutes"):
        OptimConfig(budget_schedule=True)


def test_the_fused_optimiser_steps_like_the_default_up_to_float_rounding():
    # docs/pretraining.md, "Fused AdamW steps": 20 steps of the same gradients on a small
    # network; PyTorch's default loops over the parameters on the CPU, fused does the same sums
    # in one kernel
    torch.manual_seed(0)
    shapes = [(64, 32), (64,), (8, 64), (8,)]
    start = [torch.randn(s) for s in shapes]
    grads = [[torch.randn(s) for s in shapes] for _ in range(20)]
    out = {}
    for fused in (False, True):
        params = [torch.nn.Parameter(x.clone()) for x in start]
        opt = make_optimizer(params, OptimConfig(lr=1e-2, weight_decay=0.1, fused=fused))
        assert opt.defaults["fused"] is (True if fused else None)
        for step in grads:
            for p, g in zip(params, step, strict=True):
                p.grad = g.clone()
            opt.step()
        out[fused] = [p.detach() for p in params]
    for a, b, s in zip(out[False], out[True], start, strict=True):
        assert not torch.equal(a, s)  # the weights moved: 20 steps of 1e-2
        torch.testing.assert_close(a, b, rtol=0, atol=1e-6)


def test_a_warm_up_as_long_as_the_run_is_named_with_its_numbers_and_remedy():
    # a shipped config's 200 warm-up steps on a small dataset: 3 steps an epoch x 60 epochs
    note = warmup_note("denoiser", OptimConfig(warmup_steps=200, lr=1e-3), total=180)
    assert note is not None
    assert "denoiser.warmup_steps=200" in note and "all of this run's 180 optimiser" in note
    assert "never reaches denoiser.lr=0.001" in note and "0.0009" in note  # 180 / 200 of it
    assert "--set denoiser.warmup_steps=N (e.g. N=18" in note
    # fine-tuning's default warm-up, 20 of its 36 steps, ends inside the run: no line
    assert warmup_note("finetune", OptimConfig(warmup_steps=20, lr=3e-4), total=36) is None
    assert warmup_note("denoiser", OptimConfig(warmup_steps=100), total=100) is not None
    assert warmup_note("denoiser", OptimConfig(warmup_steps=4), total=104) is None
    assert warmup_note("denoiser", OptimConfig(warmup_steps=50), total=100) is None  # half
    assert warmup_note("denoiser", OptimConfig(warmup_steps=0), total=0) is None


def test_a_run_inside_its_warm_up_says_so_once_and_a_normal_run_says_nothing(
    tmp_path, tiny_cfg, capsys
):
    from trajpref.train.run import train_stage

    warm = dataclasses.replace(tiny_cfg.denoiser, warmup_steps=200)
    long = dataclasses.replace(tiny_cfg, denoiser=warm)
    train_stage("diffusion", long, tmp_path / "long", device="cpu", progress=False)
    out = capsys.readouterr().out
    assert out.count("[denoiser] the warm-up (denoiser.warmup_steps=200)") == 1
    assert "--set denoiser.warmup_steps=N" in out
    train_stage("diffusion", tiny_cfg, tmp_path / "short", device="cpu", progress=False)
    assert "warm-up" not in capsys.readouterr().out


def test_each_rank_after_the_first_seeds_its_own_dropout_stream():
    """Rank 0 keeps the builder's seed (a one-process run unchanged); ranks 1, 2 each get
    another stream, from the seed and the rank."""
    from trajpref.train.loop import seed_rank_generators

    def state_after(rank: int) -> torch.Tensor:
        torch.manual_seed(7)  # the stage builder's seed
        seed_rank_generators(7, rank, torch.device("cpu"))
        return torch.default_generator.get_state()

    torch.manual_seed(7)
    built = torch.default_generator.get_state()
    states = [state_after(rank) for rank in range(3)]
    assert torch.equal(states[0], built)
    assert not torch.equal(states[1], built) and not torch.equal(states[2], built)
    assert not torch.equal(states[1], states[2])
    assert torch.equal(state_after(1), states[1])


@pytest.mark.parametrize(("minutes", "text"), [(12.4, "12 min"), (210, "3.5 h"),
                                               (1.2e6, "833 days")])  # fmt: skip
def test_the_budget_message_says_how_long_training_every_step_would_take(minutes, text):
    """The stop line's advice to train every step names its cost: under --equal-budget the
    schedule is a cap of 100,000 epochs (1.2 million steps), not a plan (a Robo walkthrough
    of 2026-12-06 was told to run it without a word of its length)."""
    from trajpref.train.loop import _duration

    assert _duration(minutes) == text


def _saved_default_optimizer(shapes) -> dict:
    """The state of PyTorch's default (not fused) AdamW after one step on CPU parameters."""
    torch.manual_seed(0)
    params = [torch.nn.Parameter(torch.randn(s)) for s in shapes]
    opt = make_optimizer(params, OptimConfig(lr=1e-2))
    for p in params:
        p.grad = torch.randn_like(p)
    opt.step()
    return opt.state_dict()


def test_a_resume_that_switches_fused_on_puts_each_step_on_its_parameters_device():
    """A default AdamW keeps each parameter's ``step`` on the CPU, and torch's
    ``load_state_dict`` leaves it there when the saved groups were not fused; the fused CUDA
    kernel reads it on the GPU. ``meta`` stands for the GPU here."""
    from trajpref.train.loop import resume_optimizer

    shapes = [(8, 4), (8,)]
    state = _saved_default_optimizer(shapes)
    assert {s["step"].device.type for s in state["state"].values()} == {"cpu"}
    fused = OptimConfig(lr=1e-2, fused=True)
    params = [torch.nn.Parameter(torch.empty(s, device="meta")) for s in shapes]
    opt = make_optimizer(params, fused)
    resume_optimizer(opt, state, fused)
    assert all(group["fused"] is True for group in opt.param_groups)  # the config decides
    for p in params:
        step = opt.state[p]["step"]
        assert step.device == p.device and step.dtype == torch.float32
    # on the CPU the step keeps its count, and a step after the resume runs
    cpu = [torch.nn.Parameter(torch.randn(s)) for s in shapes]
    opt = make_optimizer(cpu, fused)
    resume_optimizer(opt, state, fused)
    assert [float(opt.state[p]["step"]) for p in cpu] == [1.0, 1.0]
    for p in cpu:
        p.grad = torch.ones_like(p)
    opt.step()
    assert [float(opt.state[p]["step"]) for p in cpu] == [2.0, 2.0]
    # switched off again: the groups follow the config
    opt = make_optimizer(cpu, OptimConfig(lr=1e-2))
    resume_optimizer(opt, state, OptimConfig(lr=1e-2))
    assert all(group["fused"] is None for group in opt.param_groups)


def test_a_run_resumed_with_fused_on_ends_where_the_uninterrupted_run_does(tmp_path, tiny_cfg):
    """Up to float rounding (the fused arithmetic's, docs/pretraining.md, "Fused AdamW
    steps"): the saved optimiser state carries over to the fused implementation."""
    from trajpref.train.run import train_stage

    full, stop = tmp_path / "full", tmp_path / "stop"
    train_stage("diffusion", tiny_cfg, full, device="cpu", progress=False)
    steps = torch.load(full / "denoiser_last.pt", weights_only=True)["step"]
    train_stage("diffusion", tiny_cfg, stop, device="cpu", progress=False, max_steps=steps // 2)
    fused = dataclasses.replace(tiny_cfg, denoiser=dataclasses.replace(tiny_cfg.denoiser,
                                                                       fused=True))  # fmt: skip
    train_stage("diffusion", fused, stop, device="cpu", progress=False,
                resume=str(stop / "denoiser_last.pt"))  # fmt: skip
    a = torch.load(full / "denoiser_last.pt", weights_only=True)
    b = torch.load(stop / "denoiser_last.pt", weights_only=True)
    assert a["step"] == b["step"]
    assert b["optimizer"]["param_groups"][0]["fused"] is True
    assert {s["step"].device.type for s in b["optimizer"]["state"].values()} == {"cpu"}
    for key, value in a["trainable"].items():
        torch.testing.assert_close(b["trainable"][key], value, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize(("capability", "fast"), [((7, 5), False), ((8, 0), True),
                                                  ((9, 0), True), ((6, 1), False)])  # fmt: skip
def test_bf16_is_fast_on_ampere_and_later_gpus_only(monkeypatch, capability, fast):
    """A GPU before Ampere (compute capability 8) has no bfloat16 arithmetic: autocast
    emulates it, slower than float32 (a T4 is 7.5, a V100 7.0)."""
    from trajpref.train import loop

    asked: list = []
    monkeypatch.setattr(torch.cuda, "get_device_capability",
                        lambda device=None: asked.append(device) or capability)  # fmt: skip
    assert loop.bf16_is_fast(torch.device("cuda:0")) is fast
    assert asked == [torch.device("cuda:0")]


def test_a_pre_ampere_gpu_is_warned_about_bf16_in_its_own_words(monkeypatch):
    from trajpref.train import loop

    monkeypatch.setattr(torch.cuda, "get_device_capability", lambda device=None: (7, 0))
    note = loop.bf16_note("denoiser", torch.device("cuda"))
    assert note is not None and "compute capability 7.0" in note and "CPU" not in note
    assert "--set denoiser.precision=fp32" in note
    monkeypatch.setattr(torch.cuda, "get_device_capability", lambda device=None: (8, 6))
    assert loop.bf16_note("denoiser", torch.device("cuda")) is None
