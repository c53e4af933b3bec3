"""Readers for track text files (``frame agent x y [type]``, the Social-GAN format) and the
windowing rule that turns tracks into scenes. The format and its options are documented in
``docs/data_format.md``.

Windowing (the standard of Social-GAN, Trajectron++, AgentFormer and LED): per file, take the
sorted unique frame numbers; a window is ``T_h + T_f`` consecutive entries of that list,
starting at every ``stride``-th entry; an agent belongs to a window when it has a row in all
of its frames; every window with at least one such agent is a scene. Scenes come in the order
of their first frame, and a scene's agents in the order of their ids, which each scene keeps
(``Scene.agent_id``, exact: ``source_ids``).

Memory: rows are parsed by numpy's C parser, sorted by (agent, frame), and each track's
windows are read off runs of consecutive frame indices, so the reader holds O(rows + windows)
numbers and never a frames x agents array. A file's scenes are views into two arrays
(histories and futures of all its windows).
"""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import math
import os
import re
import warnings
from array import array
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation, localcontext
from pathlib import Path
from typing import BinaryIO

import numpy as np

from trajpref.errors import ConfigError, DataError, DataNotFound, GapWarning
from trajpref.types import AGENT_BALL, AGENT_PERSON, WINDOW, Scene

DEFAULT_MAX_COORD = 1e6
"""Largest accepted |x| or |y|, in the dataset's units (after any unit scaling)."""

DELIMITERS = {",": ",", ";": ";", "|": "|", "\t": "\t", "tab": "\t", "comma": ",",
              "semicolon": ";", "whitespace": "whitespace"}  # fmt: skip
"""Accepted ``delimiter`` values and what they mean (``whitespace``: runs of spaces or tabs)."""

TYPE_NAMES = {"PLAYER": AGENT_PERSON, "PERSON": AGENT_PERSON, "BALL": AGENT_BALL}
"""The names a 5th column of agent types may hold (any case), and the ``agent_type`` each
becomes. A file whose first data row has a 5th field among them is read with that column (the
NBA files; any folder's files alike); any other 5th column is refused."""
_TYPE_LIST = "BALL, PLAYER or PERSON"
"""``TYPE_NAMES`` as the messages name them."""
_TYPED = np.dtype([("frame", "f8"), ("agent", "f8"), ("x", "f8"), ("y", "f8"), ("kind", "U16")])
_CHUNK = 1 << 16
"""Windows gathered per step when the window arrays are filled."""


@dataclass(frozen=True)
class ReadOptions:
    """How track text files are read (``docs/data_format.md``)."""

    delimiter: str | None = None
    """Column separator: ``None`` sniffs it from the first data line (a comma if it has one,
    else a semicolon if it has one, else runs of spaces/tabs); or one of ``, ; | \\t`` (also
    spelled ``comma semicolon tab``), or ``whitespace``."""
    max_gap: int | None = None
    """Missing frames a window may span. ``None``: windows follow the unique frame numbers
    across any jump (the Social-GAN rule) and a ``GapWarning`` says how many do; ``0``: no
    window spans a missing frame."""
    max_coord: float = DEFAULT_MAX_COORD
    """Largest accepted |x| or |y| in the dataset's units (after unit scaling); a larger
    coordinate is a ``DataError``."""
    time_step: float = 1.0
    """Read each file as if it had been annotated every ``time_step`` of its frame steps
    (``resample_tracks``: positions interpolated in time; 1: as recorded; an integer picks
    every n-th frame exactly). For data recorded faster than a model's step (10 Hz data and a
    0.4 s model: 4), and for simulating a file whose steps span more time than their label
    says, as eth's test file does (docs/data.md)."""
    partial_future: int = 0
    """Also cut windows of the agents seen in every history frame and in at least this many
    first future frames, but not in all of them (an agent that leaves the view): their future
    is NaN from the first frame they are missing on (0: complete windows only, the
    benchmarks' rule). For training splits only (``DataConfig.partial_future``); such agents
    are then targets, not context-only agents."""
    reverse_context: bool = False
    """Also keep each window's context-only agents as seen played backwards
    (``Scene.context_reverse``), read by training with ``DataConfig.reverse_context`` alone;
    off (None), since they add as much memory again as the forward ones (``Scene.context``)."""
    t_hist: int = WINDOW[0]
    """Observed frames per window (T_h) that text track files and TrajNet++ scenes are cut
    into: 8 for every published model. A model reads windows of its own ``model.t_hist``;
    windows already cut (SDD's, Robo's ``.npz``) and the simulator come at 8 + 12 alone."""
    t_fut: int = WINDOW[1]
    """Future frames per window (T_f), as ``t_hist``: 12 for every published model."""

    def __post_init__(self) -> None:
        if self.delimiter is not None:
            if self.delimiter not in DELIMITERS:
                names = ", ".join(repr(k) for k in DELIMITERS)
                raise ConfigError(f"delimiter {self.delimiter!r}: choose one of {names}")
            object.__setattr__(self, "delimiter", DELIMITERS[self.delimiter])
        if self.max_gap is not None and (isinstance(self.max_gap, bool) or self.max_gap < 0):
            raise ConfigError(f"max_gap must be None or an integer >= 0, got {self.max_gap!r}")
        if not (np.isfinite(self.max_coord) and self.max_coord > 0):
            raise ConfigError(f"max_coord must be a positive finite number, got {self.max_coord}")
        if isinstance(self.partial_future, bool) or self.partial_future < 0:
            raise ConfigError(f"partial_future must be an integer >= 0 (0: off), "
                              f"got {self.partial_future!r}")  # fmt: skip
        for key, least in (("t_hist", 2), ("t_fut", 1)):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                raise ConfigError(f"{key} must be an integer >= {least} (frames per window), "
                                  f"got {value!r}")  # fmt: skip
            object.__setattr__(self, key, int(value))
        if not (np.isfinite(self.time_step) and 0.1 <= self.time_step <= 100):
            raise ConfigError(f"time_step must be a number of frame steps in [0.1, 100], "
                              f"got {self.time_step}")  # fmt: skip


@dataclass
class Tracks:
    """The rows of one track file, validated, sorted by (agent, frame)."""

    path: Path
    frames: np.ndarray
    """[F] float64 sorted unique frame numbers, counted from ``frame_origin``."""
    agents: np.ndarray
    """[A] float64 sorted unique agent ids; an object array of exact ints (or Decimals) when
    an id reaches ``EXACT_ID_LIMIT`` (2**53), which float64 cannot hold exactly."""
    frame_index: np.ndarray
    """[R] int32 index into ``frames`` of each row."""
    agent_index: np.ndarray
    """[R] int32 index into ``agents`` of each row (non-decreasing)."""
    xy: np.ndarray
    """[R, 2] float32 positions, in the dataset's units (``scale`` applied)."""
    agent_type: np.ndarray
    """[A] int64 agent-type flag per agent (the type on the agent's last row in the file)."""
    frame_name: str | None = None
    """The header's name of the frame column, lower case (None: no header)."""
    frame_noise: float = 0.0
    """How far the frame numbers may lie from their exact values: 0 for frames as read, a
    few units of float64's rounding for a resampled grid (``resample_tracks``), which the
    scene ids' labels round away (``frame_labels``)."""
    frame_origin: int = 0
    """What ``frames`` count from, exactly: 0, unless a frame number reaches
    ``EXACT_ID_LIMIT`` (2**53; nanosecond timestamps), which float64 rounds; then the file's
    smallest frame (rounded down to an integer), and ``frames`` are the exact distances from
    it (``_frame_numbers``). Scene ids add it back (``frame_labels``)."""

    @property
    def num_rows(self) -> int:
        return int(self.xy.shape[0])


@dataclass
class _Layout:
    """What the first data line says about a file."""

    delimiter: str | None
    header_line: int | None
    """1-based number of a header line to skip (None: no header)."""
    frame_name: str | None = None
    """The header's name of the first (frame) column, lower case."""
    typed: bool = False
    """Whether the first data row has a 5th field naming an agent type (``TYPE_NAMES``): the
    file is then read with its column of agent types, as the NBA files are."""


def _sep_name(delimiter: str | None) -> str:
    return {None: "whitespace", "\t": "tab"}.get(delimiter, repr(delimiter))


def _split(content: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return content.split()
    return [field.strip() for field in content.split(delimiter)]


def _to_float(v: str) -> float:
    """A field's number, in the syntax numpy's parser reads: Python's ``float`` also reads
    digit separators (``1_12`` and ``11_2`` both as 112, so two camera_track ids became one
    agent) and digits of other scripts, which numpy refuses; the line parser took them."""
    if not v.isascii() or "_" in v:
        raise ValueError(f"not a number: {v!r}")
    return float(v)


def _is_float(v: str, strict: bool = True) -> bool:
    """Whether ``v`` is a number (``_to_float``); not ``strict``: whether Python's ``float``
    reads it, which is how a header is told from data (a line of ``1_0`` is a data line to
    refuse, not a header to skip)."""
    try:
        _to_float(v) if strict else float(v)
    except ValueError:
        return False
    return True


def _link_error(path: Path) -> DataError:
    """The error for a path that is a symlink whose target cannot be reached."""
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return DataError("symlink loop (the link leads back to itself)", path)
        try:
            target = os.readlink(path)
        except OSError:
            target = "?"
        return DataNotFound(f"broken symlink (points to {target}, which does not exist)", path)
    return DataError("cannot follow symlink", path)


def check_file(path: Path) -> None:
    """Raise ``DataError`` unless ``path`` is a readable-looking file (says which symlink
    problem when it is a link)."""
    if path.is_file():
        return
    if path.is_symlink():
        raise _link_error(path)
    raise DataNotFound("no such file", path)


SECONDS_COLUMNS = ("time", "timestamp", "time_s", "timestamp_s", "seconds")
"""Header names of a frame column whose values are times in seconds: unless a frame interval
is given, a folder of such files takes their frame step (``frame_step``) as its interval in
seconds (``DatasetInfo.interval_from == "timestamps"``)."""
MILLISECONDS_COLUMNS = ("time_ms", "timestamp_ms")
"""Header names of a frame column whose values are times in milliseconds: as
``SECONDS_COLUMNS``, their frame step divided by 1000 (``column_seconds``)."""


def column_seconds(name: str | None) -> float | None:
    """Seconds per unit of a frame column headed ``name`` (lower case): 1 for a
    ``SECONDS_COLUMNS`` name, 0.001 for a ``MILLISECONDS_COLUMNS`` one, None for anything else
    (frame numbers, or no header)."""
    if name in SECONDS_COLUMNS:
        return 1.0
    if name in MILLISECONDS_COLUMNS:
        return 1e-3
    return None


_HEADER_ROLES = {
    "frame": {"frame", "frames", "frame_id", "frameid", "f", "t", "step", *SECONDS_COLUMNS,
              *MILLISECONDS_COLUMNS},
    "agent": {"agent", "agent_id", "agentid", "id", "ped", "ped_id", "pedid", "pedestrian",
              "person", "person_id", "track", "track_id", "trackid", "obj", "object_id", "p"},
    "x": {"x", "pos_x", "x_m", "px"},
    "y": {"y", "pos_y", "y_m", "py"},
}  # fmt: skip
"""Column names a header may use for each of the four columns read (lower case)."""


def _check_header(tokens: list[str], path: Path, line: int) -> None:
    """Refuse a header whose names say the columns are not in the order they are read
    (``frame agent x y``, by position): read anyway, such a file gives wrong tracks silently.
    A header of two or three known names (``frame,x,y``) is refused naming the missing
    column, which reordering could not supply."""
    roles = []
    for token in tokens[:4]:
        name = token.strip("\"'").lower()
        roles.append(next((r for r, names in _HEADER_ROLES.items() if name in names), None))
    known = [r for r in roles if r is not None]
    if 2 <= len(tokens) < 4 and len(set(known)) == len(tokens):
        # every column named, and one short: reordering cannot help (``frame,x,y``)
        missing = [r for r in _HEADER_ROLES if r not in known]
        one = " (a file of one agent: the same agent id on every row)" if "agent" in missing else ""
        where = (f"it as column {list(_HEADER_ROLES).index(missing[0]) + 1}" if len(missing) == 1
                 else "them in that order")  # fmt: skip
        raise DataError(
            f"the header names {len(tokens)} columns ({' '.join(tokens)}), where 4 are needed "
            f"(frame agent x y, read by position): no {' or '.join(missing)} column was found; "
            f"add {where}{one}",
            path,
            line,
        )
    if len(known) >= 3 and any(r is not None and r != want for r, want in
                               zip(roles, _HEADER_ROLES, strict=False)):  # fmt: skip
        raise DataError(
            f"the header names the first columns {' '.join(tokens[:4])}, but columns are read "
            "by position as frame agent x y: reorder the file's columns to that order",
            path,
            line,
        )


def _layout(path: Path, options: ReadOptions) -> _Layout:
    """Sniff the delimiter and a header from the first line that holds data, and whether the
    first data row (after a header, if any) has a 5th column of agent types."""
    header: _Layout | None = None
    try:
        with open(path, "rb") as fh:
            for lineno, raw in enumerate(file_lines(fh), start=1):
                try:
                    line = raw.decode("utf-8-sig" if lineno == 1 else "utf-8")
                except UnicodeDecodeError:
                    break  # the parser reports it with its line number
                content = line.split("#", 1)[0]
                if not content.strip():
                    continue
                if header is not None:  # the first data row after the header
                    return _Layout(header.delimiter, header.header_line, header.frame_name,
                                   _names_type(content, header.delimiter))  # fmt: skip
                delimiter = options.delimiter
                if delimiter is None:
                    delimiter = "," if "," in content else ";" if ";" in content else None
                elif delimiter == "whitespace":
                    delimiter = None
                tokens = [t for t in re.split(r"[\s,;|]+", content) if t]
                is_header = not any(_is_float(t, strict=False) for t in tokens)
                if is_header:
                    _check_header(tokens, path, lineno)
                    name = tokens[0].strip("\"'").lower() if tokens else None
                    header = _Layout(delimiter, lineno, name)
                    continue
                return _Layout(delimiter, None, typed=_names_type(content, delimiter))
    except OSError as exc:
        raise DataError(f"cannot read file ({exc.strerror or exc})", path) from None
    if header is not None:  # a header and no data: the parser says the file is empty
        return header
    return _Layout(None if options.delimiter == "whitespace" else options.delimiter, None)


def _names_type(content: str, delimiter: str | None) -> bool:
    """Whether a data line has exactly 5 fields, the 5th an agent type's name (``TYPE_NAMES``,
    any case)."""
    fields = _split(content.rstrip("\r\n"), delimiter)
    return len(fields) == 5 and fields[4].upper() in TYPE_NAMES


def _parse_fast(path: Path, layout: _Layout, with_type: bool):
    """numpy's C parser; ``None`` when it refuses the file (the slow path then says why)."""
    skip = layout.header_line or 0
    kwargs = dict(comments="#", delimiter=layout.delimiter, skiprows=skip, encoding="utf-8-sig")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data"
            if with_type:
                table = np.loadtxt(path, dtype=_TYPED, ndmin=1, **kwargs)  # [R]
                if table.size == 0:
                    return np.zeros((0, 4)), np.zeros(0, "U16")
                values = np.stack([table[k] for k in ("frame", "agent", "x", "y")], 1)  # [R, 4]
                return values, table["kind"]
            values = np.loadtxt(path, dtype=np.float64, ndmin=2, **kwargs)  # [R, C]
    except (ValueError, TypeError, IndexError, OverflowError, UnicodeError, OSError):
        return None
    if values.size == 0:
        return np.zeros((0, 4)), None
    if values.shape[1] != 4:
        return None
    return values, None


def open_data_file(path: Path) -> BinaryIO:
    """``path`` opened for binary reading; a file that cannot be opened is a DataError."""
    try:
        return open(path, "rb")
    except OSError as exc:
        raise DataError(f"cannot read file ({exc.strerror or exc})", path) from None


def file_lines(fh: BinaryIO) -> Iterator[bytes]:
    """The lines of a file opened in binary, ending at ``\\n``, ``\\r\\n`` or a lone ``\\r``
    (old Mac line ends), as numpy's parser and Python's text mode count them: iterating the
    file itself splits at ``\\n`` alone, so a CR-only file was one line, and its errors all
    said line 1. (No UTF-8 character holds the byte ``\\r``: splitting bytes is safe.)"""
    for raw in fh:
        cr = raw.count(b"\r")
        if cr == 0 or (cr == 1 and raw.endswith(b"\r\n")):
            yield raw
        else:
            yield from raw.splitlines(keepends=True)


def _data_content(path: Path, layout: _Layout, errors: str = "strict") -> Iterator[tuple[int, str]]:
    """``(line number, content)`` of each data line of a text track file: the header skipped,
    a byte-order mark dropped, a ``#`` comment cut, blank lines skipped; text that is not
    UTF-8 is a ``DataError`` naming its line (``errors="replace"``: decoded anyway)."""
    with open_data_file(path) as fh:
        for lineno, raw in enumerate(file_lines(fh), start=1):
            if lineno == layout.header_line:
                continue
            try:
                line = raw.decode("utf-8-sig" if lineno == 1 else "utf-8", errors)  # a BOM
            except UnicodeDecodeError:
                raise DataError("not UTF-8 text", path, lineno) from None
            content = line.split("#", 1)[0]
            if content.strip():
                yield lineno, content


def _parse_slow(path: Path, layout: _Layout, with_type: bool):
    """Line-by-line parser: the reference for what is accepted, and the source of the
    line-numbered error messages. Returns ``(values [R, 4], kinds [R] | None, lines [R])``."""
    n_cols = 5 if with_type else 4
    expect = "frame agent x y BALL|PLAYER|PERSON" if with_type else "frame agent x y"
    delimiter = layout.delimiter
    values = array("d")
    kinds: list[str] = []
    lines = array("q")
    for lineno, content in _data_content(path, layout):
        fields = _split(content.rstrip("\r\n"), delimiter)
        if len(fields) != n_cols:
            message = (
                f"expected {n_cols} columns ({expect}) separated by {_sep_name(delimiter)}, "
                f"found {len(fields)}"
            )
            raise DataError(message + _column_hint(content, delimiter, len(fields), n_cols),
                            path, lineno)  # fmt: skip
        try:
            values.extend(_to_float(v) for v in fields[:4])
        except ValueError:
            bad = next(v for v in fields[:4] if not _is_float(v))
            raise DataError(f"not a number: {bad!r}", path, lineno) from None
        if with_type:
            kinds.append(fields[4])
        lines.append(lineno)
    table = np.frombuffer(values, dtype=np.float64).reshape(-1, 4)  # [R, 4]
    return table, (np.asarray(kinds, dtype="U16") if with_type else None), np.asarray(lines)


def _column_hint(content: str, delimiter: str | None, found: int, n_cols: int) -> str:
    # a separator worth naming splits the line into more fields than were found (a tab in a
    # whitespace-separated line is already a separator: the line is short of a column)
    others = [c for c in (",", ";", "\t", "|") if c in content and c != delimiter
              and len(_split(content.rstrip("\r\n"), c)) > found]  # fmt: skip
    if found < n_cols and others:
        sep = others[0]
        held = "a tab" if sep == "\t" else repr(sep)
        return f"; the line holds {held}: pass --delimiter {_sep_name(sep)}"
    if found > n_cols and n_cols == 4:
        other = "column" if found == 5 else f"{found - n_cols} columns"
        fifth = _split(content.rstrip("\r\n"), delimiter)[4] if found == 5 else ""
        types = ""
        if fifth.upper() in TYPE_NAMES:  # types, but the first data row has none
            types = ("; a 5th column of agent types is read when the first data row has one: "
                     "give every row its type")  # fmt: skip
        elif found == 5:
            types = (f"; a 5th column is read only as agent types, {_TYPE_LIST} (any case), "
                     f"not {fifth!r}")  # fmt: skip
        return (f"; only frame agent x y are read, the first 4 columns, by position, not by "
                f"header name: drop the other {other} (keep frame agent x y, in that order)"
                f"{types}")  # fmt: skip
    if found == 1 and delimiter is not None:
        return "; is the file whitespace-separated? pass --delimiter whitespace"
    return ""


def _data_lines(path: Path, layout: _Layout, rows: Iterable[int]) -> dict[int, int]:
    """Line numbers of the given data rows (0-based, file order) of a file the fast parser
    accepted: a re-scan only done to word an error."""
    wanted = sorted(set(int(r) for r in rows))
    found: dict[int, int] = {}
    for row, (lineno, _) in enumerate(_data_content(path, layout, "replace")):
        if row == wanted[len(found)]:
            found[row] = lineno
            if len(found) == len(wanted):
                break
    return found


def read_tracks(
    path: str | Path,
    with_type: bool = False,
    options: ReadOptions | None = None,
    scale: float = 1.0,
    units: str = "unknown",
) -> Tracks:
    """Read ``frame agent x y`` rows, plus a column of agent types (``TYPE_NAMES``) when
    ``with_type`` or when the file's first data row has one (``_Layout.typed``).

    ``scale`` multiplies coordinates (e.g. feet to metres); ``units`` names the units after
    scaling, for messages. Raises ``DataError`` naming the file and line for: a wrong number of
    columns, a value that is not a number, NaN or infinity, a coordinate that overflows float32
    or exceeds ``options.max_coord``, a duplicated (frame, agent) pair, an unknown agent type,
    text that is not UTF-8, or an empty file.
    """
    path = Path(path)
    options = options or ReadOptions()
    check_file(path)
    layout = _layout(path, options)
    with_type = with_type or layout.typed  # a 5th column of agent types, in any file
    parsed = _parse_fast(path, layout, with_type)
    lines = None
    if parsed is None:
        values, kinds, lines = _parse_slow(path, layout, with_type)
    else:
        values, kinds = parsed
    if len(values) == 0:
        raise DataError("empty file: no data rows", path)

    def line_of(rows: list[int]) -> list[int]:
        known = lines
        if known is None:
            found = _data_lines(path, layout, rows)
            if all(int(r) in found for r in rows):
                return [found[int(r)] for r in rows]
            known = _parse_slow(path, layout, with_type)[2]  # the two parsers disagree on rows
        return [int(known[r]) for r in rows]

    xy, rounding = _checked_xy(values, scale, options.max_coord, units, path, line_of)  # [R, 2]
    column, origin = _frame_numbers(values[:, 0], path, layout)  # [R] counted from origin
    frames, f_idx = np.unique(column, return_inverse=True)  # [F], [R]
    ids = _agent_ids(values[:, 1], path, layout)  # [R] float64, or exact beyond 2**53
    agents, a_idx = np.unique(ids, return_inverse=True)  # [A], [R]
    agent_type = np.zeros(len(agents), np.int64)  # [A]
    if kinds is not None:
        agent_type[a_idx] = _kind_flags(kinds, path, line_of)  # last row of an agent wins
    order = np.lexsort((f_idx, a_idx))  # [R] rows by (agent, frame), stable
    index = np.int32 if max(len(frames), len(agents)) < 2**31 else np.int64
    f_idx, a_idx = f_idx[order].astype(index), a_idx[order].astype(index)
    same = (f_idx[1:] == f_idx[:-1]) & (a_idx[1:] == a_idx[:-1])
    if same.any():
        _raise_duplicate(np.flatnonzero(same), order, f_idx, a_idx, frames, agents, path, line_of,
                         origin)  # fmt: skip
    if rounding:  # float32 rounded the positions: by how much of a step, in (agent, frame) order
        _check_precision(values[order, 2:4] * scale, a_idx, rounding, path, options.time_step)
    del values
    return Tracks(path, frames, agents, f_idx, a_idx, xy[order], agent_type, layout.frame_name,
                  frame_origin=origin)  # fmt: skip


EXACT_ID_LIMIT = 2**53
"""Agent ids and frame numbers at least this large (in absolute value) are beyond float64's
exact integers: ``_agent_ids`` and ``_frame_numbers`` re-read them from the text."""


def _agent_ids(parsed: np.ndarray, path: Path, layout: _Layout) -> np.ndarray:
    """[R] the agent ids of a file's rows: ``parsed`` (the float64 column) when every id is
    below ``EXACT_ID_LIMIT``, else the ids read again from the text as exact numbers (an
    object array of ints, or Decimals for non-integers), since float64 rounds 64-bit tracker
    ids (9007199254740993 reads as 9007199254740992) and two agents would become one."""
    if not len(parsed) or float(np.abs(parsed).max()) < EXACT_ID_LIMIT:
        return parsed
    exact = _exact_column(path, layout, 1, len(parsed), "agent ids", "an agent id",
                          "renumber the agents below 2**53")  # fmt: skip
    return np.array(exact, dtype=object)


def _frame_numbers(parsed: np.ndarray, path: Path, layout: _Layout) -> tuple[np.ndarray, int]:
    """[R] the frame numbers of a file's rows as float64, and the exact integer they count
    from: ``parsed`` (the float64 column) and 0 when every frame is below ``EXACT_ID_LIMIT``;
    else the frames read again from the text as exact numbers, counted from the smallest
    (rounded down), since float64 rounds nanosecond timestamps (1700000000000000123 reads as
    1700000000000000000): scene ids named frames the file does not hold, frames one apart
    became one (a "duplicate row") and rows of two agents logged 100 ns apart one frame. The
    distances from it are exact below 2**53 (104 days of nanoseconds); a file whose frames
    float64 cannot keep apart even so is a ``DataError`` asking to rescale its time column."""
    if not len(parsed) or float(np.abs(parsed).max()) < EXACT_ID_LIMIT:
        return parsed, 0
    advice = "rescale the time column (nanoseconds to microseconds, say) or subtract its start"
    exact = _exact_column(path, layout, 0, len(parsed), "frame numbers", "a frame number", advice)
    origin = math.floor(min(exact))
    column = np.array([float(v - origin) for v in exact])  # [R] exact below 2**53
    first: dict[float, int | Decimal] = {}  # the exact frame of each float: two would merge
    for value, number in zip(column.tolist(), exact, strict=True):
        other = first.setdefault(value, number)
        if other != number:
            lo, hi = sorted((other, number))
            low, high = min(exact), max(exact)
            raise DataError(
                f"frame numbers (column 1) {_exact_text(lo)} and {_exact_text(hi)} are "
                f"{_exact_text(hi - lo)} apart, but the file's frames span "
                f"{_exact_text(high - low)} (from {_exact_text(low)} to {_exact_text(high)}), "
                f"too far for float64 to keep them apart (2**53 = {EXACT_ID_LIMIT}): {advice}",
                path,
            )
    return column, origin


def _exact_number(token: str) -> int | Decimal:
    """A number's text as an exact int (integral values) or Decimal."""
    value = Decimal(token.strip())
    return int(value) if value == value.to_integral_value() else value


def _exact_text(value: int | Decimal) -> str:
    """An exact number as text without an exponent: ``9007199254740993``, ``2.5``."""
    return str(value) if isinstance(value, int) else format(value, "f")


def _exact_column(path: Path, layout: _Layout, column: int, rows: int, what: str, one: str,
                  advice: str) -> list[int | Decimal]:  # fmt: skip
    """Column ``column`` (0-based) of every data row as exact numbers (``_exact_number``), in
    file order: the text read again, rows as ``_parse_slow`` finds them. ``rows`` is how many
    rows the parser read; ``what`` and ``one`` name the column's values (plural, one) in the
    errors, and ``advice`` says what to do when the two parsers disagree on the rows."""
    tokens = [_split(content.rstrip("\r\n"), layout.delimiter)[column]
              for _, content in _data_content(path, layout)]  # fmt: skip
    if len(tokens) != rows:  # the parsers disagree on rows: the slow one's are the rows
        raise DataError(f"{what} of 2**53 ({EXACT_ID_LIMIT}) or more (column {column + 1}) "
                        f"could not be read exactly: {advice}", path)  # fmt: skip
    try:
        return [_exact_number(t) for t in tokens]
    except InvalidOperation:
        raise DataError(f"{one} (column {column + 1}) is not a number", path) from None


def source_ids(agents: np.ndarray) -> np.ndarray:
    """[A] a file's agent ids (``Tracks.agents``) as ``Scene.agent_id`` holds them, exact:
    int64 where every id is a whole number that int64 holds, else float64 for ids that float64
    reads exactly (below ``EXACT_ID_LIMIT``: ``2.5``), else each id's exact text
    (``_exact_text``: ``9007199254740993.5``, or an integer beyond int64)."""
    if agents.dtype != object:  # float64, every id below 2**53
        whole = bool((agents == np.round(agents)).all())
        return agents.astype(np.int64) if whole else agents.astype(np.float64)
    values = agents.tolist()
    if all(isinstance(v, int) and -(2**63) <= v < 2**63 for v in values):
        return np.array(values, dtype=np.int64)
    return np.array([_exact_text(v) for v in values], dtype=str)


def _id_label(value) -> str:
    """An agent id as text, exact: ``1``, ``-1``, ``2.5``, ``9007199254740993``."""
    if isinstance(value, (float, np.floating)):
        return _frame_label(float(value))
    return str(value)


def _checked_xy(values, scale, max_coord, units, path, line_of) -> tuple[np.ndarray, float]:
    """[R, 2] float32 positions after ``scale``, and the largest rounding float32 made in them;
    the first bad row (file order) raises."""
    finite = np.isfinite(values).all(1)  # [R]
    with np.errstate(over="ignore", invalid="ignore"):
        exact = values[:, 2:4] * scale  # [R, 2] float64
        xy = exact.astype(np.float32)  # [R, 2]
    fits = np.isfinite(xy).all(1)  # [R]
    inside = (np.abs(xy) <= max_coord).all(1)  # [R]
    bad = ~(finite & fits & inside)  # [R]
    if not bad.any():
        return xy, float(np.abs(exact - xy).max()) if len(xy) else 0.0
    r = int(np.argmax(bad))
    (line,) = line_of([r])
    if not finite[r]:
        raise DataError("NaN or infinite value", path, line)
    v = values[r, 2:4] * scale  # [2]
    big = float(v[np.argmax(np.abs(v))])
    if not fits[r]:
        raise DataError(f"coordinate {big:g} does not fit float32 (|value| > 3.4e38)", path, line)
    if abs(big) <= max_coord:  # only float32's rounding put it beyond: show that value
        big = float(xy[r, int(np.argmax(np.abs(xy[r])))])
    shown, bound = _apart(big, max_coord)
    unit = f" {units}" if units and units != "unknown" else ""
    raise DataError(
        f"coordinate {shown}{unit} is beyond the sane bound of {bound}{unit} "
        "(map coordinates such as UTM: subtract an origin from x and y, since every model "
        "computes in float32; raise it with --max-coord only if the data really spans that "
        "far)",
        path,
        line,
    )


def _apart(value: float, bound: float) -> tuple[str, str]:
    """``value`` and ``bound`` as text (``:g``) with the fewest significant digits, 6 or more,
    at which the magnitude of ``value`` reads differently from ``bound``: ``1000000.5`` and
    ``1000000``, not ``1e+06`` twice."""
    for digits in range(6, 18):
        shown, limit = f"{value:.{digits}g}", f"{bound:.{digits}g}"
        if shown.lstrip("-") != limit:
            return shown, limit
    return repr(value), repr(bound)


PRECISION_SHARE = 0.01
"""The largest float32 rounding of a position, as a share of the file's median step, that a
file may carry (``_check_precision``), or of the step a model's check compares with
(``float32_precision_loss``'s ``floor``)."""
PRECISION_STEP_FLOOR = 0.1
"""The least step (model units: positions / the model's data scale) that the check of the
histories handed to a model (``models.predictor.check_coordinates``) compares the float32
rounding with, whatever the median step of the scene: a slow walker's step (0.15 m per 0.4 s
at zara1's scale of 1.47 m, 0.37 m/s; 5.9 px at sdd's 59 px), below a typical scene's median
moving step (0.29, 0.26 and 0.22 model units, the median over zara1's, eth's and sdd's test
scenes), so that walkers are judged by their own steps as before. Without it, a crowd
that stands still with millimetre tracker jitter made the bar microscopic: three people
standing with 2 mm of jitter 2 km from a map frame's origin were refused (rounding 0.12 mm,
4 % of their 3.4 mm median step) while the same frame with walkers was accepted, so a
planner's map frame raised or not with the crowd's motion. With it, the rounding may reach
``PRECISION_SHARE`` of 0.1, 0.001 model units (1.5 mm at zara1's scale): coordinates up to
0.001 / 2**-24 = 16,777 model units from the origin (24.7 km at zara1's scale) whatever moves,
while UTM eastings (5e5 m: 3 cm of rounding) are refused whether the crowd walks or stands.
That much rounding is below a tracker's noise: 60 of zara1's test scenes moved 24 km out
moved zara1's generator futures (same seed) by a median 2.0 cm (largest 0.44 m) from those at
the origin, less than 0.7 mm of Gaussian noise on their histories does (3.1 cm; 0.21 m);
2 km out, by 1.3 mm (2.4 cm) (2026-12, walkthrough 65).
The text reader, which knows no model, keeps the median step alone (``_check_precision``)."""


def _check_precision(
    exact: np.ndarray, agent: np.ndarray, rounding: float, path: Path, time_step: float = 1.0
) -> None:
    """Refuse a file whose coordinates are so large that float32, in which every model
    computes, rounds them (by up to ``rounding``) by more than ``PRECISION_SHARE`` of its
    median step (between an agent's consecutive rows, times ``time_step``: the step it is read
    at) — map coordinates such as UTM eastings and northings. ``exact`` [R, 2] are the float64
    positions and ``agent`` [R] their agents, rows in (agent, frame) order."""
    same = agent[1:] == agent[:-1]  # consecutive rows of one agent
    steps = np.linalg.norm(np.diff(exact, axis=0), axis=1)[same] * time_step  # [S]
    problem = float32_precision_loss(float(np.abs(exact).max()), rounding, steps)
    if problem is not None:
        raise DataError(
            f"{problem}: every model computes in float32, so subtract an origin from x and y "
            "(e.g. the first row's) before reading, and add it back to the predictions",
            path,
        )


def float32_precision_loss(largest: float, rounding: float, steps: np.ndarray,
                           floor: float = 0.0) -> str | None:  # fmt: skip
    """What is wrong when coordinates as large as ``largest``, rounded by up to ``rounding``
    in float32, lose more than ``PRECISION_SHARE`` of the step compared with: the median of
    ``steps`` (the moving ones), or ``floor`` where that is larger (a model's check passes
    ``PRECISION_STEP_FLOOR`` model units in data units; the text reader none); None when the
    rounding stays within it, or when nothing moves and there is no floor. The text reader's
    rule, which ``models.predictor.check_coordinates`` applies to histories handed in from
    Python."""
    moving = steps[steps > 0]
    median = float(np.median(moving)) if len(moving) else 0.0
    step = max(median, float(floor))
    if step <= 0 or rounding <= PRECISION_SHARE * step:
        return None
    head = f"coordinates as large as {largest:.6g} lose up to {rounding:.3g} to float32 rounding"
    if step == median:
        return f"{head}, {rounding / median:.0%} of a median step ({median:.3g})"
    moves = f"their median step {median:.3g}" if len(moving) else "nothing moves"
    return (f"{head}, {rounding / step:.0%} of a step of {step:.3g} (the least step this check "
            f"compares with; {moves})")  # fmt: skip


def _kind_flags(kinds: np.ndarray, path: Path, line_of) -> np.ndarray:
    """[R] agent-type flags from the type column (file order)."""
    names, inverse = np.unique(kinds, return_inverse=True)  # [U], [R]
    flags = np.empty(len(names), np.int64)  # [U]
    for i, name in enumerate(names):
        flag = TYPE_NAMES.get(str(name).upper())
        if flag is None:
            (line,) = line_of([int(np.argmax(inverse == i))])
            raise DataError(f"unknown agent type {str(name)!r} ({_TYPE_LIST}, any case)", path,
                            line)  # fmt: skip
        flags[i] = flag
    return flags[inverse]


def _raise_duplicate(pos, order, f_idx, a_idx, frames, agents, path, line_of, origin=0):
    """Report the smallest duplicated (frame, agent) pair at its second row in the file, the
    frame exact (``origin`` added; ``:g`` wrote 1700000000.1 as 1.7e+09)."""
    first = pos[np.lexsort((a_idx[pos], f_idx[pos]))[0]]  # sorted position of the pair's 1st row
    line_first, line_second = line_of([int(order[first]), int(order[first + 1])])
    (f,) = frame_labels(frames[f_idx[first], None], 0.0, origin)
    a = agents[a_idx[first]]
    raise DataError(
        f"duplicate row for frame {f}, agent {_id_label(a)} (also on line {line_first})",
        path,
        line_second,
    )


@dataclass
class _Windows:
    scenes: list[Scene]
    gap_scenes: int = 0
    """Scenes (windows) that span missing frames (kept: ``max_gap`` is None)."""
    gap_agents: int = 0
    """Agent-windows among them."""
    max_missing: int = 0
    """The largest number of missing frames one of them spans."""
    step: float = 0.0
    """The file's frame step (the most common difference between unique frames)."""


def _missing_frames(frames: np.ndarray) -> tuple[np.ndarray, float]:
    """Missing frames between consecutive unique frames [F-1], and the frame step."""
    jumps = np.diff(frames)  # [F-1]
    if len(jumps) == 0:
        return np.zeros(0, np.int64), 0.0
    step = _common_jump(jumps, float(np.abs(frames).max()))
    missing = np.maximum(np.rint(jumps / step).astype(np.int64) - 1, 0)  # [F-1]
    return missing, step


def _common_jump(jumps: np.ndarray, largest: float) -> float:
    """The most common of ``jumps`` [J] (> 0; the smallest on ties), counting as one the jumps
    that differ by no more than float64's rounding of frame numbers as large as ``largest``:
    non-integer frame numbers (0.4 * k, Unix seconds) give one step as several float values
    (0.39999986, 0.40000009, ...), and counted apart, a less common jump of two steps could
    win and hide every missing frame. Returns the median of the winning group's jumps."""
    quantum = 64 * float(np.spacing(largest))
    keys = np.rint(jumps / quantum).astype(np.int64)  # [J] jump / quantum <= 2**47: no overflow
    values, counts = np.unique(keys, return_counts=True)
    return float(np.median(jumps[keys == values[np.argmax(counts)]]))


def _window(tracks: Tracks, t_hist: int, t_fut: int, stride: int, max_gap: int | None,
            partial: int = 0, reverse_context: bool = False):  # fmt: skip
    t_total = t_hist + t_fut
    if partial >= t_fut:
        raise ConfigError(f"partial_future must be below the {t_fut} future frames (0: off), "
                          f"got {partial}")  # fmt: skip
    need = t_hist + partial if partial else t_total  # frames a target must be seen in
    frames = tracks.frames
    n_f = len(frames)
    if n_f < t_total:
        raise DataError(
            f"too few frames: {n_f} unique frames, a window needs {t_total} ({t_hist} observed "
            f"+ {t_total - t_hist} future)",
            tracks.path,
        )
    f_idx, a_idx, n_r = tracks.frame_index, tracks.agent_index, tracks.num_rows
    # a row starts a window when the row need-1 further holds the same agent need-1 frames
    # later (rows are sorted by agent, then frame, without duplicates); need = T unless
    # ``partial``, whose windows may end before the file does
    head = slice(0, max(n_r - need + 1, 0))
    tail = slice(need - 1, n_r)
    full = (a_idx[tail] == a_idx[head]) & (f_idx[tail] - f_idx[head] == need - 1)  # [R-need+1]
    if partial:  # a window still needs all T frames of the file
        full &= f_idx[head] + t_total <= n_f
    full &= f_idx[head] % stride == 0
    start_row = np.flatnonzero(full)  # [W] first row of each agent-window
    start = f_idx[start_row]  # [W] index of its first frame
    missing, step = _missing_frames(frames)  # [F-1]
    out = _Windows([], step=step)
    if missing.any():
        # jumps of a window starting at unique frame j: missing[j : j + T - 1]
        over = missing > (max_gap or 0)  # [F-1]
        count = np.concatenate([[0], np.cumsum(over)])  # [F]
        spans = count[start + t_total - 1] - count[start] > 0  # [W]
        if max_gap is None and spans.any():
            out.gap_scenes = len(np.unique(start[spans]))
            out.gap_agents = int(spans.sum())
            runs = [int(missing[s : s + t_total - 1].max()) for s in np.unique(start[spans])]
            out.max_missing = max(runs)
        elif max_gap is not None:
            start_row, start = start_row[~spans], start[~spans]
    by_start = np.argsort(start, kind="stable")  # [W] scene order; agents stay sorted by id
    start_row, start = start_row[by_start], start[by_start]
    n_w = len(start_row)
    cuts = np.flatnonzero(np.diff(start)) + 1  # [S-1] where a new scene begins
    bounds = np.concatenate([[0], cuts, [n_w]]) if n_w else np.zeros(1, np.int64)
    firsts = start[bounds[:-1]] if n_w else start  # [S] each scene's first frame
    # context-only agents before the windows are gathered: their temporaries and the windows
    # are not held at once (the reader's peak memory on big files)
    context = _context(tracks, t_hist, t_total, firsts, need=need)
    context_reverse = (_context(tracks, t_hist, t_total, firsts, backwards=True)
                       if reverse_context else [None] * len(context))  # fmt: skip
    history = np.empty((n_w, t_hist, 2), np.float32)  # [W, T_h, 2]
    future = np.empty((n_w, t_fut, 2), np.float32)  # [W, T_f, 2]
    offsets = np.arange(t_total)  # [T]
    for c in range(0, n_w, _CHUNK):
        rows = start_row[c : c + _CHUNK, None] + offsets  # [C, T]
        if partial:
            rows = np.minimum(rows, n_r - 1)  # [C, T]
        np.take(tracks.xy, rows[:, :t_hist], axis=0, out=history[c : c + _CHUNK])
        np.take(tracks.xy, rows[:, t_hist:], axis=0, out=future[c : c + _CHUNK])
        if partial:  # NaN from the first future frame the agent is not seen on
            first = start_row[c : c + _CHUNK, None]  # [C, 1]
            seen = (a_idx[rows] == a_idx[first]) & (f_idx[rows] - f_idx[first] == offsets)
            future[c : c + _CHUNK][~seen[:, t_hist:]] = np.nan  # seen: [C, T]
    kind = tracks.agent_type[a_idx[start_row]]  # [W]
    ids = source_ids(tracks.agents)[a_idx[start_row]]  # [W] each agent-window's source id
    name = tracks.path.name
    labels = frame_labels(frames[firsts], tracks.frame_noise, tracks.frame_origin) if n_w else []
    for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        out.scenes.append(
            Scene(
                history=history[a:b],
                future=future[a:b],
                agent_type=kind[a:b],
                scene_id=f"{name}@frame={labels[i]}",
                context=context[i],
                context_reverse=context_reverse[i],
                agent_id=ids[a:b],
            )
        )
    return out


def _frame_label(frame: float) -> str:
    """A frame number as text, exact and without an exponent: ``780``, ``1700000000.1``
    (``:g`` kept six digits, so large frame numbers gave colliding scene ids)."""
    return np.format_float_positional(float(frame), trim="-")


LABEL_ULPS = 16
"""How far, in units of float64's spacing at a resampled file's largest frame number, its
frames may lie from their exact values (``Tracks.frame_noise``): the grid ``origin + j * step``
is rounded by a few such units."""


_EXACT_LABELS = [False]
"""Set by ``exact_frame_labels``: every label is its float's exact text, as before 2026-12-06."""


@contextlib.contextmanager
def exact_frame_labels() -> Iterator[None]:
    """Within it, ``frame_labels`` gives every frame its float's exact text, float noise and
    all: the scene ids a reader gave before 2026-12-06, which the data fingerprints of resume
    states written then hold (``train.run``)."""
    before = _EXACT_LABELS[0]
    _EXACT_LABELS[0] = True
    try:
        yield
    finally:
        _EXACT_LABELS[0] = before


NOISE_DIGITS = 4
"""A resampled frame's label is rounded only when that drops at least this many characters: a
run of float noise (``227.70000000000002`` -> ``227.7``, ``1000.0000000000001`` -> ``1000``),
not the last digit of a repeating decimal (``796.6666666666666`` stays). eth read every 5/3
steps (its paced copy) changed 160 of its 1,445 training scene ids this way on 2026-12-05;
resume states that recorded the old ids still resume on unchanged data."""


def frame_labels(frames: np.ndarray, noise: float = 0.0, origin: int = 0) -> list[str]:
    """Distinct frame numbers [S] of one file as scene-id text. ``noise`` 0 (frames as read):
    each float's exact shortest text (``_frame_label``: ``780``, ``1700000000.1``). Otherwise
    the shortest decimal within ``noise`` of it where that sheds a run of float noise
    (``NOISE_DIGITS``), so that a grid resampled from seconds reads ``227.7``, not
    ``227.70000000000002``. Distinct frames keep distinct labels: should two round alike
    (frames closer than ``noise``), every label is its float's exact text. ``origin``
    (``Tracks.frame_origin``: what the frames count from) is added to each label exactly."""
    labels = _float_labels(np.asarray(frames, np.float64).tolist(), noise)
    return [_add_origin(label, origin) for label in labels] if origin else labels


def _add_origin(label: str, origin: int) -> str:
    """``origin + label`` as exact text (``1700000000000000123``, ``1700000000000000123.5``)."""
    with localcontext() as ctx:
        ctx.prec = len(label) + len(str(origin)) + 2  # room for every digit of the sum
        return _exact_text(Decimal(label) + origin)


def _float_labels(values: list[float], noise: float) -> list[str]:
    """``frame_labels`` of the float frame numbers ``values``, no origin added."""
    exact = [_frame_label(v) for v in values]
    if not noise > 0 or _EXACT_LABELS[0]:
        return exact
    labels = []
    for value, text in zip(values, exact, strict=True):
        for digits in range(18):
            short = f"{value:.{digits}f}"
            if abs(float(short) - value) <= noise:
                short = np.format_float_positional(float(short), trim="-")
                break
        else:
            short = text
        labels.append(short if len(text) - len(short) >= NOISE_DIGITS else text)
    return labels if len(set(labels)) == len(set(values)) else exact


def _context(
    tracks: Tracks,
    t_hist: int,
    t_total: int,
    starts: np.ndarray,
    backwards: bool = False,
    need: int | None = None,
) -> list[np.ndarray]:
    """For each scene starting at unique-frame index ``starts`` [S], the histories [C, T_h, 2]
    of the other agents seen at its last observed frame (``Scene.context``): those not in all
    T_total frames, NaN at the history frames where they were not seen, in agent order.
    Which agents count is decided by the window's history frames and the targets alone; none
    of their later positions is read. With ``backwards``, the same for the window played
    backwards (``Scene.context_reverse``): its history is the window's last T_h frames in
    reverse order, so its last observed frame is the first of them. ``need`` (None:
    T_total): an agent seen in all of a window's first ``need`` frames is a target, not context
    (``partial_future``; ``_window`` passes it for the forward windows only)."""
    n_f = len(tracks.frames)
    key = tracks.agent_index.astype(np.int64) * n_f + tracks.frame_index  # [R] sorted
    empty = np.zeros((0, t_hist, 2), np.float32)
    if len(starts) == 0:
        return []
    span = t_total - t_hist if backwards else 0  # offset of the history frames in the window
    anchor = span if backwards else t_hist - 1  # offset of the last observed frame
    last = starts + anchor  # [S] each scene's last observed unique frame

    def find(k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row of each (agent, frame) key [...], and whether it exists."""
        idx = np.minimum(np.searchsorted(key, k), len(key) - 1)
        return idx, key[idx] == k

    rows = np.flatnonzero(np.isin(tracks.frame_index, last))  # [C0] rows at a last frame
    need = t_total if need is None else need
    target = np.empty(len(rows), bool)  # [C0] seen in its window's first need frames
    for c in range(0, len(rows), _CHUNK):  # in chunks: a few [C0] int64 arrays at once are big
        first = key[rows[c : c + _CHUNK]] - anchor  # [c] the same agent at its scene's first frame
        row0, seen0 = find(first)
        row_end, seen_end = find(first + need - 1)
        target[c : c + _CHUNK] = seen0 & seen_end & (row_end - row0 == need - 1)
    rows = rows[~target]  # [C]
    rows = rows[np.argsort(tracks.frame_index[rows], kind="stable")]  # by scene, agents by id
    first = key[rows] - anchor  # [C]
    # gathered in chunks straight into float32: the whole [C, T_h] gather at once, with its
    # int64 rows and a float64 NaN fill, tripled the reader's peak memory on big files
    offsets = span + np.arange(t_hist)  # [T_h]
    if backwards:
        offsets = offsets[::-1]  # the reversed window's order: its first frame is the last seen
    hist = np.empty((len(rows), t_hist, 2), np.float32)  # [C, T_h, 2]
    for c in range(0, len(rows), _CHUNK):
        idx, seen = find(first[c : c + _CHUNK, None] + offsets)  # [c, T_h]
        np.take(tracks.xy, idx, axis=0, out=hist[c : c + _CHUNK])
        hist[c : c + _CHUNK][~seen] = np.nan
    frame = tracks.frame_index[rows]  # [C] last observed frame of each
    a = np.searchsorted(frame, last)  # [S]
    b = np.searchsorted(frame, last, side="right")  # [S]
    return [hist[i:j] if j > i else empty for i, j in zip(a, b, strict=True)]


def resample_tracks(tracks: Tracks, factor: float, step: float | None = None) -> Tracks:
    """The tracks as if annotated every ``factor`` frame steps: frames ``f_0 + j * factor *
    step`` (``step`` the file's frame step, ``frame_step(tracks.frames)``, computed here unless
    the caller has it), each agent's position linearly interpolated between its two annotated
    rows around each such frame. An agent has no row at a frame before its first row, after
    its last, or inside a jump of more than one frame step in its own rows (a gap is not
    bridged). ``factor`` 1 returns ``tracks`` itself."""
    if factor == 1.0:
        return tracks
    if step is None:
        step = frame_step(tracks.frames)
    if step <= 0:
        return tracks
    span = float(tracks.frames[-1] - tracks.frames[0])
    # a frame "on" a grid point: within a millionth of a step, or within float64's rounding at
    # the frames' magnitude (Unix-time frame numbers: 1.7e9 s is rounded to 2.4e-7 already)
    largest = float(np.abs(tracks.frames).max())
    tol = max(step * 1e-6, 64 * float(np.spacing(largest)))
    origin = float(tracks.frames[0])
    grid = _grid(span, step * factor, tol)  # [G] grid frames, counted from ``origin``
    time = (tracks.frames - origin)[tracks.frame_index]  # [R] each row's frame, from ``origin``
    cuts = np.flatnonzero(np.diff(tracks.agent_index)) + 1  # [A'-1] where a new agent begins
    bounds = np.concatenate([[0], cuts, [tracks.num_rows]])
    g_parts, a_parts, xy_parts = [], [], []
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        t = time[a:b]  # [r] this agent's frames, increasing
        lo = np.searchsorted(grid, t[0] - tol, side="left")
        hi = np.searchsorted(grid, t[-1] + tol, side="right")
        g = np.arange(lo, hi)  # [g] grid frames inside its span
        if len(g) == 0:
            continue
        # the row at or before each grid frame; a row within ``tol`` after it counts as at it
        i = np.clip(np.searchsorted(t, grid[g] + tol, side="right") - 1, 0, len(t) - 1)  # [g]
        j = np.minimum(i + 1, len(t) - 1)  # [g] row after
        span = t[j] - t[i]  # [g]
        exact = np.abs(grid[g] - t[i]) <= tol  # [g] on an annotated frame
        keep = exact | (span <= step * 1.5)  # [g] no gap bridged
        w = np.where(span > 0, (grid[g] - t[i]) / np.where(span > 0, span, 1), 0.0)  # [g]
        w = np.where(exact, 0.0, w)[:, None]  # [g, 1]
        xy = (1 - w) * tracks.xy[a + i] + w * tracks.xy[a + j]  # [g, 2]
        g_parts.append(g[keep])
        a_parts.append(np.full(int(keep.sum()), tracks.agent_index[a]))
        xy_parts.append(xy[keep].astype(np.float32))
    if not g_parts:
        raise DataError(f"no agent spans two frames {factor:g} steps apart", tracks.path)
    f_idx = np.concatenate(g_parts)  # [R'] grid index per new row (sorted within agents)
    a_idx = np.concatenate(a_parts)  # [R'] agent index per new row (non-decreasing)
    used = np.unique(f_idx)  # [F'] grid frames that hold a row
    frame_index = np.searchsorted(used, f_idx).astype(tracks.frame_index.dtype)
    frames = origin + grid[used]  # [F'] each a rounded sum: a few units of float64's spacing off
    noise = LABEL_ULPS * float(np.spacing(np.abs(frames).max()))
    return Tracks(tracks.path, frames, tracks.agents, frame_index,
                  a_idx.astype(tracks.agent_index.dtype), np.concatenate(xy_parts),
                  tracks.agent_type, tracks.frame_name, noise, tracks.frame_origin)  # fmt: skip


def frame_step(frames: np.ndarray) -> float:
    """A file's frame step (0 with fewer than two frames): its most common jump between
    unique frames [F], refined as the whole span over its number of such steps, since the
    most common jump alone is off by float64's rounding on large frame numbers (Unix times:
    0.0999999 for 0.1), and a grid built from it drifts off the rows over thousands of
    steps."""
    _, step = _missing_frames(frames)
    if step <= 0:
        return 0.0
    span = float(frames[-1] - frames[0])
    return span / max(float(np.rint(span / step)), 1.0)


def _grid(span: float, every: float, tol: float) -> np.ndarray:
    """[G] the frames ``0, every, 2 * every, ...`` up to ``span`` (plus ``tol``), each one
    product ``j * every``. Counted from the file's first frame rather than laid from it with
    ``np.arange(first, ...)``: numpy takes arange's increment as ``(first + every) - first``,
    which at Unix-time magnitudes is rounded (0.16 became 0.16000009 at 1.5e9 s), and that
    error grew with every step until the grid missed the rows (issue: Unix-second
    timestamps read with ``--time-step 0.4`` lost windows)."""
    return np.arange(int(np.floor((span + tol) / every)) + 1) * every


def _gap_message(where: Path, gap_scenes: int, gap_agents: int, max_missing: int) -> str:
    return (
        f"{where}: {gap_scenes} windows ({gap_agents} agent-windows) span missing frames "
        f"(up to {max_missing} in a row); they are kept as the Social-GAN rule does: pass "
        "--max-gap 0 (ReadOptions.max_gap=0) to leave them out"
    )


def window_scenes(
    tracks: Tracks,
    t_hist: int,
    t_fut: int,
    stride: int = 1,
    max_gap: int | None = None,
    reverse_context: bool = False,
) -> list[Scene]:
    """Cut one file's tracks into scenes by the windowing rule in the module docstring.

    ``max_gap`` and ``reverse_context`` as in ``ReadOptions``; with ``max_gap`` None a
    ``GapWarning`` reports windows that span missing frames. Raises ``DataError`` when the file
    has fewer unique frames than one window needs.
    """
    out = _window(tracks, t_hist, t_fut, stride, max_gap, reverse_context=reverse_context)
    if out.gap_scenes:
        message = _gap_message(tracks.path, out.gap_scenes, out.gap_agents, out.max_missing)
        warnings.warn(message, GapWarning, stacklevel=2)
    return out.scenes


def folder_error(folder: Path, exc: OSError) -> DataError:
    """The error for a folder that exists but cannot be listed (permission denied, ...):
    saying it has no track files would send the user looking for files that are there."""
    return DataError(f"cannot read folder ({exc.strerror or exc}): check its permissions",
                     folder)  # fmt: skip


def folder_entries(folder: Path) -> list[Path]:
    """What ``folder`` holds, sorted by name; ``folder_error`` when it cannot be listed
    (``Path.glob`` answered an unreadable folder with nothing at all)."""
    try:
        return sorted(folder.iterdir())
    except OSError as exc:
        raise folder_error(folder, exc) from None


def name_matches(path: Path, patterns: tuple[str, ...]) -> bool:
    """Whether ``path``'s name matches one of the glob ``patterns``, ignoring case
    (``a.TXT`` matches ``*.txt``)."""
    name = path.name.lower()
    return any(fnmatch.fnmatchcase(name, pat.lower()) for pat in patterns)


def matching_files(folder: Path, patterns: tuple[str, ...]) -> list[Path]:
    """The entries of ``folder`` whose names match ``patterns`` (ignoring case), sorted by
    name; files, broken links and anything else alike."""
    return [p for p in folder_entries(folder) if name_matches(p, patterns)]


def track_files(folder: str | Path, pattern: str | tuple[str, ...] = "*.txt") -> list[Path]:
    """The files matching ``pattern`` (one glob pattern or several, matched ignoring case:
    ``*.txt`` takes ``a.TXT`` too) in ``folder``, sorted by name. Raises ``DataError`` for a
    missing folder, one that cannot be read, a symlink loop or a broken symlink, and a folder
    without such files."""
    folder = Path(folder)
    patterns = (pattern,) if isinstance(pattern, str) else tuple(pattern)
    try:
        if not folder.is_dir():
            if folder.is_symlink():
                raise _link_error(folder)
            raise DataNotFound("no such folder", folder)
        files = []
        for path in matching_files(folder, patterns):
            if path.is_file():
                files.append(path)
            elif path.is_symlink() and not path.exists():
                raise _link_error(path)
    except DataError:  # its own (DataNotFound is an OSError too): passed on as it is
        raise
    except OSError as exc:  # a folder on the way that cannot be searched
        raise folder_error(folder, exc) from None
    if not files:
        raise DataError(f"no {' or '.join(patterns)} files in folder", folder)
    return files


def window_lengths(t_hist: int | None, t_fut: int | None,
                   options: ReadOptions | None) -> tuple[int, int]:  # fmt: skip
    """The (T_h, T_f) a reader cuts: ``t_hist`` / ``t_fut`` where given, else ``options``'
    (8 + 12 without options). ``ConfigError`` where both are given and disagree: the lengths
    are said once, so that a caller passing a dataset's usual lengths cannot override the
    ones its ``ReadOptions`` asked for without a word."""
    asked = options or ReadOptions()
    own = (asked.t_hist, asked.t_fut)
    given = (own[0] if t_hist is None else t_hist, own[1] if t_fut is None else t_fut)
    if options is not None and given != own:
        raise ConfigError(f"windows of {given[0]} + {given[1]} frames asked, but the "
                          f"ReadOptions ask {own[0]} + {own[1]}: give the lengths once "
                          "(ReadOptions(t_hist=..., t_fut=...))")  # fmt: skip
    return given


def read_files(
    files: list[Path],
    t_hist: int | None = None,
    t_fut: int | None = None,
    stride: int = 1,
    scale: float = 1.0,
    with_type: bool = False,
    options: ReadOptions | None = None,
    units: str = "unknown",
    where: Path | None = None,
    steps: dict[Path, tuple[str | None, float]] | None = None,
) -> list[Scene]:
    """Read track files into scenes of ``t_hist + t_fut`` frames (None: ``options``' lengths,
    ``window_lengths``), in the given order. Windows that span missing frames give one
    ``GapWarning`` for all files (naming ``where``, else the first file). ``steps`` (a dict)
    receives each file's header name of its frame column (None: no header) and its frame
    step as recorded (``frame_step``, before any resampling)."""
    t_hist, t_fut = window_lengths(t_hist, t_fut, options)
    options = options or ReadOptions()
    scenes: list[Scene] = []
    gap = [0, 0, 0]  # scenes, agent-windows, largest run of missing frames
    for path in files:
        tracks = read_tracks(path, with_type, options, scale, units)
        step = frame_step(tracks.frames)  # as recorded: for ``steps`` and the resampling
        if steps is not None:
            steps[path] = (tracks.frame_name, step)
        tracks = resample_tracks(tracks, options.time_step, step)
        out = _window(tracks, t_hist, t_fut, stride, options.max_gap, options.partial_future,
                      options.reverse_context)  # fmt: skip
        scenes.extend(out.scenes)
        gap = [gap[0] + out.gap_scenes, gap[1] + out.gap_agents, max(gap[2], out.max_missing)]
    if gap[0]:
        warnings.warn(_gap_message(where or files[0], *gap), GapWarning, stacklevel=2)
    return scenes


def read_folder(
    folder: str | Path,
    t_hist: int | None = None,
    t_fut: int | None = None,
    stride: int = 1,
    scale: float = 1.0,
    with_type: bool = False,
    pattern: str | tuple[str, ...] = "*.txt",
    options: ReadOptions | None = None,
    units: str = "unknown",
    steps: dict[Path, tuple[str | None, float]] | None = None,
) -> list[Scene]:
    """Read every track file in ``folder`` matching ``pattern`` (sorted by name) into scenes
    (the lengths and ``steps`` as ``read_files`` takes them)."""
    folder = Path(folder)
    t_hist, t_fut = window_lengths(t_hist, t_fut, options)
    files = track_files(folder, pattern)
    scenes = read_files(files, t_hist, t_fut, stride, scale, with_type, options, units, folder,
                        steps)  # fmt: skip
    if not scenes:
        raise DataError(
            f"no agent is observed in {t_hist + t_fut} consecutive frames in any file", folder
        )
    return scenes
