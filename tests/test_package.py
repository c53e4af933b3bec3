"""Importing the package: the one process-wide setting it makes (oneDNN's kernel cache)."""

import os
import subprocess
import sys

import trajpref

_SHOW = "import os, trajpref; print(os.environ['ONEDNN_PRIMITIVE_CACHE_CAPACITY'])"


def _import_in_fresh_process(env: dict[str, str]) -> str:
    out = subprocess.run([sys.executable, "-c", _SHOW], env=env, capture_output=True,
                         text=True, check=True)  # fmt: skip
    return out.stdout.strip()


def test_import_raises_onednns_kernel_cache_when_the_user_did_not_set_it():
    env = {k: v for k, v in os.environ.items() if k != "ONEDNN_PRIMITIVE_CACHE_CAPACITY"}
    assert _import_in_fresh_process(env) == str(trajpref.ONEDNN_CACHE_CAPACITY)
    assert trajpref.ONEDNN_CACHE_CAPACITY > 1024  # oneDNN's own default


def test_a_value_the_user_set_is_kept():
    env = dict(os.environ, ONEDNN_PRIMITIVE_CACHE_CAPACITY="64")
    assert _import_in_fresh_process(env) == "64"
