"""Data in other units than the model's (centimetres given to a metre model): the generator's
speed clamp hides it and the score's ranking does not, so every entry point warns when the
observed pace is far above the model's training (``models.timing.check_observed_steps``)."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from helpers import UNITS
from synthetic import write_tracks

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.models.registry import load_predictor
from trajpref.models.timing import PACE_LIMIT, pace_problem, pace_quantile
from trajpref.score import TrajectoryScorer, predict_scene, predict_scenes, rank_samples
from trajpref.score.selection import SelectionConfig, select_for_scene


class _Scaled:
    scale = 1.5
    units = "m"


def _walkers(step: float, agents: int = 3) -> np.ndarray:
    """[P, 8, 2] agents walking ``step`` data units per step along x."""
    t = np.arange(8, dtype=np.float32)[None, :, None]  # [1, 8, 1]
    start = np.arange(agents, dtype=np.float32)[:, None, None]  # [P, 1, 1]
    return np.concatenate([start + step * t, np.broadcast_to(start, (agents, 8, 1))], -1)


def _pace_warnings(record) -> list[str]:
    return [str(w.message) for w in record if UNITS in str(w.message)]


def test_pace_problem_names_the_units_and_reads_the_same_at_every_call():
    assert pace_quantile(_walkers(0.6), 1.5)[0] == pytest.approx(0.4)
    assert pace_quantile(_walkers(60.0), 1.5)[0] == pytest.approx(40.0)
    assert pace_problem(_Scaled(), _walkers(0.6)) is None  # 1.5 m/s at 0.4 s
    text = pace_problem(_Scaled(), _walkers(60.0), "zara1/generator")  # the same in cm
    assert text.startswith("zara1/generator is given agents much faster")
    assert UNITS in text and "(m;" in text
    # the same text for another scene of the same mistake: a planner's loop is warned once
    assert pace_problem(_Scaled(), _walkers(45.0), "zara1/generator") == text
    # one agent at 52 "m" per step (130 m/s at 0.4 s) alone in its scene
    assert pace_problem(_Scaled(), _walkers(52.0, 1)) is not None
    # one mistracked agent among ten standing ones is not taken for the data's units
    scene = np.concatenate([_walkers(0.0, 10), _walkers(52.0, 1)])
    assert pace_problem(_Scaled(), scene) is None
    # just below and above the limit; a model without a data scale (cv) reads any units
    assert pace_problem(_Scaled(), _walkers(PACE_LIMIT * 1.5 * 0.99)) is None
    assert pace_problem(_Scaled(), _walkers(PACE_LIMIT * 1.5 * 1.01)) is not None
    assert pace_problem(object(), _walkers(60.0)) is None


@pytest.fixture(scope="module")
def model(tiny_run):
    return load_predictor(str(tiny_run / "generator.safetensors"), device="cpu")


@pytest.fixture(scope="module")
def scorer(tiny_run):
    return TrajectoryScorer.from_checkpoint(tiny_run / "denoiser.safetensors", steps=[0])


@pytest.fixture(scope="module")
def scene(walks):
    return load_dataset(str(walks), "test").scenes[0]


def test_python_calls_warn_once_for_centimetres(model, scorer, scene):
    history = scene.history
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        samples = predict_scene(model, history, 4)
        rank_samples(scorer, history, samples)
        select_for_scene(scorer, history, samples, SelectionConfig(keep=2))
    assert _pace_warnings(record) == []
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        predict_scene(model, history * 100, 4)
        predict_scenes(model, [history * 100, history * 100], 4)  # one call, one warning
        rank_samples(scorer, history * 100, samples * 100)
        select_for_scene(scorer, history * 100, samples * 100, SelectionConfig(keep=2))
    found = _pace_warnings(record)
    assert len(found) == 4
    assert [w.filename for w in record if UNITS in str(w.message)] == [__file__] * 4
    assert found[2].startswith("this scorer is given agents")


def _centimetres(walks: Path, root: Path) -> Path:
    """The walks' test split with every position in centimetres."""
    test = load_dataset(str(walks), "test")
    rows = []
    for s in test.scenes[:1]:
        for a, track in enumerate(np.concatenate([s.history, s.future], 1)):
            rows += [(10 * t, a + 1, float(x) * 100, float(y) * 100) for t, (x, y) in
                     enumerate(track)]  # fmt: skip
    write_tracks(root / "test" / "walk0.txt", rows)
    return root


def test_cli_warns_once_per_run_for_centimetres(tiny_run, walks, tmp_path, capsys):
    generator = tiny_run / "generator.safetensors"
    cm = _centimetres(walks, tmp_path / "cm")
    for data, expected in ((walks, 0), (cm, 1)):
        for argv in (["evaluate", "--samples", "4"],
                     ["predict", "--samples", "4", "--out", tmp_path / "p.npz"],
                     ["plot", "--samples", "4", "--out", tmp_path / "p.png"]):  # fmt: skip
            code = main([str(a) for a in [*argv, "--dataset", data, "--model", generator,
                                          "--no-progress"]])  # fmt: skip
            err = capsys.readouterr().err
            assert code == 0, err
            assert err.count(UNITS) == expected, (argv, err)
    shutil.rmtree(cm)


@pytest.mark.parametrize("name", ["zara1", "sdd", "robo"])
def test_published_models_read_their_own_test_split(name, data_root):
    model = load_predictor(f"{name}/generator", device="cpu")
    scorer = TrajectoryScorer.from_checkpoint(f"{name}/denoiser", steps=[0])
    scenes = load_dataset(name, "test", data_root).scenes
    history = np.concatenate([s.history for s in scenes])  # the CLI's check: the whole split
    assert pace_problem(model, history) is None and pace_problem(scorer, history) is None
    fastest = max(scenes, key=lambda s: pace_quantile(s.history, model.scale)[0])
    for s in [*scenes[:3], fastest]:
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            samples = predict_scene(model, s.history)
            rank_samples(scorer, s.history, samples[:3])
        assert _pace_warnings(record) == []
    with pytest.warns(UserWarning, match=UNITS):
        predict_scene(model, fastest.history * 100)
    with pytest.warns(UserWarning, match=UNITS):
        rank_samples(scorer, fastest.history * 100, samples[:3] * 100)
