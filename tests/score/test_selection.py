"""Keeping K' of K samples: hand-checked picks, the score's role, determinism, and that the
ground truth is never read."""

import dataclasses
import itertools
import json
import warnings

import numpy as np
import pytest
import torch
from score.helpers import _scene
from synthetic import make_scene

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.models.registry import load_predictor
from trajpref.score import (
    TrajectoryScorer,
    predict_scene,
    rank_samples,
    score_timesteps,
    selection,
)
from trajpref.score.selection import (
    MEDOID_PASSES,
    SelectingPredictor,
    SelectionConfig,
    _medoids,
    chosen_selection,
    gather,
    select_for_scene,
    select_indices,
    select_samples,
    select_with_scorer,
    within_pace,
)
from trajpref.types import collate


def _line(xs: list[float]) -> torch.Tensor:
    """K samples of one agent whose endpoints lie at (x, 0): features [K, 1, 2]."""
    return torch.tensor([[[x, 0.0]] for x in xs])


def test_farthest_point_covers_the_extremes():
    feats = _line([0.0, 0.1, 5.0, 10.0, 4.9])  # mean 4.0
    idx = select_indices(feats, 3, SelectionConfig(method="fps", keep=3))[:, 0].tolist()
    assert idx[0] == 4  # 4.9 is nearest the mean 4.0
    assert set(idx[1:]) == {0, 3}  # then the two ends


def test_kmeans_represents_each_cluster_once():
    feats = _line([0.0, 0.1, 0.2, 10.0, 10.1, 10.2, 20.0])
    idx = select_indices(feats, 3, SelectionConfig(method="kmeans", keep=3))[:, 0].tolist()
    assert sorted(idx) == [1, 4, 6]  # one per cluster: the member nearest its centre


def test_top_and_score_coverage_follow_the_residual():
    feats = _line([0.0, 0.1, 5.0, 10.0])
    residual = torch.tensor([[1.0], [0.5], [9.0], [2.0]])  # sample 2 is the least human-like
    top = select_indices(feats, 2, SelectionConfig(method="top", keep=2), residual)
    assert top[:, 0].tolist() == [1, 0]
    cfg = SelectionConfig(method="score-fps", keep=2, drop=0.25)  # drops 1 of 4: sample 2
    idx = select_indices(feats, 2, cfg, residual)[:, 0].tolist()
    assert idx == [1, 3]  # the best-scored first, then the farthest of those kept
    # never more dropped than leaves K' (drop 0.75 would leave 1 < 2)
    idx = select_indices(feats, 2, SelectionConfig(method="score-kmeans", keep=2, drop=0.75),
                         residual)[:, 0].tolist()  # fmt: skip
    assert len(set(idx)) == 2 and 2 not in idx


@pytest.mark.parametrize(
    "method", ["kmeans", "fps", "medoids", "score-kmeans", "score-fps", "score-medoids", "random"]
)
def test_picks_are_distinct_per_agent(method):
    g = torch.Generator().manual_seed(0)
    feats = torch.randn(20, 7, 2, generator=g)  # [K, M, F]
    feats[:, 3] = 0.0  # an agent whose samples all coincide
    residual = torch.rand(20, 7, generator=g)
    cfg = SelectionConfig(method=method, keep=5, drop=0.5)
    idx = select_indices(feats, 5, cfg, residual, torch.Generator().manual_seed(1))  # [5, M]
    for m in range(7):
        assert len(set(idx[:, m].tolist())) == 5


def test_per_scene_selection_shares_indices_within_a_scene():
    batch = collate([make_scene(3, seed=1), make_scene(2, seed=2)])
    pred = torch.randn(10, batch.num_agents, 12, 2, generator=torch.Generator().manual_seed(0))
    idx = select_samples(pred, SelectionConfig(method="kmeans", keep=3, per="scene"), None, batch)
    assert idx.shape == (3, batch.num_agents)
    for s in range(2):
        cols = idx[:, batch.scene == s]
        assert (cols == cols[:, :1]).all()
    out = gather(pred, idx)
    assert torch.equal(out[:, 0], pred[idx[:, 0], 0])


def test_bad_settings_are_config_errors():
    with pytest.raises(ConfigError, match="method"):
        SelectionConfig(method="best")
    with pytest.raises(ConfigError, match="drop"):
        SelectionConfig(drop=1.0)
    with pytest.raises(ConfigError, match="cannot keep 6 of 5"):
        select_indices(torch.zeros(5, 1, 2), 6, SelectionConfig(method="first", keep=6))
    with pytest.raises(ConfigError, match="needs the diffusion score"):
        select_indices(torch.zeros(5, 1, 2), 2, SelectionConfig(method="top", keep=2))


def test_selecting_predictor_is_seeded_and_never_reads_the_future(tiny_run, walks):
    from trajpref.data import load_dataset

    model = ckpt.load_predictor(tiny_run / "generator.safetensors")
    scorer = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors")
    batch = collate(load_dataset(str(walks), "test").scenes[:4])
    blind = collate(load_dataset(str(walks), "test").scenes[:4])
    blind.future = torch.full_like(blind.future, float("nan"))
    for method in ("score-kmeans", "random", "top"):
        cfg = SelectionConfig(method=method, keep=2, drop=0.5)
        outs = []
        for b in (batch, batch, blind):
            sel = SelectingPredictor(model, cfg, candidates=4, scorer=scorer)
            outs.append(sel.predict(b, 2, torch.Generator().manual_seed(0)))
        assert outs[0].shape == (2, batch.num_agents, 12, 2)
        assert torch.equal(outs[0], outs[1]), method  # deterministic under a seed
        assert torch.equal(outs[0], outs[2]), method  # NaN futures change nothing
    with pytest.raises(ConfigError, match="needs a scorer"):
        SelectingPredictor(model, SelectionConfig(method="top", keep=2), candidates=4)


def test_facility_location_covers_both_clusters_and_follows_the_weights():
    feats = _line([0.0, 0.1, 0.2, 10.0, 10.1])  # a heavy cluster and a light one
    idx = select_indices(feats, 2, SelectionConfig(method="facility", keep=2))[:, 0].tolist()
    assert idx[0] == 1 and idx[1] in (3, 4)  # the heavy cluster's centre, then the other
    # with the score, samples 0-2 are implausible: the light cluster comes first
    residual = torch.tensor([[9.0], [9.0], [9.0], [1.0], [1.2]])
    cfg = SelectionConfig(method="score-facility", keep=1, drop=0.0, temperature=0.5)
    assert select_indices(feats, 1, cfg, residual)[0, 0].item() in (3, 4)


def test_medoids_swap_out_the_greedy_median():
    # greedy alone starts from the 1-medoid (5.0, sample 3); the best pair is {0.1, 10.0}
    feats = _line([0.0, 0.1, 0.2, 5.0, 9.9, 10.0, 10.1])
    assert 3 in _medoids(feats, torch.ones(7, 1, dtype=torch.bool), torch.ones(7, 1), 2, 0)
    idx = select_indices(feats, 2, SelectionConfig(method="medoids", keep=2))[:, 0].tolist()
    assert sorted(idx) == [1, 5]  # cost 0.1 + 0 + 0.1 + 4.9 + 0.1 + 0 + 0.1 = 5.3


def test_medoids_nearly_always_reach_the_brute_force_optimum():
    g = torch.Generator().manual_seed(0)
    x = torch.randn(8, 200, 2, generator=g)  # [K, M, F]
    w = torch.rand(8, 200, generator=g) + 0.1  # [K, M] target weights
    idx = _medoids(x, torch.ones(8, 200, dtype=torch.bool), w, 3, MEDOID_PASSES)  # [3, M]
    d = (x[:, None] - x[None]).pow(2).sum(-1).sqrt()  # [K, K, M]
    m = torch.arange(200)
    cost = (d[idx, :, m[None]] * w.T[None]).min(0).values.sum(-1)  # [M]
    every = [(d[list(c)] * w[None]).min(0).values.sum(0)  # [M] each 3-set's cost
             for c in itertools.combinations(range(8), 3)]  # fmt: skip
    best = torch.stack(every).min(0).values  # [M]
    assert (cost >= best - 1e-5).all()
    assert ((cost - best).abs() < 1e-5).float().mean() >= 0.9
    assert (cost / best).mean() <= 1.01


def test_score_medoids_follow_the_weights():
    feats = _line([0.0, 0.1, 0.2, 10.0, 10.1])
    # uniform weights: the median of the five (0.2); with the score, samples 0-2 are implausible
    assert select_indices(feats, 1, SelectionConfig(method="medoids", keep=1))[0, 0] == 2
    residual = torch.tensor([[9.0], [9.0], [9.0], [1.0], [1.2]])
    cfg = SelectionConfig(method="score-medoids", keep=1, drop=0.0, temperature=0.5)
    assert select_indices(feats, 1, cfg, residual)[0, 0].item() in (3, 4)
    # dropped samples are never kept, even where they would cover best
    cfg = SelectionConfig(method="score-medoids", keep=2, drop=0.6, temperature=100.0)
    assert sorted(select_indices(feats, 2, cfg, residual)[:, 0].tolist()) == [3, 4]


def test_score_first_keeps_the_generators_order_but_skips_the_worst():
    feats = _line([0.0, 1.0, 2.0, 3.0])
    residual = torch.tensor([[1.0], [9.0], [2.0], [3.0]])  # sample 1 is the worst
    cfg = SelectionConfig(method="score-first", keep=2, drop=0.25)
    assert select_indices(feats, 2, cfg, residual)[:, 0].tolist() == [0, 2]


def test_cli_keep_selects_and_reports(tiny_run, walks, capsys, tmp_path):
    gen = str(tiny_run / "generator.safetensors")
    code = main(["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4",
                 "--keep", "2", "--select", "score-kmeans", "--json", "--no-progress"])  # fmt: skip
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["samples"] == 2 and res["candidates"] == 4
    assert res["select"] == "score-kmeans"
    assert (res["drop"], res["score_every"], res["score_from"]) == (0.3, 9, 0)  # the defaults
    code = main(["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4",
                 "--keep", "2", "--select", "score-kmeans", "--score-every", "3",
                 "--score-from", "4", "--json", "--no-progress"])  # fmt: skip
    assert code == 0 and json.loads(capsys.readouterr().out)["score_from"] == 4
    code = main(["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4",
                 "--keep", "2", "--select", "score-kmeans", "--score-from", "10",
                 "--no-progress"])  # fmt: skip
    assert code == 2 and "first step must lie in 0..9" in capsys.readouterr().err
    out = tmp_path / "kept.npz"
    code = main(["predict", "--dataset", str(walks), "--model", gen, "--samples", "4",
                 "--keep", "3", "--select", "kmeans", "--out", str(out),
                 "--no-progress"])  # fmt: skip
    assert code == 0 and np.load(out)["pred"].shape[0] == 3
    code = main(["evaluate", "--dataset", str(walks), "--model", "cv", "--keep", "2",
                 "--select", "top", "--no-progress"])  # fmt: skip
    assert code == 2 and "needs --scorer" in capsys.readouterr().err


def test_cli_bandwidth_and_temperature_reach_the_selection(tiny_run, walks, capsys, monkeypatch):
    # --bandwidth and --select-temperature are the table rows' b and t (README): they are
    # recorded with the result and passed to the selection's config
    import trajpref.score.selection as selection

    seen = []
    original = selection.select_samples

    def spy(pred, cfg, *args, **kwargs):
        seen.append((cfg.bandwidth, cfg.temperature))
        return original(pred, cfg, *args, **kwargs)

    monkeypatch.setattr(selection, "select_samples", spy)
    gen = str(tiny_run / "generator.safetensors")
    base = ["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4", "--keep",
            "2", "--select", "score-facility", "--json", "--no-progress"]  # fmt: skip
    assert main(base) == 0
    res = json.loads(capsys.readouterr().out)
    assert (res["bandwidth"], res["select_temperature"]) == (0.5, 2.0)  # the defaults
    assert set(seen) == {(0.5, 2.0)}
    seen.clear()
    assert main([*base, "--bandwidth", "1", "--select-temperature", "0.5"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert (res["bandwidth"], res["select_temperature"]) == (1.0, 0.5)
    assert set(seen) == {(1.0, 0.5)}
    for flag, bad in (("--bandwidth", "0"), ("--bandwidth", "nan"),
                      ("--select-temperature", "inf")):  # fmt: skip
        assert main([*base, flag, bad]) == 2
        assert "bandwidth and temperature must be finite and > 0" in capsys.readouterr().err


def test_untrusted_agents_fall_back_to_the_score_free_counterpart():
    g = torch.Generator().manual_seed(0)
    feats = torch.randn(20, 6, 2, generator=g)  # [K, M, F]
    residual = torch.rand(20, 6, generator=g)
    trusted = torch.tensor([True, False, True, True, False, True])
    pairs = [("score-facility", "facility"), ("score-kmeans", "kmeans"), ("score-fps", "fps"),
             ("top", "first"), ("score-first", "first")]  # fmt: skip
    for method, free in pairs:
        cfg = SelectionConfig(method=method, keep=5, drop=0.3)
        gated = select_indices(feats, 5, cfg, residual, trusted=trusted)
        scored = select_indices(feats, 5, cfg, residual)
        plain = select_indices(feats, 5, SelectionConfig(method=free, keep=5))
        assert torch.equal(gated[:, trusted], scored[:, trusted]), method
        assert torch.equal(gated[:, ~trusted], plain[:, ~trusted]), method
        # the untrusted agents' picks do not depend on the residual at all
        shuffled = select_indices(feats, 5, cfg, residual.flip(0), trusted=trusted)
        assert torch.equal(shuffled[:, ~trusted], gated[:, ~trusted]), method
    # all trusted, or a score-free method: the gate changes nothing
    cfg = SelectionConfig(method="score-facility", keep=5)
    everyone = torch.ones(6, dtype=torch.bool)
    assert torch.equal(select_indices(feats, 5, cfg, residual, trusted=everyone),
                       select_indices(feats, 5, cfg, residual))  # fmt: skip


def test_within_pace_measures_first_to_last_observed_step_in_model_units():
    scene = make_scene(3, seed=4)
    batch = collate([scene])
    hist = batch.history.clone()  # [N, T_h, 2]
    t = torch.arange(hist.shape[1], dtype=hist.dtype)
    hist[0] = torch.stack([0.5 * t, 0 * t], -1)  # 0.5 data units per step
    hist[1] = torch.stack([0 * t, 2.0 * t], -1)  # 2.0
    hist[2] = 0.0  # standing
    batch.history = hist
    assert within_pace(batch, scale=1.0, trust_speed=0.0) is None  # off
    assert within_pace(batch, scale=1.0, trust_speed=1.0).tolist() == [True, False, True]
    # in model units: with a data scale of 4, 2.0 units/step is 0.5 model units/step
    assert within_pace(batch, scale=4.0, trust_speed=0.5).tolist() == [True, True, True]
    with pytest.raises(ConfigError, match="trust_speed"):
        SelectionConfig(trust_speed=-1.0)


def test_per_scene_gate_falls_back_for_a_scene_with_one_fast_agent():
    batch = collate([make_scene(3, seed=1), make_scene(2, seed=2)])
    g = torch.Generator().manual_seed(0)
    pred = torch.randn(12, batch.num_agents, 12, 2, generator=g)
    residual = torch.rand(12, batch.num_agents, generator=g)
    cfg = SelectionConfig(method="score-kmeans", keep=3, per="scene", drop=0.5)
    trusted = torch.ones(batch.num_agents, dtype=torch.bool)
    trusted[0] = False  # one agent of scene 0 is too fast
    gated = select_samples(pred, cfg, residual, batch, trusted=trusted)
    scored = select_samples(pred, cfg, residual, batch)
    plain = select_samples(pred, SelectionConfig(method="kmeans", keep=3, per="scene"), None,
                           batch)  # fmt: skip
    s0, s1 = batch.scene == 0, batch.scene == 1
    assert torch.equal(gated[:, s0], plain[:, s0])
    assert torch.equal(gated[:, s1], scored[:, s1])


def test_cli_trust_speed_is_reported(tiny_run, walks, capsys):
    gen = str(tiny_run / "generator.safetensors")
    code = main(["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4",
                 "--keep", "2", "--select", "score-kmeans", "--trust-speed", "1e-6",
                 "--json", "--no-progress"])  # fmt: skip
    gated = json.loads(capsys.readouterr().out)
    code2 = main(["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4",
                  "--keep", "2", "--select", "kmeans", "--json", "--no-progress"])  # fmt: skip
    plain = json.loads(capsys.readouterr().out)
    assert code == code2 == 0 and gated["trust_speed"] == 1e-6
    # every walker moves faster than 1e-6 model units per step: kmeans for all of them
    assert gated["min_fde"] == pytest.approx(plain["min_fde"])


def test_select_for_scene_keeps_k_of_numpy_samples_without_the_future(tiny_run, walks):
    from trajpref.data import load_dataset
    from trajpref.score.selection import select_for_scene

    scorer = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors")
    scene = load_dataset(str(walks), "test").scenes[0]
    g = np.random.default_rng(0)
    samples = scene.future[None] + 0.3 * g.standard_normal((8, *scene.future.shape))  # [K,P,T,2]
    cfg = SelectionConfig(method="score-facility", keep=3, drop=0.25)
    idx = select_for_scene(scorer, scene.history, samples, cfg)
    assert isinstance(idx, np.ndarray) and idx.shape == (3, scene.history.shape[0])
    for p in range(idx.shape[1]):
        assert len(set(idx[:, p].tolist())) == 3
    # the same as the batch path at the config's score steps (every 9 of S), and a tensor in
    # gives a tensor out
    batch = collate([scene])
    futures = torch.as_tensor(samples, dtype=torch.float32)
    at_nine = scorer.with_steps(score_timesteps(scorer.schedule.num_steps, 9))
    ref = select_samples(futures, cfg, at_nine.residual(batch, futures).sum(-1), batch)
    assert np.array_equal(idx, ref.numpy())
    # score_every=None scores at the scorer's own steps (from_checkpoint's: every 3)
    own = dataclasses.replace(cfg, score_every=None)
    ref = select_samples(futures, own, scorer.residual(batch, futures).sum(-1), batch)
    assert np.array_equal(select_for_scene(scorer, scene.history, samples, own), ref.numpy())
    out = select_for_scene(scorer, torch.as_tensor(scene.history), torch.as_tensor(samples), cfg)
    assert isinstance(out, torch.Tensor)
    kept = samples[idx, np.arange(idx.shape[1])]  # [K', P, T_f, 2]
    assert kept.shape == (3, *scene.future.shape)


def test_the_documented_python_selection_keeps_what_the_cli_keeps(tiny_run, walks, tmp_path):
    # `select_for_scene(scorer, history, samples, SelectionConfig(keep=K'))` is the README's
    # Python version of `predict --keep K'`: with the defaults of both they score at the same
    # steps (every 9 of S) and keep the same samples, scene by scene; and so do the README's
    # 34-step setting and `--score-every 3`
    from trajpref.score.selection import select_for_scene

    gen = str(tiny_run / "generator.safetensors")
    plain, kept = tmp_path / "plain.npz", tmp_path / "kept.npz"
    base = ["predict", "--dataset", str(walks), "--model", gen, "--samples", "4",
            "--no-progress", "--device", "cpu"]  # fmt: skip
    assert main([*base, "--out", str(plain)]) == 0
    scorer = TrajectoryScorer.from_checkpoint(gen)  # the default: the paper's every 3
    p = np.load(plain)
    for flags, cfg in (([], SelectionConfig(keep=2)),
                       (["--score-every", "3", "--drop", "0.5"],
                        SelectionConfig(keep=2, drop=0.5, score_every=3))):  # fmt: skip
        assert main([*base, "--keep", "2", *flags, "--out", str(kept)]) == 0
        k = np.load(kept)
        for b in range(int(p["scene"].max()) + 1):
            agents = p["scene"] == b
            idx = select_for_scene(scorer, p["history"][agents], p["pred"][:, agents], cfg)
            assert np.array_equal(idx, k["kept"][:, agents]), (flags, b)


def test_score_steps_are_checked_and_unread_without_the_score():
    with pytest.raises(ConfigError, match="score_every must be an integer >= 1 or None"):
        SelectionConfig(score_every=0)
    with pytest.raises(ConfigError, match="score_from must be an integer >= 0"):
        SelectionConfig(score_from=-1)
    with pytest.raises(ConfigError, match="score_from needs score_every"):
        SelectionConfig(score_every=None, score_from=3)
    assert SelectionConfig(method="kmeans", score_every=3).unread() == ["score_every"]
    assert SelectionConfig(method="score-kmeans", score_every=3).unread() == []


@pytest.mark.parametrize("keep", [0, 5.0, "5", True])
def test_keep_must_be_a_positive_integer(keep):
    with pytest.raises(ConfigError, match="keep must be an integer >= 1"):
        SelectionConfig(keep=keep)


# Walkthrough 67 (a robotics engineer's planning loop): samples that do not continue the
# history (another frame, offsets) are refused instead of ranked; ``select_for_scene`` can return
# the residuals and the pace gate it used; the selection's pace helper has its own name.


# ----------------------------------------------------------------------------- finding 2


def test_return_info_gives_the_residual_and_the_gate_of_the_same_pass(
    scorer, zara1, monkeypatch
):  # fmt: skip
    history = _scene(fast=2.0)  # agent 2: 0.8 m per step, above zara1's trust_speed 0.445
    samples = predict_scene(zara1, history)
    cfg = chosen_selection("zara1/generator", keep=3)
    idx = select_for_scene(scorer, history, samples, cfg)
    calls = []
    real = TrajectoryScorer.residual
    monkeypatch.setattr(TrajectoryScorer, "residual",
                        lambda self, *a, **k: calls.append(1) or real(self, *a, **k))  # fmt: skip
    info = select_for_scene(scorer, history, samples, cfg, return_info=True)
    assert len(calls) == 1  # one scoring pass
    got, residual, trusted = info  # a named tuple
    assert isinstance(info, selection.SceneSelection) and info.idx is got
    np.testing.assert_array_equal(got, idx)  # the default's indices
    assert residual.shape == (20, 3) and residual.dtype == np.float32
    assert trusted.dtype == np.bool_ and trusted.tolist() == [True, True, False]
    # the per-agent numbers rank_samples sums, at the selection's score steps
    _, total = rank_samples(selection.score_steps(scorer, cfg), history, samples)
    np.testing.assert_allclose(residual.sum(1), total, rtol=1e-5)
    kept = residual[got, np.arange(3)]  # the docstring's take: [K', P]
    assert kept.shape == (3, 3)
    # one scene: every agent falls back when any does
    scene_cfg = chosen_selection("zara1/generator", keep=3, per="scene")
    assert select_for_scene(scorer, history, samples, scene_cfg,
                            return_info=True).trusted.tolist() == [False] * 3  # fmt: skip
    # no gate: all trusted; a score-free method: nothing scored, nothing trusted
    plain = select_for_scene(scorer, history, samples, SelectionConfig(keep=3), return_info=True)
    assert plain.trusted.tolist() == [True] * 3
    free = select_for_scene(scorer, history, samples, SelectionConfig(keep=3, method="fps"),
                            return_info=True)  # fmt: skip
    assert free.residual is None and free.trusted.tolist() == [False] * 3
    # tensors in, tensors out
    out = select_for_scene(scorer, torch.from_numpy(history), samples, cfg, return_info=True)
    assert all(isinstance(t, torch.Tensor) for t in out)
    empty = select_for_scene(scorer, np.zeros((0, 8, 2)), np.zeros((20, 0, 12, 2)), cfg,
                             return_info=True)  # fmt: skip
    assert empty.idx.shape == (3, 0) and empty.residual.shape == (20, 0)
    assert empty.trusted.shape == (0,)


# ----------------------------------------------------------------------------- finding 4


def test_the_selections_pace_helper_is_not_a_twin_of_the_transforms_one():
    from trajpref.data import transforms

    assert not hasattr(selection, "observed_pace")  # one name, one argument
    batch = selection.Batch(history=torch.tensor([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]]),
                            future=torch.zeros(1, 12, 2), scene=torch.zeros(1, dtype=torch.int64),
                            agent_type=torch.zeros(1, dtype=torch.int64),
                            num_scenes=1)  # fmt: skip
    torch.testing.assert_close(selection.batch_observed_pace(batch, 2.0),
                               transforms.observed_pace(batch.history, 2.0))  # fmt: skip


# Two bugs a static type sweep found (walkthrough 67-G): a score selection given no scorer
# raised AttributeError from deep inside instead of the module's one-line ConfigError, and a
# scorer's ``with_steps`` copy lost the file name the data checks' warnings give.


def test_a_score_selection_without_a_scorer_is_a_config_error():
    batch = collate([make_scene(3)])
    pred = torch.from_numpy(np.random.default_rng(0).normal(size=(20, 3, 12, 2))).float()
    with pytest.raises(ConfigError, match="needs the diffusion score"):
        select_with_scorer(pred, SelectionConfig(keep=5, method="score-facility"), batch, None)


# A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
# and inputs the models read; feet given to a metre model are told the factor; a scene with no
# ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
# are types.


def test_select_for_scene_warns_of_a_scene_without_its_ball():
    """select_for_scene reads the same NBA scorer as rank_samples, which warns of a scene
    whose agent types flag no ball; it said nothing (the fixer's open item)."""
    from trajpref.score.scorer import TrajectoryScorer, predict_scene
    from trajpref.score.selection import SelectionConfig, select_for_scene

    scene = load_dataset("nba", "test").scenes[0]
    model = load_predictor("nba/generator")
    scorer = TrajectoryScorer.from_checkpoint("nba/denoiser").with_steps([0])
    samples = predict_scene(model, scene.history, 20, agent_type=scene.agent_type)  # [K, P, T_f, 2]
    cfg = SelectionConfig(keep=5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        select_for_scene(scorer, scene.history, samples, cfg, agent_type=scene.agent_type)
    with pytest.warns(UserWarning, match="select_for_scene: agent_type flags no ball"):
        select_for_scene(scorer, scene.history, samples, cfg,
                         agent_type=np.zeros_like(scene.agent_type))  # fmt: skip
