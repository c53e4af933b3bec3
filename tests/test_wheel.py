"""The wheel carries the model zoo: built from the repository, it stays under 50 MB, holds
every published model with its card and index, and, installed alone into a fresh virtual
environment, runs ``trajpref models`` and ``trajpref evaluate --model zara1/generator``.

Marked ``wheel`` (about 40 s on two busy CPU cores: a build, a venv, three CLI runs); it runs
in ``make test``.
"""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

import trajpref
from trajpref.cli import main
from trajpref.models import zoo

ROOT = Path(__file__).resolve().parents[1]
MAX_WHEEL_MB = 50
HEAD_ROWS = 400
"""Rows of zara1's test file kept for the installed wheel's evaluate (141 agent-windows today)."""


def _run(cmd: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{cmd}: {proc.stdout}\n{proc.stderr}"
    return proc


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel, built from a clean copy of the project (no stale build/ folder), with this
    environment's setuptools (no download)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(ROOT / name, src / name)
    shutil.copytree(ROOT / "src", src / "src",
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))  # fmt: skip
    out = tmp_path_factory.mktemp("dist")
    cmd = [sys.executable, "-m", "pip", "wheel", ".", "--no-deps", "--no-build-isolation",
           "--quiet", "-w", str(out)]  # fmt: skip
    _run(cmd, src, os.environ.copy())
    (path,) = out.glob("trajpref-*.whl")
    return path


@pytest.mark.wheel
def test_the_wheel_holds_the_zoo_and_stays_small(wheel):
    mb = wheel.stat().st_size / 2**20
    assert mb < MAX_WHEEL_MB, f"{wheel.name}: {mb:.1f} MB"
    names = set(zipfile.ZipFile(wheel).namelist())
    # the package's version is written once (trajpref.__version__, which --version prints)
    assert wheel.name.split("-")[1] == trajpref.__version__, wheel.name
    published = zoo.published()
    assert len(published) >= 2
    for name in published:
        assert f"trajpref/zoo/{name}.safetensors" in names, name
        assert f"trajpref/zoo/{name}.md" in names, name
    assert "trajpref/zoo/index.json" in names
    assert "trajpref/py.typed" in names  # PEP 561: its type hints are for type checkers
    assert "trajpref/__main__.py" in names  # python -m trajpref
    assert "trajpref/resources/demo.yaml" in names  # python -m trajpref.demo
    for asset in ("index.html", "app.js", "style.css"):  # trajpref survey serve
        assert f"trajpref/survey/static/{asset}" in names, asset
    from trajpref.config import builtin_configs

    for name in builtin_configs():  # --config NAME works from an installed wheel
        assert f"trajpref/configs/{name}.yaml" in names, name


@pytest.mark.wheel
@pytest.mark.realdata
def test_the_installed_wheel_evaluates_a_published_model(wheel, data_root, tmp_path, capsys,
                                                         monkeypatch):  # fmt: skip
    # a fresh venv that reuses this environment's packages (torch, numpy, ...) through a
    # .pth line, which does not run the editable install's own .pth: only the wheel's
    # trajpref is importable there
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, os.environ.copy())
    py = venv / "bin" / "python"
    site = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     tmp_path, os.environ.copy()).stdout.strip())  # fmt: skip
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "_reuse_test_env.pth").write_text("".join(f"{p}\n" for p in sorted(ours)))
    pip = [sys.executable, "-m", "pip", "--python", str(py), "install", "--no-deps",
           "--force-reinstall", "--quiet", str(wheel)]  # fmt: skip
    _run(pip, tmp_path, os.environ.copy())

    work = tmp_path / "work"  # outside the repository: the source tree is not importable
    (work / "z" / "test").mkdir(parents=True)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    where = _run([str(py), "-c", "import trajpref; print(trajpref.__file__)"], work, env)
    assert Path(where.stdout.strip()).is_relative_to(venv), where.stdout

    trajpref = str(venv / "bin" / "trajpref")
    listing = _run([trajpref, "models"], work, env).stdout
    # its test row, as the repository's own index states it (not a number frozen in the test)
    expected = zoo._test(zoo.load_index()["zara1/generator"])
    assert "zara1/generator " in listing and expected in listing, (expected, listing)

    # a small split: the first rows of zara1's test file, as a folder dataset
    (src,) = (data_root / "eth_ucy" / "zara1" / "test").glob("*.txt")
    head = src.read_text().splitlines(keepends=True)[:HEAD_ROWS]
    (work / "z" / "test" / src.name).write_text("".join(head))
    argv = ["evaluate", "--dataset", "z", "--split", "test", "--units", "m", "--model",
            "zara1/generator", "--json", "--no-progress", "--device", "cpu"]  # fmt: skip
    installed = json.loads(_run([trajpref, *argv], work, env).stdout)
    assert installed["agents"] > 20 and 0 < installed["min_ade"] < 1.0

    # the same numbers as the repository's own files give
    monkeypatch.chdir(work)
    assert main(argv) == 0
    here = json.loads(capsys.readouterr().out)
    for key in ("agents", "min_ade", "min_fde", "joint_min_ade", "joint_min_fde"):
        assert installed[key] == here[key], key
