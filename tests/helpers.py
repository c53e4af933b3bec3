"""Plain helpers shared by test files of more than one package (fixtures live in
``conftest.py``; synthetic data builders in ``synthetic.py``)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from bench import load_benchmark

from trajpref.cli import main

# ---- the CLI ---------------------------------------------------------------------------------


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


ZARA1 = "zara1/generator was trained on the zara1 fold (leave-one-out: the other four scenes)"


# ---- warnings of a scene outside the model's training data --------------------------------


FAST = "faster than its training data"
WIDE = "model units apart at its last observed frame"  # each model's own limit before it
UNITS = "looks like it is in other units than the model's"


def _messages(call) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [str(w.message) for w in caught]


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A rebound-like scene: 10 players and the ball (agent 0), 8 steps of 0.12 s, metres,
    x along the court's 28.65 m length. Returns history [11, 8, 2] and agent_type [11]."""
    rng = np.random.default_rng(seed)
    start = rng.uniform([2.0, 2.0], [12.0, 13.0], size=(11, 2))  # [11, 2] one half-court
    velocity = rng.normal(0.0, 0.1, size=(11, 2))  # [11, 2] metres per step
    velocity[0] *= 3  # the ball moves faster
    history = start[:, None] + velocity[:, None] * np.arange(8)[None, :, None]  # [11, 8, 2]
    types = np.zeros(11, np.int64)
    types[0] = 1
    return history, types


# ---- RL methods -------------------------------------------------------------------------------


NEW = "rlhf-new"
"""A method's name as a contributor adds it to the list, before its dispatch entries."""


# ---- the benchmark scripts (finetune.py, pretrain.py) and their result rows ----------------


METRICS = dict.fromkeys(("min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "max_ats",
                         "max_fts", "top1_recall_ats", "top5_recall_ats"), 0.5)  # fmt: skip


def _files(*folders: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for f in folders if f.is_dir() for p in f.rglob("*") if p.is_file()}


def _pretrain(monkeypatch, root: Path, *argv: str):
    pre = load_benchmark("pretrain")
    monkeypatch.setattr(pre, "ROOT", root)
    monkeypatch.setattr(pre, "load_dataset", lambda *a, **k: None)
    monkeypatch.setattr(pre, "time_predictors", lambda *a, **k: {"leapfrog": 1.0, "full": 9.0})
    monkeypatch.setattr(pre, "evaluate", lambda *a, **k: METRICS)
    monkeypatch.setattr("sys.argv", ["pretrain.py", "--dataset", "walks", "--no-full-eval",
                                     *argv])  # fmt: skip
    pre.main()


def _row(method, checkpoint, date, model_hash=None, **fields):
    return {"dataset": "zara2", "method": method, "seed": 0, "split": "test", "samples": 20,
            "protocol": "all", "checkpoint": checkpoint, "model_hash": model_hash,
            "machine": "m, 2 CPU cores, 2 threads", "min_ade": 0.1, "min_fde": 0.2,
            "joint_min_ade": 0.3, "joint_min_fde": 0.4, "date": date,
            "command": "python benchmarks/x.py", **fields}  # fmt: skip


def walker_and_far(distance: float) -> np.ndarray:
    """[2, 8, 2] a straight walker (0.5 a step, data units) and one ``distance`` to its side:
    a scene as wide as ``distance`` at its last observed frame."""
    walker = np.arange(8)[:, None] * np.array([0.5, 0.0])  # [T_h, 2]
    return np.stack([walker, walker + [0.0, distance]]).astype(np.float32)
