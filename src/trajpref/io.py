"""Small file helpers: write-then-rename so a failed run never leaves a half-written file,
output checks made before any compute, and JSON that is always valid (no NaN/Infinity); and
the progress bars' options, quieter where stderr is a log file (``bar_options``)."""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import sys
import tempfile
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from trajpref.errors import ConfigError, ModelNotFound, TrajprefError

PROC_STATUS = "/proc/self/status"
"""Where Linux (4.7 and later) states this process's umask (its ``Umask:`` line), read by
``file_mode`` without changing the umask."""


def _stated_umask() -> int | None:
    """The umask on ``PROC_STATUS``'s ``Umask:`` line (octal), None where there is no such
    file or line (not Linux, an older kernel, no /proc)."""
    try:
        with open(PROC_STATUS, encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        return None
    return None


def file_mode() -> int:
    """The mode a new file gets from ``open()`` under this process's umask (0644 under the
    usual 022). ``tempfile.mkstemp`` always creates 0600, so renamed files need this. The
    umask is read from ``/proc/self/status`` where there is one (Linux): setting it to read it
    would, for that moment, give the files another thread creates the wrong mode. Elsewhere
    it is set and put back at once (the only portable way to read it)."""
    mask = _stated_umask()
    if mask is None:
        mask = os.umask(0o022)
        os.umask(mask)
    return 0o666 & ~mask


def _nearest_existing(path: Path) -> Path:
    """``path`` or its closest ancestor that exists (the first thing a write would touch)."""
    for candidate in (path, *path.parents):
        if candidate.exists() or candidate.is_symlink():
            return candidate
    return Path(".")


def write_probe(folder: str | Path) -> OSError | None:
    """Create a file in ``folder`` and remove it at once: the ``OSError`` creating it raised
    (no write permission, a read-only file system or mount, /proc or /sys), or None. What
    ``os.access`` cannot tell root, whom ``chattr +i`` or a read-only mount still stops."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".trajpref-probe-", dir=folder)
    except OSError as exc:
        return exc
    os.close(fd)
    os.unlink(probe)
    return None


def _probe_folder(folder: Path, what: str, path: Path) -> None:
    """Make sure a file can be created in the existing ``folder`` (``write_probe``)."""
    if not folder.is_dir():
        raise ConfigError(f"{what} {path}: {folder} is not a folder")
    exc = write_probe(folder)
    if exc is not None:
        raise ConfigError(
            f"{what} {path}: cannot write in {folder} ({exc.strerror or exc.__class__.__name__})"
        )


def check_output_file(path: str | Path, suffix: str | None = None, what: str = "--out") -> Path:
    """Check, before any compute and without leaving anything behind, that ``path`` can be
    written as a file: not an existing folder, the nearest existing ancestor a writable folder,
    and ending in ``suffix`` when given. Raises ``ConfigError`` naming ``what``."""
    path = Path(path)
    if suffix is not None and path.suffix.lower() != suffix:
        raise ConfigError(f"{what} {path}: the output must be a {suffix} file")
    if path.is_dir():
        raise ConfigError(f"{what} {path}: is an existing folder, not a file")
    if path.exists() and not path.is_file():
        raise ConfigError(f"{what} {path}: exists and is not a regular file")
    if path.is_file() and not os.access(path, os.W_OK):
        raise ConfigError(f"{what} {path}: the existing file is not writable")
    parent = path.parent
    _probe_folder(_nearest_existing(parent), what, path)
    return path


def check_output_dir(path: str | Path, what: str = "--out") -> Path:
    """Check that ``path`` is, or can be created as, a folder that files can be written in
    (before any compute; nothing is created). Raises ``ConfigError`` naming ``what``."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{what} {path}: exists and is not a folder")
    _probe_folder(_nearest_existing(path), what, path)
    return path


@contextlib.contextmanager
def atomic_path(path: str | Path, mode: int | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    The file gets ``mode``, or with None the umask's mode (as ``open()`` would give it).
    Folders created for it are removed again when the write fails; an ``OSError`` becomes a
    one-line ``TrajprefError`` naming ``path``: creating the file, renaming it, and one raised
    in the ``with`` body while writing the temporary file (a full disk's ENOSPC, a quota's
    EDQUOT, which name no file). An ``OSError`` of the body that names another file (one the
    body reads) is passed on as it is."""
    path = Path(path)
    existing = _nearest_existing(path.parent)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as exc:
        _remove_new_folders(path.parent, existing)
        raise TrajprefError(f"{path}: cannot write ({exc.strerror or exc})") from None
    os.close(fd)
    tmp_path = Path(tmp)
    done = False
    try:
        try:
            yield tmp_path
            os.chmod(tmp_path, file_mode() if mode is None else mode)
            os.replace(tmp_path, path)
        except OSError as exc:
            if not _about(exc, (tmp_path, path)):
                raise  # another file's (one the body reads): its own message names it
            raise TrajprefError(f"{path}: cannot write ({exc.strerror or exc})") from None
        done = True
    finally:
        tmp_path.unlink(missing_ok=True)
        if not done:
            _remove_new_folders(path.parent, existing)


def write_failed(path: Path, what: str, exc: BaseException) -> TrajprefError:
    """The one-line error for a file of a run that could not be written (``what``: the resume
    state, a checkpoint, the metrics log): the file, the reason (an ``OSError``'s, or the
    first line of torch's or safetensors' message less its source location) and the space
    left on its disk, which a full disk shows as 0. The file written before (an earlier
    epoch's) is left as it was."""
    why = exc.strerror if isinstance(exc, OSError) and exc.strerror else None
    if why is None:
        lines = str(exc).strip().splitlines()
        why = re.sub(r"^\[enforce fail at [^\]]*\]\s*\.?\s*", "", lines[0]) if lines else ""
        said = re.search(r'message: "([^"]+)"', why)  # safetensors: IoError(Os { .. message })
        why = said.group(1) if said else why or exc.__class__.__name__
    free = ""
    with contextlib.suppress(OSError):
        free = f"; {shutil.disk_usage(path.parent).free / 1e6:,.0f} MB free there"
    return TrajprefError(f"{path}: cannot write {what} ({why}{free})")


def _about(exc: OSError, paths: tuple[Path, ...]) -> bool:
    """Whether ``exc`` concerns one of ``paths``: it names one of them, or no file at all (a
    write's or a flush's ``OSError``, ENOSPC, carries no file name)."""
    names = [n for n in (exc.filename, exc.filename2) if isinstance(n, (str, bytes, os.PathLike))]
    return not names or any(Path(os.fsdecode(n)) in paths for n in names)


def _remove_new_folders(folder: Path, existing: Path) -> None:
    """Remove ``folder`` and its empty ancestors up to (not including) ``existing``."""
    for candidate in (folder, *folder.parents):
        if candidate == existing or existing not in candidate.parents:
            return
        try:
            candidate.rmdir()
        except OSError:
            return


def dotted(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts as one level of dotted keys: ``{"a": {"b": 1}, "c": 2}`` ->
    ``{"a.b": 1, "c": 2}`` (a CSV row of a nested result, the keys a config sets)."""
    out: dict[str, Any] = {}
    for key, value in d.items():
        if isinstance(value, dict):
            out.update(dotted(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float (NaN, +-Infinity) replaced by ``None``, so that it
    serialises as strict JSON (``null``); numpy scalars become Python numbers."""
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "item") and getattr(obj, "ndim", None) == 0:  # numpy / torch scalars
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps_json(obj: Any, indent: int | None = None) -> str:
    """Strict JSON text of ``obj``: non-finite numbers are written as ``null``."""
    return json.dumps(json_safe(obj), indent=indent, allow_nan=False)


def write_json(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as strict JSON (non-finite numbers as ``null``), atomically."""
    text = dumps_json(obj, indent=2) + "\n"
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def resume_state_message(path: str | Path) -> str:
    """What to say when a ``<stage>_last.pt`` resume state is given where a model goes: what
    training writes beside the model, and a common slip."""
    name = Path(path).name
    return (f"{path}: a resume state (pass it to --resume), not a model; the model is "
            f"{name[: -len('_last.pt')]}.safetensors beside it")  # fmt: skip


def read_checkpoint_header(path: str | Path) -> dict[str, Any]:
    """The ``trajpref`` JSON metadata of a safetensors checkpoint, without its weights."""
    try:
        with open(path, "rb") as fh:
            length = int.from_bytes(fh.read(8), "little")
            if length > os.fstat(fh.fileno()).st_size - 8:
                raise ValueError("header longer than the file")
            meta = json.loads(fh.read(length)).get("__metadata__") or {}
        out = json.loads(meta["trajpref"])
    except (OSError, ValueError, KeyError, AttributeError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise ModelNotFound(f"{path}: no such checkpoint file") from None
        if Path(path).name.endswith("_last.pt"):
            raise TrajprefError(resume_state_message(path)) from None
        raise TrajprefError(
            f"{path}: not a trajpref checkpoint ({exc.__class__.__name__})"
        ) from None
    if not isinstance(out, dict):
        raise TrajprefError(f"{path}: not a trajpref checkpoint")
    return out


def load_tensors(path: str | Path) -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU, with torch's own warnings about the
    file silenced: for a damaged or foreign file the caller's one-line error is the message,
    not a pickle-protocol warning printed before it."""
    import torch  # local: the other helpers here are used by tools that never load torch

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return torch.load(path, map_location="cpu", weights_only=True)


LOG_REDRAW_SECONDS = 60.0
"""How often at most a progress bar writes a line when stderr is not a terminal (a log file,
``nohup``, a pipe), and how long it waits before its first (``bar_options``): tqdm's own 0.1 s
wrote ten carriage-return updates a second into a log (36,000 in an hour of training). The
lines a run prints (per epoch, summaries, warnings) are lines either way."""

NO_PROGRESS_VARIABLES = ("TRAJPREF_NO_PROGRESS", "TQDM_DISABLE")
"""Environment variables that hide every progress bar, as ``--no-progress`` (or
``progress=False``) does, when set to anything but empty, ``0``, ``false``, ``no`` or ``off``:
trajpref's own, and tqdm's, which the bars' explicit options would otherwise override."""


def progress_hidden_by_environment() -> str | None:
    """The first of ``NO_PROGRESS_VARIABLES`` set to hide the bars, or None."""
    for name in NO_PROGRESS_VARIABLES:
        value = os.environ.get(name, "").strip().lower()
        if value not in ("", "0", "false", "no", "off"):
            return name
    return None


class LogLines:
    r"""The stream a progress bar writes to where stderr is not a terminal: each redraw (tqdm
    writes ``\r`` + the bar, never a newline) becomes one whole line on the current
    ``sys.stderr``, and the writes that clear a finished bar (``\r`` + spaces) are dropped,
    so that a log holds lines only and every line after a bar (``trajpref: error: ...``)
    starts one. No ``encoding``: tqdm then draws the bar in ASCII."""

    def write(self, text: str) -> int:
        line = text.replace("\x1b[A", "").replace("\r", "").strip()
        if line:
            sys.stderr.write(line + "\n")
        return len(text)

    def flush(self) -> None:
        with contextlib.suppress(AttributeError, ValueError, OSError):
            sys.stderr.flush()


def _is_terminal(stream: Any) -> bool:
    """Whether ``stream`` is a terminal (False for a file, a pipe, a closed stream, or an
    object without ``isatty``)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (``ipykernel`` is loaded, as in every notebook
    and in nothing run from a terminal or a log): there stderr is no terminal, yet a
    progress bar is watched live (``tqdm.auto`` draws a notebook widget)."""
    return "ipykernel" in sys.modules


def bar_options(show: bool) -> dict[str, Any]:
    """The options of every progress bar (``tqdm(..., **bar_options(progress))``, the Python
    API's ``progress=True`` included): hidden unless ``show`` (the commands' ``--no-progress``)
    or where the environment hides them (``TRAJPREF_NO_PROGRESS=1`` or ``TQDM_DISABLE=1``,
    ``progress_hidden_by_environment``). On a terminal, and in a notebook (``in_notebook``:
    stderr is no terminal there, but a bar is watched live), tqdm's own. Elsewhere (a log file,
    ``nohup``, a pipe, a batch job) a bar writes nothing for its first ``LOG_REDRAW_SECONDS``
    (a shorter pass leaves no trace), then one plain line at most every ``LOG_REDRAW_SECONDS``
    (``LogLines``: newline-ended, ASCII, nothing written to clear it at the end)."""
    if not show or progress_hidden_by_environment() is not None:
        return {"disable": True}
    if _is_terminal(sys.stderr) or in_notebook():
        return {"disable": False}
    # maxinterval too: tqdm's monitor thread would otherwise redraw every maxinterval (10 s)
    return {"disable": False, "mininterval": LOG_REDRAW_SECONDS,
            "maxinterval": LOG_REDRAW_SECONDS, "delay": LOG_REDRAW_SECONDS,
            "file": LogLines()}  # fmt: skip
