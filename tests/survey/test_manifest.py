"""The study manifest: a key a researcher misspells is an error that names it."""

import json
import os
import subprocess
import sys

import pytest
from starlette.testclient import TestClient
from survey.helpers import _fixed, _order

from trajpref.errors import ConfigError, DataError
from trajpref.survey.build import BuildConfig
from trajpref.survey.manifest import DATABASE, MANIFEST, load_study
from trajpref.survey.server import create_app
from trajpref.survey.store import AnswerStore
from trajpref.survey.study import (
    make_synthetic_study,
)


def _edit(folder, edit) -> None:
    manifest = folder / "manifest.json"
    data = json.loads(manifest.read_text())
    edit(data)
    manifest.write_text(json.dumps(data))


def _rename(obj: dict, old: str, new: str) -> None:
    obj[new] = obj.pop(old)


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda m: _rename(m, "instructions", "instruction"),
            "top level: unknown key 'instruction' (did you mean 'instructions'?); the keys "
            "are: build, consent, created, dataset, format, instructions, key, methods, order, "
            "scenes, synthetic, title",
        ),
        (
            lambda m: m.update(titel="Rate these"),
            "top level: unknown key 'titel' (did you mean 'title'?)",
        ),
        (
            lambda m: _rename(m["scenes"][1], "reference", "referense"),
            "scenes[1]: unknown key 'referense' (did you mean 'reference'?); the keys are: "
            "id, panels, reference",
        ),
        (
            lambda m: m["scenes"][0]["panels"][2].update(img="x.png"),
            "scenes[0].panels[2]: unknown key 'img' (did you mean 'image'?); the keys are: "
            "id, image",
        ),
        (
            lambda m: _rename(m["key"]["s02"], "stratum", "strata"),
            "key.s02: unknown key 'strata' (did you mean 'stratum'?); the keys are: agents, "
            "index, panels, source, stratum",
        ),
        (
            lambda m: _rename(m["key"]["s01"]["panels"]["B"], "ats", "ast"),
            "key.s01.panels.B: unknown key 'ast' (did you mean 'ats'?); the keys are: ade, "
            "ats, fde, fts, max_ats, max_fts, method, shown",
        ),
        (
            lambda m: m.update(colour="red"),
            "top level: unknown key 'colour'; the keys are: build,",
        ),
    ],
    ids=["instructions", "title", "scene", "panel", "key-scene", "key-panel", "no-match"],
)
def test_an_unknown_key_names_itself_the_closest_key_and_the_allowed_ones(
    synthetic_study, edit, message
):
    _edit(synthetic_study, edit)
    with pytest.raises(DataError) as err:
        load_study(synthetic_study)
    assert message in str(err.value)
    assert str(err.value).startswith(f"{synthetic_study / 'manifest.json'}: ")


def test_two_unknown_keys_are_both_named(synthetic_study):
    _edit(synthetic_study, lambda m: m.update(titel="x", instruction="y"))
    with pytest.raises(DataError, match="unknown keys 'instruction' \\(did you mean "
                       "'instructions'\\?\\), 'titel' \\(did you mean 'title'\\?\\)"):  # fmt: skip
        load_study(synthetic_study)


def test_the_records_dataset_and_build_take_any_key(synthetic_study):
    _edit(synthetic_study, lambda m: (m["dataset"].update(note="x"), m["build"].update(y=1)))
    assert load_study(synthetic_study).dataset["note"] == "x"


# Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
# with a trailing newline, the study folder deleted while serving, a database write that fails,
# the docs against the code, and the page's resumed session on a shared machine.


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


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


# ---- 1. a per-rater order, the same at every visit -----------------------------------------


def test_two_raters_see_different_orders_and_one_rater_the_same_at_every_visit(
    synthetic_study,
):
    study = load_study(synthetic_study)
    assert study.order == "rater"  # what a new build writes
    manifest = [(s.id, tuple(p.id for p in s.panels)) for s in study.scenes]
    store = AnswerStore(synthetic_study / DATABASE, study)
    with TestClient(create_app(study, store)) as client:
        alice = _order(client.get("/api/raters/alice").json())
        # a reload, a resumed session, the id typed in another case: the same order
        assert _order(client.get("/api/raters/alice").json()) == alice
        assert _order(client.get("/api/raters/ALICE").json()) == alice
        bob = _order(client.get("/api/raters/bob").json())
        orders = [_order(client.get(f"/api/raters/r{i}").json()) for i in range(40)]
    store.close()
    assert alice != bob

    def content(order):
        return sorted((s, tuple(sorted(p))) for s, p in order)

    for order in (alice, bob, *orders):  # a permutation of the scenes and of each scene's panels
        assert content(order) == content(manifest)
    # scenes are permuted, and panels within each scene: every scene comes first for some
    # rater, every panel first within its scene for some rater
    assert {o[0][0] for o in orders} == {s for s, _ in manifest}
    for sid, panels in manifest:
        firsts = {dict(o)[sid][0] for o in orders}
        assert firsts == set(panels)
    # a server started again (another process, another hash seed) gives the same order
    code = ("import json, sys; from trajpref.survey.manifest import load_study; "
            "s = load_study(sys.argv[1]); "
            "o = s.rater_order('Alice'); "
            "print(json.dumps([[x.id, [p.id for p in ps]] for x, ps in o]))")  # fmt: skip
    for seed in ("1", "2"):
        out = subprocess.run([sys.executable, "-c", code, str(synthetic_study)], check=True,
                             capture_output=True, text=True,
                             env={**os.environ, "PYTHONHASHSEED": seed}).stdout  # fmt: skip
        assert [(s, tuple(p)) for s, p in json.loads(out)] == alice


def test_a_study_without_order_keeps_the_fixed_order_for_every_rater(synthetic_study):
    _fixed(synthetic_study)
    study = load_study(synthetic_study)
    assert study.order == "fixed"
    manifest = [(s.id, tuple(p.id for p in s.panels)) for s in study.scenes]
    store = AnswerStore(synthetic_study / DATABASE, study)
    for rater in ("alice", "bob", "r7"):
        assert _order(store.progress(rater)) == manifest
    store.close()
