"""The tracked tree stays small enough for the device tool, which sends the working tree to a
borrowed GPU and refuses one over 64 MiB with what a run carries beside it (the packed ETH/UCY
and SDD data of benchmarks/gpu_sweep, 3.5 MB). docs/architecture.md, "Size of the tree"."""

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LIMIT = 52 * 2**20
"""Bytes of tracked files allowed (published weights are half precision): 64 MiB less the
3.5 MB a run carries, with 8 MiB to spare (docs/architecture.md, "Size of the tree")."""


def test_the_tracked_files_stay_under_the_line():
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                            check=True).stdout.split(b"\0")  # fmt: skip
    sizes = {name: (ROOT / name).stat().st_size for name in map(bytes.decode, listed)
             if name and (ROOT / name).is_file()}  # fmt: skip
    total = sum(sizes.values())
    largest = sorted(sizes, key=sizes.get, reverse=True)[:5]
    assert total <= LIMIT, (
        f"tracked files {total / 2**20:.2f} MiB > {LIMIT / 2**20:.0f} MiB; the largest: "
        + ", ".join(f"{n} ({sizes[n] / 2**20:.2f} MiB)" for n in largest)
    )
