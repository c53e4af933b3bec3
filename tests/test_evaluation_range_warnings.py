"""The CLI's ``evaluate``, ``predict`` and ``plot`` (and Python's ``evaluate``) warn of one's own
data outside the models' range as ``predict_scenes`` does (``evaluation.warn_observed_pace``,
``models.timing.observed_problems``; walkthrough 68): agents faster than training for a model
without an input speed clamp (``FAST_LIMIT``) and a window wider than training for a model
without a neighbour radius (``WIDE_LIMIT``, measured per window, not across the split), beside
the other-units and id-switch warnings, which keep their precedence."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import FAST, UNITS, WIDE

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.evaluation import evaluate, warn_observed_pace
from trajpref.models.timing import FAST_LIMIT, WIDE_LIMIT
from trajpref.types import AGENT_PERSON, DatasetInfo, Scene, TrajectoryDataset

JUMP = "jumps more than 5 model units"


def _folder(root, pace: float = 0.5, gap: float = 2.0, jump: float = 0.0):
    """``test/walk.txt`` (frame, id, x, y; 10 frames a step, metres): three walkers for 20
    steps (one window of 8 + 12) at ``pace`` metres a step along x, ``gap`` metres apart
    along y; walker 1 jumps ``jump`` metres along y at its 4th step."""
    rows = []
    for k in range(20):
        for a in (1, 2, 3):
            y = gap * (a - 1) + (jump if a == 1 and k >= 4 else 0.0)
            rows.append(f"{10 * k}\t{a}\t{pace * k:.2f}\t{y:.2f}")
    (root / "test").mkdir(parents=True)
    (root / "test" / "walk.txt").write_text("\n".join(rows) + "\n")
    return str(root)


def _run(tmp_path, capsys, command: str, data: str, model: str, interval: str,
         *options: str) -> str:  # fmt: skip
    """``command`` run on ``data`` with ``model`` (and ``options``); it must succeed: its
    stderr."""
    argv = [command, "--dataset", data, "--model", model, "--units", "m",
            "--frame-interval", interval, "--no-progress", *options]  # fmt: skip
    if command != "evaluate":
        argv += ["--out", str(tmp_path / ("p.npz" if command == "predict" else "f.png"))]
    capsys.readouterr()
    assert main(argv) == 0
    return capsys.readouterr().err


# --- the CLI, on published models ------------------------------------------------------------


@pytest.mark.parametrize("command", ["predict", "evaluate", "plot"])
def test_a_walker_one_kilometre_away_is_warned_of_by_the_cli(tmp_path, capsys, command):
    data = _folder(tmp_path / "wide", gap=1000.0)  # 680 of zara1's model units apart
    err = _run(tmp_path, capsys, command, data, "zara1/generator", "0.4")
    assert err.count(WIDE) == 1 and "--neighbour-radius" in err
    assert FAST not in err and UNITS not in err


def test_a_neighbour_radius_silences_the_wide_warning(tmp_path, capsys):
    data = _folder(tmp_path / "wide", gap=1000.0)
    err = _run(tmp_path, capsys, "predict", data, "zara1/generator", "0.4",
               "--neighbour-radius", "12")  # fmt: skip
    assert WIDE not in err


@pytest.mark.parametrize("command", ["predict", "evaluate"])
def test_agents_faster_than_training_are_warned_of_for_a_model_without_a_clamp(
    tmp_path, capsys, command
):
    data = _folder(tmp_path / "fast", pace=3.8)  # 2.2 of robo's model units a step
    err = _run(tmp_path, capsys, command, data, "robo/generator", "0.5")
    assert err.count(FAST) == 1 and "--max-speed" in err and "0.280 for robo" in err
    assert WIDE not in err and UNITS not in err and JUMP not in err


def test_the_same_agents_given_max_speed_are_not_warned_of(tmp_path, capsys):
    data = _folder(tmp_path / "fast", pace=3.8)
    err = _run(tmp_path, capsys, "predict", data, "robo/generator", "0.5", "--max-speed", "0.280")
    assert FAST not in err


@pytest.mark.parametrize(("model", "interval"), [("zara1/generator", "0.4"),
                                                 ("robo/generator", "0.5")])  # fmt: skip
def test_ordinary_walkers_are_warned_of_neither(tmp_path, capsys, model, interval):
    err = _run(tmp_path, capsys, "evaluate", _folder(tmp_path / "calm"), model, interval)
    assert FAST not in err and WIDE not in err and UNITS not in err and JUMP not in err


def test_python_evaluate_warns_of_a_wide_window(tmp_path):
    from trajpref.models.registry import load_predictor

    data = load_dataset(_folder(tmp_path / "wide", gap=1000.0), "test", frame_interval=0.4,
                        units="m")  # fmt: skip
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        evaluate(load_predictor("zara1/generator"), data, num_samples=2, progress=False)
    texts = [str(w.message) for w in seen if WIDE in str(w.message)]
    assert len(texts) == 1 and texts[0].endswith("[the model: zara1/generator]")


# --- warn_observed_pace's rules, on stand-in models ------------------------------------------


class _Model:
    """A predictor's attributes the checks read: data scale 1, no radius, no clamp."""

    scale = 1.0
    units = "m"
    neighbour_radius = None


class _Clamped(_Model):
    sampler = "leapfrog"

    class generator:  # noqa: N801 - the attribute the speed clamp is read from
        class cfg:  # noqa: N801
            max_speed = 0.3


def _scene(pace: float, gap: float, at: float = 0.0) -> Scene:
    """Two walkers ``gap`` apart along y, at ``pace`` a step along x from x = ``at``."""
    steps = np.arange(20)[:, None] * [pace, 0.0] + [at, 0.0]  # [20, 2]
    track = np.stack([steps, steps + [0.0, gap]])  # [2, 20, 2]
    return Scene(track[:, :8], track[:, 8:], np.full(2, AGENT_PERSON), "s")


def _data(*scenes: Scene) -> TrajectoryDataset:
    return TrajectoryDataset(list(scenes), DatasetInfo("mine", "test", "m", 0.4))


def _warned(checked, dataset) -> list[str]:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        said = warn_observed_pace(checked, dataset)
    texts = [str(w.message) for w in seen]
    assert said == bool(texts)
    return texts


def test_widths_are_measured_per_window_not_across_the_split():
    near = _data(_scene(0.3, 2.0), _scene(0.3, 2.0, at=5000.0))  # windows 5 km apart
    assert _warned([("m", _Model())], near) == []
    wide = _data(_scene(0.3, 2.0), _scene(0.3, 1.01 * WIDE_LIMIT))
    shown = _warned([("m", _Model())], wide)
    assert len(shown) == 1 and shown[0].startswith("m is given a scene") and WIDE in shown[0]
    assert _warned([("m", _Model())], _data(_scene(0.3, 0.99 * WIDE_LIMIT))) == []


def test_fast_and_wide_are_both_said_and_other_units_alone():
    both = _warned([("m", _Model())], _data(_scene(1.5 * FAST_LIMIT, 2 * WIDE_LIMIT)))
    assert len(both) == 2 and FAST in both[0] and WIDE in both[1]
    alone = _warned([("m", _Model())], _data(_scene(10.0, 2 * WIDE_LIMIT)))  # above PACE_LIMIT
    assert len(alone) == 1 and UNITS in alone[0]


def test_each_cause_once_for_the_first_that_has_it():
    data = _data(_scene(1.5 * FAST_LIMIT, 2 * WIDE_LIMIT))
    shown = _warned([("the model", _Clamped()), ("the scorer", _Model())], data)
    # the clamped model is warned of the width; its scorer, without a clamp, of the pace
    assert [t.split(" is given")[0] for t in shown] == ["the model", "the scorer"]
    assert WIDE in shown[0] and FAST in shown[1]
    twice = _warned([("the model", _Model()), ("the scorer", _Model())], data)
    assert [t.split(" is given")[0] for t in twice] == ["the model", "the model"]
