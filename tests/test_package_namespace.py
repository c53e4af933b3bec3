"""What ``trajpref``'s namespace offers (walkthrough 69): ``dir(trajpref)`` listed every lazy
subpackage, so that ``help(trajpref)`` and ``inspect.getmembers(trajpref)``, which read each
name it lists, imported them all (viz, and with it matplotlib, the command line, the demo);
and ``trajpref.os`` was the ``os`` module."""

from __future__ import annotations

import subprocess
import sys

import pytest

import trajpref

HEAVY = ("trajpref.viz", "trajpref.cli", "trajpref.demo", "trajpref.survey", "matplotlib")


def _python(code: str) -> None:
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=False)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]


@pytest.mark.parametrize("read", ["inspect.getmembers(trajpref)", "pydoc.render_doc(trajpref)"])
def test_reading_every_member_imports_no_figures_and_no_command_line(read):
    """In a fresh interpreter (this one may have imported them already)."""
    _python(
        "import inspect, pydoc, sys\n"
        "import trajpref\n"
        f"{read}\n"
        f"loaded = [m for m in {HEAVY!r} if m in sys.modules]\n"
        "assert not loaded, loaded\n"
    )


def test_the_unlisted_modules_are_still_read_on_first_use_and_listed_after():
    _python(
        "import sys\n"
        "import trajpref\n"
        "assert not {'viz', 'cli', 'demo', 'survey'} & set(dir(trajpref)), dir(trajpref)\n"
        "assert {'evaluation', 'score', 'models', 'config'} <= set(dir(trajpref))\n"
        "assert callable(trajpref.viz.plot_scene)\n"  # imported on first use
        "assert 'viz' in dir(trajpref) and 'cli' not in dir(trajpref)\n"
        "from trajpref import survey\n"
        "assert 'survey' in dir(trajpref)\n"
    )


def test_the_os_module_is_not_an_attribute():
    assert "os" not in dir(trajpref)
    with pytest.raises(AttributeError, match="no attribute 'os'"):
        trajpref.os  # noqa: B018
    assert set(trajpref.UNLISTED) <= set(trajpref.SUBPACKAGES) | set(trajpref.ENTRY_MODULES)
