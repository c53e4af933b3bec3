"""The answers database: one SQLite file in WAL mode, one row per (rater, scene, panel).

Schema (``SCHEMA``)::

    meta(key PRIMARY KEY, value)            study_id: the study the answers belong to
    raters(rater PRIMARY KEY, kind, created_at, submitted_at)
        kind: 'human' (the page) or 'synthetic' (``survey simulate``)
    answers(rater, scene, panel, social, kinetics, revision, created_at, updated_at,
            PRIMARY KEY (rater, scene, panel))
        social, kinetics: 1..5 (CHECK); revision: 1, +1 for each later change

Every write is validated here (rater id, known scene and panel, ratings integers in 1..5),
runs in one transaction, and is committed (``synchronous=FULL``: on disk, not only handed to
the operating system) before the call returns; a second answer for the same panel updates the
row, never adds one.
"""

from __future__ import annotations

import contextlib
import re
import sqlite3
import threading
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from trajpref.errors import ConfigError, TrajprefError
from trajpref.survey.manifest import CRITERIA, RATING_MAX, RATING_MIN, Study

RATER_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.@-]{0,63}$")
"""Rater ids: what a person types (letters, digits, ``_ . @ -``, at most 64)."""
KINDS = ("human", "synthetic")
"""Who gave an answer."""

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
    PRIMARY KEY (rater, scene, panel)
);
"""
"""The tables (``CREATE ... IF NOT EXISTS``: opening an existing file keeps it)."""


class AnswerError(TrajprefError, ValueError):
    """An answer the store refuses; ``status`` is the HTTP status the server answers with
    (400 malformed, 404 unknown scene or panel, 409 conflict, 422 invalid value)."""

    def __init__(self, message: str, status: int = 422):
        super().__init__(message)
        self.status = status


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def check_rater(rater: Any) -> str:
    if not isinstance(rater, str) or not RATER_RE.match(rater):
        raise AnswerError("rater id: 1-64 letters, digits or '_.@-', starting with a letter "
                          "or digit", 422)  # fmt: skip
    return rater


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


class AnswerStore:
    """The answers of one study. Thread-safe (one connection behind a lock: SQLite writes
    one transaction at a time anyway); several processes may share the file."""

    def __init__(self, path: str | Path, study: Study, create: bool = True):
        self.path = Path(path)
        self.study = study
        self.panels = study.panel_ids()  # scene -> panel letters
        self.total = sum(len(p) for p in self.panels.values())
        if not create and not self.path.is_file():
            raise ConfigError(f"{self.path}: no answers yet (run `trajpref survey serve` or "
                              "`trajpref survey simulate` first)")  # fmt: skip
        self._lock = threading.Lock()
        self.db = sqlite3.connect(self.path, timeout=30, isolation_level=None,
                                  check_same_thread=False)  # fmt: skip
        try:
            mode = self.db.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if mode.lower() != "wal":
                raise ConfigError(f"{self.path}: SQLite could not use WAL mode here ({mode})")
            self.db.execute("PRAGMA synchronous=FULL")
            self.db.execute("PRAGMA foreign_keys=ON")
            self.db.execute("PRAGMA busy_timeout=30000")
            self.db.executescript(SCHEMA)
            self._claim_study()
        except sqlite3.DatabaseError as exc:
            self.db.close()
            raise ConfigError(f"{self.path}: not a usable answers database ({exc})") from None
        except BaseException:
            self.db.close()
            raise

    def _claim_study(self) -> None:
        with self._tx():
            row = self.db.execute("SELECT value FROM meta WHERE key = 'study_id'").fetchone()
            if row is None:
                self.db.execute("INSERT INTO meta VALUES ('study_id', ?)", (self.study.study_id,))
            elif row[0] != self.study.study_id:
                raise ConfigError(f"{self.path}: these answers belong to another study "
                                  f"({row[0]}, this one is {self.study.study_id})")  # fmt: skip

    @contextlib.contextmanager
    def _tx(self) -> Iterator[None]:
        """One IMMEDIATE transaction under the lock: committed on success, else rolled back."""
        with self._lock:
            self.db.execute("BEGIN IMMEDIATE")
            try:
                yield
            except BaseException:
                self.db.execute("ROLLBACK")
                raise
            self.db.execute("COMMIT")

    def close(self) -> None:
        with self._lock:
            self.db.close()

    # ---- writes -------------------------------------------------------------------------
    def check_panel(self, scene: Any, panel: Any) -> None:
        if scene not in self.panels:
            raise AnswerError(f"unknown scene {str(scene)!r:.40}", 404)
        if panel not in self.panels[scene]:
            raise AnswerError(f"scene {scene} has no panel {str(panel)!r:.40}", 404)

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
        all are written or none. Returns the revision of the last one."""
        check_rater(rater)
        if kind not in KINDS:
            raise AnswerError(f"kind must be one of {KINDS}", 422)
        checked = []
        for scene, panel, ratings in answers:
            self.check_panel(scene, panel)
            checked.append((scene, panel, *check_ratings(ratings)))
        now = _now()
        revision = 0
        with self._tx():
            row = self._rater_row(rater, kind, create=True)
            if row is not None and row[1] is not None:
                raise AnswerError(f"rater {rater} has already submitted; answers are final", 409)
            for scene, panel, social, kinetics in checked:
                revision = self.db.execute(
                    """INSERT INTO answers (rater, scene, panel, social, kinetics, revision,
                                            created_at, updated_at)
                       VALUES (?, ?, ?, ?, ?, 1, ?, ?)
                       ON CONFLICT (rater, scene, panel) DO UPDATE SET
                           social = excluded.social, kinetics = excluded.kinetics,
                           revision = answers.revision + 1, updated_at = excluded.updated_at
                       RETURNING revision""",
                    (rater, scene, panel, social, kinetics, now, now),
                ).fetchall()[0][0]
            answered = self._answered(rater)
        return {"revision": revision, "answered": answered, "total": self.total}

    def submit(self, rater: str, kind: str = "human") -> dict[str, Any]:
        """Mark a rater's answers final; 409 while panels are unanswered. Idempotent."""
        check_rater(rater)
        with self._tx():
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
        kinetics}}}, "answered", "total", "submitted"}`` (empty for an unknown rater)."""
        check_rater(rater)
        with self._lock:
            row = self.db.execute("SELECT kind, submitted_at FROM raters WHERE rater = ?",
                                  (rater,)).fetchone()  # fmt: skip
            rows = self.db.execute(
                "SELECT scene, panel, social, kinetics FROM answers WHERE rater = ?", (rater,)
            ).fetchall()
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
        }

    def rows(self) -> list[tuple[str, str, str, str, int, int, bool]]:
        """Every answer of this study: ``(rater, kind, scene, panel, social, kinetics,
        submitted)``."""
        with self._lock:
            rows = self.db.execute(
                """SELECT a.rater, r.kind, a.scene, a.panel, a.social, a.kinetics,
                          r.submitted_at IS NOT NULL
                   FROM answers a JOIN raters r USING (rater)
                   ORDER BY a.rater, a.scene, a.panel"""
            ).fetchall()
        return [(*r[:6], bool(r[6])) for r in rows if r[3] in self.panels.get(r[2], ())]

    def raters(self) -> dict[str, str]:
        """rater -> kind."""
        with self._lock:
            return dict(self.db.execute("SELECT rater, kind FROM raters").fetchall())
