"""Load a script of ``benchmarks/`` as a module, for the tests of that script.

The scripts are not a package (they are run as ``python benchmarks/x.py``), so each test file
loads the one it tests with :func:`load_benchmark`; every call returns a fresh module, so a test
that monkeypatches a module-level name (``ROOT``) cannot leak into another.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent


def load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` as the module ``bench_<name>``."""
    path = ROOT / "benchmarks" / f"{name}.py"
    if not path.is_file():
        raise FileNotFoundError(f"no benchmark script {path}")
    spec = importlib.util.spec_from_file_location(f"bench_{name}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it executes
    if str(path.parent) not in sys.path:  # the scripts import their shared helpers
        sys.path.insert(0, str(path.parent))
    spec.loader.exec_module(module)
    return module
