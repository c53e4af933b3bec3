"""The CLI on sports data: evaluate --agents persons (the ball left out of every metric, and
recorded), --max-scenes for evaluate and predict (a subset, recorded and noted), and plot's
per-agent printout naming the ball."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import _run


@pytest.fixture
def court(tmp_path):
    """A folder of one file: a ball (id -1) and two players, 30 frames (11 windows), types in a
    5th column, metres at 0.12 s."""
    rows = []
    for f in range(30):
        bounce = 0.5 * (f % 3)  # the ball moves unlike the walkers: a constant velocity misses
        rows.append(f"{f * 12} -1 {0.9 * f:.2f} {bounce:.2f} BALL")
        rows += [f"{f * 12} {a} {0.2 * f:.2f} {3.0 * a:.2f} PLAYER" for a in (5, 7)]
    (tmp_path / "d" / "test").mkdir(parents=True)
    (tmp_path / "d" / "test" / "game.txt").write_text("\n".join(rows) + "\n")
    return ["--dataset", tmp_path / "d", "--units", "m", "--frame-interval", "0.12",
            "--model", "cv", "--samples", "1", "--no-progress"]  # fmt: skip


def test_evaluate_persons_leaves_the_ball_out_and_records_it(capsys, court, tmp_path):
    code, out, _ = _run(capsys, "evaluate", *court, "--json")
    every = json.loads(out)
    assert code == 0 and every["agent_set"] == "all" and every["agents"] == 33
    code, out, _ = _run(capsys, "evaluate", *court, "--agents", "persons", "--json", "--out",
                        tmp_path / "p.json")  # fmt: skip
    persons = json.loads(out)
    assert code == 0 and persons["agent_set"] == "persons" and persons["agents"] == 22
    assert json.loads((tmp_path / "p.json").read_text())["agent_set"] == "persons"
    assert persons["min_ade"] == pytest.approx(0.0, abs=1e-5)  # players walk straight
    assert every["min_ade"] > 0.05  # the bouncing ball's error, in the all-agents number
    code, out, _ = _run(capsys, "evaluate", *court, "--agents", "persons")
    assert "(protocol all, persons only)" in out and "(22 persons, 11 scenes" in out
    code, _, err = _run(capsys, "evaluate", *court, "--agents", "persons", "--in-context", "40")
    assert code == 2 and "--in-context does not combine with --agents persons" in err


def test_max_scenes_evaluates_and_predicts_an_evenly_spaced_subset(capsys, court, tmp_path):
    code, out, err = _run(capsys, "evaluate", *court, "--max-scenes", "3", "--json")
    res = json.loads(out)
    assert code == 0 and res["scenes"] == 3 and res["agents"] == 9
    assert res["max_scenes"] == 3 and res["split_scenes"] == 11
    assert ("note: --max-scenes 3: 3 of the split's 11 scenes, evenly spaced; the numbers are "
            "this subset's, not the split's") in err  # fmt: skip
    code, out, err = _run(capsys, "evaluate", *court, "--json")
    assert json.loads(out)["max_scenes"] is None and "note" not in err
    npz = tmp_path / "p.npz"
    code, out, err = _run(capsys, "predict", *court, "--max-scenes", "3", "--out", npz)
    assert code == 0 and "3 of the split's 11 scenes" in err
    with np.load(npz) as saved:
        meta = json.loads(str(saved["meta"]))
        ids = saved["scene_id"].tolist()
    assert meta["max_scenes"] == 3 and meta["split_scenes"] == 11
    assert ids == ["game.txt@frame=0", "game.txt@frame=60", "game.txt@frame=120"]  # 0, 5, 10
    code, _, err = _run(capsys, "evaluate", *court, "--max-scenes", "0")
    assert code == 2 and "--max-scenes must be >= 1, got 0" in err


def test_plot_names_the_ball_in_its_printout(capsys, court, tmp_path):
    code, out, _ = _run(capsys, "plot", *court, "--out", tmp_path / "f.png")
    assert code == 0
    lines = [line.strip() for line in out.splitlines() if line.strip().startswith("agent ")]
    assert lines[0].startswith("agent 0 (the ball): minADE")
    assert lines[1].startswith("agent 1: minADE") and lines[2].startswith("agent 2: minADE")
