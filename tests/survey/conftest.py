"""Fixtures of the survey tests: a study built from the tiny trained run, and a synthetic one."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from survey.helpers import METHODS


@pytest.fixture(scope="session")
def tiny_study(tmp_path_factory, tiny_run, walks) -> Path:
    """A real study: 3 scenes of the ``walks`` test split, constant velocity and the tiny
    generator as methods, the ground truth as a third panel; built by the CLI."""
    from trajpref.cli import main

    out = tmp_path_factory.mktemp("tiny_study") / "study"
    code = main(
        [
            "survey",
            "build",
            "--dataset",
            str(walks),
            "--units",
            "m",
            "--models",
            f"{METHODS[0]}=cv",
            f"{METHODS[1]}={tiny_run / 'generator.safetensors'}",
            "--scenes",
            "3",
            "--samples",
            "4",
            "--min-gap",
            "0",
            "--device",
            "cpu",
            "--no-progress",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    return out


@pytest.fixture(scope="session")
def _synthetic_template(tmp_path_factory) -> Path:
    from trajpref.survey.study import make_synthetic_study

    out = tmp_path_factory.mktemp("synthetic") / "study"
    make_synthetic_study(out, scenes=3, methods=METHODS, seed=0)
    return out


@pytest.fixture
def synthetic_study(_synthetic_template, tmp_path) -> Path:
    """A fresh copy of a synthetic study (3 scenes x 3 panels, no answers yet)."""
    return Path(shutil.copytree(_synthetic_template, tmp_path / "study"))


@pytest.fixture
def store(synthetic_study):
    """The synthetic study's answers database, opened (and closed after the test)."""
    from trajpref.survey.manifest import DATABASE, load_study
    from trajpref.survey.store import AnswerStore

    study = load_study(synthetic_study)
    s = AnswerStore(synthetic_study / DATABASE, study)
    yield s
    s.close()


@pytest.fixture
def saved_labels(monkeypatch):
    """The axis titles every saved figure shows: (text, colour) of each x and y label."""
    import matplotlib.figure

    labels: list[tuple[str, str]] = []
    original = matplotlib.figure.Figure.savefig

    def savefig(fig, *args, **kwargs):
        for ax in fig.axes:
            for label in (ax.xaxis.label, ax.yaxis.label):
                labels.append((label.get_text(), str(label.get_color())))
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    return labels
