"""Both pretraining stages on tiny synthetic data: they learn, freeze what they should,
checkpoint, resume and reproduce."""

import dataclasses
import json
import re

import pytest
import torch
from helpers import NEW
from synthetic import TINY_OVERRIDES, write_dataset

from trajpref import config
from trajpref.cli import main
from trajpref.config import load_config
from trajpref.data import load_dataset, transforms
from trajpref.data.loader import SceneLoader
from trajpref.errors import ConfigError, TrajprefError
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.train import read_metrics
from trajpref.train.run import train_stage
from trajpref.train.stages import build_denoiser_stage, build_finetune_stage, build_generator_stage
from trajpref.types import collate


@pytest.fixture
def folder(walks):
    return walks


@pytest.fixture
def cfg(tiny_cfg):
    return tiny_cfg


@pytest.fixture
def trained(tiny_run):
    return tiny_run


def _params(module):
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def _changed(before, module):
    return [k for k, v in module.state_dict().items() if not torch.equal(before[k], v)]


def _one_step(stage, batch):
    opt = torch.optim.SGD([p for p in stage.trainable.parameters() if p.requires_grad], lr=0.1)
    loss, _ = stage.objective(batch, torch.Generator().manual_seed(0))
    opt.zero_grad()
    loss.backward()
    opt.step()
    return loss


def test_a_denoiser_step_changes_every_parameter(cfg, folder):
    train = load_dataset(str(folder), "train")
    stage, scale = build_denoiser_stage(cfg, train, train, torch.device("cpu"))
    assert scale > 0
    before = _params(stage.trainable)
    _one_step(stage, collate(train.scenes[:4]))
    assert set(_changed(before, stage.trainable)) == set(before)


def test_generator_width_may_differ_from_the_denoiser_config_but_nothing_else(cfg, folder, trained):
    import dataclasses

    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    wide = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, generator_width=48))
    stage = build_generator_stage(wide, payload, train, torch.device("cpu"))
    assert stage.trainable.mean_head[0].out_features == 48
    rebuilt, _ = ckpt.build_generator(stage.payload({"epoch": 0}))  # the checkpoint says 48
    assert rebuilt.mean_head[0].out_features == 48
    longer = dataclasses.replace(
        cfg, model=dataclasses.replace(cfg.model, t_fut=cfg.model.t_fut + 1)
    )
    with pytest.raises(ConfigError, match="GENERATOR_ONLY") as err:
        build_generator_stage(longer, payload, train, torch.device("cpu"))
    assert "(its window lengths: --history 8 --future 12)" in str(err.value)
    more = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, samples=6, tau=3))
    stage = build_generator_stage(more, payload, train, torch.device("cpu"))  # G-only fields
    assert stage.trainable.samples == 6


def test_the_generator_encoder_may_be_wider_than_the_denoisers(cfg, folder, trained):
    import dataclasses

    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    h = 2 * cfg.model.hidden
    wide = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, generator_hidden=h))
    stage = build_generator_stage(wide, payload, train, torch.device("cpu"))
    assert stage.trainable.encoder.norm.normalized_shape == (h,)
    assert stage.objective.denoiser.encoder.norm.normalized_shape == (cfg.model.hidden,)
    rebuilt, _ = ckpt.build_generator(stage.payload({"epoch": 0}))  # the checkpoint says h
    assert rebuilt.encoder.norm.normalized_shape == (h,)
    batch = next(iter(SceneLoader(train, max_agents=64, shuffle=False)))
    y = stage.objective.sampler.rollout(batch).y  # [K, N, T_f, 2]
    assert y.shape == (cfg.model.samples, batch.num_agents, cfg.model.t_fut, 2)
    assert torch.isfinite(y).all()


def test_the_generator_encoder_may_be_deeper_than_the_denoisers(cfg, folder, trained):
    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    depth = cfg.model.encoder_layers + 1
    deep = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, generator_layers=depth))
    stage = build_generator_stage(deep, payload, train, torch.device("cpu"))
    assert len(stage.trainable.encoder.layers) == depth
    assert len(stage.objective.denoiser.encoder.layers) == cfg.model.encoder_layers
    rebuilt, _ = ckpt.build_generator(stage.payload({"epoch": 0}))  # the checkpoint says depth
    assert len(rebuilt.encoder.layers) == depth


def test_a_generator_step_changes_the_generator_not_the_denoiser(cfg, folder, trained):
    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    stage = build_generator_stage(cfg, payload, train, torch.device("cpu"))
    denoiser = stage.objective.denoiser
    gen_before, den_before = _params(stage.trainable), _params(denoiser)
    stage.objective.train()
    _one_step(stage, collate(train.scenes[:4]))
    assert not denoiser.training
    assert _changed(den_before, denoiser) == []
    assert all(not p.requires_grad for p in denoiser.parameters())
    changed = set(_changed(gen_before, stage.trainable))
    assert {
        k for k in gen_before if k.startswith(("encoder", "mean_head", "shift_head"))
    } <= changed


def test_run_folder_holds_config_metrics_and_self_sufficient_checkpoints(trained):
    assert (trained / "config.yaml").is_file()
    for stage in ("denoiser", "generator"):  # each stage's own resolved config, kept
        assert load_config(trained / f"{stage}_config.yaml") == load_config(trained / "config.yaml")
    records = [json.loads(line) for line in (trained / "generator_metrics.jsonl").open()]
    assert len(records) == 2 and "val_min_ade" in records[-1]
    assert read_metrics(trained, "generator") == records  # the reader the benchmarks use
    assert read_metrics(trained, "finetune") == []  # a stage the run did not train
    payload = ckpt.load(trained / "generator.safetensors")
    assert payload["kind"] == "generator" and payload["denoiser"]["kind"] == "denoiser"
    assert payload["config"]["model"]["samples"] == 4  # K lives in the model section
    # where the training process ran, threads included (the zoo cards name it)
    assert re.search(r"CPU cores.*\d+ threads", payload["meta"]["machine"])
    assert sorted(p.name for p in trained.glob("*.pt")) == ["denoiser_last.pt",
                                                            "generator_last.pt"]  # fmt: skip


def test_saved_best_checkpoint_predicts_as_the_trained_model(folder, trained, cfg):
    """The best checkpoint reproduces the predictions of the model it saved (rebuilt here from
    the stage and the weights of the resume file, which the loop wrote at that epoch), and
    an untrained generator does not."""
    test = load_dataset(str(folder), "test")
    batch = collate(test.scenes)
    a = ckpt.load_predictor(trained / "generator.safetensors")
    pa = a.predict(batch, 4, torch.Generator().manual_seed(0))
    assert pa.shape == (4, batch.num_agents, 12, 2)
    stage = build_generator_stage(cfg, ckpt.load(trained / "denoiser.safetensors"), test,
                                  torch.device("cpu"))  # fmt: skip
    fresh = stage.objective.sampler.predict(batch, 4, torch.Generator().manual_seed(0))
    assert not torch.allclose(fresh, pa)
    last = torch.load(trained / "generator_last.pt", weights_only=True)
    best_epoch = ckpt.load(trained / "generator.safetensors")["meta"]["epoch"]
    if last["epoch"] + 1 == best_epoch:  # the last epoch was the best
        stage.trainable.load_state_dict(last["trainable"])
        trained_pred = stage.objective.sampler.predict(batch, 4, torch.Generator().manual_seed(0))
        assert torch.equal(trained_pred, pa)
    full = ckpt.load_predictor(trained / "generator.safetensors", sampler="full")
    assert full.predict(batch, 7).shape[0] == 7  # the full sampler draws any K
    with pytest.raises(TrajprefError, match="emits K = 4"):
        a.predict(batch, 5)


def test_seeded_runs_are_identical(tmp_path, cfg):
    summaries = []
    for run in ("a", "b"):
        train_stage("diffusion", cfg, tmp_path / run, device="cpu", progress=False)
        summaries.append(ckpt.load(tmp_path / run / "denoiser.safetensors")["hash"])
    assert summaries[0] == summaries[1]


def test_seeded_generator_runs_with_the_pedestrian_recipe_are_identical(tmp_path, folder, trained,
                                                                        monkeypatch):  # fmt: skip
    # the published pedestrian folds train with mirrored and rotated scenes, dropout, a weight
    # average, bf16 steps and the heading frame: every random draw must come from the seed
    recipe = [
        *TINY_OVERRIDES, f"data.dataset={folder}", "data.flip=true", "data.rotate=true",
        "model.generator_dropout=0.2", "generator.ema_epochs=1", "generator.precision=bf16",
        "model.agent_frame=heading",
    ]  # fmt: skip
    denoiser = str(trained / "denoiser.safetensors")
    options = {"device": "cpu", "progress": False, "denoiser": denoiser}
    import trajpref.data.transforms as transforms

    played_backwards = []  # per run: how many training scenes reverse_time turned round
    original = transforms.reverse_time

    def counting(batch, scenes, *args, **kwargs):
        played_backwards[-1] += int(scenes.sum())
        return original(batch, scenes, *args, **kwargs)

    monkeypatch.setattr(transforms, "reverse_time", counting)
    hashes = []
    runs = (("a", 0, []), ("b", 0, []), ("c", 1, []), ("d", 0, ["data.reverse=true"]))
    for run, seed, extra in runs:
        cfg = load_config(None, [*recipe, f"seed={seed}", *extra])
        played_backwards.append(0)
        train_stage("generator", cfg, tmp_path / run, **options)
        hashes.append(ckpt.load(tmp_path / run / "generator.safetensors")["hash"])
    assert hashes[0] == hashes[1]  # same seed, same weights
    assert hashes[2] != hashes[0]  # and the seed matters
    assert hashes[3] != hashes[0]
    # the loop plays scenes backwards when the config says so, and only then (a different
    # hash alone would not show it: the coin's draws move the other draws' stream too)
    assert played_backwards[:3] == [0, 0, 0] and played_backwards[3] > 0


def test_resume_continues_to_the_same_result(tmp_path, cfg):
    full = tmp_path / "full"
    train_stage("diffusion", cfg, full, device="cpu", progress=False)
    stop = tmp_path / "stop"  # stopped after the first epoch, then resumed
    train_stage("diffusion", cfg, stop, device="cpu", progress=False, max_steps=_steps(cfg))
    assert torch.load(stop / "denoiser_last.pt", weights_only=True)["epoch"] == 0
    train_stage("diffusion", cfg, stop, device="cpu", progress=False,
                resume=str(stop / "denoiser_last.pt"))  # fmt: skip
    last_full = torch.load(full / "denoiser_last.pt", weights_only=True)
    last_stop = torch.load(stop / "denoiser_last.pt", weights_only=True)
    assert last_full["step"] == last_stop["step"]
    for key, value in last_full["trainable"].items():
        torch.testing.assert_close(last_stop["trainable"][key], value)


def _dropout_generator_run(tmp_path, folder, trained, name, **kw):
    """The tiny generator stage with dropout (every shipped config has it), in ``name``."""
    cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={folder}",
                             "model.generator_dropout=0.2"])  # fmt: skip
    train_stage("generator", cfg, tmp_path / name, device="cpu", progress=False,
                denoiser=str(trained / "denoiser.safetensors"), **kw)  # fmt: skip
    return cfg, tmp_path / name / "generator_last.pt"


def test_a_generator_with_dropout_resumes_to_the_same_result(tmp_path, folder, trained):
    """Dropout draws from torch's global generator: the resume state keeps it, so that a
    resumed run draws the masks an uninterrupted one would (it replayed them from the seed)."""
    cfg, full = _dropout_generator_run(tmp_path, folder, trained, "full")
    _, stop = _dropout_generator_run(tmp_path, folder, trained, "stop", max_steps=_steps(cfg))
    assert torch.load(stop, weights_only=True)["epoch"] == 0
    _dropout_generator_run(tmp_path, folder, trained, "stop", resume=str(stop))
    last_full = torch.load(full, weights_only=True)
    last_stop = torch.load(stop, weights_only=True)
    assert last_full["step"] == last_stop["step"] == cfg.generator.epochs * _steps(cfg)
    for key, value in last_full["trainable"].items():
        assert torch.equal(last_stop["trainable"][key], value), key


def test_a_resume_state_without_torchs_generator_says_the_resume_is_not_exact(
    tmp_path, folder, trained, cfg, capsys
):
    """A state written before torch's own generator was kept still resumes, with a line that
    says the dropout masks will not be an uninterrupted run's; a denoiser (no dropout) says
    nothing."""
    _, stop = _dropout_generator_run(tmp_path, folder, trained, "old", max_steps=_steps(cfg))
    state = torch.load(stop, weights_only=True)
    for own in state["rank_generators"]:
        own.pop("torch_rng", None)
    torch.save(state, stop)
    capsys.readouterr()
    _dropout_generator_run(tmp_path, folder, trained, "old", resume=str(stop))
    out = capsys.readouterr().out
    assert "will not end bit for bit" in out and "dropout masks" in out
    assert torch.load(stop, weights_only=True)["step"] == cfg.generator.epochs * _steps(cfg)
    den = tmp_path / "den"
    train_stage("diffusion", cfg, den, device="cpu", progress=False, max_steps=_steps(cfg))
    state = torch.load(den / "denoiser_last.pt", weights_only=True)
    for own in state["rank_generators"]:
        own.pop("torch_rng", None)
    torch.save(state, den / "denoiser_last.pt")
    capsys.readouterr()
    train_stage("diffusion", cfg, den, device="cpu", progress=False,
                resume=str(den / "denoiser_last.pt"))  # fmt: skip
    assert "bit for bit" not in capsys.readouterr().out


def test_a_resumed_run_follows_its_configs_fused_setting_not_its_states(tmp_path, cfg):
    # AdamW's state dict carries its "fused" flag; resuming with another setting must not
    # silently keep the old implementation while the run's config says otherwise
    stop = tmp_path / "stop"
    plain = [*TINY_OVERRIDES, f"data.dataset={cfg.data.dataset}", "denoiser.fused=false"]
    train_stage("diffusion", load_config(None, plain), stop, device="cpu", progress=False,
                max_steps=_steps(cfg))  # fmt: skip
    saved = torch.load(stop / "denoiser_last.pt", weights_only=True)["optimizer"]
    assert saved["param_groups"][0]["fused"] is None
    fused = load_config(None, [*plain[:-1], "denoiser.fused=true"])
    train_stage("diffusion", fused, stop, device="cpu", progress=False,
                resume=str(stop / "denoiser_last.pt"))  # fmt: skip
    saved = torch.load(stop / "denoiser_last.pt", weights_only=True)["optimizer"]
    assert saved["param_groups"][0]["fused"] is True


def test_a_fresh_run_in_a_used_folder_moves_the_earlier_log_aside(tmp_path, cfg):
    """A resumed run appends to its own log; a run started anew in the same folder keeps
    its log to its own epochs and moves the earlier one aside (it was appended to before)."""
    from trajpref.train import read_metrics

    out = tmp_path / "run"
    train_stage("diffusion", cfg, out, device="cpu", progress=False, max_steps=_steps(cfg))
    train_stage("diffusion", cfg, out, device="cpu", progress=False,
                resume=str(out / "denoiser_last.pt"))  # fmt: skip
    epochs = [r["epoch"] for r in read_metrics(out, "denoiser")]
    assert epochs == list(range(1, cfg.denoiser.epochs + 1))  # stopped, then resumed: one log
    train_stage("diffusion", cfg, out, device="cpu", progress=False)
    assert [r["epoch"] for r in read_metrics(out, "denoiser")] == epochs
    aside = out / "denoiser_metrics.replaced-1.jsonl"
    assert [json.loads(line)["epoch"] for line in aside.read_text().splitlines()] == epochs


def _steps(cfg):
    from trajpref.data.loader import SceneLoader

    train = load_dataset(cfg.data.dataset, "train")
    return len(SceneLoader(train, max_agents=cfg.data.max_agents))


def test_cli_train_evaluate_predict(tmp_path, folder, capsys):
    out = tmp_path / "cli"
    sets = [a for o in TINY_OVERRIDES for a in ("--set", o)]
    for stage in ("diffusion", "generator"):
        code = main(["train", stage, "--out", str(out), "--dataset", str(folder), *sets,
                     "--device", "cpu", "--no-progress"])  # fmt: skip
        assert code == 0
    capsys.readouterr()
    gen = str(out / "generator.safetensors")
    code = main(["evaluate", "--dataset", str(folder), "--model", gen, "--samples", "4",
                 "--json", "--no-progress"])  # fmt: skip
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["agents"] > 0 and res["min_ade"] > 0
    code = main(["evaluate", "--dataset", str(folder), "--model", str(out / "denoiser.safetensors"),
                 "--samples", "3", "--json", "--no-progress"])  # fmt: skip
    assert code == 0 and json.loads(capsys.readouterr().out)["samples"] == 3


def test_trained_generator_beats_its_untrained_self(cfg, folder, trained):
    """Sanity: training lowers validation error (tiny data, loose bound)."""
    val = load_dataset(str(folder), "val")
    payload = ckpt.load(trained / "denoiser.safetensors")
    fresh = build_generator_stage(cfg, payload, val, torch.device("cpu")).validate()
    best = ckpt.load(trained / "generator.safetensors")["meta"]["val"]
    assert best["score"] < fresh["score"]
    # the saved model reproduces the validation it was chosen by (same pass: K, batches, seed)
    res = evaluate(ckpt.load_predictor(trained / "generator.safetensors"), val,
                   cfg.model.samples, seed=0, max_agents=cfg.data.max_agents,
                   progress=False)  # fmt: skip
    assert res["min_ade"] == pytest.approx(best["min_ade"], abs=1e-6)
    assert res["min_fde"] == pytest.approx(best["min_fde"], abs=1e-6)


def test_published_generator_names_its_denoiser_by_hash(tmp_path, trained, folder):
    pub = tmp_path / "models"
    run_gen = trained / "generator.safetensors"
    ckpt.publish(run_gen, pub / "generator.safetensors", half=False)
    assert (pub / "denoiser.safetensors").is_file()
    raw = ckpt.load(pub / "generator.safetensors")
    assert raw["denoiser_ref"]["path"] == "denoiser.safetensors"
    assert (pub / "generator.safetensors").stat().st_size < run_gen.stat().st_size
    batch = collate(load_dataset(str(folder), "test").scenes)
    a = ckpt.load_predictor(run_gen).predict(batch, 4, torch.Generator())
    b = ckpt.load_predictor(pub / "generator.safetensors").predict(batch, 4, torch.Generator())
    assert torch.equal(a, b)
    # a different denoiser beside it is refused
    other = ckpt.load(trained / "denoiser.safetensors")
    other["state_dict"] = {k: v + 1e-3 for k, v in other["state_dict"].items()}
    other["hash"] = ckpt.state_hash(other["state_dict"])
    ckpt.save(pub / "denoiser.safetensors", other)
    with pytest.raises(TrajprefError, match="does not match the recorded hash"):
        ckpt.load(pub / "generator.safetensors")
    # and publishing next to a different denoiser does not overwrite it unless asked
    with pytest.raises(TrajprefError, match="holds a different denoiser"):
        ckpt.publish(run_gen, pub / "generator-v2.safetensors", half=False)
    assert ckpt.load(pub / "denoiser.safetensors")["hash"] == other["hash"]
    ckpt.publish(run_gen, pub / "generator-v2.safetensors", replace_denoiser=True, half=False)
    v2 = ckpt.load_predictor(pub / "generator-v2.safetensors")
    assert v2.predict(batch, 4, torch.Generator()).equal(a)


def test_steps_per_epoch_caps_each_epoch(tmp_path, cfg):
    import dataclasses

    capped = dataclasses.replace(cfg, denoiser=dataclasses.replace(cfg.denoiser,
                                                                   steps_per_epoch=1))  # fmt: skip
    summary = train_stage("diffusion", capped, tmp_path, device="cpu", progress=False)
    assert summary["steps"] == capped.denoiser.epochs
    # the summary's throughput is the last epoch's, as its metrics line logs it
    last = json.loads((tmp_path / "denoiser_metrics.jsonl").read_text().splitlines()[-1])
    assert summary["samples_per_second"] == pytest.approx(last["samples_per_second"], abs=0.06)


def test_nonfinite_losses_are_skipped_then_refused(tmp_path, cfg, folder):
    from trajpref.train.loop import fit

    train = load_dataset(str(folder), "train")
    stage, _ = build_denoiser_stage(cfg, train, train, torch.device("cpu"))
    before = _params(stage.trainable)
    real_forward = stage.objective.forward
    stage.objective.forward = lambda batch, gen: (real_forward(batch, gen)[0] * float("nan"), {})
    with pytest.raises(TrajprefError, match="non-finite losses; lower the learning rate$"):
        fit(stage, train, cfg.data, cfg.denoiser, tmp_path, torch.device("cpu"), progress=False)
    assert _changed(before, stage.trainable) == []  # no NaN update reached the weights


def test_the_generator_stage_names_its_own_remedy_for_nonfinite_losses(
    tmp_path, cfg, folder, trained
):
    # the generator's hint points at the spread cap, not at a reward it does not have
    from trajpref.train.loop import fit

    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    stage = build_generator_stage(cfg, payload, train, torch.device("cpu"))
    real_forward = stage.objective.forward
    stage.objective.forward = lambda batch, gen: (real_forward(batch, gen)[0] * float("inf"), {})
    with pytest.raises(TrajprefError, match="model.max_log_sigma") as err:
        fit(stage, train, cfg.data, cfg.generator, tmp_path, torch.device("cpu"), progress=False)
    assert "reward" not in str(err.value)


@pytest.mark.parametrize("clock", ["wall", "cpu"])
def test_a_time_budget_stops_the_stage_and_still_validates(tmp_path, cfg, clock):
    import dataclasses

    denoiser = dataclasses.replace(cfg.denoiser, epochs=50, max_minutes=1e-6, budget_clock=clock)
    budget = dataclasses.replace(cfg, denoiser=denoiser)
    summary = train_stage("diffusion", budget, tmp_path, device="cpu", progress=False)
    assert summary["steps"] == 1  # the first step already crosses the budget
    assert 0 < summary["budget_seconds"]
    records = [json.loads(line) for line in (tmp_path / "denoiser_metrics.jsonl").open()]
    assert len(records) == 1 and "val_denoise_loss" in records[0]
    assert records[0][f"budget_{clock}_seconds"] > 0


def test_a_stage_that_meets_its_budget_with_budget_schedule_ends_annealed(tmp_path, cfg, capsys):
    optim = dict(epochs=50, warmup_steps=0, max_minutes=1e-6, final_lr=0.1)
    lrs = {}
    for on in (False, True):
        denoiser = dataclasses.replace(cfg.denoiser, **optim, budget_schedule=on)
        out = tmp_path / str(on)
        summary = train_stage("diffusion", dataclasses.replace(cfg, denoiser=denoiser), out,
                              device="cpu", progress=False)  # fmt: skip
        assert summary["budget_reached"] and summary["steps"] == 1
        (record,) = read_metrics(out, "denoiser")  # one step, past the budget, then validation
        lrs[on] = record["lr"] / cfg.denoiser.lr
        said = capsys.readouterr().out
        assert "the time budget of 1e-06 min (wall clock) ended the stage after 1 of" in said
        assert ("annealed to it" if on else "cut mid-schedule") in said
        assert "--set denoiser.max_minutes=null --set denoiser.budget_schedule=false" in said
    assert lrs[True] == pytest.approx(0.1)  # at the floor where the budget ran out
    assert lrs[False] > 0.99  # cut one step into a 50-epoch cosine: still near the peak


def test_a_budget_that_is_not_met_leaves_the_run_as_it_was(tmp_path, cfg, trained):
    weights = []
    # two minutes: the steps' share stays ahead of the time's (the last step ends a tiny run
    # in well under a second), so the schedule is the steps' own
    for extra in ({}, {"max_minutes": 2.0, "budget_schedule": True}):
        generator = dataclasses.replace(cfg.generator, **extra)
        out = tmp_path / str(len(weights))
        summary = train_stage("generator", dataclasses.replace(cfg, generator=generator), out,
                              device="cpu", progress=False,
                              denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
        weights.append(ckpt.load(out / "generator.safetensors")["state_dict"])
        assert not summary["budget_reached"]
    assert weights[0].keys() == weights[1].keys()
    assert all(torch.equal(weights[0][k], weights[1][k]) for k in weights[0])
    shares = [r["budget_share"] for r in read_metrics(tmp_path / "1", "generator")]
    assert 0 < shares[0] <= shares[-1] < 0.5  # logged, rising, far from the budget


def test_an_unknown_budget_clock_is_a_config_error():
    from trajpref.config import DenoiserTrainConfig

    with pytest.raises(ConfigError, match="budget_clock must be 'wall' or 'cpu'"):
        DenoiserTrainConfig(budget_clock="gpu")


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("data.max_coord=0.5", r"beyond .*0\.5"),  # the synthetic walks leave a 0.5 box
        ("data.delimiter=x", "delimiter 'x'"),
        ("data.max_gap=-1", "max_gap must be >= 0"),
    ],
)
def test_training_reads_with_the_configs_read_options(tmp_path, folder, capsys, setting, message):
    out = tmp_path / "run"
    sets = [a for o in [*TINY_OVERRIDES, setting] for a in ("--set", o)]
    code = main(["train", "diffusion", "--out", str(out), "--dataset", str(folder), *sets,
                 "--device", "cpu", "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert re.search(message, err), err
    assert not out.exists()  # nothing written


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_bf16_precision_autocasts_the_training_steps_only(tmp_path, cfg, precision):
    import dataclasses

    seen: list[tuple[bool, torch.dtype]] = []  # (module in training mode, Linear output dtype)

    def hook(module, args, output):
        if isinstance(module, torch.nn.Linear) and isinstance(output, torch.Tensor):
            seen.append((module.training, output.dtype))

    denoiser = dataclasses.replace(cfg.denoiser, epochs=1, precision=precision)
    handle = torch.nn.modules.module.register_module_forward_hook(hook)
    try:
        train_stage("diffusion", dataclasses.replace(cfg, denoiser=denoiser), tmp_path,
                    device="cpu", progress=False, max_steps=2)  # fmt: skip
    finally:
        handle.remove()
    train_dtypes = {d for training, d in seen if training}
    eval_dtypes = {d for training, d in seen if not training}
    assert train_dtypes == ({torch.bfloat16} if precision == "bf16" else {torch.float32})
    assert eval_dtypes == {torch.float32}  # validation is never autocast
    weights = ckpt.load(tmp_path / f"denoiser{ckpt.SUFFIX}")
    denoiser_model, _ = ckpt.build_denoiser(weights)
    assert all(p.dtype == torch.float32 and torch.isfinite(p).all()
               for p in denoiser_model.parameters())  # fmt: skip


def test_an_unknown_precision_is_a_config_error():
    from trajpref.config import GeneratorTrainConfig

    with pytest.raises(ConfigError, match="precision must be 'fp32' or 'bf16'"):
        GeneratorTrainConfig(precision="fp16")


def test_a_run_with_a_held_out_scene_trains_without_it_and_validates_on_it(
    tmp_path, cfg, monkeypatch
):
    import dataclasses

    from trajpref.data import registry  # where run_splits calls it

    seen, original = {}, registry.hold_out_scene

    def spy(train, val, prefix):
        seen["train"], seen["val"] = original(train, val, prefix)
        return seen["train"], seen["val"]

    monkeypatch.setattr(registry, "hold_out_scene", spy)
    full = train_stage("diffusion", cfg, tmp_path / "all", device="cpu", progress=False)
    assert not seen  # no held-out scene: the usual splits
    held_cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, holdout_scene="walk2"))
    held = train_stage("diffusion", held_cfg, tmp_path / "held", device="cpu", progress=False)
    train = load_dataset(cfg.data.dataset, "train")
    walk2 = sum(s.num_agents for s in train.scenes if s.scene_id.startswith("walk2"))
    assert 0 < walk2 and held["train_agents"] == full["train_agents"] - walk2
    assert {s.scene_id.split("@")[0] for s in seen["val"].scenes} == {"walk2.txt"}
    assert "holdout_scene: walk2" in (tmp_path / "held" / "config.yaml").read_text()


def test_a_run_at_two_paces_adds_the_paced_copy_to_training_only(tmp_path, cfg):
    import dataclasses

    from synthetic import write_dataset

    from trajpref.data import ReadOptions

    root = write_dataset(tmp_path / "long", frames=44)  # long enough for windows at step 2
    cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, dataset=str(root)))
    full = train_stage("diffusion", cfg, tmp_path / "one", device="cpu", progress=False)
    data = dataclasses.replace(cfg.data, extra_time_step=2.0, holdout_scene="walk2")
    two = train_stage("diffusion", dataclasses.replace(cfg, data=data), tmp_path / "two",
                      device="cpu", progress=False)  # fmt: skip
    train = load_dataset(cfg.data.dataset, "train")
    paced = load_dataset(cfg.data.dataset, "train", options=ReadOptions(time_step=2.0))

    def agents(ds):  # the agent-windows outside the held-out scene
        return sum(s.num_agents for s in ds.scenes if not s.scene_id.startswith("walk2"))

    assert 0 < agents(paced) < agents(train)
    assert two["train_agents"] == agents(train) + agents(paced) < full["train_agents"] + agents(
        paced)  # the held-out scene left the copy too  # fmt: skip
    assert "extra_time_step: 2.0" in (tmp_path / "two" / "config.yaml").read_text()


def test_a_run_with_a_validation_cut_trains_on_its_early_windows_and_validates_on_the_rest(
    tmp_path, cfg, monkeypatch
):
    import dataclasses

    from trajpref.data import registry  # where run_splits calls it

    seen, original = [], registry.split_validation_in_time

    def spy(train, val, share, to_train):
        seen.append(original(train, val, share, to_train))
        return seen[-1]

    monkeypatch.setattr(registry, "split_validation_in_time", spy)
    root = write_dataset(tmp_path / "long", frames=70)  # 51 windows per file, room for the gap
    cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, dataset=str(root)))
    full = train_stage("diffusion", cfg, tmp_path / "all", device="cpu", progress=False)
    assert not seen  # no cut: the usual splits
    data = dataclasses.replace(cfg.data, val_cut=0.5, val_cut_to_train=True)
    more = train_stage("diffusion", dataclasses.replace(cfg, data=data), tmp_path / "more",
                       device="cpu", progress=False)  # fmt: skip
    data = dataclasses.replace(data, val_cut_to_train=False)
    same = train_stage("diffusion", dataclasses.replace(cfg, data=data), tmp_path / "same",
                       device="cpu", progress=False)  # fmt: skip
    val = load_dataset(cfg.data.dataset, "val")
    (train_more, val_more), (_, val_same) = seen
    added = train_more.num_agents - full["train_agents"]
    assert 0 < added < val.num_agents and more["train_agents"] == full["train_agents"] + added
    assert same["train_agents"] == full["train_agents"]  # the control trains on the same data
    assert [s.scene_id for s in val_more.scenes] == [s.scene_id for s in val_same.scenes]
    assert 0 < val_more.num_agents < val.num_agents
    assert "val_cut: 0.5" in (tmp_path / "more" / "config.yaml").read_text()


def test_keep_checkpoints_saves_every_validated_epoch_and_the_best_is_one_of_them(
    tmp_path, cfg, trained
):
    import dataclasses

    generator = dataclasses.replace(cfg.generator, epochs=3, eval_every=1, keep_checkpoints=True)
    run = dataclasses.replace(cfg, generator=generator)
    train_stage("generator", run, tmp_path, device="cpu", progress=False,
                denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
    kept = sorted(p.name for p in tmp_path.glob("generator_epoch*.safetensors"))
    assert kept == ["generator_epoch001.safetensors", "generator_epoch002.safetensors",
                    "generator_epoch003.safetensors"]  # fmt: skip
    records = read_metrics(tmp_path, "generator")
    best = ckpt.load(tmp_path / "generator.safetensors")
    same = ckpt.load(tmp_path / f"generator_epoch{best['meta']['epoch']:03d}.safetensors")
    assert all(
        torch.equal(best["state_dict"][k], same["state_dict"][k]) for k in best["state_dict"]
    )
    for record in records:  # each file records the validation its epoch logged
        meta = ckpt.load(tmp_path / f"generator_epoch{record['epoch']:03d}.safetensors")["meta"]
        assert meta["val"]["score"] == pytest.approx(record["val_score"])


def test_checkpoints_are_not_kept_by_default(tmp_path, cfg, trained):
    train_stage("generator", cfg, tmp_path, device="cpu", progress=False,
                denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
    assert list(tmp_path.glob("generator_epoch*")) == []


@pytest.mark.parametrize("minutes, validated", [(1e-9, [1, 2, 3, 4]), (1e3, [4])])
def test_eval_every_minutes_validates_by_the_budget_clock(tmp_path, cfg, trained, minutes,
                                                          validated):  # fmt: skip
    import dataclasses

    generator = dataclasses.replace(cfg.generator, epochs=4, eval_every=2,
                                    eval_every_minutes=minutes, budget_clock="cpu")  # fmt: skip
    run = dataclasses.replace(cfg, generator=generator)
    train_stage("generator", run, tmp_path, device="cpu", progress=False,
                denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
    records = read_metrics(tmp_path, "generator")
    # every epoch passes a tiny interval; a long one leaves only the last epoch's validation
    assert [r["epoch"] for r in records if "val_score" in r] == validated


def test_eval_every_minutes_must_be_positive():
    from trajpref.config import GeneratorTrainConfig

    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError, match="eval_every_minutes must be > 0"):
            GeneratorTrainConfig(eval_every_minutes=bad)


def _generator_off_and_on(tmp_path, cfg, trained, switch: str, steps: int):
    """The tiny generator trained for ``steps`` steps with ``generator.<switch>`` false and
    true (runs ``off`` and ``on``), and the weights it started from: three state dicts."""
    denoiser = str(trained / "denoiser.safetensors")
    options = {"device": "cpu", "progress": False, "denoiser": denoiser, "max_steps": steps}
    weights = {}
    for run, value in (("off", "false"), ("on", "true")):
        run_cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={cfg.data.dataset}",
                                     f"generator.{switch}={value}"])  # fmt: skip
        train_stage("generator", run_cfg, tmp_path / run, **options)
        weights[run] = torch.load(tmp_path / run / "generator_last.pt", weights_only=True)
    start = build_generator_stage(cfg, ckpt.load(denoiser), load_dataset(cfg.data.dataset, "val"),
                                  torch.device("cpu")).trainable.state_dict()  # fmt: skip
    return weights["off"]["trainable"], weights["on"]["trainable"], start


def test_a_compiled_generator_stage_trains_the_same_weights(tmp_path, cfg, trained, monkeypatch):
    # generator.compile compiles the generator and the frozen denoiser in place: the run's
    # checkpoint has the same keys and, up to the compiler's rounding, the same weights. The
    # graphs are captured by TorchDynamo as in a real run, but run without generating code
    # (backend eager): inductor's code generation takes minutes on a CPU.
    compiled_modules = []
    original = torch.nn.Module.compile

    def capture(module, **kwargs):
        compiled_modules.append(type(module).__name__)
        original(module, backend="eager", **kwargs)

    monkeypatch.setattr(torch.nn.Module, "compile", capture)
    eager, compiled, start = _generator_off_and_on(tmp_path, cfg, trained, "compile", 2)
    assert compiled_modules == ["Generator", "Denoiser"]
    assert eager.keys() == compiled.keys()  # no "_orig_mod." prefixes
    assert any(not torch.equal(start[k], v) for k, v in compiled.items())  # it trained
    for key, value in eager.items():
        torch.testing.assert_close(compiled[key], value, rtol=1e-3, atol=1e-4)


def test_a_fused_adamw_stage_trains_the_same_weights_up_to_rounding(tmp_path, cfg, trained):
    # generator.fused swaps AdamW's implementation, not its arithmetic: the same seeded run
    # ends at the same weights up to float rounding, and both moved from the start
    default, fused, start = _generator_off_and_on(tmp_path, cfg, trained, "fused", 3)
    assert any(not torch.equal(start[k], v) for k, v in fused.items())  # it trained
    for key, value in default.items():
        torch.testing.assert_close(fused[key], value, rtol=0, atol=1e-6)


def test_fused_must_be_a_boolean():
    with pytest.raises(ConfigError, match="fused"):
        load_config(None, ["generator.fused=maybe"])


def test_compile_must_be_a_boolean():
    with pytest.raises(ConfigError, match="compile"):
        load_config(None, ["generator.compile=sometimes"])


def test_without_a_cpp_compiler_a_compiled_config_trains_eagerly(
    tmp_path, cfg, monkeypatch, capsys
):
    monkeypatch.setattr("trajpref.train.loop.shutil.which", lambda name: None)
    monkeypatch.delenv("CXX", raising=False)
    monkeypatch.setattr(torch.nn.Module, "compile", lambda *a, **k: pytest.fail("compiled"))
    run_cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={cfg.data.dataset}",
                                 "denoiser.compile=true"])  # fmt: skip
    train_stage("diffusion", run_cfg, tmp_path / "run", device="cpu", progress=False,
                max_steps=1)  # fmt: skip
    assert "no C++ compiler" in capsys.readouterr().out


def test_an_annealed_best_of_k_run_cools_to_the_hard_minimum(tmp_path, folder, trained):
    # four epochs, annealed over the first half: the logged temperature falls from epoch to
    # epoch and is 0 (the hard minimum) once half the steps are done
    cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={folder}", "generator.epochs=4",
                             "generator.wta_temperature=1.0",
                             "generator.wta_anneal=0.5"])  # fmt: skip
    train_stage("generator", cfg, tmp_path, device="cpu", progress=False,
                denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
    temps = [r["train_wta_temperature"] for r in read_metrics(tmp_path, "generator")]
    assert len(temps) == 4
    assert temps[0] < 1.0 and temps[0] > temps[1] > 0  # epoch means of a falling schedule
    assert temps[2] == temps[3] == 0.0
    # and the hard-minimum default logs no temperature at all
    assert "train_wta_temperature" not in read_metrics(trained, "generator")[0]


@pytest.mark.parametrize("moved", [{"rotate": True}, {"flip": True}, {"reverse": True},
                                   {"scale_min": 0.8}])  # fmt: skip
def test_a_generator_that_sees_scene_positions_refuses_augmentations_that_move_the_scene(
    cfg, folder, trained, moved
):
    import dataclasses

    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    model = dataclasses.replace(cfg.model, scene_position=True)
    still = dataclasses.replace(cfg.data, rotate=False, flip=False, reverse=False)
    stage = build_generator_stage(dataclasses.replace(cfg, model=model, data=still), payload,
                                  train, torch.device("cpu"))  # fmt: skip
    assert stage.trainable.encoder.site_embed is not None
    rebuilt, _ = ckpt.build_generator(stage.payload({"epoch": 0}))  # the checkpoint says so
    assert rebuilt.cfg.scene_position and rebuilt.encoder.site_embed is not None
    moving = dataclasses.replace(cfg, model=model, data=dataclasses.replace(still, **moved))
    with pytest.raises(ConfigError, match="scene_position"):
        build_generator_stage(moving, payload, train, torch.device("cpu"))


def test_a_generator_with_agent_roles_refuses_dropped_agents_and_its_checkpoint_keeps_them(
    cfg, folder, trained
):
    import dataclasses

    train = load_dataset(str(folder), "train")
    payload = ckpt.load(trained / "denoiser.safetensors")
    model = dataclasses.replace(cfg.model, agent_roles=4)
    stage = build_generator_stage(dataclasses.replace(cfg, model=model), payload, train,
                                  torch.device("cpu"))  # fmt: skip
    rebuilt, _ = ckpt.build_generator(stage.payload({"epoch": 0}))  # the checkpoint says so
    assert rebuilt.cfg.agent_roles == 4 and rebuilt.encoder.role_embed.num_embeddings == 4
    dropping = dataclasses.replace(cfg.data, drop_agents=0.2)
    with pytest.raises(ConfigError, match="agent_roles"):
        build_generator_stage(dataclasses.replace(cfg, model=model, data=dropping), payload,
                              train, torch.device("cpu"))  # fmt: skip


def test_a_run_with_dropped_agents_trains_on_fewer_agents_than_it_reads(tmp_path, cfg, monkeypatch):
    seen = []  # (agents read, agents kept) per training batch
    original = transforms.drop_agents_at_random

    def spy(batch, p, generator=None):
        out = original(batch, p, generator)
        seen.append((batch.num_agents, out.num_agents))
        return out

    monkeypatch.setattr(transforms, "drop_agents_at_random", spy)
    c = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, drop_agents=0.5))
    train_stage("diffusion", c, tmp_path, device="cpu", progress=False)
    read, kept = sum(r for r, _ in seen), sum(k for _, k in seen)
    assert 0 < kept < read


@pytest.mark.parametrize("fast", [True, False])
def test_bf16_on_a_cpu_without_bfloat16_instructions_says_so(tmp_path, cfg, monkeypatch,
                                                            capsys, fast):  # fmt: skip
    monkeypatch.setattr("trajpref.train.loop.bf16_is_fast", lambda device: fast)
    run_cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={cfg.data.dataset}",
                                 "denoiser.precision=bf16"])  # fmt: skip
    train_stage("diffusion", run_cfg, tmp_path / "run", device="cpu", progress=False,
                max_steps=1)  # fmt: skip
    said = "no bfloat16 instructions" in capsys.readouterr().out
    assert said is not fast


def test_only_a_context_generator_trains_on_batches_with_context_agents(tmp_path, monkeypatch):
    root = write_dataset(tmp_path / "data")
    for path in root.rglob("*.txt"):  # one more walker per file, who leaves after frame 11
        with path.open("a") as f:
            f.writelines(f"{t * 10}\t99\t{0.3 * t}\t1.0\n" for t in range(12))
    cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={root}"])
    assert sum(len(s.context) for s in load_dataset(str(root), "train").scenes) > 0
    seen = []  # context agents of each training batch
    original = transforms.augment

    def spy(batch, *args, **kwargs):
        seen.append(batch.num_context)
        return original(batch, *args, **kwargs)

    monkeypatch.setattr("trajpref.train.loop.augment", spy)
    train_stage("diffusion", cfg, tmp_path / "plain", device="cpu", progress=False)
    train_stage("generator", cfg, tmp_path / "plain", device="cpu", progress=False)
    assert seen and max(seen) == 0
    seen.clear()
    ctx = load_config(None, [*TINY_OVERRIDES, f"data.dataset={root}", "model.context_agents=true"])
    train_stage("generator", ctx, tmp_path / "ctx", device="cpu", progress=False,
                denoiser=tmp_path / "plain" / "denoiser.safetensors")  # fmt: skip
    assert seen and min(seen) > 0
    rebuilt, _ = ckpt.build_generator(ckpt.load(tmp_path / "ctx" / "generator.safetensors"))
    assert rebuilt.cfg.context_agents


def test_a_generator_trains_on_agents_that_leave_the_view_and_the_denoiser_does_not(
    tmp_path, cfg, trained
):
    import dataclasses

    import numpy as np
    from synthetic import write_tracks

    rng = np.random.default_rng(0)
    for split in ("train", "val", "test"):
        rows = []
        for a in range(5):  # agents 4 and 5 leave the view after 6 future frames
            frames = 24 if a < 3 else 14
            pos, vel = rng.uniform(-3, 3, 2), rng.uniform(-0.5, 0.5, 2)
            rows += [(t * 10, a + 1, *(pos + t * vel)) for t in range(frames)]
        write_tracks(tmp_path / "data" / split / "w.txt", rows)
    data = dataclasses.replace(cfg.data, dataset=str(tmp_path / "data"), partial_future=4)
    run = dataclasses.replace(cfg, data=data)
    with pytest.raises(ConfigError, match="partial_future trains the generator stage only"):
        build_denoiser_stage(run, None, None, torch.device("cpu"))  # the stage itself refuses
    # the denoiser stage trains on the complete futures alone, and its run says so
    den = train_stage("diffusion", run, tmp_path / "d", device="cpu", progress=False)
    assert den["train_agents"] == 15
    assert "partial_future: 0" in (tmp_path / "d" / "config.yaml").read_text()
    res = train_stage("generator", run, tmp_path / "g", device="cpu", progress=False,
                      denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
    plain = load_dataset(str(tmp_path / "data"), "train")
    # windows start at frames 0..4; agents 4 and 5 are seen in 6 - s >= 4 future frames of
    # the windows starting at s = 0, 1, 2: 3 partial targets each
    assert (plain.num_agents, res["train_agents"]) == (15, 15 + 6)
    records = read_metrics(tmp_path / "g", "generator")
    assert all(np.isfinite(r["train_loss"]) for r in records)
    assert "partial_future: 4" in (tmp_path / "g" / "config.yaml").read_text()


def test_the_epoch_line_keeps_a_small_learning_rate_readable(tmp_path, cfg, capsys):
    # the line printed after each validated epoch rounds to 4 significant digits, not 4
    # decimals: a rate of 1e-5 must not read 0.0
    run_cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={cfg.data.dataset}",
                                 "denoiser.lr=1e-5", "denoiser.warmup_steps=0",
                                 "denoiser.final_lr=1", "denoiser.epochs=1"])  # fmt: skip
    train_stage("diffusion", run_cfg, tmp_path, device="cpu", progress=True, max_steps=1)
    printed = capsys.readouterr()
    lines = (printed.out + printed.err).splitlines()
    line = next(x for x in lines if x.startswith("[denoiser] epoch"))
    assert " lr=1e-05 " in line


def test_validation_shows_a_bar_and_a_budgeted_stage_the_share_of_its_budget(
    tmp_path, cfg, trained, capsys, monkeypatch
):
    monkeypatch.setattr("trajpref.io._is_terminal", lambda stream: True)  # bars as on a terminal
    # a time budget ends the stage, not its epochs: the bar says the budget and its share
    denoiser = dataclasses.replace(cfg.denoiser, epochs=50, max_minutes=1e-6)
    train_stage("diffusion", dataclasses.replace(cfg, denoiser=denoiser), tmp_path / "a",
                device="cpu", progress=True)  # fmt: skip
    err = capsys.readouterr().err
    assert "denoiser epoch 1 (1e-06 min budget)" in err and "1/50" not in err
    assert "budget=100%" in err
    assert "denoiser validation" in err  # the validation pass has its own bar
    train_stage("diffusion", cfg, tmp_path / "b", device="cpu", progress=True)
    err = capsys.readouterr().err
    assert f"denoiser epoch 1/{cfg.denoiser.epochs}" in err and "budget=" not in err
    # a generator's (and fine-tuning's) validation: the evaluation's bar; none without progress
    generator = dataclasses.replace(cfg.generator, epochs=1)
    for progress in (True, False):
        train_stage("generator", dataclasses.replace(cfg, generator=generator),
                    tmp_path / f"g{progress}", device="cpu", progress=progress,
                    denoiser=str(trained / "denoiser.safetensors"))  # fmt: skip
        err = capsys.readouterr().err
        assert ("evaluate " in err) is progress and ("generator epoch 1/1" in err) is progress


def test_a_validation_whose_samples_diverge_scores_inf_and_the_run_goes_on(folder, capsys):
    """The evaluation refuses NaN predictions (``evaluation.NonFinitePrediction``); training's
    validation turns that into a score never kept (a diverged epoch), as it was before the
    check, rather than stopping the run."""
    from torch import nn

    from trajpref.train.stages import _leapfrog_validation

    class Diverged(nn.Module):
        def predict(self, batch, num_samples, generator=None):
            t_f = batch.future.shape[1]
            return torch.full((num_samples, batch.num_agents, t_f, 2), float("nan"))

    val = load_dataset(str(folder), "val")
    res = _leapfrog_validation(Diverged(), val, 3, 256, torch.device("cpu"))()
    assert res["score"] == float("inf") and res["min_ade"] != res["min_ade"]  # NaN
    assert "scored as never the best" in capsys.readouterr().out


def test_validation_skips_the_collision_metrics_it_does_not_report(folder, monkeypatch):
    """A generator's (and fine-tuning's) validation returns minADE, minFDE (and the scorer's
    keys), never Col-I / Col-II: it evaluates with the collision metrics off, so that no batch
    computes their flags, and its numbers are those of an evaluation with them on."""
    from torch import nn

    import trajpref.evaluation as evaluation
    from trajpref.train import stages

    class Walker(nn.Module):  # each agent's last step, repeated with seeded noise
        def predict(self, batch, num_samples, generator=None):
            step = batch.history[:, -1] - batch.history[:, -2]  # [N, 2]
            t_f = batch.future.shape[1]
            ahead = torch.arange(1, t_f + 1, dtype=step.dtype)[:, None] * step[:, None]
            noise = torch.randn((num_samples, batch.num_agents, t_f, 2), generator=generator)
            return batch.history[:, -1, None] + ahead + 0.3 * noise.cumsum(2)

    calls = []

    def counted(*args, **kwargs):
        calls.append(1)
        return flags(*args, **kwargs)

    flags = evaluation.collision_flags
    monkeypatch.setattr(evaluation, "collision_flags", counted)
    val = load_dataset(str(folder), "val", units="m")  # in metres: collisions are counted
    validate = stages._leapfrog_validation(Walker(), val, 5, 256, torch.device("cpu"))

    def with_collisions(*args, **kwargs):  # the evaluation as its default (auto) runs it
        kwargs.pop("collision_radius", None)
        return evaluate(*args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(stages, "evaluate", with_collisions)
        expected = validate()
    assert calls, "the data is in metres: an evaluation with collisions computes their flags"
    calls.clear()
    assert validate() == expected and set(expected) == {"min_ade", "min_fde", "score"}
    assert calls == []


# One table of fine-tuning methods (config.FinetuneMethod, config.USES_RL,
# rl.objective.LOSS_SAMPLES): the CLI offers its names, and a name that reaches a dispatch
# without an entry there is an error, never trained as RLHF-ReS (the walkthrough's finding: a
# new method's name took the k* path of ``RLObjective.selection``).


@pytest.mark.parametrize("in_uses_rl", [False, True])
def test_a_fine_tuning_stage_of_a_method_without_entries_is_refused(
    tiny_run, walks, monkeypatch, in_uses_rl
):
    """Before any step: the stage is not built (HEAD built it and trained RLHF-ReS)."""
    if in_uses_rl:
        monkeypatch.setitem(config.USES_RL, NEW, True)
    start = ckpt.load(tiny_run / "generator.safetensors")
    cfg = load_config(None, [], base=start["config"])
    object.__setattr__(cfg.finetune, "method", NEW)  # past the Literal, as if added to it
    train = load_dataset(str(walks), "train")
    table = "LOSS_SAMPLES" if in_uses_rl else "USES_RL"
    with pytest.raises(ConfigError, match=rf"'rlhf-new'.*{table}"):
        build_finetune_stage(cfg, start, train, torch.device("cpu"))
