"""survey analyze: means, the Wilcoxon tests and their stars, agreement, the written report."""

import csv
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import _run
from scipy import stats
from survey.helpers import DOCS, _write

from trajpref.errors import ConfigError, DataError, DataWarning
from trajpref.survey import analyze as analyze_module
from trajpref.survey.analyze import analyze, holm, run_analysis, spearman, stars, wilcoxon
from trajpref.survey.manifest import (
    DATABASE,
    GROUND_TRUTH,
    Panel,
    PanelKey,
    Study,
    StudyScene,
    load_study,
)
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerStore
from trajpref.survey.study import (
    make_synthetic_study,
)

ATS = {"A": (0.5, 0.3), "B": (0.2, 0.1), "C": (-0.1, -0.4)}
"""ATS per method in scenes s1, s2; FTS is ATS - 1."""


def _study(methods=("A", "B", "C")) -> Study:
    scenes = []
    for j, sid in enumerate(("s1", "s2")):
        panels = []
        for i, m in enumerate(methods):
            ats = 0.0 if m == GROUND_TRUTH else ATS[m][j]
            fts = 0.0 if m == GROUND_TRUTH else ats - 1
            key = PanelKey(m, ats, fts, 0.0, 0.0)
            panels.append(Panel("XYZW"[(i + j) % len(methods)], f"{sid}-{i}.png", key))
        scenes.append(StudyScene(sid, tuple(sorted(panels, key=lambda p: p.id))))
    return Study(
        folder=None, title="t", instructions="", methods=tuple(methods), scenes=tuple(scenes)
    )


def _ratings(deficit: int) -> list[int]:
    """Four ratings (social, kinetics in s1 and s2) summing to 20 - deficit."""
    r = [5, 5, 5, 5]
    for k in range(deficit):
        r[k % 4] -= 1
    return r


def _rows(study: Study, raters: int = 6, gt_deficit: int | None = None) -> list[tuple]:
    """Rater i (1..6) gives A all 5s, B a deficit of i points, C one of i + 6 points: each
    rater's mean is 5 (A), 5 - i/4 (B), 5 - (i + 6)/4 (C)."""
    rows = []
    for i in range(1, raters + 1):
        deficits = {"A": 0, "B": i, "C": i + 6, GROUND_TRUTH: gt_deficit}
        for m in study.methods:
            r = _ratings(deficits[m])
            for j, scene in enumerate(study.scenes):
                (panel,) = [p for p in scene.panels if p.key.method == m]
                rows.append((f"r{i}", "human", scene.id, panel.id, r[2 * j], r[2 * j + 1], True))
    return rows


def test_means_tests_and_agreement_on_a_hand_computed_case():
    study = _study()
    res = analyze(study, _rows(study))
    assert res.best == "A" and [r.method for r in res.rows] == ["A", "B", "C"]
    a, b, c = res.rows
    assert (a.human, a.human_sd) == (5.0, 0.0)
    assert b.human == pytest.approx(5 - 3.5 / 4) and c.human == pytest.approx(5 - 9.5 / 4)
    assert a.ats == pytest.approx(0.4) and a.ats_sd == pytest.approx(np.std([0.5, 0.3], ddof=1))
    assert b.fts == pytest.approx(0.15 - 1) and a.answers == 12
    assert res.raters == res.complete_raters == 6
    human = {t.other: t for t in res.tests if t.column == "human"}
    # six positive, distinct differences: W = 0 and the exact two-sided p = 2 / 2^6
    for t in human.values():
        assert (t.n, t.statistic, t.method) == (6, 0.0, "exact")
        assert t.p == pytest.approx(2 / 64)
        assert t.p_holm == pytest.approx(2 * 2 / 64) and t.mark == "ns"  # Holm over 2 tests
    ats = [t for t in res.tests if t.column == "ats"]
    assert len(ats) == 2 and all(t.n == 2 and t.p == pytest.approx(0.5) for t in ats)
    # humans rank the methods as ATS and FTS do, overall and within every scene
    for col in ("ats", "fts"):
        m = res.agreement["methods"][col]
        assert (m["n"], m["spearman"], m["kendall"]) == (3, pytest.approx(1.0), 1.0)
        assert m["spearman_p"] == pytest.approx(2 / 6)  # exact: 2 of the 3! orderings
        assert res.agreement["within_scene"][col]["kendall"] == 1.0
        assert res.agreement["panels"][col]["n"] == 6
        assert res.agreement["panels"][col]["spearman"] > 0.8
    assert "| **A** | 5.00 ± 0.00 | 0.40 ± 0.14 | -0.60 ± 0.14 |" in res.table()
    assert "| B | 4.12 ± 0.57 ns |" in res.table()  # sd of 4.5, 5, 4, 5, ..., 3, 4
    assert not res.synthetic and "SYNTHETIC" not in res.markdown()


def test_with_more_raters_the_difference_becomes_significant():
    study = _study()
    rows = _rows(study, raters=6)
    # 12 raters: six more who repeat the first six (ties: the normal approximation)
    rows += [(r[0] + "b", *r[1:]) for r in rows]
    res = analyze(study, rows)
    t = next(t for t in res.tests if t.column == "human" and t.other == "C")
    x = np.repeat([5.0] * 6, 2)
    y = np.tile(5 - (np.arange(1, 7) + 6) / 4, 2)
    expected = stats.wilcoxon(x, y, method="asymptotic").pvalue
    assert t.method == "normal approximation" and t.p == pytest.approx(expected)
    assert t.p < 0.01 and t.mark in ("**", "*")  # Holm doubles the smaller p


def test_the_ground_truth_is_rated_but_left_out_of_ats_tests_and_agreement():
    study = _study(("A", "B", "C", GROUND_TRUTH))
    res = analyze(study, _rows(study, gt_deficit=1))
    assert res.best == "A" and res.rows[-1].method == GROUND_TRUTH
    assert [t.other for t in res.tests if t.column == "ats"] == ["B", "C"]
    assert [t.other for t in res.tests if t.column == "human"] == ["B", "C", GROUND_TRUTH]
    assert res.agreement["methods"]["ats"]["n"] == 3
    assert "| ground truth | 4.75 ± 0.26" in res.table()  # 4.5 in s1, 5 in s2
    assert "0 (by definition)" in res.table()


def test_partial_raters_count_in_the_means_but_not_in_the_paired_test():
    study = _study()
    rows = _rows(study) + [("late", "human", "s1", "X", 1, 1, False)]
    res = analyze(study, rows)
    assert res.raters == 7 and res.complete_raters == 6
    assert {t.n for t in res.tests if t.column == "human"} == {6}


def test_rater_kinds_are_chosen_and_labelled():
    study = _study()
    synthetic = [(r[0], "synthetic", *r[2:]) for r in _rows(study)]
    res = analyze(study, synthetic)  # auto: no humans, so the synthetic raters
    assert res.synthetic and res.rater_kind == "synthetic"
    assert "SYNTHETIC RATERS" in res.markdown()
    with pytest.raises(ConfigError, match="no answers from human raters"):
        analyze(study, synthetic, "human")


def test_spearman_p_is_exact_for_few_pairs_and_matches_scipy():
    rng = np.random.default_rng(0)
    a = rng.normal(size=7)
    b = a + rng.normal(size=7)
    rho, p = spearman(a, b)
    exact = stats.permutation_test(
        (b,),
        lambda y: stats.spearmanr(a, y).statistic,
        permutation_type="pairings",
        n_resamples=np.inf,
    )
    assert rho == pytest.approx(stats.spearmanr(a, b).statistic) and p == pytest.approx(
        exact.pvalue
    )
    a, b = rng.normal(size=30), rng.normal(size=30)
    assert spearman(a, b) == pytest.approx(tuple(stats.spearmanr(a, b)))


def test_stars_and_holm():
    assert [stars(p) for p in (0.0005, 0.005, 0.03, 0.05, 0.2, math.nan)] == [
        "***",
        "**",
        "*",
        "ns",
        "ns",
        "n/a",
    ]
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    assert holm([0.5, math.nan]) == pytest.approx([0.5, math.nan], nan_ok=True)
    assert wilcoxon(np.ones(4), np.ones(4))[1:] == (1.0, "no differences")


def test_run_analysis_writes_markdown_json_and_figure(synthetic_study, store):
    from trajpref.survey.simulate import SimulateConfig, simulate

    simulate(store.study, store, SimulateConfig(raters=6))
    result, paths = run_analysis(synthetic_study)
    assert paths["markdown"].read_text().startswith("# Human evaluation")
    assert "SYNTHETIC" in paths["markdown"].read_text()
    data = json.loads(paths["json"].read_text())  # strict JSON: no NaN
    assert data["best"] == result.best and data["raters"] == 6
    assert paths["figure"].read_bytes()[:4] == b"\x89PNG"


def test_run_analysis_writes_nothing_for_a_corrupt_manifest_or_no_answers(synthetic_study):
    out = synthetic_study / "report"
    with pytest.raises(ConfigError, match="no answers yet"):
        run_analysis(synthetic_study, out=out)
    assert not out.exists() and not (synthetic_study / "answers.sqlite").exists()
    manifest = synthetic_study / "manifest.json"
    manifest.write_text(manifest.read_text()[:-40])
    with pytest.raises(DataError, match="corrupt manifest"):
        run_analysis(synthetic_study, out=out)
    assert not out.exists()


def _insert(path, *rows) -> None:
    """Answers added by hand (foreign keys off, as the sqlite3 tool adds them)."""
    import sqlite3

    now = "2026-12-05T00:00:00"
    with sqlite3.connect(path) as db:
        for rater, scene, panel in rows:
            db.execute("INSERT INTO answers (rater, scene, panel, social, kinetics, revision, "
                       "created_at, updated_at) VALUES (?, ?, ?, 3, 3, 1, ?, ?)",
                       (rater, scene, panel, now, now))  # fmt: skip
    db.close()


def test_answers_the_analysis_cannot_use_are_counted_in_a_warning_and_the_report(
    synthetic_study, store
):
    from trajpref.survey.simulate import SimulateConfig, simulate

    simulate(store.study, store, SimulateConfig(raters=3))
    _insert(store.path, ("synthetic-01", "S01", "A"), ("synthetic-02", "s01", "Z"),
            ("ghost", "s01", "A"))  # fmt: skip
    text = ("ignored: 3 answers (2 to scenes or panels this study does not have, 1 from "
            "raters not in the raters table)")  # fmt: skip
    with pytest.warns(DataWarning) as seen:
        result, paths = run_analysis(synthetic_study)
    assert [str(w.message) for w in seen] == [f"{store.path}: {text}"]
    assert result.raters == 3 and result.rows[0].answers == 9  # 3 raters x 3 scenes
    assert f"\nI{text[1:]}: they are not in the tables below.\n" in paths["markdown"].read_text()
    data = json.loads(paths["json"].read_text())
    assert data["ignored"] == {"answers": 3, "unknown_panels": 2, "unknown_raters": 1}


def test_when_every_answer_is_ignored_the_error_says_why(synthetic_study, store):
    _insert(store.path, ("ghost", "s01", "A"), ("ghost", "S02", "B"))
    with pytest.raises(ConfigError) as err:
        run_analysis(synthetic_study)
    assert str(err.value) == (
        "no answers to this study's panels yet; ignored: 2 answers (1 to scenes or panels "
        "this study does not have, 1 from raters not in the raters table)"
    )
    assert not (synthetic_study / "analysis.md").exists()


def test_the_output_paths_are_checked_before_anything_is_written(synthetic_study, store):
    from trajpref.survey.simulate import SimulateConfig, simulate

    simulate(store.study, store, SimulateConfig(raters=2))
    for taken in ("analysis.md", "analysis.json", "analysis.png"):
        out = synthetic_study.parent / f"out-{taken}"
        (out / taken).mkdir(parents=True)
        with pytest.raises(ConfigError) as err:
            run_analysis(synthetic_study, out=out)
        assert str(err.value) == f"cannot write {out / taken}: is an existing folder, not a file"
        assert [p.name for p in out.iterdir()] == [taken]  # nothing else written
    manifest = synthetic_study / "manifest.json"
    with pytest.raises(ConfigError) as err:
        run_analysis(synthetic_study, out=manifest)
    assert str(err.value) == f"--out {manifest}: exists and is not a folder"


def test_analysis_never_writes_into_the_database(synthetic_study, tmp_path):
    from trajpref.survey.manifest import DATABASE, load_study
    from trajpref.survey.simulate import SimulateConfig, simulate
    from trajpref.survey.store import AnswerStore

    store = AnswerStore(synthetic_study / DATABASE, load_study(synthetic_study))
    simulate(store.study, store, SimulateConfig(raters=2))
    store.close()
    before = store.path.read_bytes()
    run_analysis(synthetic_study, out=tmp_path / "report")
    assert store.path.read_bytes() == before
    empty = tmp_path / "empty.sqlite"
    empty.touch()
    with pytest.raises(ConfigError) as err:
        run_analysis(synthetic_study, db=empty, out=tmp_path / "r2")
    assert str(err.value) == (
        f"{empty}: not an answers database (no answers and raters tables; it holds no table)"
    )
    assert empty.read_bytes() == b"" and not (tmp_path / "r2").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty.sqlite", "report", "study"]


# ---- leaving raters out, ids that differ by case, units ------------------------------------
def test_excluded_raters_are_left_out_and_named():
    study = _study()
    rows = _rows(study)
    full = analyze(study, rows)
    result = analyze(study, rows, exclude=["r1", "r6"])
    assert (full.raters, result.raters, result.complete_raters) == (6, 4, 4)
    assert result.excluded == ["r1", "r6"] and result.excluded_answers == 2 * 6
    a = next(r for r in result.rows if r.method == "B")
    assert a.human == pytest.approx(5 - np.mean([2, 3, 4, 5]) / 4)  # raters 2..5 only
    text = result.markdown()
    assert "Excluded raters (--exclude-rater): r1, r6 (12 answers)" in text
    assert result.to_dict()["excluded"] == ["r1", "r6"]


def test_excluding_every_human_rater_is_an_error_not_a_switch_to_synthetic_raters():
    study = _study()
    rows = _rows(study, raters=2)
    rows += [("syn-1", "synthetic", *r[2:]) for r in rows if r[0] == "r1"]
    with pytest.raises(ConfigError, match="no answers from human raters left after "
                       "--exclude-rater r1, r2"):  # fmt: skip
        analyze(study, rows, exclude=["r1", "r2"])


def test_rater_ids_that_differ_only_by_case_are_reported():
    study = _study()
    rows = [(r[0].replace("r1", "R2"), *r[1:]) for r in _rows(study)]  # R2 and r2: one person?
    result = analyze(study, rows)
    assert result.case_variants == [["R2", "r2"]] and result.raters == 6
    assert "Rater ids that differ only by case, counted as different raters: R2 = r2" in (
        result.markdown()
    )


def test_a_tie_for_the_best_method_is_said():
    study = _study(("A", "B"))
    rows = [r for r in _rows(study) if r[0] == "r1"]
    rows = [(*r[:4], 5, 5, True) for r in rows]  # A and B both all 5s
    assert "**A** has the highest (tied with B:" in analyze(study, rows).legend()


@pytest.mark.parametrize("units, label", [("m", "ADE of the shown futures [m]"),
                                          ("px", "ADE of the shown futures [px]"),
                                          ("unknown", "ADE of the shown futures (units "
                                                      "unknown)")])  # fmt: skip
def test_the_figure_and_the_report_name_each_axis_unit(units, label):
    from trajpref.survey.analyze import figure_data

    study = _study()
    study = Study(**{**study.__dict__, "dataset": {"units": units}})
    result = analyze(study, _rows(study))
    names, columns, marks, xlims = figure_data(result)
    assert list(columns) == ["human score (rating 1-5)", "ATS (ratio, no unit)",
                             "FTS (ratio, no unit)", label]  # fmt: skip
    assert xlims == {"human score (rating 1-5)": (0.0, 5.4)} and names[0] == "A"
    assert set(marks) == set(list(columns)[:3])
    ade = "ADE [px]" if units == "px" else "ADE [m]" if units == "m" else "ADE (units unknown)"
    assert f"| answers | {ade} |" in result.markdown()


def test_the_report_files_are_owner_only_and_the_figure_is_not(synthetic_study, store):
    import os

    from trajpref.survey.simulate import SimulateConfig, simulate

    simulate(store.study, store, SimulateConfig(raters=2))
    old = os.umask(0o022)
    try:
        _, paths = run_analysis(synthetic_study, out=synthetic_study.parent / "new" / "report")
    finally:
        os.umask(old)
    modes = {k: oct(p.stat().st_mode & 0o777) for k, p in paths.items()}
    assert modes == {"markdown": "0o600", "json": "0o600", "figure": "0o644"}


def test_run_analysis_finds_excluded_raters_in_any_case_and_refuses_unknown_ones(
    synthetic_study, store
):
    from trajpref.survey.simulate import SimulateConfig, simulate

    simulate(store.study, store, SimulateConfig(raters=3))
    result, _ = run_analysis(synthetic_study, exclude=["SYNTHETIC-02"])
    assert result.excluded == ["synthetic-02"] and result.raters == 2
    with pytest.raises(ConfigError) as err:
        run_analysis(synthetic_study, exclude=["synthetic-2"])
    assert str(err.value) == (
        f"--exclude-rater synthetic-2: no such rater in {store.path} (did you mean "
        "synthetic-02?); its raters: synthetic-01, synthetic-02, synthetic-03"
    )


# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


def _study_with_truth(methods=("A", "B", GROUND_TRUTH), scenes=("s1", "s2")) -> Study:
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
    study = _study_with_truth()
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
    study = _study_with_truth(methods=("B", "A", GROUND_TRUTH))
    res = analyze(study, [("pilot", "human", "s1", "Y", 3, 4, False)])  # Y: method A
    assert [r.method for r in res.rows] == ["A", "B", GROUND_TRUTH]


def test_a_method_with_fewer_than_two_answers_names_no_best_method():
    study = _study_with_truth(
        scenes=("s1",)
    )  # one scene: one complete rater gives one answer a method
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

    study = _study_with_truth()
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


def test_select_rows_error_without_other_raters_has_no_hint():
    study = _study_with_truth()
    rows = _complete(study, "r1", "human", {"A": 3, "B": 3, GROUND_TRUTH: 3})
    with pytest.raises(ConfigError) as err:
        analyze(study, rows, exclude=["r1"])
    assert str(err.value) == "no answers from human raters left after --exclude-rater r1"


# Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
# with a trailing newline, the study folder deleted while serving, a database write that fails,
# the docs against the code, and the page's resumed session on a shared machine.


# ---- 6. the docs against the code -----------------------------------------------------------


def test_the_docs_ground_truth_rows_carry_the_mark_analyze_prints():
    rows = [line for line in DOCS.read_text().splitlines() if line.startswith("| ground truth |")]
    assert len(rows) == 2
    assert all("*** ↑ |" in row for row in rows), rows


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


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
