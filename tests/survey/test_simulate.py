"""survey simulate: synthetic raters, labelled as such, seeded, and following the error."""

import contextlib
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from survey.helpers import _fixed, _positions

from trajpref.errors import ConfigError
from trajpref.survey.manifest import DATABASE, GROUND_TRUTH, load_study
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerStore


def _answers(path):
    with sqlite3.connect(path) as db:
        return db.execute(
            "SELECT a.rater, r.kind, r.submitted_at IS NOT NULL, a.scene, a.panel, "
            "a.social, a.kinetics FROM answers a JOIN raters r USING (rater) "
            "ORDER BY 1, 4, 5"
        ).fetchall()


def test_every_synthetic_rater_answers_every_panel_and_is_labelled(store):
    ids = simulate(store.study, store, SimulateConfig(raters=5, seed=1))
    assert ids == [f"synthetic-0{i}" for i in range(1, 6)]
    rows = _answers(store.path)
    assert len(rows) == 5 * 9
    assert {r[1] for r in rows} == {"synthetic"} and all(r[2] for r in rows)
    assert all(1 <= r[5] <= 5 and 1 <= r[6] <= 5 for r in rows)


def test_simulation_is_seeded(store, synthetic_study, tmp_path):
    from trajpref.survey.manifest import load_study
    from trajpref.survey.store import AnswerStore

    simulate(store.study, store, SimulateConfig(raters=3, seed=7))
    other = AnswerStore(tmp_path / "b.sqlite", load_study(synthetic_study))
    simulate(other.study, other, SimulateConfig(raters=3, seed=7))
    assert [r[3:] for r in _answers(store.path)] == [r[3:] for r in _answers(other.path)]
    other.close()
    third = AnswerStore(tmp_path / "c.sqlite", load_study(synthetic_study))
    simulate(third.study, third, SimulateConfig(raters=3, seed=8))  # another seed, other ratings
    assert [r[3:] for r in _answers(store.path)] != [r[3:] for r in _answers(third.path)]
    third.close()


def test_synthetic_raters_prefer_small_errors(store):
    simulate(store.study, store, SimulateConfig(raters=30, seed=0))
    method = {(s.id, p.id): p.key.method for s in store.study.scenes for p in s.panels}
    score: dict[str, list[float]] = {}
    for _, _, _, scene, panel, social, kinetics in _answers(store.path):
        score.setdefault(method[(scene, panel)], []).append((social + kinetics) / 2)
    mean = {m: np.mean(v) for m, v in score.items()}
    # the synthetic study's second method has twice the noise of the first
    assert mean[GROUND_TRUTH] > mean["methodalpha"] > mean["methodbeta"]


def test_simulate_refuses_existing_ids_and_bad_settings(store):
    simulate(store.study, store, SimulateConfig(raters=2))
    with pytest.raises(ConfigError, match="already exist"):
        simulate(store.study, store, SimulateConfig(raters=3))
    assert len(simulate(store.study, store, SimulateConfig(raters=2, prefix="more"))) == 2
    with pytest.raises(ConfigError, match="raters"):
        SimulateConfig(raters=0)
    with pytest.raises(ConfigError, match="prefix"):
        SimulateConfig(prefix="a b")


def test_a_prefix_in_capitals_gives_lower_case_ids_and_meets_existing_ones(store):
    ids = simulate(store.study, store, SimulateConfig(raters=2, prefix="Pilot"))
    assert ids == ["pilot-01", "pilot-02"] and set(store.raters()) == set(ids)
    with pytest.raises(ConfigError, match="pilot-01, pilot-02 already exist"):
        simulate(store.study, store, SimulateConfig(raters=2, prefix="PILOT"))


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


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
