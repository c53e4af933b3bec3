"""Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
with a trailing newline, the study folder deleted while serving, a database write that fails,
the docs against the code, and the page's resumed session on a shared machine."""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest
from starlette.testclient import TestClient

from trajpref.cli import main
from trajpref.errors import ConfigError, DataError
from trajpref.survey import server as server_module
from trajpref.survey.build import BuildConfig
from trajpref.survey.manifest import DATABASE, MANIFEST, load_study
from trajpref.survey.server import create_app, serve_subprocess
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerError, AnswerStore, check_rater
from trajpref.survey.study import make_synthetic_study

OK = {"social": 4, "kinetics": 2}
ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "survey.md"
STATIC = ROOT / "src" / "trajpref" / "survey" / "static"


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _answers(path: Path) -> list[tuple]:
    with contextlib.closing(sqlite3.connect(path)) as db:
        return db.execute("SELECT rater, scene, panel, social, kinetics FROM answers").fetchall()


@contextlib.contextmanager
def _read_only(folder: Path):
    """``folder`` read-only for this process, restored afterwards: ``chattr +i`` as root (who
    ignores modes), else mode 0555."""
    if getattr(os, "geteuid", lambda: 1)() == 0:
        if shutil.which("chattr") is None:
            pytest.skip("root without chattr: cannot make a folder read-only")
        done = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, text=True)
        if done.returncode:
            pytest.skip(f"chattr +i is not supported here: {done.stderr.strip()}")
        try:
            yield
        finally:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
    else:
        mode = folder.stat().st_mode & 0o777
        folder.chmod(0o555)
        try:
            yield
        finally:
            folder.chmod(mode)


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


# ---- 2. a study in a read-only folder -------------------------------------------------------


def _simulated(folder: Path) -> None:
    study = load_study(folder)
    store = AnswerStore(folder / DATABASE, study)
    try:
        simulate(study, store, SimulateConfig(raters=3))
    finally:
        store.close()


def test_analyze_and_export_read_a_study_in_a_read_only_folder(capsys, synthetic_study, tmp_path):
    _simulated(synthetic_study)
    before = {p.name: p.read_bytes() for p in synthetic_study.iterdir() if p.is_file()}
    with _read_only(synthetic_study):
        code, out, err = _run(capsys, "survey", "analyze", synthetic_study, "--out",
                              tmp_path)  # fmt: skip
        assert code == 0, err
        assert "raters: 3 synthetic" in out
        code, out, err = _run(capsys, "survey", "export", synthetic_study, "--csv",
                              tmp_path / "answers.csv")  # fmt: skip
        assert code == 0, err
    assert (tmp_path / "answers.csv").read_text().count("synthetic-0") == 27
    assert {p.name: p.read_bytes() for p in synthetic_study.iterdir() if p.is_file()} == before


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


def test_names_with_a_trailing_newline_are_refused_in_the_manifest_and_the_build(
    synthetic_study, tmp_path
):
    manifest = json.loads((synthetic_study / MANIFEST).read_text())
    scene = manifest["scenes"][0]["id"]
    manifest["scenes"][0]["id"] = scene + "\n"
    manifest["key"][scene + "\n"] = manifest["key"].pop(scene)
    (synthetic_study / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(DataError, match=r"scenes\[0\]\.id: not a valid name"):
        load_study(synthetic_study)
    with pytest.raises(ConfigError, match="bad method name"):
        BuildConfig(dataset="zara1", models={"gen\n": "cv"})
    with pytest.raises(ConfigError, match="method name"):
        make_synthetic_study(tmp_path / "s", scenes=1, methods=("alpha\n",))


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


# ---- 6. the docs against the code -----------------------------------------------------------


def test_the_docs_ground_truth_rows_carry_the_mark_analyze_prints():
    rows = [line for line in DOCS.read_text().splitlines() if line.startswith("| ground truth |")]
    assert len(rows) == 2
    assert all("*** ↑ |" in row for row in rows), rows


def _option_help(help_text: str, option: str) -> str:
    """The help of ``option`` in argparse's ``--help`` output, on one line."""
    lines = help_text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip().startswith(option + " "))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].strip().startswith("-")),
               len(lines))  # fmt: skip
    return " ".join(" ".join(lines[start:end]).split())


def test_the_help_gives_the_defaults_of_seed_and_title(capsys):
    with contextlib.suppress(SystemExit):
        main(["survey", "build", "--help"])
    out = capsys.readouterr().out
    assert _option_help(out, "--seed").endswith("(default 0)")
    assert _option_help(out, "--title").endswith("(default 'Which predicted paths look human?')")


def test_the_docs_name_simulate_db_sigterm_line_breaks_and_the_blinding_limits():
    text = " ".join(DOCS.read_text().split())
    assert "`survey simulate study/ --raters 20 [--seed 0 --prefix synthetic --db PATH]`" in text
    assert "a blank line starts a new paragraph" not in text
    assert "SIGTERM" in text and "SIGKILL" in text
    assert "drawn differently" in text  # the one limit of the blinding left
    assert "an order of their own" in text and "one byte size" in text  # the two lifted


# ---- 7. the page says whose session it resumed ----------------------------------------------

PAGE_HARNESS = r"""
const fs = require("fs"), vm = require("vm");
const elements = new Map(), listeners = new Map(), store = new Map();
function element(id) {
  const el = { id, hidden: false, textContent: "", value: "", dataset: {}, children: [],
    classList: { toggle() {}, add() {}, remove() {} }, setAttribute() {}, focus() {},
    checkValidity: () => true, append(...c) { this.children.push(...c); }, after() {},
    querySelectorAll: () => [],
    addEventListener(type, f) { listeners.set(`${id}:${type}`, f); } };
  return el;
}
const document = {
  body: element("body"),
  getElementById(id) {
    if (!elements.has(id)) elements.set(id, element(id));
    return elements.get(id);
  },
  createElement: () => element(""), querySelectorAll: () => [], addEventListener() {},
};
const study = { title: "t", instructions: "", consent: null, scale: [1, 5],
  criteria: [{ id: "social", label: "S", help: "" }, { id: "kinetics", label: "K", help: "" }],
  scenes: [{ id: "s01", reference: null, panels: [{ id: "A", image: "images/s01-A.png" }] }] };
const progress = (rater) => ({ rater, answers: {}, answered: 0, total: 1, submitted: false,
  consent_required: false, consented: false, order: [{ scene: "s01", panels: ["A"] }] });
const fetch = async (path) => ({ ok: true, status: 200, json: async () =>
  path === "api/study" ? study : progress(decodeURIComponent(path.split("/").pop())) });
const localStorage = { getItem: (k) => store.has(k) ? store.get(k) : null,
  setItem: (k, v) => store.set(k, String(v)), removeItem: (k) => store.delete(k) };
store.set("trajpref-survey-rater", "alice");
const context = { document, fetch, localStorage, Image: class {}, console, Promise, Object,
  Number, String, Math, Error, encodeURIComponent, decodeURIComponent, setTimeout };
vm.createContext(context);
vm.runInContext(fs.readFileSync(process.argv[2], "utf8"), context);
const $ = (id) => document.getElementById(id);
const report = (label) => console.log(JSON.stringify({ label, view: document.body.dataset.view,
  note: !$("resume-note").hidden, who: $("resume-rater").textContent,
  saved: localStorage.getItem("trajpref-survey-rater") }));
setTimeout(async () => {
  report("resumed");
  listeners.get("not-me:click")();
  report("not me");
  $("rater").value = "bob";
  listeners.get("login-form:submit")({ preventDefault() {} });
  await new Promise((r) => setTimeout(r, 20));
  report("typed");
}, 50);
"""


def test_a_session_resumed_from_the_browser_says_whose_it_is_with_a_not_you_control(tmp_path):
    """A shared lab machine: the page resumes the last rater of the browser, and says so with
    a visible "not you?" control that starts as a new rater; a typed id shows no such note."""
    page = (STATIC / "index.html").read_text()
    assert 'id="resume-note"' in page and 'id="not-me"' in page
    assert re.search(r'id="not-me"[^>]*>\s*Not you\? Start as a new rater', page)
    node = shutil.which("node") or shutil.which("nodejs")
    if node is None:
        pytest.skip("node is not installed: the page's script is checked in the browser test")
    harness = tmp_path / "harness.js"
    harness.write_text(PAGE_HARNESS)
    done = subprocess.run([node, str(harness), str(STATIC / "app.js")], capture_output=True,
                          text=True, timeout=30)  # fmt: skip
    assert done.returncode == 0, done.stderr
    states = [json.loads(line) for line in done.stdout.splitlines()]
    assert states[0] == {"label": "resumed", "view": "rate", "note": True, "who": "alice",
                         "saved": "alice"}  # fmt: skip
    assert [(s["label"], s["view"], s["note"], s["saved"]) for s in states[1:]] == [
        ("not me", "login", False, None),
        ("typed", "rate", False, "bob"),
    ]
