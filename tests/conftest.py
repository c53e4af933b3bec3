"""Shared fixtures. Synthetic data builders live in ``synthetic.py``."""

from __future__ import annotations

import os
from pathlib import Path

import pytest


@pytest.fixture
def data_root() -> Path:
    """The real data (``$TRAJPREF_DATA``). Skips when missing, but fails when ``CI`` is set."""
    value = os.environ.get("TRAJPREF_DATA")
    if value and Path(value).is_dir():
        return Path(value)
    message = f"real data not found (TRAJPREF_DATA={value!r})"
    if os.environ.get("CI"):
        pytest.fail(message + " and CI is set: real-data tests must run in CI")
    pytest.skip(message)


@pytest.fixture(scope="session")
def walks(tmp_path_factory) -> Path:
    """A tiny synthetic dataset folder (train/val/test) of curved walks."""
    from synthetic import write_dataset

    return write_dataset(tmp_path_factory.mktemp("walks"))


@pytest.fixture(scope="session")
def tiny_cfg(walks):
    from synthetic import TINY_OVERRIDES

    from trajpref.config import load_config

    return load_config(None, [*TINY_OVERRIDES, f"data.dataset={walks}"])


@pytest.fixture(scope="session")
def tiny_run(tmp_path_factory, tiny_cfg) -> Path:
    """Both pretraining stages trained once on ``walks`` (a second or two)."""
    from trajpref.train.run import train_stage

    out = tmp_path_factory.mktemp("run")
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False)
    train_stage("generator", tiny_cfg, out, device="cpu", progress=False)
    return out
