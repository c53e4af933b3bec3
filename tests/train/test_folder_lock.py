"""One run of a stage in a run folder at a time (batch walkthrough 2026-12-06): two jobs given
the same ``--out`` both exited 0 and left one metrics log written by both, one job's weights
and the other's run record moved aside. The second is refused now, naming the first's pid and
host; a lock file left by a killed run blocks nothing (the kernel let its ``flock`` go)."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys

import pytest
from synthetic import TINY_OVERRIDES

from trajpref.cli import main
from trajpref.errors import TrajprefError
from trajpref.train.run import (
    lock_path,
    release_stage_lock,
    take_stage_lock,
    train_stage,
)

fcntl = pytest.importorskip("fcntl")  # no flock on Windows: the lock is skipped there

TINY = [a for o in TINY_OVERRIDES for a in ("--set", o)]


def _train_argv(walks, out) -> list[str]:
    return ["train", "diffusion", "--set", f"data.dataset={walks}", *TINY, "--device", "cpu",
            "--no-progress", "--out", str(out)]  # fmt: skip


def test_a_second_job_in_a_folder_a_run_holds_is_refused_and_writes_nothing(
    tmp_path, walks, capsys
):
    """The first job's lock taken as any process takes one (``flock`` on ``.denoiser.lock``):
    the second, the CLI, exits 2 with one line and leaves the folder as it was."""
    out = tmp_path / "run"
    out.mkdir()
    held = lock_path(out, "denoiser")
    fd = os.open(held, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.write(fd, json.dumps({"pid": 4242, "host": "node7", "started": "then"}).encode())
        code = main(_train_argv(walks, out))
        _, err = capsys.readouterr()
    finally:
        os.close(fd)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert lines[-1].startswith(f"trajpref: error: --out {out}: another run is training denoiser "
                                "there (pid 4242 on host node7, started then; it holds "
                                ".denoiser.lock)")  # fmt: skip
    assert not [line for line in lines if line.startswith("trajpref: error") and line != lines[-1]]
    assert sorted(p.name for p in out.iterdir()) == [".denoiser.lock"]  # nothing of its own
    # once the first has ended, the same command trains, and lets the folder go at its end
    assert main(_train_argv(walks, out)) == 0
    assert (out / "denoiser.safetensors").is_file() and not held.exists()


def test_the_lock_names_this_process_and_another_stage_is_not_held(tmp_path):
    lock = take_stage_lock(tmp_path / "new", "generator")  # the folder is created
    try:
        record = json.loads(lock_path(tmp_path / "new", "generator").read_text())
        assert (record["pid"], record["host"]) == (os.getpid(), socket.gethostname())
        with pytest.raises(TrajprefError, match=rf"pid {os.getpid()} on host "):
            take_stage_lock(tmp_path / "new", "generator")  # another open file: refused
        other = take_stage_lock(tmp_path / "new", "finetune")  # a stage of its own
        release_stage_lock(other)
    finally:
        release_stage_lock(lock)
    assert list((tmp_path / "new").iterdir()) == []
    again = take_stage_lock(tmp_path / "new", "generator")
    release_stage_lock(again)


HOLDER = """
import sys, time
from trajpref.train.run import take_stage_lock
lock = take_stage_lock(sys.argv[1], "denoiser")
print("held", flush=True)
time.sleep(120)
"""


def test_a_lock_left_by_a_killed_job_blocks_nothing(tmp_path):
    """SIGKILL leaves the lock file (with the dead job's pid), but the kernel released its
    ``flock`` with the process: the next run takes the folder."""
    out = tmp_path / "run"
    job = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdout=subprocess.PIPE,
                           text=True)  # fmt: skip
    try:
        assert job.stdout.readline().strip() == "held"
        with pytest.raises(TrajprefError, match=rf"\(pid {job.pid} on host "):
            take_stage_lock(out, "denoiser")
    finally:
        job.send_signal(signal.SIGKILL)
        job.wait(timeout=60)
        job.stdout.close()
    stale = lock_path(out, "denoiser")
    assert json.loads(stale.read_text())["pid"] == job.pid  # left behind
    lock = take_stage_lock(out, "denoiser")
    assert lock is not None and json.loads(stale.read_text())["pid"] == os.getpid()
    release_stage_lock(lock)


def test_the_python_api_is_refused_alike(tmp_path, tiny_cfg):
    out = tmp_path / "run"
    lock = take_stage_lock(out, "denoiser")
    try:
        with pytest.raises(TrajprefError, match=re.escape(f"--out {out}: another run")):
            train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False)
    finally:
        release_stage_lock(lock)
    assert list(out.iterdir()) == []


def _held_by_another(path, command: str = "trajpref train diffusion") -> int:
    """An open file holding ``path``'s lock, recorded as pid 4242's on node7 (as a run of
    another process writes it), for the caller to close."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    record = {"pid": 4242, "host": "node7", "started": "then", "command": command}
    os.write(fd, (json.dumps(record) + "\n").encode())
    return fd


def test_a_holder_with_a_long_command_is_still_named(tmp_path):
    """The record ends with the holder's command; one over 4 KB (many --set with long paths)
    hid its pid and host behind "a process that has not said which yet"."""
    out = tmp_path / "run"
    out.mkdir()
    fd = _held_by_another(lock_path(out, "denoiser"), "trajpref train " + "--set x=y " * 900)
    try:
        with pytest.raises(TrajprefError, match=r"\(pid 4242 on host node7, started then;"):
            take_stage_lock(out, "denoiser")
    finally:
        os.close(fd)


def _as_another_users_file(monkeypatch, path) -> None:
    """Opening ``path`` to write fails as for another user's 0644 file while it holds pid
    4242's record (these tests may run as root, whom permissions do not stop)."""
    real = os.open

    def opened(name, flags, *args, **kwargs):
        if (os.fspath(name) == os.fspath(path) and flags & (os.O_RDWR | os.O_WRONLY)
                and path.exists() and '"pid": 4242' in path.read_text()):  # fmt: skip
            raise PermissionError(13, "Permission denied", os.fspath(name))
        return real(name, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", opened)


def test_a_lock_file_left_by_another_users_killed_run_blocks_nothing(tmp_path, monkeypatch):
    """In a shared folder a killed run of another user leaves a file this user may not write:
    it was "cannot write (Permission denied)"; now, its lock being free, it is replaced."""
    out = tmp_path / "run"
    out.mkdir()
    stale = lock_path(out, "denoiser")
    stale.write_text(json.dumps({"pid": 4242, "host": "node7"}) + "\n")
    _as_another_users_file(monkeypatch, stale)
    lock = take_stage_lock(out, "denoiser")
    try:
        assert json.loads(stale.read_text())["pid"] == os.getpid()
    finally:
        release_stage_lock(lock)


def test_another_users_run_that_holds_the_folder_is_named(tmp_path, monkeypatch):
    out = tmp_path / "run"
    out.mkdir()
    held = lock_path(out, "denoiser")
    fd = _held_by_another(held)
    try:
        _as_another_users_file(monkeypatch, held)
        with pytest.raises(TrajprefError, match=r"another run is training denoiser there \(pid "
                                                r"4242 on host node7"):  # fmt: skip
            take_stage_lock(out, "denoiser")
        assert held.exists()  # its run's file is left alone
    finally:
        os.close(fd)
