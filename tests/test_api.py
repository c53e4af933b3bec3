"""The Python API users call directly: the README's example runs as written against a
published model, and ``rank_samples`` takes numpy or torch and refuses bad input clearly."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.errors import DataError
from trajpref.score import TrajectoryScorer, rank_samples
from trajpref.types import collate

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.fixture(scope="module")
def scorer() -> TrajectoryScorer:
    return TrajectoryScorer.from_checkpoint("zara1/denoiser")


def _walk(p: int = 2, k: int = 4):
    """history [P, 8, 2] of agents walking at 1.2 m/s, and K futures [K, P, 12, 2]: sample 0
    goes on straight, the others turn, stop dead or jump 5 m (all far less human-like)."""
    t = np.arange(20, dtype=np.float64)[:, None]  # [T, 1]
    tracks = np.stack([np.hstack([0.48 * t, 0 * t + 2.0 * a]) for a in range(p)])  # [P, 20, 2]
    history, straight = tracks[:, :8], tracks[:, 8:]  # [P, 8, 2], [P, 12, 2]
    stop = np.repeat(history[:, -1:], 12, axis=1)  # [P, 12, 2]
    jump = straight + np.array([5.0, -5.0])
    turn = straight.copy()
    turn[..., 1] += 0.3 * np.arange(12) ** 1.5
    return history, np.stack([straight, turn, stop, jump][:k])


def test_readme_example_runs_as_written(data_root, tmp_path, monkeypatch):
    text = README.read_text()
    section = text.split("## Python API", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert 'from_checkpoint("zara1/denoiser")' in code  # a published model, by name
    monkeypatch.chdir(tmp_path)
    out = re.search(r"# from: trajpref predict .*--out (\S+)", code).group(1)  # the file it loads
    argv = ["predict", "--dataset", "zara1", "--data-root", str(data_root), "--model", "cv",
            "--out", out, "--no-progress", "--device", "cpu"]  # fmt: skip
    assert main(argv) == 0
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)  # noqa: S102 - our own README
    order, residual = namespace["order"], namespace["residual"]
    assert isinstance(order, np.ndarray) and isinstance(residual, np.ndarray)
    assert order.dtype == np.int64 and residual.dtype == np.float32
    assert sorted(order.tolist()) == list(range(20))
    assert np.isfinite(residual).all() and (np.diff(residual[order]) >= 0).all()
    idx, kept = namespace["idx"], namespace["kept"]
    samples = namespace["samples"]
    assert idx.shape == (5, samples.shape[1]) and kept.shape == (5, *samples.shape[1:])
    assert all(len(set(col)) == 5 for col in idx.T.tolist())  # five distinct futures per agent
    assert namespace["futures"].shape == (20, *samples.shape[1:])  # predict_scene
    # the same numbers from tensors (the scorer's noise is seeded)
    pred = np.load(out)
    agents = pred["scene"] == 0
    t_order, t_res = rank_samples(namespace["scorer"], torch.from_numpy(pred["history"][agents]),
                                  torch.from_numpy(pred["pred"][:, agents]))  # fmt: skip
    assert t_order.tolist() == order.tolist()
    np.testing.assert_allclose(t_res.numpy(), residual, rtol=1e-6)


def test_published_scorer_prefers_walking_on_and_reports_its_window(scorer):
    assert (scorer.t_hist, scorer.t_fut) == (8, 12)
    history, samples = _walk()
    order, residual = rank_samples(scorer, history, samples)
    assert order[0] == 0  # straight on at the same pace is the most human-like
    assert residual[3] > residual[0]  # a 5 m jump is not


def test_numpy_lists_float64_and_torch_give_the_same_ranking(scorer):
    history, samples = _walk()
    ref_order, ref_res = rank_samples(scorer, history.astype(np.float32), samples)
    for h, s in [
        (history, samples),  # float64 arrays
        (history.tolist(), samples.tolist()),  # nested lists
        (torch.from_numpy(history), torch.from_numpy(samples)),  # float64 tensors
        (torch.from_numpy(history).float(), samples),  # mixed: tensors out
    ]:
        order, res = rank_samples(scorer, h, s)
        as_np = isinstance(h, torch.Tensor) or isinstance(s, torch.Tensor)
        assert isinstance(order, torch.Tensor) is as_np
        assert np.asarray(order).tolist() == ref_order.tolist()
        np.testing.assert_allclose(np.asarray(res), ref_res, rtol=1e-6)


def test_final_step_ranking_and_agent_types(scorer):
    history, samples = _walk()
    order, res = rank_samples(scorer, history, samples, final=True)
    _, full = rank_samples(scorer, history, samples)
    assert order[0] == 0 and (res < full).all()  # one step of 12, summed over agents
    same, _ = rank_samples(scorer, history, samples, agent_type=np.array([0, 0]))
    assert same.tolist() == rank_samples(scorer, history, samples)[0].tolist()


H, S = _walk()


@pytest.mark.parametrize(
    ("history", "samples", "kwargs", "message"),
    [
        (H[:, 1:], S, {}, r"history: expected \[P, 8, 2\] .*T_h = 8\), got \[2, 7, 2\]"),
        (H[..., :1], S, {}, r"history: expected \[P, 8, 2\].* got \[2, 8, 1\]"),
        (H[0], S, {}, r"history: expected \[P, 8, 2\].* got \[8, 2\]"),
        (H[:0], S, {}, r"samples: expected \[K, 0, 12, 2\] \(samples, the history's 0 agents"),
        (H, S[:, :, :10], {}, r"samples: expected \[K, 2, 12, 2\] .*T_f = 12\), got \[4, 2, 10"),
        (H, S[:, :1], {}, r"samples: expected \[K, 2, 12, 2\] \(samples, the history's 2 agents"),
        (H, S[0], {}, r"got \[2, 12, 2\] \(one sample\? add a leading axis: samples\[None\]\)"),
        (H, S[:0], {}, r"samples: no samples \(K = 0\)"),
        (np.where(np.arange(32).reshape(2, 8, 2) == 9, np.nan, H), S, {},
         r"history: 1 value\(s\) not finite after conversion to float32 .*index \[0, 4, 1\]"),
        (H, np.where(S > 5, np.inf, S), {}, r"samples: \d+ value\(s\) not finite"),
        (H + 1e39, S, {}, r"history: 32 value\(s\) not finite .*beyond \+-3.4e38"),
        (torch.full((2, 8, 2), float("nan")), S, {}, r"history: 32 value\(s\) not finite"),
        ([["a", "b"]], S, {}, r"history: expected an array of numbers \(could not convert"),
        ([[1.0, 2.0], [3.0]], S, {}, r"history: expected an array of numbers"),
        (torch.zeros(2, 8, 2, dtype=torch.bool), S, {}, r"history: expected real numbers"),
        (H, S, {"agent_type": [0, 0, 0]}, r"agent_type: expected 2 integer flags \[P\]"),
        (H, S, {"agent_type": [0.0, 0.5]}, r"agent_type: expected 2 integer flags"),
        (H, S, {"agent_type": [0, 7]}, r"agent_type: flags must be 0 \(person\) or 1 \(ball\)"),
    ],
)  # fmt: skip
def test_bad_input_is_a_data_error_with_a_clear_message(scorer, history, samples, kwargs,
                                                        message):  # fmt: skip
    with pytest.raises(DataError, match=message):
        rank_samples(scorer, history, samples, **kwargs)


def test_an_empty_view_ranks_the_samples_as_they_came(scorer):
    # no agent in view (history [0, 8, 2], samples [K, 0, 12, 2]): nothing tells the samples
    # apart, so the order is 0..K-1 and every residual is 0 (a sum over no agents), and
    # samples[order] stays a valid index; it used to be a DataError
    order, residual = rank_samples(scorer, H[:0], S[:, :0])
    assert isinstance(order, np.ndarray) and order.tolist() == [0, 1, 2, 3]
    assert isinstance(residual, np.ndarray) and residual.tolist() == [0.0] * 4
    order, residual = rank_samples(scorer, torch.as_tensor(H[:0]), S[:, :0], final=True)
    assert isinstance(order, torch.Tensor) and order.tolist() == [0, 1, 2, 3]
    assert residual.tolist() == [0.0] * 4
    assert S[:, :0][order.numpy()].shape == (4, 0, 12, 2)
    with pytest.raises(DataError, match=r"samples: no samples \(K = 0\)"):
        rank_samples(scorer, H[:0], S[:0, :0])  # still no samples to rank


def test_batch_entry_points_check_shapes(scorer, walks):
    batch = collate(load_dataset(str(walks), "test").scenes[:2])
    n = batch.num_agents
    with pytest.raises(DataError, match=rf"futures: expected \[M, {n}, 12, 2\]"):
        scorer.residual(batch, batch.future[None, :, :10])
    with pytest.raises(DataError, match=rf"futures: expected \[M, {n}, 12, 2\]"):
        scorer.score(batch, batch.future[None, :-1])
    assert scorer.rank(batch, batch.future[None].repeat(3, 1, 1, 1)).shape == (3, 2)


# --- a planner's calls on the published models (the walkthrough of 2026-12-06) ---------------


def _tracks(p: int = 3, dt: float = 0.4, seed: int = 0) -> np.ndarray:
    """[P, 8, 2] agents walking about 1.3 m/s, one position every ``dt`` seconds, metres."""
    rng = np.random.default_rng(seed)
    t = np.arange(8)[:, None] * dt  # [8, 1]
    heading = rng.uniform(0, 2 * np.pi, p)  # [P]
    v = 1.3 * np.stack([np.cos(heading), np.sin(heading)], -1)  # [P, 2]
    return (rng.uniform(-3, 3, (p, 1, 2)) + t[None] * v[:, None]).astype(np.float32)


def test_loaded_models_and_scorers_know_their_training_step_and_units(robo, zara1, scorer):
    from trajpref.models.registry import load_predictor

    assert (robo.frame_interval, robo.units) == (0.5, "m")
    assert (zara1.frame_interval, zara1.units) == (0.4, "m")
    sdd = load_predictor("sdd/generator")
    assert (sdd.frame_interval, sdd.units) == (0.4, "px")
    assert (scorer.frame_interval, scorer.units) == (0.4, "m")
    assert scorer.with_steps([0]).frame_interval == 0.4  # kept by a scorer at other steps
    robo_scorer = TrajectoryScorer.from_checkpoint("robo/denoiser")
    assert (robo_scorer.frame_interval, robo_scorer.units) == (0.5, "m")
    assert load_predictor("cv").predict is not None  # the baseline has no step: any pace


def test_a_step_or_unit_other_than_the_models_warns_as_the_cli_does(robo, scorer):
    from trajpref.errors import ConfigError
    from trajpref.score import predict_scene

    history = _tracks(3, dt=0.4)
    with pytest.warns(UserWarning, match=r"this model was trained on robo-sim: this data steps "
                      r"0\.4 s, the model's 0\.5 s \(resample the history to one position "
                      r"every 0\.5 s"):  # fmt: skip
        futures = predict_scene(robo, history, frame_interval=0.4)
    assert futures.shape == (20, 3, 12, 2)
    with pytest.warns(UserWarning, match="this data is in px, the model's in m"):
        predict_scene(robo, _tracks(3, dt=0.5), frame_interval=0.5, units="px")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predict_scene(robo, _tracks(3, dt=0.5), frame_interval=0.5, units="metres")
        predict_scene(robo, _tracks(3, dt=0.5))  # nothing said, nothing compared
    with pytest.raises(ConfigError, match="frame_interval: seconds between"):
        predict_scene(robo, history, frame_interval=0)
    history, samples = _walk()
    with pytest.warns(UserWarning, match="this scorer was trained on zara1: this data steps 0.5"):
        rank_samples(scorer, history, samples, frame_interval=0.5)


def test_models_with_agent_roles_say_so_and_the_docs_give_the_order(robo, zara1):
    from trajpref.score import predict_scene

    assert (robo.agent_roles, zara1.agent_roles) == (3, 0)
    doc = predict_scene.__doc__
    assert "model.agent_roles" in doc and "leader, follower" in doc
    python = README.read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    assert "model.agent_roles" in python and "leader, follower, approacher" in python


def test_context_neighbours_reach_a_model_that_reads_them(zara1, robo):
    from trajpref.score import predict_scene
    from trajpref.types import Scene, collate

    history = _tracks(2, seed=3)
    near = history[:1] + np.array([0.6, 0.0], np.float32)  # [1, 8, 2] beside agent 0
    alone = predict_scene(zara1, history)
    with_ctx = predict_scene(zara1, history, context=near)
    nan = np.full((2, 12, 2), np.nan, np.float32)
    batch = collate([Scene(history, nan, np.zeros(2, np.int64), "s", context=near)])
    np.testing.assert_allclose(with_ctx, zara1.predict(batch, 20).numpy(), atol=1e-5)
    assert np.abs(with_ctx - alone).max() > 1e-3  # the neighbour is read
    part = near.copy()
    part[0, :3] = np.nan  # seen in the last 5 frames only: fewer than model.context_frames
    assert zara1.reads_context and zara1.context_frames == 8
    with pytest.warns(UserWarning, match=r"context rows ignored"):  # and says so
        np.testing.assert_array_equal(predict_scene(zara1, history, context=part), alone)
    with pytest.raises(DataError, match=r"context: 1 value\(s\) not finite .*NaN marks an unseen"):
        predict_scene(zara1, history, context=np.where(near > 1e9, 0, near) + np.array(
            [[[np.inf, 0]] + [[0, 0]] * 7]))  # fmt: skip
    with pytest.raises(DataError, match=r"context: expected \[C, 8, 2\]"):
        predict_scene(zara1, history, context=near[:, 1:])
    assert not robo.reads_context
    with pytest.warns(UserWarning, match="reads no context-only neighbours"):
        predict_scene(robo, _tracks(2, dt=0.5), context=near)


def test_predict_scenes_equals_the_loop_on_a_published_generator(zara1):
    from trajpref.score import predict_scene, predict_scenes

    histories = [_tracks(p, seed=p) + 10.0 * p for p in (1, 3, 2)]
    together = predict_scenes(zara1, histories)
    for history, got in zip(histories, together, strict=True):
        np.testing.assert_allclose(got, predict_scene(zara1, history), atol=1e-4)


def test_chosen_selection_settings_are_those_the_benchmarks_recorded():
    import json
    import shlex

    from trajpref.errors import ConfigError
    from trajpref.score.selection import CHOSEN, SelectionConfig, chosen_selection

    root = README.parent / "benchmarks"
    chosen = json.loads((root / "selection_chosen.json").read_text())
    metas = [json.loads(p.read_text()) for p in (root / "results" / "meta").glob("select_*")]
    flags = {"--drop": "drop", "--temperature": "temperature", "--bandwidth": "bandwidth",
             "--score-every": "score_every", "--score-from": "score_from"}  # fmt: skip
    for dataset, rows in chosen.items():
        rows = [rows] if isinstance(rows, str) else rows
        name = "eth/generator-pace" if dataset == "eth (pace)" else f"{dataset}/generator"
        stem = "select_" + ("eth_pace" if dataset == "eth (pace)" else dataset)
        results = json.loads((root / "results" / f"{stem}.json").read_text())
        for row, cheap in zip(rows, (False, True), strict=False):
            run = next(r for r in results if r["method"] == row and r["seed"] == 0)
            argv = shlex.split(run["command"])
            given = {flags[a]: float(argv[i + 1]) for i, a in enumerate(argv) if a in flags}
            cfg = chosen_selection(name, keep=3, cheap=cheap)
            assert cfg.method == "score-facility" == row[len("select-") :].split("-d")[0]
            for key, value in given.items():
                assert getattr(cfg, key) == pytest.approx(value), (name, cheap, key)
            assert cfg.score_from == given.get("score_from", 0)
            # the gate's V: what the same run printed and recorded in its meta file
            recorded = {round(m["trust_speed"], 4) for m in metas
                        if isinstance(m, dict) and m.get("command") == run["command"]}  # fmt: skip
            assert recorded == {cfg.trust_speed}, (name, cheap, recorded)
    assert set(CHOSEN) == {"zara1/generator", "eth/generator", "robo/generator",
                           "robo-mix/generator", "eth/generator-pace"}  # fmt: skip
    readme = SelectionConfig(keep=5, drop=0.2, bandwidth=1.0, trust_speed=0.445, score_every=3)
    assert chosen_selection("zara1/generator") == readme  # the README's spelled-out setting
    with pytest.raises(ConfigError, match="no chosen selection setting for 'hotel/generator'"):
        chosen_selection("hotel/generator")


def test_resolve_device_refuses_what_this_machine_lacks_in_one_line():
    from trajpref.device import resolve_device
    from trajpref.errors import ConfigError

    assert resolve_device(torch.device("cpu")) == torch.device("cpu")
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="no CUDA GPU is available"):
            resolve_device(torch.device("cuda"))
    if not torch.backends.mps.is_available():
        with pytest.raises(ConfigError, match="device 'mps' requested"):
            resolve_device("mps")
    for value in (None, 0, 1.5):
        with pytest.raises(ConfigError, match="expected a name or a torch.device"):
            resolve_device(value)
    with pytest.raises(ConfigError, match="unsupported device 'meta'"):
        resolve_device("meta")


def test_the_python_section_says_what_a_planner_needs():
    python = README.read_text().split("## Python API", 1)[1].split("\n## ", 1)[0]
    for needed in ("model.frame_interval", "frame_interval=", "OMP_NUM_THREADS=1",
                   "docs/score.md", "predict_scenes", "chosen_selection", "progress=False",
                   "context="):  # fmt: skip
        assert needed in python, needed
