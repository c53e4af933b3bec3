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
        (H[:0], S[:, :0], {}, r"history: the scene has no agents \(P = 0\)"),
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
        (H, S, {"agent_type": [0.0, 1.0]}, r"agent_type: expected 2 integer flags"),
        (H, S, {"agent_type": [0, 7]}, r"agent_type: flags must be 0 \(person\) or 1 \(ball\)"),
    ],
)  # fmt: skip
def test_bad_input_is_a_data_error_with_a_clear_message(scorer, history, samples, kwargs,
                                                        message):  # fmt: skip
    with pytest.raises(DataError, match=message):
        rank_samples(scorer, history, samples, **kwargs)


def test_batch_entry_points_check_shapes(scorer, walks):
    batch = collate(load_dataset(str(walks), "test").scenes[:2])
    n = batch.num_agents
    with pytest.raises(DataError, match=rf"futures: expected \[M, {n}, 12, 2\]"):
        scorer.residual(batch, batch.future[None, :, :10])
    with pytest.raises(DataError, match=rf"futures: expected \[M, {n}, 12, 2\]"):
        scorer.score(batch, batch.future[None, :-1])
    assert scorer.rank(batch, batch.future[None].repeat(3, 1, 1, 1)).shape == (3, 2)
