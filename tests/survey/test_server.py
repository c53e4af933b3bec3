"""The web application: answers through HTTP, 4xx for bad requests with nothing written,
no path traversal, the body limit, the Host check, and durability when the server is killed."""

import contextlib
import json
import logging
import shutil
import signal
import sqlite3
import urllib.request
from pathlib import Path

import pytest
from starlette.testclient import TestClient
from survey.helpers import CONSENT, METHODS, OK, _write

from trajpref.survey import server as server_module
from trajpref.survey.manifest import (
    DATABASE,
    GROUND_TRUTH,
    MANIFEST,
    load_study,
)
from trajpref.survey.server import LOOPBACK_NAMES, create_app, serve_subprocess
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerError, AnswerStore

PUT = "/api/raters/r1/answers/s01/A"
SUBMIT = {"submit": True}
"""The body of ``POST .../submit`` (what the page sends)."""


@pytest.fixture
def client(store):
    study = load_study(store.study.folder)
    with TestClient(create_app(study, store, max_body=256)) as c:
        yield c


def _count(store) -> int:
    with sqlite3.connect(store.path) as db:
        return db.execute("SELECT COUNT(*) FROM answers").fetchone()[0]


def test_the_page_and_its_files_are_served_with_a_strict_policy(client):
    page = client.get("/")
    assert page.status_code == 200 and b'id="panel-image"' in page.content
    assert "script-src 'self'" in page.headers["content-security-policy"]
    assert page.headers["x-content-type-options"] == "nosniff"
    assert client.get("/static/app.js").headers["content-type"].startswith("text/javascript")
    assert client.get("/images/s01-A.png").content[:4] == b"\x89PNG"
    study = client.get("/api/study").json()
    assert len(study["scenes"]) == 3 and study["criteria"][0]["id"] == "social"


def test_an_answer_is_saved_and_a_second_one_updates_it(client, store):
    r = client.put(PUT, json={"social": 5, "kinetics": 4})
    assert r.status_code == 200 and r.json() == {
        "saved": True,
        "revision": 1,
        "answered": 1,
        "total": 9,
    }
    r = client.put(PUT, json={"social": 2, "kinetics": 4})
    assert r.json()["revision"] == 2 and _count(store) == 1
    got = client.get("/api/raters/r1").json()
    assert got["answers"] == {"s01": {"A": {"social": 2, "kinetics": 4}}}


@pytest.mark.parametrize(
    "path, body, headers, status, message",
    [
        (PUT, '{"social": 6, "kinetics": 1}', None, 422, "from 1 to 5"),
        (PUT, '{"social": 0, "kinetics": 1}', None, 422, "from 1 to 5"),
        (PUT, '{"social": 2.5, "kinetics": 1}', None, 422, "integer"),
        (PUT, '{"social": NaN, "kinetics": 1}', None, 422, "integer"),
        (PUT, '{"social": 1}', None, 422, "missing"),
        (PUT, "[1, 2]", None, 422, "JSON object"),
        (PUT, '{"social": 1, "kinetics": ', None, 400, "not valid JSON"),
        (PUT, b"\xff\xfe{}", None, 400, "not valid JSON"),
        (PUT, "", None, 400, "not valid JSON"),
        (PUT, '{"social": 1, "kinetics": 1}', {"content-type": "text/plain"}, 415, "JSON"),
        (
            PUT,
            '{"social": 1, "kinetics": 1}',
            {"content-type": "application/x-www-form-urlencoded"},
            415,
            "JSON",
        ),
        (PUT, '{"social": 1, "kinetics": 1, "pad": "' + "x" * 300 + '"}', None, 413, "limited"),
        (
            "/api/raters/r1/answers/s99/A",
            '{"social": 1, "kinetics": 1}',
            None,
            404,
            "unknown scene",
        ),
        ("/api/raters/r1/answers/s01/Q", '{"social": 1, "kinetics": 1}', None, 404, "no panel"),
        ("/api/raters/r%20x/answers/s01/A", '{"social": 1, "kinetics": 1}', None, 422, "rater"),
        ("/api/raters/r1/answers/s01", '{"social": 1, "kinetics": 1}', None, 404, "Not Found"),
    ],
)
def test_bad_requests_get_4xx_with_a_message_and_write_nothing(
    client, store, path, body, headers, status, message
):
    headers = headers or {"content-type": "application/json"}
    r = client.put(path, content=body, headers=headers)
    assert r.status_code == status
    assert message in r.json()["error"]
    assert _count(store) == 0 and store.raters() == {}


def test_an_oversized_body_is_refused_without_a_length_header_too(client, store):
    def chunks():  # sent chunked: no Content-Length to trust
        yield b'{"social": 1, "kinetics": 1, "pad": "'
        for _ in range(100):
            yield b"x" * 64
        yield b'"}'

    r = client.put(PUT, content=chunks(), headers={"content-type": "application/json"})
    assert r.status_code == 413 and _count(store) == 0


@pytest.mark.parametrize(
    "path",
    [
        "/images/../manifest.json",
        "/images/..%2Fmanifest.json",
        "/images/%2e%2e%2fmanifest.json",
        "/images/manifest.json",
        "/images/answers.sqlite",
        "/images/s01-A.png%00.json",
        "/static/../manifest.json",
        "/static/..%2F..%2Fsurvey%2Fmanifest.py",
        "/static/index.html",
        "/images/%2Fetc%2Fpasswd",
        "/images//etc/passwd",
        "/manifest.json",
        "/answers.sqlite",
        "/images/s01-ref.png",
    ],
)
def test_only_the_studys_images_and_the_page_are_served(client, path):
    r = client.get(path)
    assert r.status_code == 404
    assert b"hidden" not in r.content and b"method" not in r.content


def test_wrong_methods_and_submissions_get_4xx(client):
    assert client.get(PUT).status_code == 405
    assert client.post("/api/study").status_code == 405
    r = client.post("/api/raters/r1/submit", json=SUBMIT)
    assert r.status_code == 409 and "9 of 9" in r.json()["error"]


def test_a_full_study_can_be_submitted(client, store):
    for scene in client.get("/api/study").json()["scenes"]:
        for p in scene["panels"]:
            path = f"/api/raters/judge.7/answers/{scene['id']}/{p['id']}"
            assert client.put(path, json={"social": 3, "kinetics": 4}).status_code == 200
    assert client.post("/api/raters/judge.7/submit", json=SUBMIT).json()["submitted"]
    r = client.put("/api/raters/judge.7/answers/s01/A", json={"social": 1, "kinetics": 1})
    assert r.status_code == 409 and _count(store) == 9


def _answer_all(client, rater: str) -> None:
    for scene in client.get("/api/study").json()["scenes"]:
        for p in scene["panels"]:
            path = f"/api/raters/{rater}/answers/{scene['id']}/{p['id']}"
            assert client.put(path, json={"social": 3, "kinetics": 4}).status_code == 200


def test_a_cross_site_form_post_cannot_submit(client, store):
    """A page elsewhere can make the browser post an HTML form (urlencoded, multipart or
    text/plain), never a JSON request: submit takes JSON only, so such a post leaves a rater
    whose panels are all answered unsubmitted, free to revise."""
    _answer_all(client, "bob")
    for ctype, body in [
        ("application/x-www-form-urlencoded", "submit=true"),
        ("text/plain", '{"submit": true}'),
        ("multipart/form-data; boundary=x", "--x--"),
    ]:
        r = client.post("/api/raters/bob/submit", content=body.encode(),
                        headers={"Content-Type": ctype})  # fmt: skip
        assert r.status_code == 415 and "JSON" in r.json()["error"], ctype
    assert client.post("/api/raters/bob/submit").status_code == 415  # no body at all
    assert client.get("/api/raters/bob").json()["submitted"] is False
    r = client.put("/api/raters/bob/answers/s01/A", json={"social": 1, "kinetics": 1})
    assert r.status_code == 200 and r.json()["revision"] == 2


@pytest.mark.parametrize("body", [{}, {"submit": False}, {"submit": 1}, {"submit": "true"},
                                  {"submit": True, "extra": 1}, [True], True, None])  # fmt: skip
def test_submit_needs_the_body_submit_true(client, body):
    _answer_all(client, "bob")
    r = client.post("/api/raters/bob/submit", content=json.dumps(body).encode(),
                    headers={"Content-Type": "application/json"})  # fmt: skip
    assert r.status_code == 422 and "submit" in r.json()["error"]
    assert client.get("/api/raters/bob").json()["submitted"] is False


@pytest.mark.parametrize(
    "origin, status",
    [
        ("http://evil.example", 403),
        ("null", 403),
        ("http://testserver.evil.example", 403),
        ("http://testserver:8080", 403),
        ("http://testserver", 200),
        (None, 200),  # no Origin header (curl, scripts): allowed
    ],
)
def test_a_change_from_another_origin_is_refused(client, store, origin, status):
    """PUT answers, POST consent and POST submit from a page of another origin get 403 and
    change nothing (the TestClient's own origin is http://testserver)."""
    headers = {} if origin is None else {"Origin": origin}
    for scene in client.get("/api/study").json()["scenes"]:
        for p in scene["panels"]:
            path = f"/api/raters/bob/answers/{scene['id']}/{p['id']}"
            r = client.put(path, json={"social": 3, "kinetics": 4}, headers=headers)
            assert r.status_code == status
    r = client.post("/api/raters/bob/submit", json=SUBMIT, headers=headers)
    assert r.status_code == status
    if status == 403:
        assert "origin" in r.json()["error"] and _count(store) == 0
        assert client.get("/api/raters/bob").json()["submitted"] is False
    else:
        assert r.json()["submitted"] and _count(store) == 9


def test_a_host_that_names_the_default_port_matches_an_origin_without_it(client, store):
    """A reverse proxy may pass Host: name:443 (or :80) where the browser's Origin leaves the
    default port out: the same origin, not refused."""
    for origin, host in (("https://study.example", "study.example:443"),
                         ("http://study.example", "study.example:80")):  # fmt: skip
        r = client.put(PUT, json={"social": 2, "kinetics": 2},
                       headers={"Origin": origin, "Host": host})  # fmt: skip
        assert r.status_code == 200, r.json()
    r = client.put(
        PUT,
        json={"social": 2, "kinetics": 2},
        headers={"Origin": "https://study.example", "Host": "study.example:80"},
    )
    assert r.status_code == 403


def test_the_host_check_refuses_foreign_names_on_loopback(store):
    app = create_app(load_study(store.study.folder), store, allowed_hosts=LOOPBACK_NAMES)
    with TestClient(app, base_url="http://127.0.0.1:8000") as c:
        assert c.get("/api/study").status_code == 200
        assert c.get("/api/study", headers={"host": "localhost:8000"}).status_code == 200
        assert c.get("/api/study", headers={"host": "[::1]:8000"}).status_code == 200
        r = c.put(PUT, json={"social": 1, "kinetics": 1}, headers={"host": "evil.example"})
        assert r.status_code == 400 and "Host" in r.json()["error"]
    assert _count(store) == 0


def _request(url: str, method: str = "GET", body: dict | None = None) -> dict:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(
        url, data=data, method=method, headers={"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


def test_answers_survive_a_killed_server(synthetic_study):
    """The real command in its own process: every answer acknowledged before SIGKILL is in
    the database afterwards."""
    proc, url = serve_subprocess(synthetic_study)
    try:
        assert url.startswith("http://127.0.0.1:")
        acked = []
        for scene in _request(url + "api/study")["scenes"]:
            for p in scene["panels"][:2]:
                path = f"api/raters/r1/answers/{scene['id']}/{p['id']}"
                assert _request(url + path, "PUT", {"social": 2, "kinetics": 5})["saved"]
                acked.append((scene["id"], p["id"]))
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()
    with sqlite3.connect(synthetic_study / "answers.sqlite") as db:
        rows = db.execute("SELECT scene, panel, social, kinetics FROM answers").fetchall()
    assert sorted(rows) == sorted((s, p, 2, 5) for s, p in acked) and len(rows) == 6


def test_a_rater_id_typed_with_other_capitals_resumes_the_same_rater(client, store):
    r = client.put("/api/raters/Alice/answers/s01/A", json={"social": 5, "kinetics": 4})
    assert r.json()["answered"] == 1
    r = client.put("/api/raters/alice/answers/s01/B", json={"social": 3, "kinetics": 3})
    assert r.json()["answered"] == 2  # the same rater: two answers, not one each
    got = client.get("/api/raters/ALICE").json()
    assert got["rater"] == "alice" and got["answered"] == 2
    assert store.raters() == {"alice": "human"}


# A security review (walkthrough 67-M): a JSON body nested past Python's recursion limit
# (4,000 bytes, under the default body limit) got a plain-text 500 and a traceback in the log
# instead of the JSON 400 every other bad body gets.


def test_a_deeply_nested_body_is_a_400_with_nothing_written(store):
    study = load_study(store.study.folder)
    with TestClient(create_app(study, store), raise_server_exceptions=False) as client:
        body = "[" * 2000 + "]" * 2000
        r = client.put(PUT, content=body, headers={"content-type": "application/json"})
    assert r.status_code == 400 and "not valid JSON" in r.json()["error"]
    with sqlite3.connect(store.path) as db:
        assert db.execute("SELECT COUNT(*) FROM answers").fetchone()[0] == 0


# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


# ---- finding 6: unknown units ---------------------------------------------------------


# ---- finding 8: consent ---------------------------------------------------------------


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


# Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
# with a trailing newline, the study folder deleted while serving, a database write that fails,
# the docs against the code, and the page's resumed session on a shared machine.


def _answers(path: Path) -> list[tuple]:
    with contextlib.closing(sqlite3.connect(path)) as db:
        return db.execute("SELECT rater, scene, panel, social, kinetics FROM answers").fetchall()


@contextlib.contextmanager
def _log_lines():
    """The messages the server logs (its logger, whatever handlers uvicorn set up)."""
    lines: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            lines.append(self.format(record))

    handler = Collect(logging.ERROR)
    server_module.LOG.addHandler(handler)
    try:
        yield lines
    finally:
        server_module.LOG.removeHandler(handler)


# ---- 1. SIGTERM stops as cleanly as Ctrl-C ------------------------------------------------


def _put(url: str, path: str, body: dict) -> dict:
    req = urllib.request.Request(url + path, data=json.dumps(body).encode(), method="PUT",
                                 headers={"Content-Type": "application/json"})  # fmt: skip
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_sigterm_or_ctrl_c_leaves_every_answer_in_the_database_file_alone(
    synthetic_study, tmp_path, sig
):
    """The real command: after SIGTERM (kill, timeout, docker/systemd stop) as after Ctrl-C,
    no -wal or -shm is left and a copy of answers.sqlite alone holds the answers."""
    proc, url = serve_subprocess(synthetic_study)
    try:
        assert _put(url, "api/raters/bo/answers/s01/A", OK)["saved"]
        assert _put(url, "api/raters/bo/answers/s02/B", OK)["saved"]
    finally:
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    assert "Traceback" not in err
    left = sorted(p.name for p in synthetic_study.iterdir())
    assert left == ["answers.sqlite", "images", "manifest.json"], left
    (tmp_path / "copy").mkdir()
    copy = Path(shutil.copy(synthetic_study / DATABASE, tmp_path / "copy" / DATABASE))
    assert sorted(_answers(copy)) == [("bo", "s01", "A", 4, 2), ("bo", "s02", "B", 4, 2)]


# ---- 4. the study folder deleted while serving; 5. a write that fails ------------------------


def test_answers_after_the_study_folder_is_deleted_or_replaced_get_503(synthetic_study, tmp_path):
    copy = shutil.copytree(synthetic_study, tmp_path / "copy")
    study = load_study(synthetic_study)
    store = AnswerStore(synthetic_study / DATABASE, study)
    try:
        with _log_lines() as lines, TestClient(create_app(study, store)) as c:
            assert c.put("/api/raters/zed/answers/s01/A", json=OK).status_code == 200
            shutil.rmtree(synthetic_study)
            r = c.put("/api/raters/zed/answers/s01/B", json=OK)
            assert r.status_code == 503, r.text
            assert "study folder is gone" in r.json()["error"]
            assert "not saved" in r.json()["error"]
            shutil.copytree(copy, synthetic_study)  # another folder in its place
            r = c.put("/api/raters/zed/answers/s01/B", json=OK)
            assert r.status_code == 503 and "study folder is gone" in r.json()["error"]
            assert c.post("/api/raters/zed/submit", json={"submit": True}).status_code == 503
    finally:
        store.close()
    assert len(lines) == 3 and all("\n" not in line for line in lines), lines
    assert all(str(synthetic_study / DATABASE) in line and "zed" not in line for line in lines)
    assert sorted(p.name for p in synthetic_study.iterdir()) == ["images", MANIFEST]  # untouched


class _FailingCommit:
    """A connection whose COMMIT fails as a full disk or an unwritable -wal makes it fail."""

    def __init__(self, db: sqlite3.Connection):
        self._db = db

    def execute(self, sql: str, *args):
        if sql.strip().upper() == "COMMIT":
            raise sqlite3.OperationalError("disk I/O error")
        return self._db.execute(sql, *args)

    def __getattr__(self, name: str):
        return getattr(self._db, name)


def test_a_write_that_fails_is_a_json_503_logged_once_and_nothing_is_kept(store):
    real = store.db
    with _log_lines() as lines, TestClient(create_app(load_study(store.study.folder), store)) as c:
        store.db = _FailingCommit(real)
        try:
            r = c.put("/api/raters/ann/answers/s01/A", json=OK)
        finally:
            store.db = real
        assert r.status_code == 503 and r.headers["content-type"] == "application/json"
        assert r.json() == {"error": "the answer was not saved: disk I/O error"}
        # the failed transaction was rolled back: the next answer is saved, as the first
        r = c.put("/api/raters/ann/answers/s01/A", json=OK)
        assert r.status_code == 200 and r.json()["revision"] == 1
    assert len(lines) == 1 and "the answer was not saved: disk I/O error" in lines[0]
    assert _answers(store.path) == [("ann", "s01", "A", 4, 2)]


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


def test_the_served_pictures_name_no_method(tiny_study, tmp_path):
    study = load_study(tiny_study)
    store = AnswerStore(tmp_path / "a.sqlite", study)
    with TestClient(create_app(study, store)) as client:
        images = [client.get(f"/images/{name}").content for name in study.image_files()]
        progress = client.get("/api/raters/r1").content
    store.close()
    for body in (*images, progress):
        for name in (*METHODS, GROUND_TRUTH, "generator", "truth", "method"):
            assert name.encode() not in body.lower()
