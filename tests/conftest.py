"""Shared fixtures. Synthetic data builders live in ``synthetic.py``."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest


def trajpref_source_problem(origin: str | None, repo: Path) -> str | None:
    """Why the ``trajpref`` that ``origin`` (its ``__init__.py``, or ``None`` when it cannot be
    found) names is not the one under ``repo/src``, the checkout these tests belong to; ``None``
    when it is. In a copy of the repository, a virtual environment whose editable install
    points at another checkout would otherwise test that checkout's code."""
    expected = (repo / "src" / "trajpref").resolve()
    if origin is None:
        where = "is not importable"
    else:
        found = Path(origin).resolve().parent
        if found == expected:
            return None
        where = f"is imported from {found}"
    return (
        f"trajpref {where}, not from this checkout's {expected}: the tests would not test this "
        "tree. Give this checkout its own environment (`make install` here, after removing a "
        ".venv copied from elsewhere) or run with PYTHONPATH=src."
    )


def threads_per_worker(environ: dict[str, str], cpus: int) -> int | None:
    """How many threads each pytest-xdist worker should give torch and OpenMP: the machine's
    ``cpus`` shared among ``PYTEST_XDIST_WORKER_COUNT`` workers, at least one. ``None`` outside
    a worker, or when the user set ``OMP_NUM_THREADS`` themselves. Without it every worker
    starts torch with a thread per core, the workers' threads outnumber the cores, and the
    suite runs slower than in one process (docs/contributing.md has the timings)."""
    workers = environ.get("PYTEST_XDIST_WORKER_COUNT")
    if not workers or "OMP_NUM_THREADS" in environ:
        return None
    return max(1, cpus // int(workers))


def usable_cpus() -> int:
    """The cores this process may run on (a cpuset's, as ``taskset``, a batch job or a
    container gives it, and as pytest-xdist's ``-n auto`` counts them), else all of them."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def pytest_configure(config):
    spec = importlib.util.find_spec("trajpref")
    problem = trajpref_source_problem(spec and spec.origin, Path(__file__).resolve().parents[1])
    if problem:
        raise pytest.UsageError(problem)
    if not hasattr(config, "workerinput"):  # the controller, or a run without workers
        return
    threads = threads_per_worker(dict(os.environ), usable_cpus())
    if threads is not None:
        import torch

        os.environ["OMP_NUM_THREADS"] = str(threads)  # for the subprocesses the tests start
        torch.set_num_threads(threads)


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


@pytest.fixture
def plot_calls(monkeypatch) -> list:
    """What ``trajpref plot`` (``cli.cmd_plot``) hands to the figure functions of
    ``trajpref.viz.plot`` (which it imports when it runs), as ``(name, args, kwargs)`` per
    call; the figures are still written."""
    import trajpref.viz.plot as figures

    calls = []
    for name in ("plot_scene", "plot_scene_scored"):
        original = getattr(figures, name)

        def wrapper(*args, _name=name, _original=original, **kwargs):
            calls.append((_name, args, kwargs))
            return _original(*args, **kwargs)

        monkeypatch.setattr(figures, name, wrapper)
    return calls


@pytest.fixture(scope="module")
def nba():
    from trajpref.models.registry import load_predictor

    return load_predictor("nba/generator", device="cpu")


@pytest.fixture
def repo(tiny_run, tmp_path):
    """A repository of one published dataset, ``walks`` (the tiny run's generator)."""
    from trajpref.models import checkpoint

    root = tmp_path / "repo"
    checkpoint.publish(tiny_run / "generator.safetensors",
                       root / "models" / "walks" / "generator.safetensors")  # fmt: skip
    (root / "benchmarks" / "results").mkdir(parents=True)
    return root


@pytest.fixture(scope="module")
def zara1():
    """zara1's published generator (``zara1/generator``) on the CPU, loaded once per module."""
    from trajpref.models.registry import load_predictor

    return load_predictor("zara1/generator", device="cpu")


@pytest.fixture(scope="module")
def robo():
    """Robo's published generator (``robo/generator``) on the CPU, loaded once per module."""
    from trajpref.models.registry import load_predictor

    return load_predictor("robo/generator", device="cpu")
