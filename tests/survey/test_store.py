"""The answers database: WAL, upsert without duplicates, validation, durability, submission."""

import sqlite3
import threading

import pytest

from trajpref.errors import ConfigError
from trajpref.survey.manifest import DATABASE, load_study
from trajpref.survey.store import AnswerError, AnswerStore

OK = {"social": 4, "kinetics": 2}


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
        AnswerStore(tmp_path / "none.sqlite", other, create=False)
    (tmp_path / "junk.sqlite").write_bytes(b"this is not a database" * 100)
    with pytest.raises(ConfigError, match="not a usable answers database"):
        AnswerStore(tmp_path / "junk.sqlite", other)
