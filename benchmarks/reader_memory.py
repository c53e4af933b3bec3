"""Memory and time of loading a big track file the way `trajpref data stats` does.

    python benchmarks/reader_memory.py                 # the issue-16 file: 7.2 M rows, 180 k agents
    python benchmarks/reader_memory.py --agents 20000  # a quick, smaller run

Writes a plaza-like `frame agent x y` file (tab-separated, ETH style `780.0  1.0  8.46  3.59`)
into a temporary folder, runs `trajpref data stats --dataset FOLDER --json` in a child process,
and prints its wall-clock seconds and peak resident memory (the child's ru_maxrss). Targets of
issue 16: <= 60 s and <= 1.5 GB. The figures are quoted in docs/data_format.md.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def write_plaza(path: Path, agents: int, mean_len: int, concurrent: int, seed: int) -> int:
    """Agents enter a 100 m x 60 m plaza at random frames (10 apart) and walk for 20..60
    frames (mean ``mean_len``); about ``concurrent`` are present at once. Returns the rows."""
    rng = np.random.default_rng(seed)
    length = rng.integers(mean_len // 2, 3 * mean_len // 2 + 1, agents)  # [A]
    n_frames = int(agents * mean_len / concurrent)
    enter = rng.integers(0, max(n_frames - length.max(), 1), agents)  # [A]
    rows = int(length.sum())
    agent = np.repeat(np.arange(1, agents + 1), length)  # [R]
    step = np.arange(rows) - np.repeat(np.cumsum(length) - length, length)  # [R] 0..L-1
    frame = (np.repeat(enter, length) + step) * 10  # [R]
    start = rng.uniform([0, 0], [100, 60], (agents, 2))  # [A, 2]
    heading = rng.uniform(0, 2 * np.pi, agents)  # [A]
    vel = 0.5 * np.stack([np.cos(heading), np.sin(heading)], 1)  # [A, 2] metres per frame
    xy = np.repeat(start, length, 0) + np.repeat(vel, length, 0) * step[:, None]  # [R, 2]
    xy += rng.normal(0, 0.02, xy.shape)
    order = np.lexsort((agent, frame))  # by frame, like the Social-GAN files
    chunk = 500_000
    with open(path, "w") as fh:
        for c in range(0, rows, chunk):
            idx = order[c : c + chunk]
            f, a, p = frame[idx], agent[idx], np.round(xy[idx], 2)
            fh.write(
                "".join(
                    f"{fi}.0\t{ai}.0\t{x:.2f}\t{y:.2f}\n"
                    for fi, ai, (x, y) in zip(f.tolist(), a.tolist(), p.tolist(), strict=True)
                )
            )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=180_000)
    parser.add_argument("--mean-len", type=int, default=40, help="mean frames per track")
    parser.add_argument("--concurrent", type=int, default=200, help="agents present at once")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "plaza.txt"
        start = time.perf_counter()
        rows = write_plaza(path, args.agents, args.mean_len, args.concurrent, args.seed)
        size_mb = path.stat().st_size / 1e6
        print(f"wrote {path.name}: {rows:,} rows, {args.agents:,} agents, {size_mb:.0f} MB "
              f"in {time.perf_counter() - start:.0f} s")  # fmt: skip
        command = [sys.executable, "-m", "trajpref.cli", "data", "stats",
                   "--dataset", tmp, "--units", "m", "--json"]  # fmt: skip
        start = time.perf_counter()
        proc = subprocess.run(command, capture_output=True, text=True,
                              env={**os.environ, "PYTHONWARNINGS": "ignore"})  # fmt: skip
        seconds = time.perf_counter() - start
        peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024 / 1e9
    if proc.returncode != 0:
        sys.exit(f"data stats failed ({proc.returncode}): {proc.stderr.strip()}")
    stats = json.loads(proc.stdout)
    print(f"data stats: {stats['scenes']:,} scenes, {stats['agents']:,} agent-windows")
    print(f"seconds: {seconds:.1f}  (target <= 60)")
    print(f"peak RSS: {peak_gb:.2f} GB  (target <= 1.5)")


if __name__ == "__main__":
    main()
