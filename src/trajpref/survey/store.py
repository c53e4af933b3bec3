"""The answers database: one SQLite file (in WAL mode while a writer has it open), one row
per (rater, scene, panel).

Schema (``SCHEMA``)::

    meta(key PRIMARY KEY, value)            study_id: the study the answers belong to
    raters(rater PRIMARY KEY, kind, created_at, submitted_at)
        kind: 'human' (the page) or 'synthetic' (``survey simulate``)
    answers(rater, scene, panel, social, kinetics, revision, created_at, updated_at,
            scene_position, panel_position, PRIMARY KEY (rater, scene, panel))
        social, kinetics: 1..5 (CHECK); revision: 1, +1 for each later change;
        scene_position, panel_position: where the rater was shown the picture when the answer
        was last saved (``Study.positions``: the scene's place in the rater's order, and the
        panel's within the scene, from 1); NULL in a file written before they were recorded
        (2026-12-06), whose server showed every rater the manifest's order: readers give
        such an answer that order's position (``shown_at``); a writer that opens such a file
        adds the two columns (``ALTER TABLE``), its rows kept
    consents(rater, agreed_at, text_hash, PRIMARY KEY (rater, text_hash))
        when a rater agreed to the study's consent text, and a hash of that text
        (``Study.consent_hash``): one row per text agreed to, so that an agreement to an
        earlier text stays recorded (an audit trail); a file without the table (written
        before it) gets it when ``serve`` or ``simulate`` opens it, and a table of the first
        form (``rater PRIMARY KEY``, 2026-12-06 morning) is migrated to this one, rows kept

A study with a consent text (``Study.consent``) takes a human rater's answers only once the
rater has agreed to that very text (``consent``, given the text's hash); otherwise ``save``
refuses with 403.

Rater ids are not case-sensitive: ``Alice`` and ``alice`` are one rater, stored as ``alice``
(an older file's ``Alice`` keeps its spelling and is found under any case).

Every write is validated here (rater id, known scene and panel, ratings integers in 1..5),
runs in one transaction, and is committed (``synchronous=FULL``: on disk, not only handed to
the operating system) before the call returns; a second answer for the same panel updates the
row, never adds one.

A file made elsewhere (answers collected on paper and imported) is checked when it is opened:
the tables have the columns of ``SCHEMA``, every rating is an integer in 1..5, every kind is
``human`` or ``synthetic``, no answer or rater appears twice, and the file belongs to this
study. ``analyze`` opens the file read-only (``readonly=True``): it never writes into it,
and it reads a study in a read-only folder too (see ``AnswerStore._open_readonly``).

A writer (``serve``, ``simulate``) that closes the file cleanly merges the write-ahead log into
it and leaves it in rollback-journal mode: one self-contained file, which a copy, a backup or
a reader in a read-only folder sees whole; the next writer switches it back to WAL. A write
that fails (a full disk, an unwritable ``-wal``, the file deleted or replaced while open) is a
``StoreError`` (503), its transaction rolled back.

The answers are personal data: a new file is created owner-only (0600; SQLite gives its
``-wal`` and ``-shm`` files the same mode), and opening one that other users can read warns.
"""

from __future__ import annotations

import contextlib
import difflib
import errno
import os
import re
import sqlite3
import threading
import warnings
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from trajpref.errors import AnswerError, ConfigError, StoreError, TrajprefWarning
from trajpref.io import atomic_path, write_probe
from trajpref.survey.manifest import CRITERIA, RATING_MAX, RATING_MIN, Study

RATER_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}")
"""Rater ids: what a person types (letters, digits, ``_ . @ -``, at most 64); not
case-sensitive (``check_rater`` gives the lower-case form). Checked with ``fullmatch``
(the whole string: ``re.match`` with ``$`` would let a trailing newline through)."""
FILE_MODE = 0o600
"""The mode of a new answers database (and of SQLite's -wal and -shm beside it): owner only."""
KINDS = ("human", "synthetic")
"""Who gave an answer."""

CONSENTS_TABLE = """CREATE TABLE IF NOT EXISTS consents (
    rater     TEXT NOT NULL REFERENCES raters (rater),
    agreed_at TEXT NOT NULL,
    text_hash TEXT NOT NULL,
    PRIMARY KEY (rater, text_hash)
);"""
"""One row per (rater, consent text agreed to): a new text adds a row, never overwrites."""
SCHEMA = f"""
CREATE TABLE IF NOT EXISTS meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS raters (
    rater        TEXT PRIMARY KEY,
    kind         TEXT NOT NULL CHECK (kind IN ('human', 'synthetic')),
    created_at   TEXT NOT NULL,
    submitted_at TEXT
);
CREATE TABLE IF NOT EXISTS answers (
    rater      TEXT NOT NULL REFERENCES raters (rater),
    scene      TEXT NOT NULL,
    panel      TEXT NOT NULL,
    social     INTEGER NOT NULL CHECK (social BETWEEN {RATING_MIN} AND {RATING_MAX}),
    kinetics   INTEGER NOT NULL CHECK (kinetics BETWEEN {RATING_MIN} AND {RATING_MAX}),
    revision   INTEGER NOT NULL DEFAULT 1,
    created_at TEXT NOT NULL,
    updated_at TEXT NOT NULL,
    scene_position INTEGER CHECK (scene_position >= 1),
    panel_position INTEGER CHECK (panel_position >= 1),
    PRIMARY KEY (rater, scene, panel)
);
{CONSENTS_TABLE}
"""
"""The tables (``CREATE ... IF NOT EXISTS``: opening an existing file keeps it)."""
TABLES = {
    "meta": ("key", "value"),
    "raters": ("rater", "kind", "created_at", "submitted_at"),
    "answers": ("rater", "scene", "panel", "social", "kinetics", "revision", "created_at",
                "updated_at"),
    "consents": ("rater", "agreed_at", "text_hash"),
}  # fmt: skip
"""The columns of each table of ``SCHEMA`` that every file has, checked whenever a file is
opened (``POSITION_COLUMNS`` may be missing: a file written before them)."""
POSITION_COLUMNS = ("scene_position", "panel_position")
"""The columns of ``answers`` that record where the picture was shown (added 2026-12-06)."""


GONE = ("the study folder is gone (deleted, moved or replaced while the server ran); tell "
        "the study's researcher")  # fmt: skip
"""What a rater is told when the answers database is no longer where it was opened."""


def _cannot_open(exc: sqlite3.Error) -> bool:
    """SQLite's SQLITE_CANTOPEN (e.g. a -shm it may not create in a read-only folder)."""
    name = getattr(exc, "sqlite_errorname", None)  # Python >= 3.11
    return name == "SQLITE_CANTOPEN" if name else str(exc) == "unable to open database file"


def _identity(path: Path) -> tuple[int, int] | None:
    """The file's (device, inode), or None when there is no file at ``path``."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _count(n: int, what: str) -> str:
    """``1 answer``, ``3 answers``."""
    return f"{n} {what}{'' if n == 1 else 's'}"


def check_rater(rater: Any) -> str:
    """A valid rater id in its canonical, lower-case form (``Alice`` -> ``alice``): ids are
    not case-sensitive, so that a person who types their id once with a capital and once
    without is one rater, not two."""
    if not isinstance(rater, str) or not RATER_RE.fullmatch(rater):
        raise AnswerError("rater id: 1-64 ASCII letters (A-Z, a-z), digits or '_.@-', starting "
                          "with a letter or digit", 422)  # fmt: skip
    return rater.lower()  # ASCII only (RATER_RE): the same as SQLite's lower()


def case_variants(raters: Any) -> list[list[str]]:
    """Groups of rater ids that differ only by case (``[["Alice", "alice"]]``): possible in
    a file written before ids were made case-insensitive, or imported; each group sorted."""
    groups: dict[str, list[str]] = {}
    for r in raters:
        groups.setdefault(str(r).lower(), []).append(str(r))
    return sorted(sorted(g) for g in groups.values() if len(g) > 1)


def _create_private(path: Path) -> None:
    """Create ``path`` as an empty file of mode ``FILE_MODE`` (SQLite takes an empty file
    as a new database) unless it exists: SQLite itself would create it with the umask's
    mode, 0644 under the usual 022."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE)
    except FileExistsError:
        return  # made meanwhile by another process (or a link): checked like any file
    except OSError as exc:
        if exc.errno in READ_ONLY_ERRNOS:
            raise ConfigError(_read_only_folder(path, exc)) from None
        raise ConfigError(f"{path}: cannot create the answers database "
                          f"({exc.strerror or exc})") from None  # fmt: skip
    try:
        os.fchmod(fd, FILE_MODE)  # whatever the umask took away (e.g. 0277 -> 0400)
    finally:
        os.close(fd)


READ_ONLY_ERRNOS = (errno.EACCES, errno.EPERM, errno.EROFS)
"""What creating or opening a file for writing fails with in a read-only place."""


def _read_only_folder(path: Path, exc: OSError) -> str:
    return (f"{path}: cannot write the answers database: the folder {path.parent} is read-only "
            f"({exc.strerror or exc}); `serve` and `simulate` write the database and SQLite's "
            "-wal and -shm files there: make the folder writable, or give --db a file in a "
            "writable folder (`analyze` and `export` read a read-only folder)")  # fmt: skip


def _why_unwritable(path: Path) -> str | None:
    """Why a writer cannot write ``path`` (its folder or the file read-only), or None. Tries:
    creates (and removes) a temporary file in the folder, opens the file for writing (without
    writing); for the error message of a failed open only (``os.access`` is no help to root,
    whom ``chattr +i`` or a read-only mount still stops)."""
    exc = write_probe(path.parent)
    if exc is not None:
        return _read_only_folder(path, exc) if exc.errno in READ_ONLY_ERRNOS else None
    try:
        os.close(os.open(path, os.O_RDWR))
    except OSError as exc:
        if exc.errno in READ_ONLY_ERRNOS:
            return (f"{path}: cannot write the answers database: the file is read-only "
                    f"({exc.strerror or exc}); make it writable (e.g. `chmod 600 "
                    f"{path}`)")  # fmt: skip
    return None


def private_output(path: str | Path) -> contextlib.AbstractContextManager[Path]:
    """``trajpref.io.atomic_path`` for an owner-only file (``FILE_MODE``, whatever the umask):
    for what holds rater ids (``survey export``'s CSV, ``analyze``'s report of excluded
    raters)."""
    return atomic_path(path, mode=FILE_MODE)


def _warn_if_shared(path: Path) -> None:
    """One warning when other users may read or write the answers database."""
    try:
        mode = path.stat().st_mode & 0o777
    except OSError:
        return
    if mode & 0o077:
        warnings.warn(f"{path}: other users have access to it (mode {mode:o}); the answers "
                      f"are personal data: make it owner-only with `chmod 600 {path}` (its "
                      "-wal and -shm files follow)", TrajprefWarning, stacklevel=3)  # fmt: skip


def check_ratings(ratings: Any) -> tuple[int, int]:
    """``{"social": 1..5, "kinetics": 1..5}`` (integers, nothing else) -> (social, kinetics)."""
    names = [c for c, _, _ in CRITERIA]
    if not isinstance(ratings, dict):
        raise AnswerError(f"the body must be a JSON object with {' and '.join(names)}", 422)
    extra = sorted(set(ratings) - set(names))
    missing = [n for n in names if n not in ratings]
    if extra or missing:
        what = (f"unknown fields {extra}" if extra else "") + (
            f"{'; ' if extra else ''}missing {missing}" if missing else "")  # fmt: skip
        raise AnswerError(f"ratings: {what}", 422)
    out = []
    for n in names:
        v = ratings[n]
        if type(v) is not int or not RATING_MIN <= v <= RATING_MAX:
            raise AnswerError(f"{n}: must be an integer from {RATING_MIN} to {RATING_MAX}, "
                              f"got {v!r:.20}", 422)  # fmt: skip
        out.append(v)
    return out[0], out[1]


def check_agreement(body: Any) -> str:
    """``{"agree": true, "text_hash": "..."}`` (the body of ``POST .../consent``, nothing
    else) -> the hash of the consent text the page showed."""
    if not isinstance(body, dict):
        raise AnswerError('the body must be a JSON object {"agree": true, "text_hash": ...}',
                          422)  # fmt: skip
    extra = sorted(set(body) - {"agree", "text_hash"})
    if extra:
        raise AnswerError(f"agreement: unknown fields {extra}", 422)
    if body.get("agree") is not True:
        raise AnswerError('agreement: "agree" must be true', 422)
    if not isinstance(body.get("text_hash"), str):
        raise AnswerError('agreement: "text_hash" must be the hash of the consent text shown '
                          "(the study's consent_hash)", 422)  # fmt: skip
    return body["text_hash"]


class AnswerStore:
    """The answers of one study. Thread-safe (one connection behind a lock: SQLite writes
    one transaction at a time anyway); several processes may share the file.

    ``readonly=False`` (``serve``, ``simulate``) creates the file when needed, in WAL mode, and
    claims it for ``study``; ``readonly=True`` (``analyze``) needs an existing file and opens
    it read-only: no schema, no claim, nothing written. Either way a file that is not an
    answers database of this study is a ``ConfigError`` naming the file and the problem."""

    def __init__(self, path: str | Path, study: Study, readonly: bool = False):
        self.path = Path(path)
        self.study = study
        self.readonly = readonly
        self.panels = study.panel_ids()  # scene -> panel letters
        self.total = sum(len(p) for p in self.panels.values())
        if self.path.is_dir():
            raise ConfigError(f"{self.path}: is a folder, not an answers database file")
        if readonly and not self.path.is_file():
            raise ConfigError(f"{self.path}: no answers yet (run `trajpref survey serve` or "
                              "`trajpref survey simulate` first)")  # fmt: skip
        if not readonly and not self.path.parent.is_dir():
            raise ConfigError(f"{self.path}: cannot create the answers database: there is no "
                              f"folder {self.path.parent}")  # fmt: skip
        self._lock = threading.Lock()
        self._closed = False
        if not readonly:
            if self.path.exists():
                _warn_if_shared(self.path)
            else:
                _create_private(self.path)
        self._identity = _identity(self.path)  # a write checks that the file is still there
        try:
            if readonly:
                self.db = self._open_readonly()
            else:
                self.db = sqlite3.connect(self.path, timeout=30, isolation_level=None,
                                          check_same_thread=False)  # fmt: skip
        except sqlite3.Error as exc:
            raise ConfigError(f"{self.path}: cannot open the answers database ({exc})") from None
        try:
            self.db.execute("PRAGMA busy_timeout=30000")
            # an existing file is checked whole before anything (even its journal mode) changes
            self._check_tables(new_file_ok=not readonly)
            if self._has_table("answers"):
                self._check_values()
                self._check_study()
            if not readonly:
                mode = self.db.execute("PRAGMA journal_mode=WAL").fetchone()[0]
                if mode.lower() != "wal":
                    raise ConfigError(f"{self.path}: SQLite could not use WAL mode here ({mode})")
                self.db.execute("PRAGMA synchronous=FULL")
                self.db.execute("PRAGMA foreign_keys=ON")
                self._migrate_consents()
                self._add_position_columns()
                self.db.executescript(SCHEMA)
                self._check_tables(new_file_ok=False)
                self._check_study(claim=True)
        except sqlite3.Error as exc:
            self.db.close()
            why = None if readonly else _why_unwritable(self.path)
            raise ConfigError(why or f"{self.path}: not a usable answers database ({exc})"
                              ) from None  # fmt: skip
        except BaseException:
            self.db.close()
            raise

    def _connect(self, query: str) -> sqlite3.Connection:
        """A connection to the file's URI with ``query`` (a URI, so that SQLite itself refuses
        any write), tried with one read."""
        db = sqlite3.connect(f"{self.path.resolve().as_uri()}?{query}", uri=True, timeout=30,
                             isolation_level=None, check_same_thread=False)  # fmt: skip
        try:
            db.execute("SELECT count(*) FROM sqlite_master").fetchone()
        except BaseException:
            db.close()
            raise
        return db

    def _open_readonly(self) -> sqlite3.Connection:
        """``mode=ro``; in a folder this process cannot write, where SQLite cannot create the
        ``-shm`` that reading a WAL-mode file needs, the file as it is (``immutable=1``), but
        only when no ``-wal``, ``-shm`` or ``-journal`` is beside it: a clean stop removes
        them, and a writer needs one of them while it writes (a server run by another user,
        or through another mount, keeps its ``-wal`` and ``-shm`` open), so nothing changes
        the file while it is read. Otherwise (a server writing, or killed with its answers
        still in the ``-wal``): a ConfigError that says how to read them."""
        try:
            return self._connect("mode=ro")
        except sqlite3.OperationalError as exc:
            if not _cannot_open(exc) or not self.path.is_file():
                raise
        beside = [Path(f"{self.path}-{end}") for end in ("wal", "shm", "journal")]
        present = [p.name for p in beside if p.exists()]
        if present:
            raise ConfigError(
                f"{self.path}: cannot be read in place: the folder {self.path.parent} is "
                f"read-only here and {' and '.join(present)} beside it say that a server is "
                "writing it or was killed with answers not yet in the file, which SQLite reads "
                f"only with an {self.path.name}-shm it may create: stop the server, or copy the "
                "study folder (all the answers.sqlite* files together) somewhere writable and "
                "read the copy, or make the folder writable"
            )
        return self._connect("mode=ro&immutable=1")

    def _check_tables(self, new_file_ok: bool) -> None:
        """The tables ``answers`` and ``raters`` (and ``meta`` when present) exist with the
        columns of ``SCHEMA``. ``new_file_ok``: a file without any table passes (the schema is
        written next); a file of other tables never does, so that nothing is added to it."""
        names = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master "
                                               "WHERE type = 'table'")}  # fmt: skip
        if not names and new_file_ok:
            return
        missing = [t for t in ("answers", "raters") if t not in names]
        if missing:
            held = f"; it holds {', '.join(sorted(names))}" if names else "; it holds no table"
            raise ConfigError(f"{self.path}: not an answers database (no {' and '.join(missing)} "
                              f"table{'s' if len(missing) > 1 else ''}{held})")  # fmt: skip
        for table, columns in TABLES.items():
            if table not in names:
                continue
            have = [r[1] for r in self.db.execute(f"PRAGMA table_info({table})")]
            lacking = [c for c in columns if c not in have]
            if lacking:
                raise ConfigError(
                    f"{self.path}: table {table} has no column{'s' if len(lacking) > 1 else ''} "
                    f"{', '.join(lacking)} (it has {', '.join(have)}; the schema is in "
                    "docs/survey.md)"
                )

    def _migrate_consents(self) -> None:
        """A ``consents`` table of the first form (``rater PRIMARY KEY``: one agreement per
        rater, overwritten when the text changed) becomes one of ``CONSENTS_TABLE`` (one row
        per rater and text), its rows kept; in one transaction, so that a file is either
        migrated or not. Any other table (of this form, or made elsewhere) is left alone."""
        if self._consents_key() != ["rater"]:
            return  # checked first: no write lock for a file that needs nothing
        self.db.execute("BEGIN IMMEDIATE")
        try:
            if self._consents_key() == ["rater"]:  # not migrated meanwhile by another process
                self.db.execute("ALTER TABLE consents RENAME TO consents_first")
                self.db.execute(CONSENTS_TABLE)
                self.db.execute("INSERT INTO consents (rater, agreed_at, text_hash) SELECT "
                                "rater, agreed_at, text_hash FROM consents_first")  # fmt: skip
                self.db.execute("DROP TABLE consents_first")
        except BaseException:
            self.db.execute("ROLLBACK")
            raise
        self.db.execute("COMMIT")

    def _position_columns(self) -> bool:
        """The ``answers`` table has ``POSITION_COLUMNS`` (a file written before 2026-12-06
        has not)."""
        have = {r[1] for r in self.db.execute("PRAGMA table_info(answers)")}
        return all(c in have for c in POSITION_COLUMNS)

    def _add_position_columns(self) -> None:
        """An ``answers`` table without ``POSITION_COLUMNS`` (written before they were
        recorded) gets them, NULL in its rows (``shown_at`` gives those answers the manifest
        order's positions); in one transaction. Nothing for a new file (``SCHEMA`` has them)."""
        if not self._has_table("answers") or self._position_columns():
            return
        self.db.execute("BEGIN IMMEDIATE")
        try:
            have = {r[1] for r in self.db.execute("PRAGMA table_info(answers)")}
            for column in POSITION_COLUMNS:
                if column not in have:  # not added meanwhile by another process
                    self.db.execute(f"ALTER TABLE answers ADD COLUMN {column} INTEGER "
                                    f"CHECK ({column} >= 1)")  # fmt: skip
        except BaseException:
            self.db.execute("ROLLBACK")
            raise
        self.db.execute("COMMIT")

    def _consents_key(self) -> list[str]:
        """The primary key columns of the ``consents`` table, in order ([] without one)."""
        rows = self.db.execute("PRAGMA table_info(consents)").fetchall()
        return [r[1] for r in sorted(rows, key=lambda r: r[5]) if r[5]]

    def _check_values(self) -> None:
        """Ratings are integers in 1..5, kinds ``human`` or ``synthetic``, and no answer or
        rater appears twice (a file made elsewhere may lack the schema's constraints)."""
        names = [c for c, _, _ in CRITERIA]
        valid = " AND ".join(f"typeof({c}) = 'integer' AND {c} BETWEEN {RATING_MIN} AND "
                             f"{RATING_MAX}" for c in names)  # fmt: skip
        n, r = self._first(f"SELECT rater, scene, panel, {', '.join(names)} FROM answers "
                           f"WHERE NOT ({valid})")  # fmt: skip
        if n:
            ratings = ", ".join(f"{c} {v!r:.20}" for c, v in zip(names, r[3:], strict=True))
            raise ConfigError(
                f"{self.path}: {_count(n, 'answer')} with ratings that are not integers from "
                f"{RATING_MIN} to {RATING_MAX}, the first: rater {r[0]!r:.40}, scene "
                f"{r[1]!r:.40}, panel {r[2]!r:.40}, {ratings} (text from a CSV import? import "
                "into tables made from the schema in docs/survey.md: their INTEGER columns "
                "convert it)"
            )
        kinds = [f"'{k}'" for k in KINDS]
        n, r = self._first(f"SELECT rater, kind FROM raters WHERE kind IS NULL OR kind NOT IN "
                           f"({', '.join(kinds)})")  # fmt: skip
        if n:
            raise ConfigError(f"{self.path}: {_count(n, 'rater')} of a kind other than "
                              f"{' or '.join(kinds)}, the first: {r[0]!r:.40} "
                              f"({r[1]!r:.20})")  # fmt: skip
        n, r = self._first("SELECT rater, scene, panel FROM answers "
                           "GROUP BY rater, scene, panel HAVING count(*) > 1")  # fmt: skip
        if n:
            raise ConfigError(f"{self.path}: {_count(n, 'panel')} answered more than once by "
                              f"the same rater, the first: rater {r[0]!r:.40}, scene "
                              f"{r[1]!r:.40}, panel {r[2]!r:.40}")  # fmt: skip
        if self._position_columns():
            bad = " OR ".join(f"NOT ({c} IS NULL OR (typeof({c}) = 'integer' AND {c} >= 1))"
                              for c in POSITION_COLUMNS)  # fmt: skip
            n, r = self._first(f"SELECT rater, scene, panel FROM answers WHERE {bad}")
            if n:
                raise ConfigError(f"{self.path}: {_count(n, 'answer')} with a scene_position or "
                                  "panel_position that is not an integer >= 1 (or empty), the "
                                  f"first: rater {r[0]!r:.40}, scene {r[1]!r:.40}, panel "
                                  f"{r[2]!r:.40}")  # fmt: skip
        n, r = self._first("SELECT rater FROM raters GROUP BY rater HAVING count(*) > 1")
        if n:
            raise ConfigError(f"{self.path}: {_count(n, 'rater id')} in more than one row of "
                              f"raters, the first: {r[0]!r:.40}")  # fmt: skip

    def _first(self, query: str) -> tuple[int, tuple | None]:
        """How many rows ``query`` returns, and the first."""
        rows = self.db.execute(query).fetchall()
        return len(rows), (rows[0] if rows else None)

    def _check_study(self, claim: bool = False) -> None:
        """The file's ``meta.study_id`` is this study's. ``claim`` (a writer, once the schema
        is written): a file without one is claimed for this study. A file written before the
        id covered the data and the scores holds the structure-only
        ``Study.legacy_study_id``: it is accepted when that matches, with a warning (when
        checked, not again when claimed) that it cannot tell this study from one of the same
        structure (it is not rewritten: it may be another such study's)."""
        query = "SELECT value FROM meta WHERE key = 'study_id'"
        if claim:
            with self._tx():
                row = self.db.execute(query).fetchone()
                if row is None:
                    self.db.execute("INSERT INTO meta VALUES ('study_id', ?)",
                                    (self.study.study_id,))  # fmt: skip
            if row is not None and row[0] == self.study.legacy_study_id:
                return  # checked (and warned of) before
        else:
            row = self.db.execute(query).fetchone() if self._has_table("meta") else None
        if row is None or row[0] == self.study.study_id:
            return
        if row[0] != self.study.legacy_study_id:
            raise ConfigError(f"{self.path}: these answers belong to another study ({row[0]}, "
                              f"this one is {self.study.study_id})")  # fmt: skip
        warnings.warn(f"{self.path}: an older answers database: its study id ({row[0]}) covers "
                      "only the scene, panel and method structure, which this study shares; it "
                      "cannot tell this study from another of that structure built from other "
                      "data or models", TrajprefWarning, stacklevel=3)  # fmt: skip

    @contextlib.contextmanager
    def _tx(self, what: str | None = None) -> Iterator[None]:
        """One IMMEDIATE transaction under the lock: committed on success, else rolled back
        (also when the COMMIT itself fails: a transaction left open would refuse every later
        one). ``what`` (``"the answer"``): a write for a rater, done only while the file is
        still the one opened (``StoreError`` otherwise), and any SQLite error is a
        ``StoreError`` ("the answer was not saved: disk I/O error")."""
        with self._lock:
            if what is not None:
                self._check_present(f"{what} was not saved")
            try:
                self.db.execute("BEGIN IMMEDIATE")
                try:
                    yield
                    self.db.execute("COMMIT")
                except BaseException:
                    if self.db.in_transaction:
                        with contextlib.suppress(sqlite3.Error):
                            self.db.execute("ROLLBACK")
                    raise
            except sqlite3.Error as exc:
                if what is None:
                    raise
                message = f"{what} was not saved: {exc}"
                raise StoreError(message, f"{self.path}: {message}") from exc

    def _check_present(self, failed: str) -> None:
        """``StoreError`` (``failed``: "the answer was not saved") when the file at ``path``
        is gone or another one (the study folder deleted, moved or replaced while the server
        runs): SQLite would go on writing into the open, unlinked file, and every answer would
        be lost."""
        if self._identity is None or _identity(self.path) != self._identity:
            raise StoreError(f"{failed}: {GONE}",
                             f"{self.path}: the answers database is gone (its folder was "
                             f"deleted, moved or replaced while serving): {failed}; stop the "
                             "server, put the study folder back and serve it again")  # fmt: skip

    def close(self) -> None:
        """Close the file (again: nothing). A writer first merges the write-ahead log into the
        file and leaves it in rollback-journal mode (``journal_mode=DELETE``), so that the file
        alone holds every answer and a reader needs no ``-shm`` (a read-only folder); when
        another connection has the file open, it stays in WAL mode (the last one to close
        merges the log)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if not self.readonly and _identity(self.path) == self._identity:
                with contextlib.suppress(sqlite3.Error):
                    self.db.execute("PRAGMA busy_timeout=0")  # another connection: no wait
                    self.db.execute("PRAGMA journal_mode=DELETE").fetchall()
            self.db.close()

    # ---- writes -------------------------------------------------------------------------
    def check_panel(self, scene: Any, panel: Any) -> None:
        if scene not in self.panels:
            raise AnswerError(f"unknown scene {str(scene)!r:.40}", 404)
        if panel not in self.panels[scene]:
            raise AnswerError(f"scene {scene} has no panel {str(panel)!r:.40}", 404)

    def _stored_id(self, rater: str) -> str:
        """The id under which the canonical (lower-case) ``rater`` is stored: itself, or the
        one id of an older file that differs from it only by case (``Alice``). Several such
        ids and none of them lower case: ambiguous, 409. Call under the lock."""
        ids = [r[0] for r in self.db.execute("SELECT rater FROM raters WHERE lower(rater) = ?",
                                             (rater,))]  # fmt: skip
        if not ids or rater in ids:
            return rater
        if len(ids) == 1:
            return ids[0]
        raise AnswerError(f"rater id {rater} matches {len(ids)} raters that differ only by "
                          f"case ({', '.join(sorted(ids))}); ask the study's researcher "
                          "which is yours", 409)  # fmt: skip

    def _rater_row(self, rater: str, kind: str, create: bool) -> tuple[str, str | None] | None:
        row = self.db.execute("SELECT kind, submitted_at FROM raters WHERE rater = ?",
                              (rater,)).fetchone()  # fmt: skip
        if row is None and create:
            self.db.execute("INSERT INTO raters (rater, kind, created_at) VALUES (?, ?, ?)",
                            (rater, kind, _now()))  # fmt: skip
            return kind, None
        if row is not None and row[0] != kind:
            raise AnswerError(f"rater id {rater} is taken by a {row[0]} rater; choose another",
                              409)  # fmt: skip
        return row

    def save(self, rater: str, scene: str, panel: str, ratings: Any,
             kind: str = "human") -> dict[str, int]:  # fmt: skip
        """Insert or update one answer; returns ``{"revision", "answered", "total"}`` once
        it is committed. Raises ``AnswerError`` (and writes nothing) for a bad rater id, an
        unknown scene or panel, bad ratings, or a rater who has already submitted."""
        return self.save_many(rater, [(scene, panel, ratings)], kind)

    def save_many(self, rater: str, answers: list[tuple[str, str, Any]],
                  kind: str = "human") -> dict[str, int]:  # fmt: skip
        """``save`` for several ``(scene, panel, ratings)`` of one rater, in one transaction:
        all are written or none. Returns the revision of the last one. Each answer is stored
        with the place where this rater is shown its picture (``Study.positions``: the
        server computes it, the page does not send it)."""
        rater = check_rater(rater)
        if kind not in KINDS:
            raise AnswerError(f"kind must be one of {KINDS}", 422)
        checked = []
        shown = self.study.positions(rater)  # where this rater sees each picture
        for scene, panel, ratings in answers:
            self.check_panel(scene, panel)
            checked.append((scene, panel, *check_ratings(ratings), *shown[(scene, panel)][:2]))
        now = _now()
        revision = 0
        with self._tx("the answer" if len(checked) == 1 else "the answers"):
            rater = self._stored_id(rater)
            row = self._rater_row(rater, kind, create=True)
            if row is not None and row[1] is not None:
                raise AnswerError(f"rater {rater} has already submitted; answers are final", 409)
            if kind == "human" and self.study.consent and self._agreed(rater) is None:
                raise AnswerError(f"rater {rater} has not agreed to the study's consent text: "
                                  "agree first (POST /api/raters/ID/consent)", 403)  # fmt: skip
            for scene, panel, social, kinetics, scene_pos, panel_pos in checked:
                revision = self.db.execute(
                    """INSERT INTO answers (rater, scene, panel, social, kinetics, revision,
                                            created_at, updated_at, scene_position,
                                            panel_position)
                       VALUES (?, ?, ?, ?, ?, 1, ?, ?, ?, ?)
                       ON CONFLICT (rater, scene, panel) DO UPDATE SET
                           social = excluded.social, kinetics = excluded.kinetics,
                           revision = answers.revision + 1, updated_at = excluded.updated_at,
                           scene_position = excluded.scene_position,
                           panel_position = excluded.panel_position
                       RETURNING revision""",
                    (rater, scene, panel, social, kinetics, now, now, scene_pos, panel_pos),
                ).fetchall()[0][0]
            answered = self._answered(rater)
        return {"revision": revision, "answered": answered, "total": self.total}

    def _agreed(self, rater: str) -> str | None:
        """When ``rater`` (as stored) agreed to this study's consent text (the same text:
        ``Study.consent_hash``), or None. Call under the lock."""
        if not self._has_table("consents"):
            return None
        row = self.db.execute("SELECT agreed_at FROM consents WHERE rater = ? AND text_hash = ?",
                              (rater, self.study.consent_hash)).fetchone()  # fmt: skip
        return row[0] if row else None

    def _has_table(self, name: str) -> bool:
        return self.db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?",
                               (name,)).fetchone() is not None  # fmt: skip

    def consent(self, rater: str, text_hash: str) -> dict[str, Any]:
        """Record that a human ``rater`` agreed, now, to the consent text whose hash the page
        showed (``text_hash``): kept when already agreed to this text; a new row when the
        rater agreed to an earlier text, which stays recorded. Returns ``{"consented": True,
        "agreed_at"}``. 404 when the study has no consent text; 409 (nothing written) when
        ``text_hash`` is not the current text's (``Study.consent_hash``): the page showed
        another text, so the record could not name the text the rater read."""
        rater = check_rater(rater)
        if not self.study.consent:
            raise AnswerError("this study has no consent text", 404)
        if text_hash != self.study.consent_hash:
            raise AnswerError("the consent text has changed since the page was loaded: reload "
                              "the page and read it again", 409)  # fmt: skip
        with self._tx("the agreement"):
            rater = self._stored_id(rater)
            self._rater_row(rater, "human", create=True)
            agreed = self._agreed(rater)
            if agreed is None:  # no row for (rater, this text): the insert adds one
                agreed = _now()
                self.db.execute("INSERT INTO consents (rater, agreed_at, text_hash) "
                                "VALUES (?, ?, ?)", (rater, agreed, text_hash))  # fmt: skip
        return {"consented": True, "agreed_at": agreed}

    def submit(self, rater: str, kind: str = "human") -> dict[str, Any]:
        """Mark a rater's answers final; 409 while panels are unanswered. Idempotent."""
        rater = check_rater(rater)
        with self._tx("the submission"):
            rater = self._stored_id(rater)
            row = self._rater_row(rater, kind, create=False)
            answered = self._answered(rater) if row is not None else 0
            if answered < self.total:
                raise AnswerError(f"{self.total - answered} of {self.total} panels are still "
                                  "unanswered", 409)  # fmt: skip
            if row[1] is None:
                self.db.execute("UPDATE raters SET submitted_at = ? WHERE rater = ?",
                                (_now(), rater))  # fmt: skip
        return {"submitted": True, "answered": answered, "total": self.total}

    # ---- reads --------------------------------------------------------------------------
    def _answered(self, rater: str) -> int:
        """Answers of ``rater`` that match a panel of this study."""
        rows = self.db.execute("SELECT scene, panel FROM answers WHERE rater = ?", (rater,))
        return sum(1 for s, p in rows if p in self.panels.get(s, ()))

    def progress(self, rater: str) -> dict[str, Any]:
        """A rater's answers so far: ``{"rater", "answers": {scene: {panel: {social,
        kinetics}}}, "answered", "total", "submitted", "consent_required", "consented",
        "order"}`` (empty for an unknown rater); ``rater`` is the id as stored (lower case, or
        an older file's spelling); ``consent_required``: the study has a consent text,
        ``consented``: the rater agreed to it; ``order``: the scenes and their panels in the
        order this rater sees them, ``[{"scene": id, "panels": [letter, ...]}, ...]``
        (``Study.rater_order``: the page shows them so)."""
        rater = check_rater(rater)
        order = [{"scene": s.id, "panels": [p.id for p in panels]}
                 for s, panels in self.study.rater_order(rater)]  # fmt: skip
        failed = "the answers could not be read"
        with self._lock:
            if not self.readonly:
                self._check_present(failed)
            try:
                rater = self._stored_id(rater)
                row = self.db.execute("SELECT kind, submitted_at FROM raters WHERE rater = ?",
                                      (rater,)).fetchone()  # fmt: skip
                rows = self.db.execute(
                    "SELECT scene, panel, social, kinetics FROM answers WHERE rater = ?", (rater,)
                ).fetchall()
                agreed = self._agreed(rater) if self.study.consent else None
            except sqlite3.Error as exc:
                raise StoreError(f"{failed}: {exc}", f"{self.path}: {failed}: {exc}") from exc
        answers: dict[str, dict[str, dict[str, int]]] = {}
        for scene, panel, social, kinetics in rows:
            if panel in self.panels.get(scene, ()):
                answers.setdefault(scene, {})[panel] = {"social": social, "kinetics": kinetics}
        return {
            "rater": rater,
            "kind": row[0] if row else None,
            "answers": answers,
            "answered": sum(len(v) for v in answers.values()),
            "total": self.total,
            "submitted": bool(row and row[1]),
            "consent_required": bool(self.study.consent),
            "consented": agreed is not None,
            "order": order,
        }

    def _read(self, query: str, params: tuple = ()) -> list[tuple]:
        """``query``'s rows; an SQLite error (a file locked for too long) is a ConfigError."""
        try:
            with self._lock:
                return self.db.execute(query, params).fetchall()
        except sqlite3.Error as exc:
            raise ConfigError(f"{self.path}: cannot read the answers ({exc})") from None

    def rows(self) -> list[tuple[str, str, str, str, int, int, bool]]:
        """Every answer of this study: ``(rater, kind, scene, panel, social, kinetics,
        submitted)``. What it leaves out, :meth:`ignored` counts."""
        rows = self._read(
            """SELECT a.rater, r.kind, a.scene, a.panel, a.social, a.kinetics,
                      r.submitted_at IS NOT NULL
               FROM answers a JOIN raters r USING (rater)
               ORDER BY a.rater, a.scene, a.panel"""
        )
        return [(*r[:6], bool(r[6])) for r in rows if r[3] in self.panels.get(r[2], ())]

    def _position_select(self) -> str:
        """The SELECT list of the stored positions: ``NULL, NULL`` for a file without them."""
        with self._lock:
            stored = self._position_columns()
        return ", ".join(f"a.{c}" for c in POSITION_COLUMNS) if stored else "NULL, NULL"

    def shown_at(self, rows: list[tuple[str, str, str, Any, Any]]
                 ) -> list[tuple[int, int, int]]:  # fmt: skip
        """Where each ``(rater, scene, panel, scene_position, panel_position)`` (as stored) was
        shown: ``(scene position, panel position, position among all the panels)``, from 1.
        The stored positions when the answer has them (the position among all the panels
        counted in that rater's order, ``Study.rater_order``); else (NULL: a file written
        before they were recorded, when every rater saw the manifest's order) the manifest
        order's."""
        fixed = self.study.positions()
        orders: dict[str, dict[int, int]] = {}  # rater -> scene position -> panels before it
        out = []
        for rater, scene, panel, scene_pos, panel_pos in rows:
            if scene_pos is None or panel_pos is None:
                out.append(fixed[(scene, panel)])
                continue
            if rater not in orders:
                before, start = 0, {}
                for i, (_, panels) in enumerate(self.study.rater_order(rater), 1):
                    start[i] = before
                    before += len(panels)
                orders[rater] = start
            start = orders[rater].get(scene_pos, 0)
            out.append((scene_pos, panel_pos, start + panel_pos))
        return out

    def positions(self) -> dict[tuple[str, str, str], tuple[int, int, int]]:
        """(rater, scene, panel) -> where the rater was shown that picture (``shown_at``), for
        every answer :meth:`rows` gives (``analyze``'s position-effect check)."""
        rows = self._read(f"SELECT a.rater, a.scene, a.panel, {self._position_select()} "
                          "FROM answers a JOIN raters r USING (rater)")  # fmt: skip
        rows = [r for r in rows if r[2] in self.panels.get(r[1], ())]
        return {r[:3]: w for r, w in zip(rows, self.shown_at(rows), strict=True)}

    def ignored(self) -> dict[str, int]:
        """The answers in the file that :meth:`rows` leaves out: ``unknown_panels`` (to a
        scene or panel this study does not have), ``unknown_raters`` (to one of its panels,
        from a rater id without a row in ``raters``) and their sum ``answers``."""
        rows = self._read("SELECT a.scene, a.panel, r.rater IS NULL FROM answers a "
                          "LEFT JOIN raters r USING (rater)")  # fmt: skip
        panels = sum(1 for s, p, _ in rows if p not in self.panels.get(s, ()))
        raters = sum(1 for s, p, no_rater in rows if no_rater and p in self.panels.get(s, ()))
        return {"answers": panels + raters, "unknown_panels": panels, "unknown_raters": raters}

    def raters(self) -> dict[str, str]:
        """rater -> kind."""
        return dict(self._read("SELECT rater, kind FROM raters"))

    def records(self) -> list[dict[str, Any]]:
        """Every answer of this study (those :meth:`rows` gives) with its revision and time
        stamps: ``rater``, ``kind``, ``submitted_at``, ``scene``, ``panel``, ``social``,
        ``kinetics``, ``revision``, ``created_at``, ``updated_at``, ``consented_at`` (when the
        rater agreed to this study's consent text; None if not, or without one), and where the
        rater was shown the picture (``shown_at``): ``scene_position``, ``panel_position``,
        ``position`` (``survey export``)."""
        names = ("rater", "kind", "submitted_at", "scene", "panel", "social", "kinetics",
                 "revision", "created_at", "updated_at", "consented_at")  # fmt: skip
        shown = self._position_select()
        with self._lock:
            consents = self.study.consent and self._has_table("consents")
        agreed = ("(SELECT c.agreed_at FROM consents c WHERE c.rater = a.rater AND "
                  "c.text_hash = ?)" if consents else "NULL")  # fmt: skip
        query = f"""SELECT a.rater, r.kind, r.submitted_at, a.scene, a.panel, a.social,
                           a.kinetics, a.revision, a.created_at, a.updated_at, {agreed}, {shown}
                    FROM answers a JOIN raters r USING (rater)
                    ORDER BY a.rater, a.scene, a.panel"""
        rows = self._read(query, (self.study.consent_hash,) if consents else ())
        rows = [r for r in rows if r[4] in self.panels.get(r[3], ())]
        where = self.shown_at([(r[0], r[3], r[4], r[11], r[12]) for r in rows])
        return [{**dict(zip(names, r[:11], strict=True)), "scene_position": w[0],
                 "panel_position": w[1], "position": w[2]}
                for r, w in zip(rows, where, strict=True)]  # fmt: skip

    def find_raters(self, ids: list[str], option: str = "--exclude-rater") -> list[str]:
        """The stored ids of ``ids`` (each as stored, or differing only by case when that
        names one rater), in order, without repeats. A ``ConfigError`` naming ``option``, the
        id, the closest stored ids and this file for an id that names no rater (a typo would
        otherwise exclude nobody) or several."""
        known = sorted(self.raters())
        out: list[str] = []
        for rater in ids:
            if rater in known:
                found = rater
            else:
                same = [k for k in known if k.lower() == rater.lower()]
                if len(same) > 1:
                    raise ConfigError(f"{option} {rater}: {len(same)} raters of {self.path} "
                                      f"differ from it only by case ({', '.join(same)}); give "
                                      "one exactly")  # fmt: skip
                if not same:
                    lower = {k.lower(): k for k in known}
                    close = difflib.get_close_matches(rater.lower(), list(lower), n=1)
                    hint = (f" (did you mean {', '.join(lower[c] for c in close)}?)" if close
                            else "")  # fmt: skip
                    listed = ", ".join(known[:8]) + (f", ... ({len(known)} in all)"
                                                     if len(known) > 8 else "")  # fmt: skip
                    raise ConfigError(f"{option} {rater}: no such rater in {self.path}{hint}; "
                                      f"its raters: {listed or 'none'}")  # fmt: skip
                found = same[0]
            if found not in out:
                out.append(found)
        return out
