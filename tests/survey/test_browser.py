"""The rating page in headless Chromium (Debian's chromium + chromium-driver, driven by
selenium): a rater rates every panel with clicks and with the keyboard, reloads mid-way and
resumes, goes back and changes an answer, submits; then the SQLite file holds exactly the
expected rows.

Skipped when no browser is installed, except under CI (then it fails): `.ci/run` installs one.
With TRAJPREF_SURVEY_SCREENSHOT=path the mid-way screenshot is also written there (that is
how docs/survey-page.png is made).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import sqlite3
import subprocess
from pathlib import Path

import pytest
from survey.helpers import METHODS, ROOT

from trajpref.survey.manifest import (
    load_study,
)
from trajpref.survey.server import running

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--window-size=1000,1000",
]
"""No GPU, no sandbox (root in a container), and nothing that would try to reach out."""


def _need_browser() -> None:
    missing = [p for p in (CHROMIUM, DRIVER) if not Path(p).is_file()]
    try:
        import selenium  # noqa: F401
    except ImportError:
        missing.append("the selenium package")
    if not missing:
        return
    message = (
        f"headless Chromium not found ({', '.join(missing)} missing): install it with "
        "`apt-get install -y chromium chromium-driver` and `pip install -e '.[dev]'`"
    )
    if os.environ.get("CI"):
        pytest.fail(message + "; CI is set, so the browser test must run (.ci/run installs it)")
    pytest.skip(message)


@pytest.fixture
def browser(tmp_path):
    _need_browser()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in (*FLAGS, f"--user-data-dir={tmp_path / 'profile'}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(options=options, service=Service(DRIVER))
    driver.set_page_load_timeout(30)
    yield driver
    driver.quit()


def test_rate_a_whole_study_in_the_browser(browser, tiny_study, tmp_path):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys
    from selenium.webdriver.support.ui import WebDriverWait

    folder = Path(shutil.copytree(tiny_study, tmp_path / "study"))
    study = load_study(folder)
    # the order this rater is shown (their own: another rater sees another)
    items = [(s.id, p.id) for s, panels in study.rater_order("judge-1") for p in panels]
    assert len(items) == 9 and items != [(s.id, p.id) for s in study.scenes for p in s.panels]
    d = browser
    wait = WebDriverWait(d, 15)

    def body(name: str) -> str:
        return d.find_element(By.TAG_NAME, "body").get_attribute(f"data-{name}") or ""

    def until(name: str, value) -> None:
        wait.until(lambda _: body(name) == str(value), f"data-{name} never became {value}")

    def click(criterion: str, value: int) -> None:
        d.find_element(
            By.CSS_SELECTOR, f'button.rate[data-criterion="{criterion}"][data-value="{value}"]'
        ).click()

    def keys(*k: str) -> None:
        ActionChains(d).send_keys(*k).perform()

    def selected() -> dict[str, str]:
        return {
            b.get_attribute("data-criterion"): b.get_attribute("data-value")
            for b in d.find_elements(By.CSS_SELECTOR, "button.rate.selected")
        }

    expected: dict[tuple[str, str], tuple[int, int]] = {}
    with running(folder) as (url, _store):
        d.get(url)
        until("view", "login")
        d.find_element(By.ID, "rater").send_keys("judge-1")
        d.find_element(By.ID, "start").click()
        until("view", "rate")
        assert d.find_element(By.ID, "progress-text").text == "0 / 9 answered"
        # pictures are numbered by where they are shown, never by their letters
        assert d.find_element(By.ID, "where").text == "Scene 1 of 3 · picture 1 of 3 (1 of 9)"
        assert (
            d.find_element(By.ID, "panel-image")
            .get_attribute("src")
            .endswith(f"images/{items[0][0]}-{items[0][1]}.png")
        )
        # panels 1-4 with the mouse
        for n in range(4):
            social, kinetics = 1 + n, 5 - n
            click("social", social)
            click("kinetics", kinetics)  # the second rating sends the answer and moves on
            until("answered", n + 1)
            expected[items[n]] = (social, kinetics)
        until("pos", 4)
        # a reload mid-way resumes at the first open panel, from the server's record
        d.refresh()
        until("view", "rate")
        until("answered", 4)
        until("pos", 4)
        keys(Keys.ARROW_RIGHT)  # an unanswered panel cannot be skipped
        until("pos", 4)
        # back with the keyboard: panel 4 shows its answer, then change it with keys 2 and 3
        keys(Keys.ARROW_LEFT)
        until("pos", 3)
        assert selected() == {"social": "4", "kinetics": "2"}
        assert d.find_element(By.ID, "progress-text").text == "4 / 9 answered"
        d.save_screenshot(str(tmp_path / "survey-page.png"))
        if os.environ.get("TRAJPREF_SURVEY_SCREENSHOT"):
            shutil.copy(tmp_path / "survey-page.png", os.environ["TRAJPREF_SURVEY_SCREENSHOT"])
        keys("2", "3")
        until("pos", 4)
        wait.until(lambda _: d.find_element(By.ID, "status").text == "saved")
        expected[items[3]] = (2, 3)
        # panels 5-9 with the keyboard
        for n in range(4, 9):
            social, kinetics = 1 + (n % 5), 1 + ((n + 2) % 5)
            keys(str(social), str(kinetics))
            until("answered", n + 1)
            expected[items[n]] = (social, kinetics)
        submit = d.find_element(By.ID, "submit")
        wait.until(lambda _: submit.is_displayed())
        page = d.page_source.lower()
        assert not any(m in page for m in (*METHODS, "ground truth", "generator"))
        submit.click()
        until("view", "done")
    with sqlite3.connect(folder / "answers.sqlite") as db:
        rows = db.execute(
            "SELECT rater, scene, panel, social, kinetics, revision FROM answers"
        ).fetchall()
        where = db.execute(
            "SELECT scene, panel, scene_position, panel_position FROM answers"
        ).fetchall()
        raters = db.execute("SELECT rater, kind, submitted_at IS NOT NULL FROM raters").fetchall()
    # one row per panel; panel 4 was written three times (each change of an answered panel
    # is saved at once: first answer, then the new social rating, then the new kinetics one)
    assert sorted(rows) == sorted(
        ("judge-1", s, p, *expected[(s, p)], 3 if (s, p) == items[3] else 1) for s, p in items
    )
    assert raters == [("judge-1", "human", 1)]
    shown = study.positions("judge-1")  # each answer stored with where it was shown
    assert all((sp, pp) == shown[(s, p)][:2] for s, p, sp, pp in where)
    assert (tmp_path / "survey-page.png").read_bytes()[:4] == b"\x89PNG"


def test_without_a_browser_it_skips_with_the_install_line_but_fails_under_ci(monkeypatch):
    import sys

    module = sys.modules[__name__]
    monkeypatch.setattr(module, "CHROMIUM", "/nonexistent/chromium")
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="apt-get install -y chromium chromium-driver"):
        _need_browser()
    monkeypatch.setenv("CI", "1")
    with pytest.raises(pytest.fail.Exception, match="CI is set"):
        _need_browser()


def test_the_consent_step_comes_before_the_first_picture_and_keeps_line_breaks(
    browser, synthetic_study
):
    import json

    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    manifest = json.loads((synthetic_study / "manifest.json").read_text())
    manifest["instructions"] = "Rate each picture.\n\nTake your time."
    manifest["consent"] = "I agree to take part.\n\nMy answers are kept for a year."
    (synthetic_study / "manifest.json").write_text(json.dumps(manifest))
    d = browser
    wait = WebDriverWait(d, 15)

    def until(value: str) -> None:
        wait.until(lambda _: d.find_element(By.TAG_NAME, "body").get_attribute("data-view")
                   == value, f"the page never showed {value}")  # fmt: skip

    with running(synthetic_study) as (url, _store):
        d.get(url)
        until("login")
        instructions = d.find_element(By.ID, "instructions")
        assert instructions.value_of_css_property("white-space") == "pre-line"
        assert "Rate each picture.\n" in instructions.text  # not one run-on line
        d.find_element(By.ID, "rater").send_keys("judge-2")
        d.find_element(By.ID, "start").click()
        until("consent")  # before the first picture
        text = d.find_element(By.ID, "consent-text")
        assert text.value_of_css_property("white-space") == "pre-line"
        assert "I agree to take part.\n" in text.text and "kept for a year" in text.text
        # a page that shows another text than the server's (edited since it was loaded):
        # refused (409), and the page fetches the server's text to be read again
        d.execute_script("state.study.consent_hash = '0123456789abcdef';")
        d.find_element(By.ID, "agree").click()
        wait.until(lambda _: "please read it again" in d.find_element(By.ID, "consent-error").text)
        assert d.find_element(By.TAG_NAME, "body").get_attribute("data-view") == "consent"
        with sqlite3.connect(synthetic_study / "answers.sqlite") as db:
            assert db.execute("SELECT count(*) FROM consents").fetchone()[0] == 0
        d.find_element(By.ID, "agree").click()
        until("rate")
        d.find_element(By.CSS_SELECTOR, 'button.rate[data-criterion="social"][data-value="4"]'
                       ).click()  # fmt: skip
        d.find_element(By.CSS_SELECTOR, 'button.rate[data-criterion="kinetics"][data-value="2"]'
                       ).click()  # fmt: skip
        wait.until(lambda _: d.find_element(By.TAG_NAME, "body").get_attribute("data-answered")
                   == "1")  # fmt: skip
        d.refresh()  # agreed once: not asked again
        until("rate")
    with sqlite3.connect(synthetic_study / "answers.sqlite") as db:
        consents = db.execute("SELECT rater, agreed_at IS NOT NULL, text_hash "
                              "FROM consents").fetchall()  # fmt: skip
        answers = db.execute("SELECT rater, social, kinetics FROM answers").fetchall()
    text_hash = load_study(synthetic_study).consent_hash  # the text the page showed
    assert consents == [("judge-2", 1, text_hash)] and answers == [("judge-2", 4, 2)]


# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


def test_the_page_keeps_the_line_breaks_of_the_instructions_and_the_consent():
    from importlib import resources

    css = (resources.files("trajpref.survey") / "static" / "style.css").read_text()
    assert "#instructions, #consent-text { white-space: pre-line; }" in css


# Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
# with a trailing newline, the study folder deleted while serving, a database write that fails,
# the docs against the code, and the page's resumed session on a shared machine.


STATIC = ROOT / "src" / "trajpref" / "survey" / "static"


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
