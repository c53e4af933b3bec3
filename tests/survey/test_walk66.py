"""Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
position effect fell on the same method for every rater), and the ground truth's PNG was the
smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
order of their own, each answer is stored with where it was shown, analyze checks for a
position effect, and the pictures of a scene have one byte size."""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import os
import sqlite3
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import stats
from starlette.testclient import TestClient

from trajpref.cli import main
from trajpref.survey.analyze import analyze, run_analysis, wilcoxon
from trajpref.survey.export import export_csv
from trajpref.survey.manifest import DATABASE, GROUND_TRUTH, MANIFEST, load_study
from trajpref.survey.server import create_app
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerStore
from trajpref.survey.study import (
    SceneData,
    ground_truth_panel,
    make_synthetic_study,
    png_chunks,
    scene_limits,
    shown_predictions,
    stored_png,
    write_study,
)
from trajpref.viz.plot import plot_panel

METHODS = ("methodalpha", "methodbeta")  # as in conftest.py
OK = {"social": 4, "kinetics": 2}


def _order(got: dict) -> list[tuple[str, tuple[str, ...]]]:
    """``progress()["order"]`` as ``[(scene, (panel, ...)), ...]``."""
    return [(o["scene"], tuple(o["panels"])) for o in got["order"]]


def _positions(path: Path) -> dict[tuple[str, str, str], tuple]:
    with contextlib.closing(sqlite3.connect(path)) as db:
        rows = db.execute("SELECT rater, scene, panel, scene_position, panel_position "
                          "FROM answers").fetchall()  # fmt: skip
    return {r[:3]: r[3:] for r in rows}


def _fixed(folder: Path) -> None:
    """Make ``folder``'s manifest one of a study built before per-rater orders (no
    ``order``): what every rater of it saw was the manifest's order."""
    manifest = json.loads((folder / MANIFEST).read_text())
    del manifest["order"]
    (folder / MANIFEST).write_text(json.dumps(manifest))


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


def test_build_fixed_order_writes_a_fixed_study(tmp_path, tiny_run, walks, capsys):
    out = tmp_path / "fixed"
    code = main(["survey", "build", "--dataset", str(walks), "--units", "m", "--models",
                 "a=cv", f"b={tiny_run / 'generator.safetensors'}", "--scenes", "2",
                 "--samples", "2", "--min-gap", "0", "--device", "cpu", "--no-progress",
                 "--fixed-order", "--out", str(out)])  # fmt: skip
    assert code == 0
    study = load_study(out)
    assert study.order == "fixed" and study.build["fixed_order"] is True
    assert json.loads((out / MANIFEST).read_text())["order"] == "fixed"
    assert study.rater_order("x") == study.rater_order("y")


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


def test_simulate_answers_in_each_raters_order_with_the_same_ratings_as_a_fixed_order(
    synthetic_study, tmp_path
):
    import shutil

    fixed = Path(shutil.copytree(synthetic_study, tmp_path / "fixed"))
    _fixed(fixed)
    ratings = {}
    for folder in (synthetic_study, fixed):
        study = load_study(folder)
        store = AnswerStore(folder / DATABASE, study)
        simulate(study, store, SimulateConfig(raters=3))
        store.close()
        for (rater, scene, panel), where in _positions(folder / DATABASE).items():
            assert where == study.positions(rater)[(scene, panel)][:2]
        with contextlib.closing(sqlite3.connect(folder / DATABASE)) as db:
            ratings[folder] = sorted(db.execute("SELECT rater, scene, panel, social, kinetics "
                                                "FROM answers").fetchall())  # fmt: skip
    assert ratings[synthetic_study] == ratings[fixed]  # no position effect in these raters
    per_rater = _positions(synthetic_study / DATABASE)
    assert len({per_rater[(r, "s01", "A")] for r in ("synthetic-01", "synthetic-02",
                                                    "synthetic-03")}) > 1  # fmt: skip


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


# ---- 4. export: the position that rater saw --------------------------------------------------


def test_export_gives_each_row_the_position_its_rater_saw(synthetic_study, tmp_path):
    study = load_study(synthetic_study)
    store = AnswerStore(synthetic_study / DATABASE, study)
    simulate(study, store, SimulateConfig(raters=4))
    store.close()
    export_csv(synthetic_study, tmp_path / "a.csv")
    with open(tmp_path / "a.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 * study.num_panels
    seen: dict[tuple[str, str], set[str]] = {}
    for r in rows:
        want = study.positions(r["rater"])[(r["scene"], r["panel"])]
        assert (int(r["scene_position"]), int(r["panel_position"]), int(r["position"])) == want
        seen.setdefault((r["scene"], r["panel"]), set()).add(r["position"])
    assert any(len(v) > 1 for v in seen.values())  # not one place for every rater
    for rater in {r["rater"] for r in rows}:  # each rater's positions are 1..N
        mine = sorted(int(r["position"]) for r in rows if r["rater"] == rater)
        assert mine == list(range(1, study.num_panels + 1))


# ---- 5. analyze: the position-effect check -------------------------------------------------


def test_analyze_checks_for_a_position_effect_with_friedmans_test(synthetic_study):
    study = load_study(synthetic_study)
    rows, blocks = [], {}
    for i in range(6):
        rater = f"r{i}"
        where = study.positions(rater)
        for s in study.scenes:
            for p in s.panels:
                place = where[(s.id, p.id)][1]
                score = {1: 5, 2: 3, 3: 2}[place] if i % 2 else {1: 4, 2: 4, 3: 1}[place]
                rows.append((rater, "human", s.id, p.id, score, score, True))
                blocks.setdefault(rater, {})[place] = score  # the same in each of its scenes
    result = analyze(study, rows)
    check = result.position_effect
    assert check.order == "rater" and check.test == "Friedman"
    assert check.blocks == 6 and check.scenes == 18  # the raters are the blocks
    expected = stats.friedmanchisquare(*[[b[j] for b in blocks.values()] for j in (1, 2, 3)])
    assert check.statistic == pytest.approx(expected.statistic)
    assert check.p == pytest.approx(expected.pvalue) and check.p < 0.01
    assert [(r["position"], r["answers"], r["mean"]) for r in check.positions] == [
        (1, 18, 4.5), (2, 18, 3.5), (3, 18, 1.5)]  # fmt: skip
    md = result.markdown()
    assert "## Position effect" in md and "| 1 | 18 | 4.50 ± 0.51 |" in md
    assert "Friedman test over 6 raters (each one block" in md and "position effect" in md
    assert "18 (rater, scene) pairs in all" in md and "raters are independent" in md
    js = result.to_dict()["position_effect"]
    assert js["test"] == "Friedman" and js["blocks"] == 6 and js["scenes"] == 18
    # a fixed-order study: the report says that place and method cannot be told apart
    fixed = analyze(dataclasses.replace(study, order="fixed"), rows)
    assert "cannot be told from a difference between methods" in fixed.markdown()


def test_the_position_test_takes_raters_as_blocks_a_hand_made_case(synthetic_study):
    """Review of walkthrough 66: the test took every (rater, scene) pair as an independent
    block, so a rater's many scenes counted as many raters. Three raters, three scenes of three
    pictures; each rater's mean score per place (over the scenes in which they answered every
    picture) is one block: ranks (3, 2, 1), (3, 2, 1), (1, 3, 2), rank sums 7, 7, 4, so
    chi2 = 12 / (3 * 3 * 4) * (49 + 49 + 16) - 3 * 3 * 4 = 2 and p = exp(-1). Taken over the
    8 complete (rater, scene) pairs, the same answers gave p = 0.053, a seventh of it."""
    study = load_study(synthetic_study)
    # per rater: place -> (social, kinetics) in every scene; the human score is their mean
    plan = {"r0": {1: (5, 4), 2: (3, 3), 3: (2, 2)},  # 4.5, 3, 2
            "r1": {1: (4, 4), 2: (4, 3), 3: (1, 1)},  # 4, 3.5, 1
            "r2": {1: (2, 2), 2: (5, 5), 3: (3, 3)}}  # 2, 5, 3  # fmt: skip
    rows, pairs = [], {}
    for rater, scores in plan.items():
        where = study.positions(rater)
        for n, s in enumerate(study.scenes):
            for p in s.panels:
                place = where[(s.id, p.id)][1]
                social, kinetics = scores[place]
                if rater == "r2" and n < 2:  # r2's first two scenes: other scores, same means
                    social = kinetics = ((1, 5, 3), (3, 5, 3))[n][place - 1]
                if rater == "r1" and n == 2:  # r1 left a picture out: not in r1's means
                    if place == 3:
                        continue
                    social = kinetics = 1 if place == 1 else 5
                else:
                    pairs.setdefault((rater, s.id), {})[place] = (social + kinetics) / 2
                rows.append((rater, "human", s.id, p.id, social, kinetics, True))
    where = study.positions("r3")  # a rater without one complete scene: no block
    rows += [("r3", "human", s.id, p.id, 5, 5, True) for s in study.scenes for p in s.panels
             if where[(s.id, p.id)][1] != 2]  # fmt: skip
    check = analyze(study, rows).position_effect
    assert (check.test, check.blocks, check.scenes) == ("Friedman", 3, 3 + 2 + 3)
    assert check.statistic == pytest.approx(2.0)
    assert check.p == pytest.approx(np.exp(-1.0))
    # the (rater, scene) pairs as blocks, as before: one rater counted many times
    assert len(pairs) == 8
    old = stats.friedmanchisquare(*[[b[j] for b in pairs.values()] for j in (1, 2, 3)])
    assert old.pvalue == pytest.approx(0.0531, abs=1e-4) and old.pvalue < check.p / 5


def test_the_position_check_uses_wilcoxon_for_two_pictures_per_scene(tmp_path):
    study = make_synthetic_study(tmp_path / "two", scenes=3, methods=("a", "b"),
                                 ground_truth="reference")  # fmt: skip
    rows = []
    for i in range(5):
        where = study.positions(f"r{i}")
        rows += [(f"r{i}", "human", s.id, p.id, 5 - where[(s.id, p.id)][1], 3, True)
                 for s in study.scenes for p in s.panels]  # fmt: skip
    check = analyze(study, rows).position_effect
    assert check.test == "Wilcoxon signed-rank" and (check.blocks, check.scenes) == (5, 15)
    # five raters (not 15 pairs), each rating the first picture one point higher
    assert check.p == pytest.approx(wilcoxon(np.full(5, 4.0), np.full(5, 3.0))[1])
    assert check.p > 0.01


# ---- 6. the pictures of a scene have one byte size -----------------------------------------


def _decode(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _layout(data: bytes) -> list[tuple[bytes, int]]:
    """A PNG's chunks as (type, length): everything of its bytes but the pixels."""
    return [(kind, len(body)) for kind, body, _ in png_chunks(data)]


@pytest.mark.parametrize("which", ["tiny", "reference"])
def test_a_scenes_pictures_have_one_size_and_one_chunk_layout(which, tiny_study, tmp_path):
    """Review of walkthrough 66: a zero-filled padding chunk gave every picture one size, but
    its length (and IDAT's) still told the ground truth's (the smallest IDAT, the most
    padding) in every scene: now no chunk length differs, and the pixels are stored, not
    compressed."""
    folder = (tiny_study if which == "tiny" else make_synthetic_study(
        tmp_path / "ref", scenes=2, methods=METHODS, ground_truth="reference").folder)  # fmt: skip
    study = load_study(folder)
    for s in study.scenes:
        files = [folder / "images" / p.image for p in s.panels]
        files += [folder / "images" / s.reference] if s.reference else []
        data = [f.read_bytes() for f in files]
        assert len({len(d) for d in data}) == 1, [len(d) for d in data]
        layouts = [_layout(d) for d in data]  # well formed, every CRC right
        assert all(lay == layouts[0] for lay in layouts), layouts
        assert [k for k, _ in layouts[0]] == [b"IHDR", b"IDAT", b"IEND"]  # no text chunk
        for d in data:
            chunks = dict((k, body) for k, body, _ in png_chunks(d))
            w, h = int.from_bytes(chunks[b"IHDR"][:4], "big"), int.from_bytes(
                chunks[b"IHDR"][4:8], "big")  # fmt: skip
            assert chunks[b"IHDR"][8:] == bytes([8, 2, 0, 0, 0])  # 8-bit RGB
            raw = zlib.decompress(chunks[b"IDAT"])
            assert len(raw) == h * (1 + 3 * w)
            assert chunks[b"IDAT"] == zlib.compress(raw, 0)  # deflate stored blocks
            assert _decode(d).shape == (h, w, 3)


def test_stored_pictures_keep_the_pixels_of_the_render(tmp_path):
    """The uncompressed pictures decode to the pixels matplotlib drew (its PNG's, opaque)."""
    rng = np.random.default_rng(3)
    history = rng.normal(0, 1, (3, 8, 2)).cumsum(1)  # [P, T_h, 2]
    future = history[:, -1:] + rng.normal(0, 1, (3, 12, 2)).cumsum(1)  # [P, T_f, 2]
    pred = future[None] + rng.normal(0, 0.3, (6, 3, 12, 2)).cumsum(2)  # [K, P, T_f, 2]
    d_pred = 1 + rng.random((6, 3, 12))  # [K, P, T_f]
    panels = {"alpha": shown_predictions(pred, d_pred, np.ones((3, 12)), future, 2),
              GROUND_TRUTH: ground_truth_panel(future)}  # fmt: skip
    scene = SceneData(history, future, panels, "made#0", 0, 0)
    study = write_study(tmp_path / "s", [scene], [GROUND_TRUTH, "alpha"])
    limits = scene_limits(history, future, list(panels.values()))
    for p in study.scenes[0].panels:
        shown = panels[p.key.method]
        plot_panel(history, shown.paths, shown.weights, tmp_path / "own.png", limits, "m")
        drawn = np.asarray(Image.open(tmp_path / "own.png").convert("RGBA"))
        assert (drawn[..., 3] == 255).all()  # opaque: RGB loses nothing
        assert np.array_equal(_decode((study.folder / "images" / p.image).read_bytes()),
                              drawn[..., :3])  # fmt: skip


def test_a_stored_png_is_a_function_of_its_pixel_size_alone():
    a = stored_png(np.zeros((40, 30, 3), np.uint8))
    b = stored_png(np.random.default_rng(0).integers(0, 256, (40, 30, 3), dtype=np.uint8))
    assert len(a) == len(b) and _layout(a) == _layout(b)
    assert np.array_equal(_decode(b), np.asarray(Image.open(io.BytesIO(b))))
    with pytest.raises(ValueError, match="wrong CRC"):
        png_chunks(a[:-5] + b"\x00" + a[-4:])


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
