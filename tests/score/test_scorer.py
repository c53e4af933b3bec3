import json
import warnings

import numpy as np
import pytest
import torch
from helpers import _messages
from helpers import _scene as _nba_scene
from score.helpers import _scene
from synthetic import make_scene

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.data.transforms import to_model_frame
from trajpref.errors import ConfigError, DataError
from trajpref.models.encoder import scene_features
from trajpref.models.registry import load_predictor
from trajpref.score import (
    TrajectoryScorer,
    predict_scene,
    predict_scenes,
    rank_samples,
    score_timesteps,
)
from trajpref.score.selection import (
    chosen_selection,
    select_for_scene,
)
from trajpref.types import AGENT_BALL, AGENT_PERSON, collate


@pytest.fixture(scope="module")
def scorer(tiny_run):
    return TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors")


@pytest.fixture
def batch(walks):
    return collate(load_dataset(str(walks), "test").scenes[:3])


def _samples(batch, k=6, seed=0):
    g = torch.Generator().manual_seed(seed)
    noise = torch.randn((k, *batch.future.shape), generator=g) * 0.3
    return batch.future[None] + noise  # [K, N, T_f, 2]


def test_score_timesteps():
    assert score_timesteps(100) == list(range(0, 100, 3))
    assert score_timesteps(100)[-1] == 99 and len(score_timesteps(100)) == 34


def test_score_timesteps_from_a_later_step_keep_only_the_noisier_ones():
    assert score_timesteps(100, 3, 66) == [66, 69, 72, 75, 78, 81, 84, 87, 90, 93, 96, 99]
    assert score_timesteps(100, 100, 66) == [66]  # one step, at a high noise level
    for bad in (-1, 100):
        with pytest.raises(ConfigError, match="first step must lie in 0..99"):
            score_timesteps(100, 3, bad)


def test_r_is_exactly_zero_for_the_ground_truth(scorer, batch):
    res = scorer.score(batch, batch.future[None].expand(3, -1, -1, -1).clone())
    assert torch.equal(res.r, torch.zeros_like(res.r))
    assert torch.equal(res.ats, torch.zeros_like(res.ats))


def test_ranking_does_not_depend_on_the_ground_truth(scorer, batch):
    pred = _samples(batch)
    a = scorer.score(batch, pred)
    other = type(batch)(batch.history, batch.future + 3.0, batch.scene, batch.agent_type,
                        batch.num_scenes)  # fmt: skip
    b = scorer.score(other, pred)
    assert not torch.allclose(a.ats, b.ats)  # the score itself moves with the ground truth
    assert torch.equal(a.ats.argsort(0), b.ats.argsort(0))  # ... its ranking does not
    assert torch.equal(a.fts.argsort(0), b.fts.argsort(0))
    # rank() never reads the future: NaN futures give the same order
    blind = type(batch)(batch.history, torch.full_like(batch.future, float("nan")),
                        batch.scene, batch.agent_type, batch.num_scenes)  # fmt: skip
    assert torch.equal(scorer.rank(blind, pred), a.ats.argsort(0, descending=True))


def test_fixed_seeds_give_identical_scores(tiny_run, batch):
    pred = _samples(batch)
    s1 = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", seed=3)
    s2 = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", seed=3)
    s3 = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", seed=4)
    assert torch.equal(s1.residual(batch, pred), s2.residual(batch, pred))
    assert not torch.equal(s1.residual(batch, pred), s3.residual(batch, pred))


def test_shapes_and_scene_masks_in_a_mixed_batch(scorer):
    scenes = [make_scene(3, seed=1), make_scene(1, seed=2), make_scene(5, seed=3)]
    batch = collate(scenes)
    pred = _samples(batch, k=4)
    res = scorer.score(batch, pred)
    assert res.d_pred.shape == (4, 9, 12) and res.d_gt.shape == (9, 12)
    assert res.ats.shape == (4, 3) and res.fts.shape == (4, 3)
    assert res.ats_mean_of_ratios.shape == (4, 3)
    # each scene scored alone gives the same residuals, wherever it sits in the batch: no agent
    # sees another scene, and an agent's noise follows its place in its own scene
    alone = scorer.residual(collate(scenes[:1]), pred[:, :3])
    torch.testing.assert_close(alone, res.d_pred[:, :3], atol=1e-5, rtol=1e-4)
    last = scorer.residual(collate(scenes[2:]), pred[:, 4:])
    torch.testing.assert_close(last, res.d_pred[:, 4:], atol=1e-5, rtol=1e-4)
    order, _ = rank_samples(scorer, batch.history[4:], pred[:, 4:])  # the planning call
    assert order.tolist() == res.d_pred[:, 4:].sum((1, 2)).argsort().tolist()
    # Eq. 5 written out with one step per row (the denoiser's per-element path) agrees with
    # the scorer's step-by-step evaluation
    context = scorer.denoiser.context(scene_features(batch, scorer.scale))  # [N, H]
    y = to_model_frame(pred, batch, scorer.scale)  # [K, N, T_f, 2]
    n, s_count = batch.num_agents, len(scorer.steps)
    slots = torch.tensor([0, 1, 2, 0, 0, 1, 2, 3, 4])  # each agent's index in its scene
    z = torch.randn((5, s_count, 1, 12, 2), generator=torch.Generator().manual_seed(scorer.seed))
    z = z[slots].permute(1, 2, 0, 3, 4)  # [S', 1, N, T_f, 2]
    steps = torch.tensor(scorer.steps)[:, None, None].expand(-1, 4, n)  # [S', K, N]
    y_s = scorer.schedule.add_noise(y[None].expand(s_count, -1, -1, -1, -1), z, steps)
    eps = scorer.denoiser(y_s, steps, context)  # [S', K, N, T_f, 2]
    by_hand = (eps - z).pow(2).sum(-1).mean(0)  # [K, N, T_f]
    torch.testing.assert_close(res.d_pred, by_hand, atol=1e-5, rtol=1e-4)


def test_near_ground_truth_outranks_a_far_sample(scorer, batch):
    near = batch.future + 0.02 * torch.randn(
        batch.future.shape, generator=torch.Generator().manual_seed(0)
    )
    far = batch.future + torch.tensor([8.0, -8.0])
    pred = torch.stack([far, near])  # [2, N, T_f, 2]: the far one first
    order, total = rank_samples(scorer, batch.history[:3], pred[:, :3])
    assert order.tolist() == [1, 0] and total[1] < total[0]
    res = scorer.score(batch, pred)
    assert (res.ats[1] > res.ats[0]).all()


def test_accumulator_mean_ats_is_the_average_samples_ats(scorer, batch):
    from trajpref.score.scorer import ScoreAccumulator

    pred = _samples(batch)  # [K, N, T_f, 2]
    acc = ScoreAccumulator()
    acc.update(scorer, batch, pred)
    acc.update(scorer, batch, pred)  # twice: a mean over scenes, not a sum
    out = acc.compute()
    ats = scorer.score(batch, pred).ats  # [K, B]
    assert out["mean_ats"] == pytest.approx(float(ats.mean()), rel=1e-5)
    assert out["mean_ats"] < out["max_ats"]


def test_rank_samples_validates_shapes(scorer):
    with pytest.raises(ValueError, match="history"):
        rank_samples(scorer, torch.zeros(3, 8, 2), torch.zeros(4, 2, 12, 2))


def test_cli_evaluate_with_scorer_and_predict_rank(tiny_run, walks, tmp_path, capsys):
    den, gen = str(tiny_run / "denoiser.safetensors"), str(tiny_run / "generator.safetensors")
    code = main(["evaluate", "--dataset", str(walks), "--model", "cv", "--samples", "5",
                 "--scorer", den, "--json", "--no-progress"])  # fmt: skip
    res = json.loads(capsys.readouterr().out)
    assert code == 0
    for key in ("max_ats", "max_fts", "top1_recall_ats", "top5_recall_ats", "top1_recall_fts",
                "top5_recall_fts"):  # fmt: skip
        assert key in res
    assert res["top5_recall_ats"] == 1.0  # K = 5: the top 5 hold every sample
    out = tmp_path / "ranked.npz"
    code = main(["predict", "--dataset", str(walks), "--model", gen,
                 "--samples", "4", "--rank", "--out", str(out), "--no-progress"])  # fmt: skip
    assert code == 0
    import numpy as np

    with np.load(out) as z:
        assert z["order"].shape[0] == 4 and z["residual"].shape == z["order"].shape
        assert (np.diff(z["residual"], axis=0) >= 0).all()  # best (lowest residual) first
    code = main(["predict", "--dataset", str(walks), "--model", "cv", "--rank", "--out",
                 str(tmp_path / "x.npz")])  # fmt: skip
    assert code == 2 and "--scorer" in capsys.readouterr().err


def test_rank_and_scorer_score_at_the_score_options(tiny_run, walks, tmp_path, capsys):
    # --score-every/--score-from/--score-precision were accepted and ignored by --rank and
    # --scorer; they apply now, and without them both score as before (every 3 of S)
    import numpy as np

    gen, den = str(tiny_run / "generator.safetensors"), str(tiny_run / "denoiser.safetensors")
    base = ["predict", "--dataset", str(walks), "--model", gen, "--samples", "4", "--rank",
            "--no-progress"]  # fmt: skip
    runs = {}
    for name, flags in (("default", []), ("three", ["--score-every", "3"]),
                        ("nine", ["--score-every", "9"]),
                        ("bf16", ["--score-precision", "bf16"])):  # fmt: skip
        out = tmp_path / f"{name}.npz"
        assert main([*base, *flags, "--out", str(out)]) == 0
        assert capsys.readouterr().err == ""
        runs[name] = dict(np.load(out))
    assert np.array_equal(runs["default"]["residual"], runs["three"]["residual"])
    assert not np.allclose(runs["default"]["residual"], runs["nine"]["residual"])
    assert not np.array_equal(runs["default"]["residual"], runs["bf16"]["residual"])
    # --score-every 9 ranks as rank_samples does with a scorer at steps 0 and 9
    scorer = TrajectoryScorer.from_checkpoint(gen)
    nine = scorer.with_steps(score_timesteps(scorer.schedule.num_steps, 9))
    plain = runs["default"]
    for b in range(int(plain["scene"].max()) + 1):
        agents = plain["scene"] == b
        _, total = rank_samples(nine, plain["history"][agents], plain["pred"][:, agents])
        assert np.allclose(np.sort(total), runs["nine"]["residual"][:, b], rtol=1e-5)
    # evaluate --scorer: the metrics at the steps asked for, which the JSON names
    ev = ["evaluate", "--dataset", str(walks), "--model", gen, "--samples", "4", "--scorer",
          den, "--json", "--no-progress"]  # fmt: skip
    assert main(ev) == 0
    default = json.loads(capsys.readouterr().out)
    assert main([*ev, "--score-every", "9", "--score-precision", "bf16"]) == 0
    nine = json.loads(capsys.readouterr().out)
    assert (default["scorer_score_steps"], nine["scorer_score_steps"]) == (4, 2)
    assert nine["scorer_score_precision"] == "bf16" and nine["max_ats"] != default["max_ats"]


def test_score_and_selection_options_that_nothing_reads_say_so(tiny_run, walks, tmp_path,
                                                              capsys):  # fmt: skip
    gen = str(tiny_run / "generator.safetensors")
    base = ["predict", "--dataset", str(walks), "--model", gen, "--samples", "4",
            "--no-progress"]  # fmt: skip
    cases = [
        (["--score-every", "5"], "--score-every only applies with --keep or --rank: here it "
         "changes nothing"),
        (["--score-every", "5", "--drop", "0.5"], "--drop only applies with --keep; "
         "--score-every only applies with --keep or --rank: here they change nothing"),
        (["--keep", "2", "--select", "kmeans", "--score-every", "5", "--score-precision",
          "bf16"], "--select kmeans does not read --score-every, --score-precision: they "
         "change nothing"),
        (["--rank", "--score-every", "5", "--score-from", "1"], None),
        (["--keep", "2", "--select", "kmeans", "--rank", "--score-every", "5"], None),
        (["--keep", "2", "--score-every", "5", "--score-precision", "bf16"], None),
    ]  # fmt: skip
    for i, (flags, warning) in enumerate(cases):  # each its own --out: no replaced-file note
        assert main([*base, "--out", str(tmp_path / f"p{i}.npz"), *flags]) == 0, flags
        err = capsys.readouterr().err
        assert err == (f"trajpref: warning: {warning}\n" if warning else ""), flags


def test_cli_plot_with_scorer(tiny_run, walks, tmp_path, scorer, plot_calls):
    out = tmp_path / "fig2.png"
    model, path = str(tiny_run / "generator.safetensors"), str(tiny_run / "denoiser.safetensors")
    code = main(["plot", "--dataset", str(walks), "--model", model, "--samples", "4",
                 "--scorer", path, "--out", str(out)])  # fmt: skip
    assert code == 0 and out.read_bytes()[:4] == b"\x89PNG"
    # the ranked figure, given the scorer's ATS of each drawn sample of each agent
    ((name, args, _),) = plot_calls
    history, future, samples, scores = args[:4]
    assert name == "plot_scene_scored" and scores.shape == samples.shape[:2] == (4, len(future))
    scene = collate(load_dataset(str(walks), "test").scenes[:1])
    assert torch.equal(torch.as_tensor(history), scene.history)
    want = scorer.score(scene, torch.as_tensor(samples)).agent_ats.numpy()  # [K, P]
    assert scores == pytest.approx(want, rel=1e-5, abs=1e-6)


def test_speed_normalisation_leaves_slow_scenes_alone_and_rescales_fast_ones(tiny_run, batch):
    from trajpref.data.transforms import scene_speeds, transform_positions, transform_scenes

    path = tiny_run / "denoiser.safetensors"
    plain = TrajectoryScorer.from_checkpoint(path)
    samples = _samples(batch)
    speeds = scene_speeds(batch)  # [B]
    slow = TrajectoryScorer.from_checkpoint(path, speed_ref=float(speeds.max()) * 1.01)
    assert torch.allclose(slow.residual(batch, samples), plain.residual(batch, samples))
    # a reference at half the slowest scene's speed: every scene is shrunk by ref / speed
    ref = float(speeds.min()) / 2
    fast = TrajectoryScorer.from_checkpoint(path, speed_ref=ref)
    mats = (ref / speeds)[:, None, None] * torch.eye(2)  # [B, 2, 2]
    expected = plain.residual(transform_scenes(batch, mats),
                              transform_positions(samples, batch, mats))  # fmt: skip
    assert torch.allclose(fast.residual(batch, samples), expected)
    assert not torch.allclose(expected, plain.residual(batch, samples))
    with pytest.raises(ConfigError, match="speed_ref must be > 0"):
        TrajectoryScorer.from_checkpoint(path, speed_ref=0.0)


def test_bf16_scoring_stays_close_to_fp32_and_returns_fp32(tiny_run, batch):
    pred = _samples(batch, k=8)
    full = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors")
    low = TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", precision="bf16")
    d32, d16 = full.residual(batch, pred), low.residual(batch, pred)  # [K, N, T_f]
    assert d16.dtype == torch.float32 and d16.shape == d32.shape
    assert not torch.equal(d16, d32)  # the passes really ran in another arithmetic
    # bfloat16 keeps 8 bits of mantissa: the residuals agree to a few percent ...
    assert torch.allclose(d16, d32, rtol=0.1, atol=0.05)
    # ... and so does the per-agent order of the samples (rank correlation per agent)
    a = d32.sum(-1).argsort(0).argsort(0).float()  # [K, N] ranks
    b = d16.sum(-1).argsort(0).argsort(0).float()
    corr = torch.nn.functional.cosine_similarity(a - a.mean(0), b - b.mean(0), dim=0)  # [N]
    assert corr.mean() > 0.9
    with pytest.raises(ConfigError, match="precision"):
        TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", precision="fp16")


def test_predict_with_keep_saves_which_samples_it_kept(tiny_run, walks, tmp_path, capsys):
    import numpy as np

    gen = str(tiny_run / "generator.safetensors")
    common = ["predict", "--dataset", str(walks), "--model", gen, "--samples", "4",
              "--no-progress", "--seed", "3"]  # fmt: skip
    assert main([*common, "--out", str(tmp_path / "all.npz")]) == 0
    assert main([*common, "--keep", "2", "--select", "score-facility", "--rank", "--out",
                 str(tmp_path / "kept.npz")]) == 0  # fmt: skip
    with np.load(tmp_path / "all.npz") as a, np.load(tmp_path / "kept.npz") as b:
        drawn, pred, kept = a["pred"], b["pred"], b["kept"]
        assert kept.shape == (2, drawn.shape[1]) and b["order"].shape[0] == 2
        np.testing.assert_array_equal(pred, np.take_along_axis(drawn, kept[..., None, None], 0))


def test_predict_scene_samples_one_scene_from_arrays_as_the_batched_path_does(tiny_run, walks):
    import numpy as np

    from trajpref.errors import DataError
    from trajpref.models.registry import load_predictor
    from trajpref.score import predict_scene

    model = load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")
    scenes = load_dataset(str(walks), "test").scenes[:2]
    batched = model.predict(collate(scenes), 4, torch.Generator().manual_seed(3))  # [4, N, 12, 2]
    p = scenes[1].num_agents
    mine = predict_scene(model, scenes[1].history.astype(np.float64), 4, seed=3)
    assert isinstance(mine, np.ndarray) and mine.shape == (4, p, 12, 2)
    np.testing.assert_allclose(mine, batched[:, -p:].numpy(), atol=1e-5)
    as_tensor = predict_scene(model, torch.from_numpy(scenes[1].history), 4, seed=3)
    assert isinstance(as_tensor, torch.Tensor) and as_tensor.shape == (4, p, 12, 2)
    with pytest.raises(DataError, match=r"expected \[P, 8, 2\] .*T_h = 8\), got \[.*, 7, 2\]"):
        predict_scene(model, scenes[1].history[:, 1:])
    with pytest.raises(DataError, match="not finite"):
        predict_scene(model, np.where(np.arange(16).reshape(8, 2) == 3, np.nan,
                                      scenes[1].history))  # fmt: skip
    with pytest.raises(DataError, match="subtract an origin"):
        predict_scene(model, scenes[1].history + 5e6)
    cv = predict_scene(load_predictor("cv"), scenes[1].history, 1)  # any T_h, T_f 12
    assert cv.shape == (1, p, 12, 2)


# Walkthrough 67 (a robotics engineer's planning loop): samples that do not continue the
# history (another frame, offsets) are refused instead of ranked; ``select_for_scene`` can return
# the residuals and the pace gate it used; the selection's pace helper has its own name.


@pytest.fixture(scope="module")
def zara1_scorer():
    """conftest.py's ``scorer`` (zara1's published denoiser at score steps 0 and 3), which this
    module's own ``scorer`` (the tiny run's) hides."""
    return TrajectoryScorer.from_checkpoint("zara1/denoiser").with_steps([0, 3])


FRAME = "samples do not continue the history.*another frame.*offsets"


@pytest.fixture(scope="module")
def scene(zara1):
    history = _scene()
    return history, predict_scene(zara1, history)  # [3, 8, 2], [20, 3, 12, 2]


# ----------------------------------------------------------------------------- finding 1


def test_samples_in_another_frame_or_as_offsets_are_refused(zara1_scorer, scene):
    history, samples = scene
    cfg = chosen_selection("zara1/generator", keep=3)
    offsets = samples - history[None, :, -1:]  # each from its agent's last position
    for wrong in (offsets, samples + 100.0, samples - np.array([50.0, 20.0])):  # robot frame
        with pytest.raises(DataError, match=FRAME):
            rank_samples(zara1_scorer, history, wrong)
        with pytest.raises(DataError, match=FRAME):
            select_for_scene(zara1_scorer, history, wrong, cfg)
        with pytest.raises(DataError, match=FRAME):  # tensors alike
            rank_samples(zara1_scorer, torch.from_numpy(history), torch.from_numpy(wrong))
    with pytest.raises(DataError, match=r"agent\(s\) 0 \(\d.*1 \(.*2 \(.*7\.36 m"):
        rank_samples(zara1_scorer, history, samples + 100.0)
    # the fix the message names gives the absolute samples back
    order, _ = rank_samples(zara1_scorer, history, history[None, :, -1:] + offsets)
    np.testing.assert_array_equal(order, rank_samples(zara1_scorer, history, samples)[0])


def test_the_models_own_samples_pass_without_a_warning(zara1, zara1_scorer, scene):
    history, samples = scene
    cfg = chosen_selection("zara1/generator", keep=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rank_samples(zara1_scorer, history, samples)
        select_for_scene(zara1_scorer, history, samples, cfg)
        far = history + 1e3  # a map frame km off: both in it, nothing to say
        rank_samples(zara1_scorer, far, predict_scene(zara1, far))


def test_only_every_sample_of_an_agent_far_off_is_refused(zara1_scorer, scene):
    history, samples = scene
    stray = samples.copy()
    stray[:19, 1] += 100.0  # one of agent 1's 20 samples still starts where it is
    rank_samples(zara1_scorer, history, stray)
    one = samples.copy()
    one[:, 1] += 100.0  # every sample of one agent: refused, naming it alone
    with pytest.raises(DataError, match=r"agent\(s\) 1 \(") as caught:
        rank_samples(zara1_scorer, history, one)
    assert "agent(s) 1 (" in str(caught.value) and " 0 (" not in str(caught.value)
    # a ball may be that fast; an agent whose history jumps is the jump warning's
    ball = np.array([AGENT_PERSON, AGENT_BALL, AGENT_PERSON])
    rank_samples(zara1_scorer, history, one, ball)
    jumped = history.copy()
    jumped[1, 4:] += 10.0  # a 10 m step: an id switch, already warned of
    with pytest.warns(UserWarning, match="jumps more than"):
        rank_samples(zara1_scorer, jumped, one)


# Two bugs a static type sweep found (walkthrough 67-G): a score selection given no scorer
# raised AttributeError from deep inside instead of the module's one-line ConfigError, and a
# scorer's ``with_steps`` copy lost the file name the data checks' warnings give.


def test_with_steps_keeps_the_scorers_file_name(zara1_scorer):
    assert zara1_scorer.checkpoint is not None and zara1_scorer.checkpoint.endswith("denoiser")
    assert zara1_scorer.with_steps([0]).checkpoint == zara1_scorer.checkpoint
    fresh = TrajectoryScorer(zara1_scorer.denoiser, zara1_scorer.schedule, zara1_scorer.scale, [0])
    assert fresh.checkpoint is None  # built in code


# A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
# and inputs the models read; feet given to a metre model are told the factor; a scene with no
# ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
# are types.


@pytest.fixture(scope="module")
def nba_scorer():
    return TrajectoryScorer.from_checkpoint("nba/denoiser").with_steps([0])


# 4. float agent types


def test_float_flags_from_pandas_are_types(nba, nba_scorer):
    history, types = _nba_scene()
    as_ints = predict_scene(nba, history, 20, agent_type=types)
    for floats in (types.astype(np.float64), types.astype(np.float32).tolist(),
                   torch.tensor(types, dtype=torch.float64)):  # fmt: skip
        np.testing.assert_array_equal(predict_scene(nba, history, 20, agent_type=floats), as_ints)
    order, residual = rank_samples(nba_scorer, history, as_ints, agent_type=types)
    order_f, residual_f = rank_samples(nba_scorer, history, as_ints, types.astype(np.float64))
    np.testing.assert_array_equal(order_f, order)
    np.testing.assert_array_equal(residual_f, residual)


@pytest.mark.parametrize(
    "value, message",
    [
        (np.r_[0.5, np.zeros(10)], r"got float64 values that are not whole numbers \(the first, "
                                   r"0.5, at index 0\)"),
        (np.r_[np.zeros(10), np.nan], r"float64 values .*the first, nan, at index 10"),
        (np.r_[2.0, np.zeros(10)], r"flags must be 0 \(person\) or 1 \(ball\), got \[0.0, 2"),
        (np.zeros((11, 1)), r"expected 11 integer flags \[P\], got \[11, 1\] of float64"),
        (torch.full((11,), 0.25), r"got torch.float32 values that are not whole numbers"),
    ],
)  # fmt: skip
def test_other_floats_are_refused_naming_their_dtype(nba, value, message):
    history, _ = _nba_scene()
    with pytest.raises(DataError, match=message) as raised:
        predict_scene(nba, history, 20, agent_type=value)
    whole = "flags must be" in message  # a whole number that is no flag
    assert str(raised.value).startswith("agent_type: " + ("" if whole else "expected 11 "))


# 3. a scene with no ball or two balls


def test_predict_and_rank_say_a_scene_without_one_ball(nba, nba_scorer):
    history, types = _nba_scene()
    samples = predict_scene(nba, history, 20, agent_type=types)
    assert not _messages(lambda: predict_scene(nba, history, 20, agent_type=types))
    assert not _messages(lambda: rank_samples(nba_scorer, history, samples, types))
    two = types.copy()
    two[5] = 1
    for flags, found in ((np.zeros(11, np.int64), "no ball"), (two, "2 balls")):
        got = _messages(lambda f=flags: predict_scene(nba, history, 20, agent_type=f))
        assert got == [f"predict_scene: agent_type flags {found} (agent_type 1) in this scene; "
                       "this model was trained on nba with the ball flagged (agent_type 1; one "
                       "in every scene of NBA's splits), so its futures of such a scene are of "
                       "one it never saw: flag the ball 1 and each player 0"]  # fmt: skip
        got = _messages(lambda f=flags: rank_samples(nba_scorer, history, samples, f))
        assert len(got) == 1 and got[0].startswith(f"rank_samples: agent_type flags {found}")
        assert "this scorer was trained on nba" in got[0] and "its scores of" in got[0]
    scenes = [history, history, history, history[:0]]
    flags = [types, two, np.zeros(11), None]
    got = _messages(lambda: predict_scenes(nba, scenes, 20, agent_types=flags))
    assert len(got) == 1
    assert got[0].startswith(
        "predict_scenes: agent_types flag no ball in 1 and two or more "
        "balls in 1 of the 3 scenes given types (histories[1], "
        "histories[2]); this model was trained on nba"
    )


def test_a_model_trained_without_types_says_nothing_of_balls():
    zara1 = load_predictor("zara1/generator", device="cpu")
    history, _ = _nba_scene()
    assert not [m for m in _messages(lambda: predict_scene(zara1, history, 20,
                                                           agent_type=np.zeros(11, np.int64)))
                if "ball" in m]  # fmt: skip
