"""survey analyze: means, the Wilcoxon tests and their stars, agreement, the written report."""

import json
import math

import numpy as np
import pytest
from scipy import stats

from trajpref.errors import ConfigError, DataError
from trajpref.survey.analyze import analyze, holm, run_analysis, spearman, stars, wilcoxon
from trajpref.survey.manifest import GROUND_TRUTH, Panel, PanelKey, Study, StudyScene

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
    with pytest.warns(UserWarning) as seen:
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
