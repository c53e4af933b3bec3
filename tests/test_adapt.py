"""In-context adaptation (trajpref.adapt): the context rule, leak-freedom, no carried weights."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from synthetic import write_dataset

from trajpref.adapt import (
    AdaptConfig,
    _with_generator,
    adapt_and_predict,
    adapt_generator,
    context_windows,
    evaluate_in_context,
    window_origin,
    window_seed,
)
from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.data.transforms import to_model_frame
from trajpref.errors import ConfigError, DataError
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import TrajectoryScorer, score_timesteps
from trajpref.types import Scene, TrajectoryDataset, collate

STEP = 10  # raw frame numbers between frames in synthetic.write_dataset
CFG = AdaptConfig(ctx_frames=40, steps=3, lr=1e-2, params="all")


@pytest.fixture(scope="module")
def long_walks(tmp_path_factory):
    """The test split: one 40-frame recording (21 windows, starts 0, 10, ..., 200)."""
    root = write_dataset(tmp_path_factory.mktemp("long"), frames=40)
    return load_dataset(str(root), "test")


@pytest.fixture(scope="module")
def model(tiny_run):
    return load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")


def _poisoned(ds: TrajectoryDataset, last: float) -> TrajectoryDataset:
    """A copy of ``ds`` with every position at a raw frame after ``last`` set to NaN."""
    scenes = []
    for s in ds.scenes:
        _, start = window_origin(s.scene_id)
        frames = start + STEP * np.arange(ds.info.t_hist + ds.info.t_fut)  # [T]
        track = np.concatenate([s.history, s.future], 1).copy()  # [P, T, 2]
        track[:, frames > last] = np.nan
        t_h = ds.info.t_hist
        scenes.append(Scene(track[:, :t_h], track[:, t_h:], s.agent_type.copy(), s.scene_id))
    return TrajectoryDataset(scenes, ds.info)


def test_window_origin_parses_the_reader_ids_and_rejects_others():
    assert window_origin("crowds_zara01.txt@frame=120") == ("crowds_zara01.txt", 120.0)
    assert window_origin("a@b.txt@frame=7.5") == ("a@b.txt", 7.5)
    with pytest.raises(DataError, match="synthetic#3"):
        window_origin("synthetic#3")


def test_context_windows_hand_computed(long_walks):
    ctx = context_windows(long_walks, AdaptConfig(ctx_frames=40))
    starts = [window_origin(s.scene_id)[1] for s in long_walks.scenes]
    assert starts == [STEP * i for i in range(21)]
    # window at frame 200: last observed 270; context windows end (start + 190) <= 270 and
    # start >= 270 - 390 -> starts 0 .. 80
    assert ctx[20] == list(range(9))
    # window at frame 120: last observed 190 -> only the window at 0 (frames 0..190)
    assert ctx[12] == [0]
    assert all(c == [] for c in ctx[:12])
    # a 25-frame context at frame 200: starts >= 270 - 240 = 30 and <= 80
    assert context_windows(long_walks, AdaptConfig(ctx_frames=25))[20] == [3, 4, 5, 6, 7, 8]
    with pytest.raises(ConfigError, match="cannot hold a whole window"):
        context_windows(long_walks, AdaptConfig(ctx_frames=19))


def test_windows_stamped_in_unix_seconds_find_the_same_context(long_walks):
    """Frames that are Unix seconds (1.7e9 + 0.4 k) carry float64's rounding between starts
    (0.39999986 s): a tolerance of 1e-6 step found no context at all (walkthrough 70)."""

    def restamped(scene: Scene) -> Scene:
        name, frame = window_origin(scene.scene_id)
        seconds = np.float64(1.7e9) + np.float64(frame / STEP) * 0.4  # as a log stamps them
        return dataclasses.replace(scene, scene_id=f"{name}@frame={float(seconds)!r}")

    stamped = TrajectoryDataset([restamped(s) for s in long_walks.scenes], long_walks.info)
    gaps = np.diff([window_origin(s.scene_id)[1] for s in stamped.scenes])
    assert gaps.min() != gaps.max()  # the rounding the rule must see through
    for frames in (25, 40):
        cfg = AdaptConfig(ctx_frames=frames)
        assert context_windows(stamped, cfg) == context_windows(long_walks, cfg)
    assert context_windows(stamped, CFG)[20] == list(range(9))


def test_bad_config_is_a_config_error():
    with pytest.raises(ConfigError, match="params"):
        AdaptConfig(params="everything")
    with pytest.raises(ConfigError, match="steps"):
        AdaptConfig(steps=-1)
    with pytest.raises(ConfigError, match="supervised, score, both"):
        AdaptConfig(objective="rl")
    with pytest.raises(ConfigError, match="score_weight"):
        AdaptConfig(objective="both", score_weight=-1.0)


@pytest.mark.parametrize("objective", ["supervised", "score", "both"])
def test_adaptation_never_reads_a_frame_after_the_last_observed_one(model, long_walks, objective):
    cfg = dataclasses.replace(CFG, objective=objective)
    i = 16  # window at frame 160, last observed 230; windows 0..4 are its context
    clean = adapt_and_predict(model, long_walks, cfg, num_samples=4, seed=3, indices=[i])
    assert clean.context == [[0, 1, 2, 3, 4]]
    poisoned = _poisoned(long_walks, last=230.0)
    assert np.isnan(poisoned[i].future).all() and np.isnan(poisoned[i + 1].history).any()
    dirty = adapt_and_predict(model, poisoned, cfg, num_samples=4, seed=3, indices=[i])
    assert torch.isfinite(clean.pred[0]).all()
    assert torch.equal(clean.pred[0], dirty.pred[0])
    # the check is sensitive: poisoning one frame that IS observed (230) reaches the
    # prediction, which refuses a history with a non-finite position
    with pytest.raises(DataError, match="non-finite positions"):
        adapt_and_predict(model, _poisoned(long_walks, last=220.0), cfg, num_samples=4, seed=3,
                          indices=[i])  # fmt: skip


def test_adaptation_changes_the_prediction_and_is_not_carried(model, long_walks):
    alone = adapt_and_predict(model, long_walks, CFG, num_samples=4, seed=0, indices=[20])
    after = adapt_and_predict(model, long_walks, CFG, num_samples=4, seed=0, indices=[19, 20])
    assert torch.equal(alone.pred[0], after.pred[1])
    unadapted = adapt_and_predict(model, long_walks, AdaptConfig(steps=0), num_samples=4,
                                  seed=0, indices=[20])  # fmt: skip
    assert not torch.equal(alone.pred[0], unadapted.pred[0])  # adaptation did something
    # and the model itself was left unchanged: predicting again gives the same
    again = adapt_and_predict(model, long_walks, CFG, num_samples=4, seed=0, indices=[20])
    assert torch.equal(alone.pred[0], again.pred[0])


def test_a_window_without_context_gets_the_unadapted_prediction(model, long_walks):
    res = adapt_and_predict(model, long_walks, CFG, num_samples=4, seed=5, indices=[3])
    assert res.context == [[]] and res.windows_with_context == 0
    rng = torch.Generator().manual_seed(window_seed(5, 3))
    expected = model.predict(collate([long_walks[3]]), 4, rng)
    assert torch.equal(res.pred[0], expected)


@pytest.mark.parametrize("params", ["heads", "sigma"])
def test_only_the_chosen_parameters_change(model, long_walks, params):
    cfg = AdaptConfig(steps=3, lr=1e-2, params=params, trust=0.1)
    context = collate([long_walks[j] for j in range(5)])
    adapted = adapt_generator(model, context, cfg, torch.Generator().manual_seed(0))
    heads = ("mean_head.", "sigma_head.", "shift_head.") if params == "heads" else ("sigma_head.",)
    start = dict(model.generator.named_parameters())
    changed = {n for n, p in adapted.named_parameters() if not torch.equal(p, start[n])}
    assert changed and all(n.startswith(heads) for n in changed)
    assert any(n.startswith("sigma_head.") for n in changed)


def _context_reward(model, generator, context) -> float:
    """The mean Eq. 6 score of ``generator``'s samples on the context windows (fixed draws)."""
    view = _with_generator(model, generator)
    scorer = TrajectoryScorer(model.denoiser, model.schedule, model.scale,
                              score_timesteps(model.schedule.num_steps, 9))  # fmt: skip
    cond = view.condition(context)
    with torch.no_grad():
        y = view.rollout(context, torch.Generator().manual_seed(7), cond=cond).y
    target = to_model_frame(context.future, context, model.scale)
    return float(scorer.step_scores(cond.context, y, target).mean())


def test_the_score_objective_raises_the_score_and_leaves_the_denoiser_alone(model, long_walks):
    context = collate([long_walks[j] for j in range(5)])
    denoiser = {n: p.clone() for n, p in model.denoiser.named_parameters()}
    cfg = AdaptConfig(steps=5, lr=1e-2, params="all", objective="score")
    adapted = adapt_generator(model, context, cfg, torch.Generator().manual_seed(0))
    before = _context_reward(model, model.generator, context)
    assert _context_reward(model, adapted, context) > before + 1e-3
    assert all(torch.equal(p, denoiser[n]) for n, p in model.denoiser.named_parameters())


def test_evaluate_in_context_reports_before_and_after(model, long_walks):
    out = evaluate_in_context(model, long_walks, CFG, num_samples=4, seed=0)
    assert out["windows"] == 21 and out["windows_with_context"] == 9
    assert out["before"]["scenes"] == out["after"]["scenes"] == 9
    assert out["seconds_per_window"] > 0
    assert out["before"]["min_ade"] != out["after"]["min_ade"]


def test_zero_adaptation_steps_report_before_and_after_as_equal(model, long_walks):
    # the natural control: 0 steps predict the windows with context unadapted, so "before" is
    # defined and "after" equals it (they were null though 9 windows have context)
    zero = dataclasses.replace(CFG, steps=0)
    out = evaluate_in_context(model, long_walks, zero, num_samples=4, seed=0)
    assert out["windows_with_context"] == 9
    assert out["before"] == out["after"] and out["after"]["scenes"] == 9
    # and it is the "before" of a run with steps, on the same windows and draws
    adapted = evaluate_in_context(model, long_walks, CFG, num_samples=4, seed=0)
    assert adapted["before"] == out["before"]


def test_cli_in_context_shows_progress_unless_told_not_to(tmp_path, tiny_run, capsys,
                                                         monkeypatch):  # fmt: skip
    monkeypatch.setattr("trajpref.io._is_terminal", lambda stream: True)  # bars as on a terminal
    root = write_dataset(tmp_path / "data", frames=40)
    argv = ["evaluate", "--dataset", root, "--model", tiny_run / "generator.safetensors",
            "--samples", "2", "--device", "cpu", "--in-context", "40", "--adapt-steps",
            "1"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    err = capsys.readouterr().err
    assert "in-context" in err and "0/21 [" in err  # the adapted pass, window by window
    assert "before" in err and "0/9 [" in err  # the unadapted pass on the windows with context
    assert main([str(a) for a in argv] + ["--no-progress"]) == 0
    assert capsys.readouterr().err == ""
    # 0 steps: before and after printed, and said to be the same predictions
    assert main([str(a) for a in argv[:-2]] + ["--adapt-steps", "0", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert " before (windows with context): minADE" in out
    assert "(no adaptation step: as before)" in out


def test_cli_evaluate_in_context(tmp_path, tiny_run, capsys):
    root = write_dataset(tmp_path / "data", frames=40)
    out = tmp_path / "res.json"
    argv = ["evaluate", "--dataset", root, "--split", "test", "--model",
            tiny_run / "generator.safetensors", "--samples", "4", "--device", "cpu",
            "--in-context", "40", "--adapt-steps", "2", "--adapt-params", "all",
            "--out", out, "--no-progress"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    assert "9 of 21 windows have context" in capsys.readouterr().out
    res = json.loads(out.read_text())
    assert res["windows_with_context"] == 9 and res["adapt_params"] == "all"
    assert res["after"]["scenes"] == 9
    bad = [*map(str, argv[:-3]), "--in-context", "10"]
    assert main(bad) == 2
    assert "cannot hold a whole window" in capsys.readouterr().err
