"""Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
above the best method, unknown units, the study's reproducibility record, consent, rater ids
in the access log, and the export's details."""

from __future__ import annotations

import csv
import json
import logging
import signal
import urllib.request
from pathlib import Path

import matplotlib.figure
import numpy as np
import pytest
from starlette.testclient import TestClient

from trajpref.cli import main
from trajpref.errors import ConfigError
from trajpref.survey import analyze as analyze_module
from trajpref.survey.analyze import analyze, run_analysis
from trajpref.survey.manifest import (
    DATABASE,
    GROUND_TRUTH,
    MANIFEST,
    Panel,
    PanelKey,
    Study,
    StudyScene,
    load_study,
)
from trajpref.survey.server import create_app
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerError, AnswerStore
from trajpref.survey.study import SceneData, ground_truth_panel, shown_predictions, write_study


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _study(methods=("A", "B", GROUND_TRUTH), scenes=("s1", "s2")) -> Study:
    """Scenes whose panels X, Y, Z show the methods in order; ATS 0.5 (A), 0.2 (B)."""
    ats = {"A": 0.5, "B": 0.2, GROUND_TRUTH: 0.0}
    out = []
    for sid in scenes:
        panels = tuple(Panel("XYZ"[i], f"{sid}-{i}.png", PanelKey(m, ats[m], ats[m], 0.0, 0.0))
                       for i, m in enumerate(methods))  # fmt: skip
        out.append(StudyScene(sid, panels))
    return Study(folder=None, title="t", instructions="", methods=tuple(methods),
                 scenes=tuple(out))  # fmt: skip


def _complete(study: Study, rater: str, kind: str, score: dict[str, int]) -> list[tuple]:
    """Every panel of ``study`` answered by ``rater`` with ``score[method]`` on both."""
    return [(rater, kind, s.id, p.id, score[p.key.method], score[p.key.method], True)
            for s in study.scenes for p in s.panels]  # fmt: skip


# ---- finding 4: an unfinished pilot names no best method --------------------------------


def test_a_pilots_single_answer_names_no_best_method_and_says_which_raters_are_unused():
    study = _study()
    rows = [("pilot", "human", "s1", "X", 3, 4, False)]  # one answer, to method A
    for i in range(10):
        rows += _complete(study, f"synthetic-{i:02d}", "synthetic", {"A": 2, "B": 3,
                                                                   GROUND_TRUTH: 4})  # fmt: skip
    res = analyze(study, rows)  # --raters auto: the one human rater
    assert res.rater_kind == "human" and res.complete_raters == 0
    assert res.best is None and res.tests == [] and res.no_best == "no rater answered every panel"
    md = res.markdown()
    assert "Best method" not in md and "**A**" not in md and "**" not in res.table()
    assert "No best method is named and no tests are run: no rater answered every panel." in md
    assert "| A | 3.50 ± n/a |" in res.table()  # the sd of one value is not 0.00
    assert ("Not used: 10 synthetic raters (`--raters auto` uses the human raters when there "
            "are any; `--raters synthetic` or `--raters all` includes them).") in md  # fmt: skip
    assert res.to_dict()["best"] is None and res.to_dict()["rows"][0]["human_sd"] is None
    # --raters synthetic: complete raters, a best method again, nothing left unused
    res = analyze(study, rows, "synthetic")
    assert res.best == "B" and res.unused_synthetic == 0 and "Not used" not in res.markdown()


def test_methods_without_answers_are_listed_after_those_with_answers():
    study = _study(methods=("B", "A", GROUND_TRUTH))
    res = analyze(study, [("pilot", "human", "s1", "Y", 3, 4, False)])  # Y: method A
    assert [r.method for r in res.rows] == ["A", "B", GROUND_TRUTH]


def test_a_method_with_fewer_than_two_answers_names_no_best_method():
    study = _study(scenes=("s1",))  # one scene: one complete rater gives one answer a method
    res = analyze(study, _complete(study, "r1", "human", {"A": 4, "B": 2, GROUND_TRUTH: 5}))
    assert res.complete_raters == 1 and res.best is None and res.tests == []
    assert res.no_best == "A, B, ground truth have fewer than 2 answers"
    assert "Best method" not in res.markdown()


def test_excluding_the_only_human_rater_suggests_the_synthetic_ones(capsys, synthetic_study):
    store = AnswerStore(synthetic_study / DATABASE, load_study(synthetic_study))
    store.save("pilot", "s01", "A", {"social": 3, "kinetics": 4})
    simulate(store.study, store, SimulateConfig(raters=3))
    store.close()
    code, _, err = _run(capsys, "survey", "analyze", synthetic_study, "--exclude-rater", "pilot")
    assert code == 2 and ("no answers from human raters left after --exclude-rater pilot; there "
                          "are 3 synthetic raters: use --raters synthetic (or --raters all)"
                          ) in err  # fmt: skip


# ---- finding 5: the ground truth is not ranked; marks above the best say so -------------


def test_the_ground_truth_above_the_best_method_is_marked_and_not_ranked(tmp_path, monkeypatch):
    from trajpref.survey.analyze import ABOVE

    study = _study()
    rows = []
    for i in range(8):  # A a little above B, the ground truth far above both
        rows += _complete(study, f"r{i}", "human", {"A": 3 + (i % 2), "B": 2, GROUND_TRUTH: 5})
    res = analyze(study, rows)
    assert res.best == "A" and res.rows[-1].method == GROUND_TRUTH
    gt, b = res.rows[-1], res.rows[1]
    assert gt.marks["human"].endswith(f" {ABOVE}") and not b.marks["human"].endswith(ABOVE)
    assert f"| ground truth | 5.00 ± 0.00 {gt.marks['human']} |" in res.table()
    legend = res.legend()
    assert ("Rows by human score (the ground truth is not ranked: it is listed last); **A** "
            "has the highest of the methods.") in legend  # fmt: skip
    assert f"A {ABOVE} after a mark: the row scores *higher* than A" in legend
    # the figure's title names the reference of its marks
    titles = []
    monkeypatch.setattr(
        analyze_module,
        "plot_survey_summary",
        lambda *a, **k: titles.append(a[4]) or Path(a[3]).write_bytes(b""),
    )
    folder = tmp_path / "study"
    _write(folder, units="m")
    store = AnswerStore(folder / DATABASE, load_study(folder))
    simulate(store.study, store, SimulateConfig(raters=4))
    store.close()
    result, _ = run_analysis(folder)
    assert f"marks: Wilcoxon test against {result.best} ({ABOVE}: the row is higher)" in titles[0]


# ---- finding 6: unknown units ---------------------------------------------------------


def _write(folder: Path, units: str = "m", consent: str = "", **build) -> Study:
    """A one-scene study of two agents: the method 'alpha' and the rated ground truth."""
    rng = np.random.default_rng(0)
    track = rng.normal(0, 1, (2, 1, 2)) + 0.4 * np.arange(20)[None, :, None]  # [2, 20, 2]
    history, future = track[:, :8], track[:, 8:]
    pred = future[None] + rng.normal(0, 0.3, (4, 2, 12, 2))  # [K, P, 12, 2]
    panels = {"alpha": shown_predictions(pred, 1 + rng.random((4, 2, 12)), np.ones((2, 12)),
                                         future),
              GROUND_TRUTH: ground_truth_panel(future)}  # fmt: skip
    scenes = [
        SceneData(history, future, panels, "f@0", 0, 0),
        SceneData(history + 1, future + 1, panels, "f@20", 20, 0),
    ]
    more = {"consent": consent} if consent else {}
    return write_study(folder, scenes, [GROUND_TRUTH, "alpha"], units=units,
                       dataset={"name": "d", "split": "test", "units": units}, build=build,
                       **more)  # fmt: skip


@pytest.fixture
def saved_labels(monkeypatch):
    """The axis titles every saved figure shows: (text, colour) of each x and y label."""
    labels: list[tuple[str, str]] = []
    original = matplotlib.figure.Figure.savefig

    def savefig(fig, *args, **kwargs):
        for ax in fig.axes:
            for label in (ax.xaxis.label, ax.yaxis.label):
                labels.append((label.get_text(), str(label.get_color())))
        return original(fig, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    return labels


@pytest.mark.parametrize("units", ["unknown", ""])
def test_the_rater_pictures_of_data_in_unknown_units_show_no_unit(tmp_path, saved_labels, units):
    _write(tmp_path / "study", units=units)
    assert len(saved_labels) == 2 * 4  # 2 scenes x 2 panels, x and y
    visible = [text for text, colour in saved_labels if colour != "none"]
    assert visible == []  # before: "x [unknown]", "y [unknown]" on every picture


def test_the_rater_pictures_of_data_in_metres_name_the_unit(tmp_path, saved_labels):
    _write(tmp_path / "study", units="m")
    assert {t for t, c in saved_labels if c != "none"} == {"x [m]", "y [m]"}


def test_build_warns_of_unknown_units_names_the_models_units_and_records_hashes(
    capsys, walks, tmp_path, saved_labels
):
    consent = tmp_path / "consent.txt"
    consent.write_text("I agree to take part.\n\nMy answers are kept for a year.\n")
    out = tmp_path / "study"
    code, _, err = _run(capsys, "survey", "build", "--dataset", walks, "--models", "c=cv",
                        "gen=zara1/generator", "--scorer", "zara1/denoiser", "--scenes", "1",
                        "--samples", "2", "--min-gap", "0", "--device", "cpu", "--no-progress",
                        "--consent", consent, "--out", out)  # fmt: skip
    assert code == 0
    assert (f"trajpref: warning: {walks}: the data's units are unknown (no --units): the raters' "
            "pictures show axes without a unit and the analysis gives ADE/FDE in unknown units; "
            "the models recorded units m (zara1/generator, zara1/denoiser): pass --units m"
            ) in err  # fmt: skip
    assert saved_labels and {t for t, _ in saved_labels} == {"x", "y"}  # no "x [unknown]"
    study = load_study(out)
    build = json.loads((out / MANIFEST).read_text())["build"]
    assert build["study_id"] == study.study_id
    assert build["trajpref_version"] and build["torch_version"]
    methods = build["hashes"]["methods"]
    assert methods["c"] == {"weights_hash": None, "model_hash": None}
    assert len(methods["gen"]["weights_hash"]) == 16 and len(methods["gen"]["model_hash"]) == 12
    assert build["hashes"]["scorer"]["weights_hash"]
    assert "consent" not in build  # the text is the manifest's own key
    assert study.consent == "I agree to take part.\n\nMy answers are kept for a year."


def test_build_refuses_an_empty_or_missing_consent_file(capsys, walks, tmp_path):
    empty = tmp_path / "empty.txt"
    empty.write_text("  \n")
    for path, text in ((empty, "the file is empty"), (tmp_path / "no.txt", "cannot read it")):
        code, _, err = _run(capsys, "survey", "build", "--dataset", walks, "--models", "cv",
                            "--scorer", "zara1/denoiser", "--consent", path, "--out",
                            tmp_path / "study")  # fmt: skip
        assert code == 2 and f"--consent {path}: {text}" in err
        assert not (tmp_path / "study").exists()


# ---- finding 7: the study id, versions and hashes in analysis.json and the CSV -----------


def test_analysis_json_and_the_csv_record_the_study_id_versions_and_hashes(capsys, tmp_path):
    hashes = {"methods": {"alpha": {"weights_hash": "w" * 16, "model_hash": "m" * 12}},
              "scorer": {"weights_hash": "s" * 16, "model_hash": "t" * 12}}  # fmt: skip
    folder = tmp_path / "study"
    study = _write(folder, trajpref_version="9.9", torch_version="8.8", hashes=hashes)
    store = AnswerStore(folder / DATABASE, study)
    simulate(study, store, SimulateConfig(raters=3))
    store.close()
    result, paths = run_analysis(folder)
    saved = json.loads(paths["json"].read_text())
    assert saved["study_id"] == study.study_id
    assert saved["provenance"]["build"] == {"trajpref_version": "9.9", "torch_version": "8.8",
                                            "hashes": hashes}  # fmt: skip
    assert saved["provenance"]["trajpref"]
    path = tmp_path / "answers.csv"
    code, out, _ = _run(capsys, "survey", "export", folder, "--csv", path, "--raters", "all")
    assert code == 0 and f"wrote 12 answers of 3 raters (all) to {path}" in out
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["study_id"] for r in rows} == {study.study_id}
    made = {(r["method"], r["weights_hash"], r["model_hash"], r["trajpref_version"],
             r["torch_version"]) for r in rows}  # fmt: skip
    assert made == {("alpha", "w" * 16, "m" * 12, "9.9", "8.8"),
                    (GROUND_TRUTH, "", "", "9.9", "8.8")}  # fmt: skip
    # finding 12: the ground truth's ATS/FTS are not measured: empty (NA), not 0.0
    gt = [r for r in rows if r["method"] == GROUND_TRUTH]
    assert gt and all(r["ats"] == r["fts"] == "" for r in gt)
    assert all(float(r["ats"]) != 0 for r in rows if r["method"] == "alpha")


# ---- finding 8: consent ---------------------------------------------------------------


CONSENT = "I agree to take part.\n\nMy answers are kept for a year."


def test_a_study_without_consent_writes_no_key_and_needs_no_agreement(tmp_path):
    study = _write(tmp_path / "study")
    assert "consent" not in json.loads((tmp_path / "study" / MANIFEST).read_text())
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        store.save("alice", "s01", "A", {"social": 3, "kinetics": 3})  # as before
        assert store.progress("alice")["consent_required"] is False
    finally:
        store.close()


def _agree(client, rater: str, text_hash: str):
    """What the page's *I agree* sends."""
    return client.post(f"/api/raters/{rater}/consent", json={"agree": True,
                                                             "text_hash": text_hash})  # fmt: skip


def _consents(db: Path) -> list[tuple]:
    import sqlite3

    with sqlite3.connect(db) as con:
        return con.execute("SELECT rater, text_hash, agreed_at FROM consents "
                           "ORDER BY agreed_at").fetchall()  # fmt: skip


def test_answers_are_refused_until_the_rater_agreed_and_the_agreement_is_recorded(tmp_path):
    study = _write(tmp_path / "study", consent=CONSENT)
    assert load_study(tmp_path / "study").consent == CONSENT
    assert study.public()["consent"] == CONSENT
    first = study.consent_hash
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        with TestClient(create_app(study, store)) as c:
            assert c.get("/api/study").json()["consent_hash"] == first  # what the page sends
            put = "/api/raters/Alice/answers/s01/A"
            r = c.put(put, json={"social": 3, "kinetics": 4})
            assert (
                r.status_code == 403
                and "has not agreed to the study's consent text" in (r.json()["error"])
            )
            assert c.get("/api/raters/alice").json()["consented"] is False
            r = _agree(c, "ALICE", first)
            assert r.status_code == 200 and r.json()["consented"] is True
            agreed = r.json()["agreed_at"]
            assert _agree(c, "alice", first).json()["agreed_at"] == agreed  # kept
            progress = c.get("/api/raters/alice").json()
            assert progress["consent_required"] and progress["consented"]
            assert c.put(put, json={"social": 3, "kinetics": 4}).status_code == 200
        simulate(study, store, SimulateConfig(raters=1))  # synthetic raters are not asked
        records = {r["rater"]: r["consented_at"] for r in store.records()}
        assert records == {"alice": agreed, "synthetic-01": None}
    finally:
        store.close()
    # a changed consent text must be agreed to again; the first agreement stays recorded
    manifest = json.loads((tmp_path / "study" / MANIFEST).read_text())
    manifest["consent"] = CONSENT + "\n\nAnd a new paragraph."
    (tmp_path / "study" / MANIFEST).write_text(json.dumps(manifest))
    study = load_study(tmp_path / "study")
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        with pytest.raises(AnswerError, match="has not agreed") as err:
            store.save("alice", "s01", "B", {"social": 3, "kinetics": 4})
        assert err.value.status == 403 and not store.progress("alice")["consented"]
        with TestClient(create_app(study, store)) as c:
            put = "/api/raters/alice/answers/s01/B"
            assert c.put(put, json={"social": 3, "kinetics": 4}).status_code == 403
            r = _agree(c, "alice", first)  # a page that still shows the old text
            assert r.status_code == 409 and "consent text has changed" in r.json()["error"]
            assert c.put(put, json={"social": 3, "kinetics": 4}).status_code == 403
            r = _agree(c, "alice", study.consent_hash)
            assert r.status_code == 200 and r.json()["agreed_at"] != agreed
            assert c.put(put, json={"social": 3, "kinetics": 4}).status_code == 200
        assert _consents(tmp_path / "study" / DATABASE) == [
            ("alice", first, agreed),  # the audit trail: the older text's agreement is kept
            ("alice", study.consent_hash, r.json()["agreed_at"]),
        ]
        assert {r["rater"]: r["consented_at"] for r in store.records()}["alice"] == (
            r.json()["agreed_at"])  # fmt: skip
    finally:
        store.close()


def test_a_cross_site_form_post_cannot_record_an_agreement(tmp_path):
    """A page elsewhere can make the browser send an HTML form (urlencoded, or text/plain)
    to the server, not a JSON request: consent takes JSON only, like answers."""
    study = _write(tmp_path / "study", consent=CONSENT)
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        with TestClient(create_app(study, store)) as c:
            for ctype, body in [
                ("application/x-www-form-urlencoded", f"agree=true&text_hash={study.consent_hash}"),
                ("text/plain", json.dumps({"agree": True, "text_hash": study.consent_hash})),
                ("multipart/form-data; boundary=x", "--x--"),
            ]:
                headers = {"Content-Type": ctype, "Origin": "http://evil.example"}
                r = c.post("/api/raters/bob/consent", content=body.encode(), headers=headers)
                assert r.status_code == 415 and "JSON" in r.json()["error"], ctype
            r = c.post("/api/raters/bob/consent")  # no body at all
            assert r.status_code == 415
            assert c.get("/api/raters/bob").json()["consented"] is False
        assert _consents(tmp_path / "study" / DATABASE) == []
    finally:
        store.close()


@pytest.mark.parametrize(
    ("body", "status", "message"),
    [
        ({"agree": True, "text_hash": "0123456789abcdef"}, 409, "consent text has changed"),
        ({"agree": True, "text_hash": ""}, 409, "consent text has changed"),
        ({"agree": False, "text_hash": "HASH"}, 422, "agree"),
        ({"agree": 1, "text_hash": "HASH"}, 422, "agree"),
        ({"agree": True}, 422, "text_hash"),
        ({"agree": True, "text_hash": 7}, 422, "text_hash"),
        ({"agree": True, "text_hash": "HASH", "extra": 1}, 422, "extra"),
        ([True, "HASH"], 422, "JSON object"),
    ],
)
def test_an_agreement_to_another_text_or_a_malformed_one_records_nothing(
    tmp_path, body, status, message
):
    study = _write(tmp_path / "study", consent=CONSENT)
    body = json.loads(json.dumps(body).replace("HASH", study.consent_hash))
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        with TestClient(create_app(study, store)) as c:
            r = c.post("/api/raters/bob/consent", json=body)
            assert r.status_code == status and message in r.json()["error"]
            assert c.get("/api/raters/bob").json()["consented"] is False
            assert c.put("/api/raters/bob/answers/s01/A",
                         json={"social": 3, "kinetics": 4}).status_code == 403  # fmt: skip
        assert _consents(tmp_path / "study" / DATABASE) == []
    finally:
        store.close()


def test_a_study_without_consent_text_refuses_an_agreement(tmp_path):
    study = _write(tmp_path / "study")
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        with TestClient(create_app(study, store)) as c:
            assert c.get("/api/study").json()["consent_hash"] is None
            r = _agree(c, "bob", study.consent_hash)
            assert r.status_code == 404 and "no consent text" in r.json()["error"]
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


def test_the_page_keeps_the_line_breaks_of_the_instructions_and_the_consent():
    from importlib import resources

    css = (resources.files("trajpref.survey") / "static" / "style.css").read_text()
    assert "#instructions, #consent-text { white-space: pre-line; }" in css


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


# ---- finding 9: rater ids in the access log ---------------------------------------------


def test_the_access_log_filter_masks_rater_ids():
    from trajpref.survey.server import RaterIdMask

    record = logging.LogRecord("uvicorn.access", logging.INFO, "", 0, '%s - "%s %s HTTP/%s" %d',
                               ("127.0.0.1:5", "PUT", "/api/raters/Alice.Smith@x.org/answers/"
                                "s01/A", "1.1", 200), None)  # fmt: skip
    assert RaterIdMask().filter(record)
    assert record.getMessage() == '127.0.0.1:5 - "PUT /api/raters/<id>/answers/s01/A HTTP/1.1" 200'


def test_serve_logs_requests_without_the_rater_id(synthetic_study):
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "trajpref.cli", "survey", "serve",
                             str(synthetic_study), "--port", "0"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)  # fmt: skip
    try:
        line = proc.stdout.readline()
        url = line.split(" at ")[1].split(";")[0].strip()
        with urllib.request.urlopen(f"{url}api/raters/Secret.Person") as r:
            assert json.loads(r.read())["rater"] == "secret.person"
    finally:
        proc.send_signal(signal.SIGINT)
        log = proc.communicate(timeout=20)[0]
    assert "GET /api/raters/<id> HTTP/1.1" in log and "secret" not in log.lower()


# ---- finding 12: the docs' --frame-interval default -------------------------------------


def test_the_docs_give_the_frame_interval_default_as_the_code_takes_it():
    docs = (Path(__file__).resolve().parents[2] / "docs" / "survey.md").read_text()
    row = next(line for line in docs.splitlines() if line.startswith("| `--frame-interval`"))
    assert "| 0.4, unknown |" not in row
    assert "`time` or `timestamp`" in row and "else 0.4 (assumed)" in row


def test_select_rows_error_without_other_raters_has_no_hint():
    study = _study()
    rows = _complete(study, "r1", "human", {"A": 3, "B": 3, GROUND_TRUTH: 3})
    with pytest.raises(ConfigError) as err:
        analyze(study, rows, exclude=["r1"])
    assert str(err.value) == "no answers from human raters left after --exclude-rater r1"


def test_a_json_agreement_from_another_origin_is_refused_and_records_nothing(tmp_path):
    """Even as JSON (a page elsewhere could send it after a CORS preflight it then ignores),
    an agreement whose Origin is not the server's own is refused (403) and not stored."""
    study = _write(tmp_path / "study", consent=CONSENT)
    store = AnswerStore(tmp_path / "study" / DATABASE, study)
    try:
        with TestClient(create_app(study, store)) as c:
            body = {"agree": True, "text_hash": study.consent_hash}
            r = c.post("/api/raters/alice/consent", json=body,
                       headers={"Origin": "http://evil.example"})  # fmt: skip
            assert r.status_code == 403 and "origin" in r.json()["error"]
            assert not c.get("/api/raters/alice").json().get("consented")
            r = c.post("/api/raters/alice/consent", json=body,
                       headers={"Origin": "http://testserver"})  # fmt: skip
            assert r.status_code == 200
    finally:
        store.close()
    assert [row[0] for row in _consents(tmp_path / "study" / DATABASE)] == ["alice"]
