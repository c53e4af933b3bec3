"""The ``data_root`` fixture (``tests/conftest.py``): a real-data test skips where the data is
missing, but fails when ``CI`` is set, so that a CI run without the data cannot pass by
skipping every real-data test. Checked by running pytest on a one-test file that takes the
project's fixture, in a subprocess."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

NEEDS_DATA = """
import pytest
from conftest import data_root  # noqa: F401 - the project's fixture, as the tests get it


@pytest.mark.realdata
def test_needs_the_data(data_root):
    assert data_root.is_dir()
    print("DATA_ROOT", data_root)
"""


def _pytest(folder: Path, **env: str | None) -> tuple[int, str]:
    """Run pytest on ``folder``'s one test (its own ini, naming the realdata mark only)
    with ``env`` over this environment (None: unset); its exit code and output."""
    (folder / "pytest.ini").write_text("[pytest]\nmarkers =\n    realdata: needs the data\n")
    (folder / "test_needs_data.py").write_text(NEEDS_DATA)
    run_env = dict(os.environ)
    run_env["PYTHONPATH"] = os.pathsep.join(
        filter(None, [str(TESTS), os.environ.get("PYTHONPATH")])
    )
    for key, value in env.items():
        if value is None:
            run_env.pop(key, None)
        else:
            run_env[key] = value
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", "-s",
                           "-rfEs", "test_needs_data.py"], cwd=folder, env=run_env,
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    return done.returncode, done.stdout + done.stderr


def test_missing_data_fails_under_ci(tmp_path):
    code, out = _pytest(tmp_path, CI="1", TRAJPREF_DATA="/nonexistent")
    assert code == pytest.ExitCode.TESTS_FAILED, out
    assert "1 error" in out and "skipped" not in out, out
    assert ("real data not found (TRAJPREF_DATA='/nonexistent') and CI is set: real-data "
            "tests must run in CI") in out  # fmt: skip
    code, out = _pytest(tmp_path, CI="true", TRAJPREF_DATA=None)  # not set at all
    assert code == pytest.ExitCode.TESTS_FAILED and "1 error" in out, out
    assert "TRAJPREF_DATA=None) and CI is set" in out, out


def test_missing_data_skips_outside_ci(tmp_path):
    code, out = _pytest(tmp_path, CI=None, TRAJPREF_DATA="/nonexistent")
    assert code == pytest.ExitCode.OK and "1 skipped" in out, out
    assert "real data not found (TRAJPREF_DATA='/nonexistent')" in out and "CI is set" not in out


def test_present_data_is_given_under_ci(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    code, out = _pytest(tmp_path, CI="1", TRAJPREF_DATA=str(data))
    assert code == pytest.ExitCode.OK and "1 passed" in out, out
    assert f"DATA_ROOT {data}" in out
