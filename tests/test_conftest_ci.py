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


@pytest.mark.parametrize(
    ("environ", "cpus", "expected"),
    [
        ({}, 2, None),  # one process: torch keeps its default
        ({"PYTEST_XDIST_WORKER_COUNT": "2"}, 2, 1),
        ({"PYTEST_XDIST_WORKER_COUNT": "2"}, 16, 8),
        ({"PYTEST_XDIST_WORKER_COUNT": "3"}, 16, 5),
        ({"PYTEST_XDIST_WORKER_COUNT": "4"}, 2, 1),  # never fewer than one
        ({"PYTEST_XDIST_WORKER_COUNT": "2", "OMP_NUM_THREADS": "2"}, 2, None),  # the user's
    ],
)
def test_threads_per_worker_share_the_cores(environ, cpus, expected):
    from conftest import threads_per_worker

    assert threads_per_worker(environ, cpus) == expected


PROJECT_CONFTEST = TESTS / "conftest.py"


def test_a_worker_runs_torch_on_its_share_of_the_cores(tmp_path):
    """Under ``-n 2`` each worker's torch, and the subprocesses it starts, get
    ``cpu_count // 2`` threads (the hook in ``pytest_configure``)."""
    (tmp_path / "conftest.py").write_text(
        "import importlib.util\n"
        f"spec = importlib.util.spec_from_file_location('project', {str(PROJECT_CONFTEST)!r})\n"
        "project = importlib.util.module_from_spec(spec)\n"
        "spec.loader.exec_module(project)\n"
        "pytest_configure = project.pytest_configure\n"
    )
    from conftest import usable_cpus

    expected = max(1, usable_cpus() // 2)
    (tmp_path / "test_threads.py").write_text(
        "import os, torch\n\n"
        "def test_threads():\n"
        f"    assert torch.get_num_threads() == {expected}\n"
        f"    assert os.environ['OMP_NUM_THREADS'] == '{expected}'\n"
    )
    env = {
        k: v
        for k, v in os.environ.items()  # as from a shell, not from an xdist worker
        if k != "OMP_NUM_THREADS" and not k.startswith("PYTEST_XDIST_")
    }
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q",
                           "-n", "2", "test_threads.py"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0 and "1 passed" in done.stdout, done.stdout + done.stderr
