"""survey export: the answers as CSV rows."""

import csv

from trajpref.survey.export import export_csv
from trajpref.survey.manifest import DATABASE, load_study
from trajpref.survey.simulate import SimulateConfig, simulate
from trajpref.survey.store import AnswerStore

# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


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
