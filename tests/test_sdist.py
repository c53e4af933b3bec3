"""What the source distribution and the wheel hold beside the code: ``python -m trajpref``
(``trajpref/__main__.py``), ``py.typed`` (the type hints are for type checkers, PEP 561), and
no half of the test suite in the sdist (setuptools' default adds the top-level
``tests/test_*.py`` alone, without the ``conftest.py``, ``synthetic.py`` and sub-folders they
need; ``MANIFEST.in`` prunes ``tests/``).

The sdist test is marked ``wheel`` (a build from a copy of the project, ~10 s)."""

import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]


def test_python_m_trajpref_runs_the_command(tmp_path):
    out = subprocess.run([sys.executable, "-m", "trajpref", "--version"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("trajpref ")
    usage = subprocess.run([sys.executable, "-m", "trajpref", "--help"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=120)  # fmt: skip
    assert usage.stdout.startswith("usage: trajpref "), usage.stdout[:80]


def test_the_package_is_marked_typed_and_ships_the_marker():
    assert (ROOT / "src" / "trajpref" / "py.typed").is_file()
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "py.typed" in project["tool"]["setuptools"]["package-data"]["trajpref"]


@pytest.mark.wheel
def test_the_sdist_holds_no_tests_and_the_package_markers(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE", "MANIFEST.in"):
        if (ROOT / name).is_file():
            shutil.copy(ROOT / name, src / name)
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info", ".pytest_cache")
    for name in ("src", "tests"):  # tests/ as in the repository, for MANIFEST.in to prune
        shutil.copytree(ROOT / name, src / name, ignore=skip, symlinks=True)
    code = ("import sys; from setuptools import build_meta; "
            "print(build_meta.build_sdist(sys.argv[1]))")  # fmt: skip
    proc = subprocess.run([sys.executable, "-c", code, str(tmp_path / "dist")], cwd=src,
                          capture_output=True, text=True, timeout=300,
                          env=os.environ.copy())  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    (sdist,) = (tmp_path / "dist").glob("trajpref-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    assert not [n for n in names if n.startswith("tests/")], "the sdist ships part of tests/"
    for name in ("src/trajpref/__main__.py", "src/trajpref/py.typed", "src/trajpref/cli.py",
                 "src/trajpref/zoo/index.json", "src/trajpref/configs/zara1.yaml"):  # fmt: skip
        assert name in names, name
