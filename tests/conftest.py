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
