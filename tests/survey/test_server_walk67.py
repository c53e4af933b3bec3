"""A security review (walkthrough 67-M): a JSON body nested past Python's recursion limit
(4,000 bytes, under the default body limit) got a plain-text 500 and a traceback in the log
instead of the JSON 400 every other bad body gets."""

import sqlite3

from starlette.testclient import TestClient

from trajpref.survey.manifest import load_study
from trajpref.survey.server import create_app

PUT = "/api/raters/r1/answers/s01/A"


def test_a_deeply_nested_body_is_a_400_with_nothing_written(store):
    study = load_study(store.study.folder)
    with TestClient(create_app(study, store), raise_server_exceptions=False) as client:
        body = "[" * 2000 + "]" * 2000
        r = client.put(PUT, content=body, headers={"content-type": "application/json"})
    assert r.status_code == 400 and "not valid JSON" in r.json()["error"]
    with sqlite3.connect(store.path) as db:
        assert db.execute("SELECT COUNT(*) FROM answers").fetchone()[0] == 0
