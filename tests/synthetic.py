"""Tiny synthetic fixtures shared by the tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from trajpref.types import Scene


def make_scene(num_agents: int, seed: int = 0, t_hist: int = 8, t_fut: int = 12) -> Scene:
    """A scene of agents walking straight lines with a little noise."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(-5, 5, size=(num_agents, 1, 2))  # [P, 1, 2]
    vel = rng.normal(0, 0.5, size=(num_agents, 1, 2))  # [P, 1, 2]
    t = np.arange(t_hist + t_fut)[None, :, None]  # [1, T, 1]
    track = start + vel * t + rng.normal(0, 0.01, size=(num_agents, t_hist + t_fut, 2))
    track = track.astype(np.float32)  # [P, T, 2]
    return Scene(
        track[:, :t_hist], track[:, t_hist:], np.zeros(num_agents, np.int64), f"synthetic#{seed}"
    )


def plot_arrays(p: int = 3, k: int = 5, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random walks to draw: ``p`` agents' history ``[P, 8, 2]`` and future ``[P, 12, 2]``, and
    ``k`` noisy predictions of that future ``[K, P, 12, 2]`` (the scene figures' tests)."""
    rng = np.random.default_rng(seed)
    hist = rng.normal(size=(p, 8, 2)).cumsum(1)  # [P, T_h, 2]
    fut = hist[:, -1:] + rng.normal(size=(p, 12, 2)).cumsum(1)  # [P, T_f, 2]
    pred = fut[None] + rng.normal(size=(k, p, 12, 2))  # [K, P, T_f, 2]
    return hist, fut, pred


def write_tracks(path: Path, rows: list[tuple]) -> Path:
    """Write ``frame agent x y`` rows, tab-separated like the ETH/UCY files."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join("\t".join(str(v) for v in r) + "\n" for r in rows))
    return path


def straight_rows(num_frames: int, agents: int = 2, step: int = 10) -> list[tuple]:
    """Rows for ``agents`` walking in straight lines over ``num_frames`` frames."""
    return [
        (f * step, a + 1, 0.3 * f + a, 0.1 * f - a)
        for f in range(num_frames)
        for a in range(agents)
    ]


def write_dataset(root: Path, frames: int = 24, agents: int = 3, seed: int = 0) -> Path:
    """A user dataset folder with train/val/test sub-folders of curved walks."""
    rng = np.random.default_rng(seed)
    for split, files in (("train", 3), ("val", 1), ("test", 1)):
        for f in range(files):
            rows = []
            for a in range(agents):
                pos = rng.uniform(-3, 3, 2)
                heading, speed = rng.uniform(0, 2 * np.pi), rng.uniform(0.3, 0.6)
                turn = rng.normal(0, 0.05)
                for t in range(frames):
                    rows.append((t * 10, a + 1, float(pos[0]), float(pos[1])))
                    heading += turn
                    pos = pos + speed * np.array([np.cos(heading), np.sin(heading)])
            write_tracks(root / split / f"walk{f}.txt", rows)
    return root


TINY_OVERRIDES = [
    "model.hidden=16", "model.heads=2", "model.encoder_layers=1", "model.denoiser_width=32",
    "model.denoiser_blocks=1", "model.generator_width=32", "diffusion.num_steps=10",
    "model.samples=4", "model.tau=2", "denoiser.epochs=2", "generator.epochs=2",
    "denoiser.warmup_steps=1", "generator.warmup_steps=1", "denoiser.eval_every=1",
    "generator.eval_every=1", "data.max_agents=8",
]  # fmt: skip
"""Config overrides for a model small enough to train in a second."""


def tiny_generator_file(path: Path, seed: int) -> str:
    """Save a tiny generator checkpoint (``TINY_OVERRIDES``; its denoiser drawn at torch seed 0,
    the generator at ``seed``) at ``path``; -> its weights' hash (``model_hash``)."""
    import torch

    from trajpref.config import load_config
    from trajpref.models import checkpoint as ckpt
    from trajpref.models.denoiser import Denoiser
    from trajpref.models.generator import Generator

    cfg = load_config(None, TINY_OVERRIDES)
    torch.manual_seed(0)
    den = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 0.7, {})
    torch.manual_seed(seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    ckpt.save(path, ckpt.generator_payload(Generator(cfg.model), den, cfg, {}))
    return ckpt.model_hash(path)
