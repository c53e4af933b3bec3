"""``import trajpref.cli`` leaves out what only some commands use: scipy (``survey analyze``)
and matplotlib (``plot``, ``survey build``/``analyze``) are imported by those commands, so that
every other command starts without paying for them."""

from __future__ import annotations

import subprocess
import sys

HEAVY = (
    "scipy",
    "scipy.stats",
    "matplotlib",
    "matplotlib.pyplot",
    "trajpref.viz.plot",
    "trajpref.survey.analyze",
    "trajpref.survey.build",
    "trajpref.survey.study",
)


def test_cli_import_leaves_out_scipy_and_matplotlib():
    # a fresh interpreter: this test session may have imported them already
    code = f"import sys, trajpref.cli; print(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"
