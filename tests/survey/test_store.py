"""The answers database: WAL, upsert without duplicates, validation, durability, submission."""

import contextlib
import csv
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from starlette.testclient import TestClient
from survey.helpers import CONSENT, OK, _fixed, _order, _positions, _read_only, _simulated, _write

from trajpref.errors import ConfigError, TrajprefWarning
from trajpref.survey.analyze import run_analysis
from trajpref.survey.export import export_csv
from trajpref.survey.manifest import (
    DATABASE,
    MANIFEST,
    load_study,
)
from trajpref.survey.server import create_app
from trajpref.survey.store import SCHEMA, AnswerError, AnswerStore, StoreError, check_rater

COLUMNS = "(rater, scene, panel, social, kinetics, revision, created_at, updated_at)"
"""The columns an answer added by hand names (the positions left out: NULL)."""


def _rows(path) -> list[tuple]:
    """The answers as another connection sees them (what is committed, nothing else)."""
    with sqlite3.connect(path) as db:
        return db.execute(
            "SELECT rater, scene, panel, social, kinetics, revision FROM answers "
            "ORDER BY rater, scene, panel"
        ).fetchall()


def test_the_database_is_in_wal_mode_with_full_sync(store):
    with sqlite3.connect(store.path) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert store.db.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL


def test_a_second_answer_updates_the_row_and_never_adds_one(store):
    first = store.save("r1", "s01", "A", OK)
    assert first == {"revision": 1, "answered": 1, "total": 9}
    # committed before save() returned: a separate connection sees it
    assert _rows(store.path) == [("r1", "s01", "A", 4, 2, 1)]
    second = store.save("r1", "s01", "A", {"social": 1, "kinetics": 5})
    assert second["revision"] == 2 and second["answered"] == 1
    assert _rows(store.path) == [("r1", "s01", "A", 1, 5, 2)]
    store.save("r2", "s01", "A", OK)
    assert len(_rows(store.path)) == 2


@pytest.mark.parametrize(
    "rater, scene, panel, ratings, status, message",
    [
        ("r1", "s01", "A", {"social": 0, "kinetics": 3}, 422, "from 1 to 5"),
        ("r1", "s01", "A", {"social": 3, "kinetics": 6}, 422, "from 1 to 5"),
        ("r1", "s01", "A", {"social": 3.5, "kinetics": 3}, 422, "integer"),
        ("r1", "s01", "A", {"social": "3", "kinetics": 3}, 422, "integer"),
        ("r1", "s01", "A", {"social": True, "kinetics": 3}, 422, "integer"),
        ("r1", "s01", "A", {"social": None, "kinetics": 3}, 422, "integer"),
        ("r1", "s01", "A", {"social": 3}, 422, "missing"),
        ("r1", "s01", "A", {"social": 3, "kinetics": 3, "method": "x"}, 422, "unknown fields"),
        ("r1", "s01", "A", [3, 3], 422, "JSON object"),
        ("r1", "s99", "A", OK, 404, "unknown scene"),
        ("r1", "s01", "Z", OK, 404, "no panel"),
        ("../r1", "s01", "A", OK, 422, "rater id"),
        ("", "s01", "A", OK, 422, "rater id"),
        ("x" * 65, "s01", "A", OK, 422, "rater id"),
    ],
)
def test_bad_answers_are_refused_and_nothing_is_written(
    store, rater, scene, panel, ratings, status, message
):
    with pytest.raises(AnswerError, match=message) as err:
        store.save(rater, scene, panel, ratings)
    assert err.value.status == status
    assert _rows(store.path) == []
    assert store.raters() == {}


def test_save_many_is_all_or_nothing(store):
    with pytest.raises(AnswerError):
        store.save_many("r1", [("s01", "A", OK), ("s01", "B", {"social": 9, "kinetics": 1})])
    assert _rows(store.path) == []
    store.save_many("r1", [("s01", "A", OK), ("s01", "B", OK)])
    assert len(_rows(store.path)) == 2


def test_submit_needs_every_panel_and_makes_the_answers_final(store):
    panels = [(s, p) for s, ps in store.panels.items() for p in ps]
    for s, p in panels[:-1]:
        store.save("r1", s, p, OK)
    with pytest.raises(AnswerError, match="1 of 9 panels") as err:
        store.submit("r1")
    assert err.value.status == 409
    store.save("r1", *panels[-1], OK)
    assert store.submit("r1")["submitted"] and store.submit("r1")["submitted"]  # idempotent
    assert store.progress("r1")["submitted"]
    with pytest.raises(AnswerError, match="already submitted") as err:
        store.save("r1", "s01", "A", {"social": 1, "kinetics": 1})
    assert err.value.status == 409 and _rows(store.path)[0][3:] == (4, 2, 1)


def test_progress_returns_what_a_rater_has_answered(store):
    assert store.progress("nobody") == {
        "rater": "nobody",
        "kind": None,
        "answers": {},
        "answered": 0,
        "total": 9,
        "submitted": False,
        "consent_required": False,
        "consented": False,
        "order": [
            {"scene": sc.id, "panels": [p.id for p in panels]}
            for sc, panels in store.study.rater_order("nobody")
        ],
    }
    store.save("r1", "s02", "C", OK)
    got = store.progress("r1")
    assert got["answers"] == {"s02": {"C": OK}} and got["answered"] == 1 and got["kind"] == "human"


def test_human_and_synthetic_raters_never_share_an_id(store):
    store.save("sim-1", "s01", "A", OK, kind="synthetic")
    with pytest.raises(AnswerError, match="taken by a synthetic") as err:
        store.save("sim-1", "s01", "B", OK)
    assert err.value.status == 409


def test_concurrent_writers_lose_nothing(store):
    panels = [(s, p) for s, ps in store.panels.items() for p in ps]

    def rater(i: int) -> None:
        for s, p in panels:
            store.save(f"r{i}", s, p, {"social": 1 + i % 5, "kinetics": 1 + (i + 1) % 5})

    threads = [threading.Thread(target=rater, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    rows = _rows(store.path)
    assert len(rows) == 8 * 9 and len({r[:3] for r in rows}) == len(rows)
    assert all(r[3] == 1 + int(r[0][1:]) % 5 for r in rows)


def test_a_second_process_sees_the_same_answers(store, synthetic_study):
    store.save("r1", "s01", "A", OK)
    other = AnswerStore(synthetic_study / DATABASE, load_study(synthetic_study))
    assert other.progress("r1")["answered"] == 1
    other.close()


def test_answers_of_another_study_are_refused(store, tmp_path):
    from trajpref.survey.study import make_synthetic_study

    other = make_synthetic_study(tmp_path / "other", scenes=2, methods=("x", "y"), seed=5)
    with pytest.raises(ConfigError, match="another study"):
        AnswerStore(store.path, other)
    with pytest.raises(ConfigError, match="no answers yet"):
        AnswerStore(tmp_path / "none.sqlite", other, readonly=True)
    (tmp_path / "junk.sqlite").write_bytes(b"this is not a database" * 100)
    with pytest.raises(ConfigError, match="not a usable answers database"):
        AnswerStore(tmp_path / "junk.sqlite", other)


def _raw(path, *statements) -> None:
    """Statements on a plain connection, as an import with the sqlite3 tool makes them:
    foreign keys off, no CHECK beyond the file's own tables."""
    with sqlite3.connect(path) as db:
        for statement in statements:
            db.execute(statement)
    db.close()


def _study_id(path) -> str:
    db = sqlite3.connect(path)
    try:
        return db.execute("SELECT value FROM meta WHERE key = 'study_id'").fetchone()[0]
    finally:
        db.close()


def _edit_manifest(folder, edit) -> None:
    import json

    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    edit(data)
    manifest.write_text(json.dumps(data))


@pytest.mark.parametrize(
    "edit",
    [
        lambda m: m["key"]["s01"]["panels"]["A"].update(ats=0.123456),  # another model's scores
        lambda m: m["key"]["s02"].update(source="other#7"),  # another scene of the data
        lambda m: m["dataset"].update(name="eth"),  # another dataset
    ],
    ids=["scores", "source", "dataset"],
)
def test_a_study_of_the_same_structure_from_other_data_or_models_is_refused(
    store, synthetic_study, tmp_path, edit
):

    other = shutil.copytree(
        synthetic_study, tmp_path / "other", ignore=lambda d, n: ["answers.sqlite"]
    )
    _edit_manifest(other, edit)
    study = load_study(other)
    assert study.legacy_study_id == store.study.legacy_study_id  # the same structure
    with pytest.raises(ConfigError) as err:
        AnswerStore(store.path, study, readonly=True)
    assert str(err.value) == (
        f"{store.path}: these answers belong to another study ({store.study.study_id}, "
        f"this one is {study.study_id})"
    )


def test_a_database_with_the_legacy_structure_only_id_still_opens_for_its_study(store, tmp_path):
    from trajpref.survey.study import make_synthetic_study

    store.save("r1", "s01", "A", OK)
    legacy = store.study.legacy_study_id
    _raw(store.path, f"UPDATE meta SET value = '{legacy}' WHERE key = 'study_id'")
    message = (
        f"{store.path}: an older answers database: its study id ({legacy}) covers only the "
        "scene, panel and method structure, which this study shares; it cannot tell this "
        "study from another of that structure built from other data or models"
    )
    for readonly in (True, False):
        with pytest.warns(UserWarning) as seen:
            again = AnswerStore(store.path, store.study, readonly=readonly)
        assert [str(w.message) for w in seen] == [message]
        assert [r[:4] for r in again.rows()] == [("r1", "human", "s01", "A")]
        again.close()
    assert _study_id(store.path) == legacy  # not rewritten
    other = make_synthetic_study(tmp_path / "other", scenes=2, methods=("x", "y"), seed=5)
    with pytest.raises(ConfigError, match="belong to another study"):
        AnswerStore(store.path, other, readonly=True)  # another structure: still refused


def test_answers_that_match_no_panel_or_no_rater_are_counted(store):
    store.save("r1", "s01", "A", OK)
    now = "2026-12-05T00:00:00"
    _raw(
        store.path,
        *[
            f"INSERT INTO answers {COLUMNS} VALUES ('{r}', '{s}', '{p}', 3, 3, 1, '{now}', "
            f"'{now}')"
            for r, s, p in [("r1", "S01", "A"), ("r1", "s01", "Z"), ("ghost", "s01", "B"),
                            ("ghost", "s02", "A"), ("ghost", "s09", "A")]
        ],
    )  # fmt: skip
    assert [r[:4] for r in store.rows()] == [("r1", "human", "s01", "A")]
    assert store.ignored() == {"answers": 5, "unknown_panels": 3, "unknown_raters": 2}


@pytest.mark.parametrize(
    "statements, message",
    [
        (
            ["ALTER TABLE answers RENAME COLUMN kinetics TO kinetic"],
            "table answers has no column kinetics (it has rater, scene, panel, social, "
            "kinetic, revision, created_at, updated_at, scene_position, panel_position; the "
            "schema is in docs/survey.md)",
        ),
        (
            # what `sqlite3 answers.sqlite ".import --csv answers.csv answers"` makes: TEXT
            ["DROP TABLE answers",
             "CREATE TABLE answers (rater, scene, panel, social TEXT, kinetics TEXT, revision, "
             "created_at, updated_at)",
             "INSERT INTO answers VALUES ('r1', 's01', 'A', '4', '2', 1, 'x', 'x')"],
            "1 answer with ratings that are not integers from 1 to 5, the first: rater 'r1', "
            "scene 's01', panel 'A', social '4', kinetics '2' (text from a CSV import? import "
            "into tables made from the schema in docs/survey.md: their INTEGER columns "
            "convert it)",
        ),
        (
            ["DROP TABLE answers",
             "CREATE TABLE answers (rater, scene, panel, social, kinetics, revision, "
             "created_at, updated_at)",
             "INSERT INTO answers VALUES ('r1', 's01', 'A', 4, 7, 1, 'x', 'x')",
             "INSERT INTO answers VALUES ('r1', 's01', 'B', 3.5, 2, 1, 'x', 'x')"],
            "2 answers with ratings that are not integers from 1 to 5, the first: rater 'r1', "
            "scene 's01', panel 'A', social 4, kinetics 7",
        ),
        (
            ["DROP TABLE raters",
             "CREATE TABLE raters (rater, kind, created_at, submitted_at)",
             "INSERT INTO raters VALUES ('r1', 'Human', 'x', NULL)"],
            "1 rater of a kind other than 'human' or 'synthetic', the first: 'r1' ('Human')",
        ),
        (
            ["DROP TABLE answers",
             "CREATE TABLE answers (rater, scene, panel, social, kinetics, revision, "
             "created_at, updated_at)",
             "INSERT INTO answers VALUES ('r1', 's01', 'A', 4, 2, 1, 'x', 'x')",
             "INSERT INTO answers VALUES ('r1', 's01', 'A', 5, 2, 1, 'x', 'x')"],
            "1 panel answered more than once by the same rater, the first: rater 'r1', "
            "scene 's01', panel 'A'",
        ),
        (["DROP TABLE raters"],
         "not an answers database (no raters table; it holds answers, consents, meta)"),
    ],
    ids=["column-typo", "csv-import-text", "out-of-range", "unknown-kind", "answered-twice",
         "no-raters-table"],
)  # fmt: skip
def test_a_database_with_other_columns_or_values_is_one_clear_error(
    synthetic_study, statements, message
):
    study = load_study(synthetic_study)
    path = synthetic_study / DATABASE
    AnswerStore(path, study).close()
    _raw(path, *statements)
    before = path.read_bytes()
    for readonly in (True, False):
        with pytest.raises(ConfigError) as err:
            AnswerStore(path, study, readonly=readonly)
        assert str(err.value).startswith(f"{path}: {message}")
        assert "\n" not in str(err.value)
    assert path.read_bytes() == before


def test_a_database_in_a_missing_folder_or_a_folder_as_database(synthetic_study, tmp_path):
    study = load_study(synthetic_study)
    folder = tmp_path / "dbs"
    folder.mkdir()
    path = folder / "nodir" / "answers.sqlite"
    with pytest.raises(ConfigError) as err:
        AnswerStore(path, study)
    assert str(err.value) == (
        f"{path}: cannot create the answers database: there is no folder {path.parent}"
    )
    for readonly in (True, False):
        with pytest.raises(ConfigError) as err:
            AnswerStore(folder, study, readonly=readonly)
        assert str(err.value) == f"{folder}: is a folder, not an answers database file"
    assert list(folder.iterdir()) == []


def test_read_only_opening_writes_nothing_and_claims_nothing(synthetic_study, tmp_path):
    study = load_study(synthetic_study)
    folder = tmp_path / "dbs"
    folder.mkdir()
    empty = folder / "empty.sqlite"
    empty.touch()
    with pytest.raises(ConfigError) as err:
        AnswerStore(empty, study, readonly=True)
    assert str(err.value) == (
        f"{empty}: not an answers database (no answers and raters tables; it holds no table)"
    )
    other = folder / "other.sqlite"
    _raw(other, "CREATE TABLE notes (text)")
    for readonly in (True, False):  # a file of other tables: nothing is added to it
        with pytest.raises(ConfigError, match="no answers and raters tables; it holds notes"):
            AnswerStore(other, study, readonly=readonly)
    bare = folder / "bare.sqlite"  # the documented tables, made by hand, no study id yet
    with sqlite3.connect(bare) as db:
        db.executescript(SCHEMA)
    db.close()
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    store = AnswerStore(bare, study, readonly=True)
    assert store.rows() == [] and store.ignored()["answers"] == 0
    with pytest.raises(StoreError, match="attempt to write a readonly database"):
        store.save("r1", "s01", "A", OK)  # SQLite itself refuses
    store.close()
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    writer = AnswerStore(bare, study)  # serve / simulate claim it
    writer.close()
    assert _study_id(bare) == study.study_id


# ---- rater ids are not case-sensitive ------------------------------------------------------
def test_rater_ids_that_differ_only_by_case_are_one_rater(store):
    store.save("Alice", "s01", "A", OK)
    store.save("alice", "s01", "B", OK)
    store.save("ALICE", "s01", "A", {"social": 1, "kinetics": 1})
    assert store.raters() == {"alice": "human"}
    assert [r[:3] + r[5:] for r in _rows(store.path)] == [("alice", "s01", "A", 2),
                                                          ("alice", "s01", "B", 1)]  # fmt: skip
    got = store.progress("ALiCe")
    assert got["rater"] == "alice" and got["answered"] == 2


def test_a_mixed_case_id_of_an_older_database_resumes_under_any_case(store):
    now = "2026-12-05T00:00:00"
    _raw(store.path, f"INSERT INTO raters VALUES ('Bob', 'human', '{now}', NULL)",
         f"INSERT INTO answers {COLUMNS} VALUES ('Bob', 's01', 'A', 3, 3, 1, '{now}', "
         f"'{now}')")  # fmt: skip
    assert store.progress("bob")["answered"] == 1
    store.save("BOB", "s01", "B", OK)
    assert store.raters() == {"Bob": "human"}  # no second rater
    assert [r[0] for r in _rows(store.path)] == ["Bob", "Bob"]


def test_case_variants_of_one_id_among_the_raters_are_listed(store):
    from trajpref.survey.store import case_variants

    now = "2026-12-05T00:00:00"
    _raw(store.path, *[f"INSERT INTO raters VALUES ('{r}', 'human', '{now}', NULL)"
                       for r in ("Carol", "CAROL", "dave", "Erin", "erin")])  # fmt: skip
    assert case_variants(store.raters()) == [["CAROL", "Carol"], ["Erin", "erin"]]
    with pytest.raises(AnswerError, match="matches 2 raters that differ only by case") as err:
        store.save("carol", "s01", "A", OK)  # neither is the lower-case id: ambiguous
    assert err.value.status == 409 and _rows(store.path) == []
    store.save("ERIN", "s01", "A", OK)  # the lower-case id exists: that one
    assert [r[0] for r in _rows(store.path)] == ["erin"]


# ---- answers are personal data: owner-only files ------------------------------------------
def test_a_new_database_and_its_wal_files_are_owner_only(synthetic_study, tmp_path):

    old = os.umask(0o022)
    try:
        for path in (synthetic_study / DATABASE, tmp_path / "elsewhere.sqlite"):
            s = AnswerStore(path, load_study(synthetic_study))
            s.save("r1", "s01", "A", OK)
            files = [path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")]
            assert {f.name: oct(f.stat().st_mode & 0o777) for f in files} == {
                f.name: "0o600" for f in files
            }
            s.close()
    finally:
        os.umask(old)


def test_opening_a_database_others_can_read_warns(synthetic_study, tmp_path):
    path = tmp_path / "shared.sqlite"
    AnswerStore(path, load_study(synthetic_study)).close()
    path.chmod(0o644)
    shared = r"other users have access to it \(mode 644\).*chmod 600"
    with pytest.warns(TrajprefWarning, match=shared):
        AnswerStore(path, load_study(synthetic_study)).close()


# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


# ---- finding 6: unknown units ---------------------------------------------------------


# ---- finding 8: consent ---------------------------------------------------------------


def test_a_study_without_consent_writes_no_key_and_needs_no_agreement(tmp_path):
    study = _write(tmp_path / "study")
    assert "consent" not in json.loads((tmp_path / "study" / MANIFEST).read_text())
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        store.save("alice", "s01", "A", {"social": 3, "kinetics": 3})  # as before
        assert store.progress("alice")["consent_required"] is False
    finally:
        store.close()


def _old_consents_table(db: Path, rows: list[tuple]) -> None:
    """Make ``db``'s consents table as the code of e1862a9 wrote it (rater PRIMARY KEY)."""
    import sqlite3

    with sqlite3.connect(db) as con:
        con.execute("DROP TABLE consents")
        con.execute("CREATE TABLE consents (rater TEXT PRIMARY KEY REFERENCES raters (rater), "
                    "agreed_at TEXT NOT NULL, text_hash TEXT NOT NULL)")  # fmt: skip
        con.executemany("INSERT INTO consents VALUES (?, ?, ?)", rows)


def test_a_database_with_the_first_consents_table_is_migrated_keeping_its_agreements(tmp_path):
    import sqlite3

    study = _write(tmp_path / "study", consent=CONSENT)
    db = tmp_path / "study" / DATABASE
    AnswerStore(db, study).close()
    with sqlite3.connect(db) as con:  # the raters, for the foreign key
        made = "2000-01-01T07:59:00.000+00:00"
        con.executemany("INSERT INTO raters VALUES (?, 'human', ?, NULL)",
                        [(r, made) for r in ("alice", "bob")])  # fmt: skip
    old = [("alice", "2000-01-01T08:00:00.000+00:00", study.consent_hash),
           ("bob", "2000-01-01T08:01:00.000+00:00", "an-older-text")]  # fmt: skip
    _old_consents_table(db, old)
    store = AnswerStore(db, study, readonly=True)  # analyze: read as it is, nothing written
    try:
        assert store.progress("alice")["consented"] and not store.progress("bob")["consented"]
    finally:
        store.close()
    with sqlite3.connect(db) as con:
        pk = [r[1] for r in con.execute("PRAGMA table_info(consents)") if r[5]]
    assert pk == ["rater"]
    store = AnswerStore(db, study)  # serve: migrated to one row per (rater, text)
    try:
        assert store.progress("alice")["consented"]
        assert store.consent("bob", study.consent_hash)["consented"]  # was a UNIQUE error
        store.save("bob", "s01", "A", {"social": 3, "kinetics": 4})
    finally:
        store.close()
    with sqlite3.connect(db) as con:
        pk = sorted(r[1] for r in con.execute("PRAGMA table_info(consents)") if r[5])
        rows = con.execute("SELECT rater, agreed_at, text_hash FROM consents "
                           "ORDER BY rater, agreed_at").fetchall()  # fmt: skip
    assert pk == ["rater", "text_hash"]
    assert rows[:2] == old and rows[2][0] == "bob" and rows[2][2] == study.consent_hash
    AnswerStore(db, study).close()  # opening it again changes nothing
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT count(*) FROM consents").fetchone()[0] == 3


def test_a_database_of_an_older_version_gets_the_consents_table(synthetic_study):
    import sqlite3

    db = synthetic_study / DATABASE
    AnswerStore(db, load_study(synthetic_study)).close()
    with sqlite3.connect(db) as con:
        con.execute("DROP TABLE consents")
    store = AnswerStore(db, load_study(synthetic_study), readonly=True)
    assert store.records() == []  # read-only: read without the table
    store.close()
    AnswerStore(db, load_study(synthetic_study)).close()
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT name FROM sqlite_master WHERE name = 'consents'").fetchone()


# Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
# with a trailing newline, the study folder deleted while serving, a database write that fails,
# the docs against the code, and the page's resumed session on a shared machine.


# ---- 2. a study in a read-only folder -------------------------------------------------------


def test_a_wal_database_of_an_older_version_is_read_in_a_read_only_folder(synthetic_study):
    """A file left in WAL mode (closed by an older version: no -wal beside it) is read as it
    is (immutable): nobody can write into a folder nobody can write to."""
    _simulated(synthetic_study)
    db = synthetic_study / DATABASE
    with contextlib.closing(sqlite3.connect(db)) as con:
        assert con.execute("PRAGMA journal_mode=WAL").fetchone()[0] == "wal"
    assert not Path(f"{db}-wal").exists()
    with _read_only(synthetic_study):
        store = AnswerStore(db, load_study(synthetic_study), readonly=True)
        try:
            assert len(store.rows()) == 27
        finally:
            store.close()


def test_answers_still_in_the_wal_of_a_read_only_folder_are_one_clear_error(synthetic_study):
    """A killed server left answers in -wal, and the -shm is gone: SQLite cannot read them
    without creating one, and reading the main file alone would silently miss them."""
    db = synthetic_study / DATABASE
    AnswerStore(db, load_study(synthetic_study)).close()  # schema and study id
    code = ("import sqlite3, os, sys\n"
            "db = sqlite3.connect(sys.argv[1], isolation_level=None)\n"
            "db.execute('PRAGMA journal_mode=WAL')\n"
            "db.execute(\"INSERT INTO raters VALUES ('kim', 'human', 'now', NULL)\")\n"
            "os._exit(0)\n")  # fmt: skip
    subprocess.run([sys.executable, "-c", code, str(db)], check=True)
    assert Path(f"{db}-wal").stat().st_size > 0
    Path(f"{db}-shm").unlink()
    with _read_only(synthetic_study):
        with pytest.raises(ConfigError) as err:
            AnswerStore(db, load_study(synthetic_study), readonly=True)
    message = str(err.value)
    assert "read-only" in message and "answers.sqlite-wal" in message and "copy" in message
    assert "not a usable answers database" not in message


def test_a_live_servers_files_beside_the_database_are_not_read_as_immutable(
    synthetic_study, monkeypatch
):
    """A server run by another user keeps its -wal (empty after a checkpoint) and its -shm,
    which this reader may not open, so ``mode=ro`` cannot open the file: reading it as
    immutable could then show a state the server is changing, so the reader refuses with the
    same clear error (the other user is played by a ``mode=ro`` that cannot open, as
    SQLite's own error)."""
    _simulated(synthetic_study)
    db = synthetic_study / DATABASE
    Path(f"{db}-wal").write_bytes(b"")  # what a live writer's checkpointed -wal looks like
    Path(f"{db}-shm").write_bytes(b"\0" * 32768)
    connect = AnswerStore._connect

    def other_users_shm(self, query):
        if query == "mode=ro":
            raise sqlite3.OperationalError("unable to open database file")
        return connect(self, query)

    monkeypatch.setattr(AnswerStore, "_connect", other_users_shm)
    with pytest.raises(ConfigError) as err:
        AnswerStore(db, load_study(synthetic_study), readonly=True)
    assert "answers.sqlite-wal and answers.sqlite-shm" in str(err.value)
    assert "stop the server" in str(err.value)


@pytest.mark.parametrize("existing", [True, False])
def test_serve_in_a_read_only_folder_says_the_folder_is_read_only(synthetic_study, existing):
    db = synthetic_study / DATABASE
    if existing:
        AnswerStore(db, load_study(synthetic_study)).close()
    with _read_only(synthetic_study):
        with pytest.raises(ConfigError) as err:
            AnswerStore(db, load_study(synthetic_study))
    message = str(err.value)
    assert f"the folder {synthetic_study} is read-only" in message, message
    assert "not a usable answers database" not in message
    assert sorted(p.name for p in synthetic_study.iterdir()) == sorted(
        ["images", MANIFEST, *([DATABASE] if existing else [])]
    )


# ---- 3. rater ids (and other names) with a trailing newline ---------------------------------


def test_a_rater_id_with_a_trailing_newline_is_refused(store):
    for bad in ("eve\n", "eve\r\n", "eve\n\n"):
        with pytest.raises(AnswerError):
            check_rater(bad)
    with TestClient(create_app(load_study(store.study.folder), store)) as c:
        assert c.put("/api/raters/eve/answers/s01/A", json=OK).status_code == 200
        r = c.put("/api/raters/eve%0A/answers/s01/A", json=OK)
        assert r.status_code == 422 and "rater id" in r.json()["error"]
        assert c.get("/api/raters/eve%0A").status_code == 422
    assert store.raters() == {"eve": "human"}


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


# ---- 2. answers are stored with where they were shown ------------------------------------


def test_answers_are_stored_with_the_position_the_rater_was_shown(synthetic_study):
    study = load_study(synthetic_study)
    store = AnswerStore(synthetic_study / DATABASE, study)
    with TestClient(create_app(study, store)) as client:
        for rater in ("Alice", "bob"):
            for scene, panels in _order(client.get(f"/api/raters/{rater}").json()):
                for panel in panels:
                    r = client.put(f"/api/raters/{rater}/answers/{scene}/{panel}", json=OK)
                    assert r.status_code == 200
        client.put("/api/raters/ALICE/answers/s02/B", json={"social": 1, "kinetics": 1})
    store.close()
    stored = _positions(synthetic_study / DATABASE)
    assert len(stored) == 2 * study.num_panels
    for (rater, scene, panel), where in stored.items():
        assert where == study.positions(rater)[(scene, panel)][:2]
    # the same panel at different places for the two raters
    assert any(stored[("alice", s, p)] != stored[("bob", s, p)] for _, s, p in stored)


# ---- 3. a database of the previous version -------------------------------------------------

OLD_SCHEMA = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE raters (rater TEXT PRIMARY KEY,
    kind TEXT NOT NULL CHECK (kind IN ('human', 'synthetic')),
    created_at TEXT NOT NULL, submitted_at TEXT);
CREATE TABLE answers (rater TEXT NOT NULL REFERENCES raters (rater),
    scene TEXT NOT NULL, panel TEXT NOT NULL,
    social INTEGER NOT NULL CHECK (social BETWEEN 1 AND 5),
    kinetics INTEGER NOT NULL CHECK (kinetics BETWEEN 1 AND 5),
    revision INTEGER NOT NULL DEFAULT 1,
    created_at TEXT NOT NULL, updated_at TEXT NOT NULL,
    PRIMARY KEY (rater, scene, panel));
CREATE TABLE consents (rater TEXT NOT NULL REFERENCES raters (rater),
    agreed_at TEXT NOT NULL, text_hash TEXT NOT NULL, PRIMARY KEY (rater, text_hash));
"""
"""The tables the version before 2026-12-06 wrote (no positions)."""


def _old_database(folder: Path) -> Path:
    """An answers database as the previous version left it: two raters who answered every
    panel of the study (in the manifest's order, the only one there was)."""
    study = load_study(folder)
    path = folder / DATABASE
    now = "2026-12-05T00:00:00"
    with contextlib.closing(sqlite3.connect(path)) as db:
        db.executescript(OLD_SCHEMA)
        db.execute("INSERT INTO meta VALUES ('study_id', ?)", (study.study_id,))
        for i, rater in enumerate(("old1", "old2")):
            db.execute("INSERT INTO raters VALUES (?, 'human', ?, ?)", (rater, now, now))
            for s in study.scenes:
                for j, p in enumerate(s.panels):
                    db.execute("INSERT INTO answers VALUES (?, ?, ?, ?, ?, 1, ?, ?)",
                               (rater, s.id, p.id, 1 + (i + j) % 5, 3, now, now))  # fmt: skip
        db.commit()
    path.chmod(0o600)
    return path


def test_a_database_of_the_previous_version_is_read_by_analyze_and_export_and_kept_by_serve(
    synthetic_study, tmp_path
):
    _fixed(synthetic_study)  # the previous version's study: no order in its manifest
    path = _old_database(synthetic_study)
    study = load_study(synthetic_study)
    before = path.read_bytes()
    result, _ = run_analysis(synthetic_study, out=tmp_path / "analysis")
    check = result.position_effect
    assert result.raters == 2 and (check.blocks, check.scenes) == (2, 2 * len(study.scenes))
    done = export_csv(synthetic_study, tmp_path / "a.csv")
    assert done["answers"] == 2 * study.num_panels
    assert path.read_bytes() == before  # read-only: no column added by a reader
    with open(tmp_path / "a.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    manifest = study.positions()  # what every rater of that version saw
    for r in rows:
        got = (int(r["scene_position"]), int(r["panel_position"]), int(r["position"]))
        assert got == manifest[(r["scene"], r["panel"])]
    # serve (a writer) adds the two columns, keeps every answer, and records new positions
    store = AnswerStore(path, study)
    assert store.progress("old1")["answered"] == study.num_panels
    store.save("new", "s02", "B", OK)
    store.close()
    stored = _positions(path)
    assert len(stored) == 2 * study.num_panels + 1
    assert stored[("old1", "s01", "A")] == (None, None)
    assert stored[("new", "s02", "B")] == manifest[("s02", "B")][:2]  # a fixed-order study
    assert run_analysis(synthetic_study, out=tmp_path / "again")[0].raters == 3
