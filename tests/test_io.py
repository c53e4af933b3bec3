"""File helpers: the umask is respected, failed writes leave nothing, JSON is always strict,
and output paths are checked before any compute."""

import json
import math
import os
import stat

import numpy as np
import pytest
import torch

from trajpref import io
from trajpref.errors import ConfigError, TrajprefError
from trajpref.io import (
    atomic_path,
    check_output_dir,
    check_output_file,
    dumps_json,
    file_mode,
    json_safe,
    write_json,
)


@pytest.fixture
def umask():
    """Set the process umask for one test, and put the old one back."""
    old = os.umask(0o022)
    os.umask(old)
    yield os.umask
    os.umask(old)


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_written_files_get_the_umask_mode(tmp_path, umask, mask, mode):
    umask(mask)
    assert file_mode() == mode
    write_json(tmp_path / "a.json", {"x": 1})
    with atomic_path(tmp_path / "b.pt") as tmp:
        torch.save({"x": 1}, tmp)  # writers that reopen the temporary file keep its mode
    for name in ("a.json", "b.pt"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode
    assert os.umask(mask) == mask  # file_mode read the umask without changing it


def _refuse_umask(*args):
    raise AssertionError("file_mode set the umask to read it")


def _proc_states_umask() -> bool:
    try:
        with open("/proc/self/status") as status:
            return any(line.startswith("Umask:") for line in status)
    except OSError:
        return False


@pytest.mark.skipif(not _proc_states_umask(), reason="no Umask line in /proc/self/status")
@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600)])
def test_file_mode_reads_the_umask_without_setting_it(monkeypatch, mask, mode):
    """Setting the umask to read it gave, for that moment, another thread's new files the
    wrong mode (walkthrough 69: a host with umask 077 got 0644 files)."""
    old = os.umask(mask)
    try:
        with monkeypatch.context() as patch:
            patch.setattr(os, "umask", _refuse_umask)
            assert file_mode() == mode
    finally:
        os.umask(old)


def test_file_mode_reads_the_umask_the_status_file_states(tmp_path, monkeypatch):
    status = tmp_path / "status"
    status.write_text("Name:\tpython\nUmask:\t0027\nState:\tR (running)\n")
    monkeypatch.setattr(io, "PROC_STATUS", str(status))
    monkeypatch.setattr(os, "umask", _refuse_umask)
    assert file_mode() == 0o640


@pytest.mark.parametrize("status", ["missing", "no-line", "garbled"])
@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_file_mode_without_a_stated_umask_sets_and_restores_it(tmp_path, monkeypatch, umask,
                                                               status, mask, mode):  # fmt: skip
    """Where there is no /proc (not Linux), or no ``Umask:`` line (an older kernel), the
    umask is read by setting it and putting it back."""
    path = tmp_path / "status"
    if status == "no-line":
        path.write_text("Name:\tpython\nState:\tR (running)\n")
    elif status == "garbled":
        path.write_text("Umask:\tnot-octal\n")
    monkeypatch.setattr(io, "PROC_STATUS", str(path))
    umask(mask)
    assert file_mode() == mode
    assert os.umask(mask) == mask  # put back as it was


def test_a_failed_write_leaves_no_file_and_no_new_folders(tmp_path):
    target = tmp_path / "new" / "deeper" / "out.json"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("the writer failed")
    assert list(tmp_path.iterdir()) == []
    # folders that existed before are kept
    (tmp_path / "kept").mkdir()
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "kept" / "x" / "o.json"):
        raise RuntimeError
    assert [p.name for p in tmp_path.rglob("*")] == ["kept"]


def test_writing_where_a_file_blocks_the_folder_is_one_trajpref_error(tmp_path):
    (tmp_path / "afile").write_text("x")
    with pytest.raises(TrajprefError, match="cannot write"), atomic_path(tmp_path / "afile" / "o"):
        pass
    assert [p.name for p in tmp_path.iterdir()] == ["afile"]


def test_json_is_strict_nonfinite_numbers_become_null(tmp_path):
    obj = {"a": math.inf, "b": [math.nan, -math.inf, 1.5], "c": np.float32(2.5), "d": "x",
           "e": np.float64("nan"), "f": torch.tensor(3.0), "g": 4}  # fmt: skip
    assert json_safe(obj) == {"a": None, "b": [None, None, 1.5], "c": 2.5, "d": "x", "e": None,
                              "f": 3.0, "g": 4}  # fmt: skip
    text = dumps_json(obj)
    assert "Infinity" not in text and "NaN" not in text
    assert json.loads(text)["b"] == [None, None, 1.5]
    write_json(tmp_path / "r.json", obj)
    assert json.loads((tmp_path / "r.json").read_text())["a"] is None


def test_output_file_checks(tmp_path):
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    assert check_output_file(tmp_path / "new" / "deep" / "x.json") == tmp_path / "new/deep/x.json"
    check_output_file(tmp_path / "afile")  # overwriting a file is allowed
    cases = {
        tmp_path / "adir": "is an existing folder",
        tmp_path / "afile" / "x.json": "afile is not a folder",
        tmp_path / "x.txt": "must be a .npz file",
    }
    for path, message in cases.items():
        with pytest.raises(ConfigError, match=message):
            check_output_file(path, ".npz" if path.suffix == ".txt" else None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "afile"]


def test_output_dir_checks(tmp_path):
    (tmp_path / "afile").write_text("x")
    check_output_dir(tmp_path / "run" / "a")  # not created
    assert not (tmp_path / "run").exists()
    with pytest.raises(ConfigError, match="exists and is not a folder"):
        check_output_dir(tmp_path / "afile")
    with pytest.raises(ConfigError, match="afile is not a folder"):
        check_output_dir(tmp_path / "afile" / "run")


@pytest.mark.skipif(not os.path.isdir("/sys"), reason="needs /sys (Linux)")
def test_virtual_file_systems_are_refused_before_any_write():
    with pytest.raises(ConfigError, match="cannot write in /sys"):
        check_output_file("/sys/trajpref-test.json")
    with pytest.raises(ConfigError, match="cannot write in /sys"):
        check_output_dir("/sys/trajpref-run")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_an_unwritable_folder_is_refused(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        with pytest.raises(ConfigError, match="cannot write in"):
            check_output_file(locked / "x.json")
    finally:
        locked.chmod(0o700)


def test_dotted_flattens_nested_dicts_one_level_of_keys():
    from trajpref.io import dotted

    nested = {"min_ade": 0.2, "bins": {"<=5": {"min_fde": 0.3}, "6-10": {}}, "seed": None}
    assert dotted(nested) == {"min_ade": 0.2, "bins.<=5.min_fde": 0.3, "seed": None}
    assert dotted({}) == {}


def test_progress_bars_keep_tqdms_pace_in_a_notebook(monkeypatch):
    """Review of walkthrough 66: in Jupyter stderr is no terminal either, so evaluate()'s bar
    was throttled to one redraw a minute: it sat at 0 % and vanished. A notebook kernel
    (``ipykernel`` loaded) gets tqdm's own pace; a log still gets the throttle."""
    import io
    import sys
    import types

    from trajpref.io import LOG_REDRAW_SECONDS, bar_options

    monkeypatch.setattr(sys, "stderr", io.StringIO())  # not a terminal, as in Jupyter
    monkeypatch.delitem(sys.modules, "ipykernel", raising=False)
    assert bar_options(True)["mininterval"] == LOG_REDRAW_SECONDS  # a log file, a pipe
    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))
    assert bar_options(True) == {"disable": False}
    assert bar_options(False) == {"disable": True}  # --no-progress / progress=False still hide


def test_a_full_disk_inside_atomic_path_names_the_file(tmp_path, monkeypatch):
    """Batch walkthrough 2026-12-06: an OSError raised while the body wrote (ENOSPC, which
    names no file) reached the CLI as `trajpref: error: No space left on device`. It names the
    file now; an OSError of another file (one the body reads) is passed on as it was."""
    import errno
    from pathlib import Path

    target = tmp_path / "new" / "o.json"
    with pytest.raises(TrajprefError) as caught, atomic_path(target) as tmp:
        tmp.write_text("{")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(caught.value) == f"{target}: cannot write (No space left on device)"
    assert not (tmp_path / "new").exists()  # no temporary file, no new folder
    other = tmp_path / "in.txt"
    with pytest.raises(FileNotFoundError) as caught, atomic_path(target) as tmp:
        tmp.write_text(other.read_text())
    assert caught.value.filename == str(other)
    real = Path.write_text

    def full(self, *args, **kwargs):
        if self.name.startswith(".o.json."):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(TrajprefError, match=rf"^{target}: cannot write \(No space left"):
        write_json(target, {"a": 1})


def test_the_environment_hides_the_progress_bars(monkeypatch):
    """TQDM_DISABLE=1 was overridden by the bars' explicit disable=False; TRAJPREF_NO_PROGRESS
    is trajpref's own. Both hide every bar, on a terminal too; 0 (or empty) hides none."""
    import sys
    from io import StringIO

    from trajpref.io import bar_options

    class Terminal(StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stderr", Terminal())
    for name in ("TQDM_DISABLE", "TRAJPREF_NO_PROGRESS"):
        monkeypatch.delenv("TQDM_DISABLE", raising=False)
        monkeypatch.delenv("TRAJPREF_NO_PROGRESS", raising=False)
        assert bar_options(True) == {"disable": False}
        monkeypatch.setenv(name, "1")
        assert bar_options(True) == {"disable": True}, name
        monkeypatch.setenv(name, "0")
        assert bar_options(True) == {"disable": False}, name


def test_a_bar_in_a_log_writes_whole_lines_and_what_follows_starts_a_line(monkeypatch):
    """A bar's carriage-return redraws and its clearing at the end left a log's last line
    open: `trajpref: error: ...` printed after it did not start a line (`grep '^trajpref:
    error'` found nothing). Where stderr is a log, a bar writes nothing for its first
    LOG_REDRAW_SECONDS, then whole lines; here the minute is shortened to 20 ms."""
    import re
    import sys
    import time
    from io import StringIO

    from tqdm.auto import tqdm

    log = StringIO()  # not a terminal
    monkeypatch.setattr(sys, "stderr", log)
    monkeypatch.delitem(sys.modules, "ipykernel", raising=False)
    monkeypatch.delenv("TQDM_DISABLE", raising=False)
    monkeypatch.delenv("TRAJPREF_NO_PROGRESS", raising=False)
    monkeypatch.setattr(io, "LOG_REDRAW_SECONDS", 0.02)
    for _ in tqdm(range(12), desc="epoch", leave=False, **io.bar_options(True)):
        time.sleep(0.01)
    monkeypatch.setattr(io, "LOG_REDRAW_SECONDS", 60.0)  # a pass far shorter than its wait,
    for _ in tqdm(range(3), desc="short", leave=False, **io.bar_options(True)):
        pass  # however busy the host: nothing written
    print("trajpref: error: boom", file=sys.stderr)
    text = log.getvalue()
    assert "\r" not in text and "short" not in text
    lines = text.splitlines()
    assert lines[-1] == "trajpref: error: boom" and re.search("^trajpref: error", text, re.M)
    assert lines[:-1] and all(re.match(r"epoch: +\d+%\|", line) for line in lines[:-1]), lines
