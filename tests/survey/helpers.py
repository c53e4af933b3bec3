"""Plain helpers shared by the survey tests (their fixtures live in ``conftest.py``)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sqlite3
import subprocess
from pathlib import Path

import numpy as np
import pytest

from trajpref.survey.manifest import DATABASE, GROUND_TRUTH, MANIFEST, Study, load_study
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerStore
from trajpref.survey.study import SceneData, ground_truth_panel, shown_predictions, write_study

ROOT = Path(__file__).resolve().parents[2]


DOCS = ROOT / "docs" / "survey.md"


METHODS = ("methodalpha", "methodbeta")
"""Method names chosen to be easy to search for: they must never reach the page."""


OK = {"social": 4, "kinetics": 2}


CONSENT = "I agree to take part.\n\nMy answers are kept for a year."


def _write(folder: Path, units: str = "m", consent: str = "", **build) -> Study:
    """A one-scene study of two agents: the method 'alpha' and the rated ground truth."""
    rng = np.random.default_rng(0)
    track = rng.normal(0, 1, (2, 1, 2)) + 0.4 * np.arange(20)[None, :, None]  # [2, 20, 2]
    history, future = track[:, :8], track[:, 8:]
    pred = future[None] + rng.normal(0, 0.3, (4, 2, 12, 2))  # [K, P, 12, 2]
    panels = {"alpha": shown_predictions(pred, 1 + rng.random((4, 2, 12)), np.ones((2, 12)),
                                         future),
              GROUND_TRUTH: ground_truth_panel(future)}  # fmt: skip
    scenes = [
        SceneData(history, future, panels, "f@0", 0, 0),
        SceneData(history + 1, future + 1, panels, "f@20", 20, 0),
    ]
    more = {"consent": consent} if consent else {}
    return write_study(folder, scenes, [GROUND_TRUTH, "alpha"], units=units,
                       dataset={"name": "d", "split": "test", "units": units}, build=build,
                       **more)  # fmt: skip


@contextlib.contextmanager
def _read_only(folder: Path):
    """``folder`` read-only for this process, restored afterwards: ``chattr +i`` as root (who
    ignores modes), else mode 0555."""
    if getattr(os, "geteuid", lambda: 1)() == 0:
        if shutil.which("chattr") is None:
            pytest.skip("root without chattr: cannot make a folder read-only")
        done = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, text=True)
        if done.returncode:
            pytest.skip(f"chattr +i is not supported here: {done.stderr.strip()}")
        try:
            yield
        finally:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
    else:
        mode = folder.stat().st_mode & 0o777
        folder.chmod(0o555)
        try:
            yield
        finally:
            folder.chmod(mode)


def _simulated(folder: Path) -> None:
    study = load_study(folder)
    store = AnswerStore(folder / DATABASE, study)
    try:
        simulate(study, store, SimulateConfig(raters=3))
    finally:
        store.close()


def _order(got: dict) -> list[tuple[str, tuple[str, ...]]]:
    """``progress()["order"]`` as ``[(scene, (panel, ...)), ...]``."""
    return [(o["scene"], tuple(o["panels"])) for o in got["order"]]


def _positions(path: Path) -> dict[tuple[str, str, str], tuple]:
    with contextlib.closing(sqlite3.connect(path)) as db:
        rows = db.execute("SELECT rater, scene, panel, scene_position, panel_position "
                          "FROM answers").fetchall()  # fmt: skip
    return {r[:3]: r[3:] for r in rows}


def _fixed(folder: Path) -> None:
    """Make ``folder``'s manifest one of a study built before per-rater orders (no
    ``order``): what every rater of it saw was the manifest's order."""
    manifest = json.loads((folder / MANIFEST).read_text())
    del manifest["order"]
    (folder / MANIFEST).write_text(json.dumps(manifest))
