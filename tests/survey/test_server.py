"""The web application: answers through HTTP, 4xx for bad requests with nothing written,
no path traversal, the body limit, the Host check, and durability when the server is killed."""

import json
import signal
import sqlite3
import urllib.request

import pytest
from starlette.testclient import TestClient

from trajpref.survey.manifest import load_study
from trajpref.survey.server import LOOPBACK_NAMES, create_app, serve_subprocess

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
