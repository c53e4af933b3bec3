"""A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
and inputs the models read; feet given to a metre model are told the factor; a scene with no
ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
are types."""

import dataclasses
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.errors import DataError
from trajpref.evaluation import warn_untyped_data
from trajpref.models.registry import load_predictor
from trajpref.models.timing import timing_problems
from trajpref.score import TrajectoryScorer, predict_scene, predict_scenes, rank_samples
from trajpref.types import TrajectoryDataset

ROOT = Path(__file__).resolve().parents[1]
CARDS = ROOT / "src" / "trajpref" / "zoo" / "nba"


@pytest.fixture(scope="module")
def nba():
    return load_predictor("nba/generator", device="cpu")


@pytest.fixture(scope="module")
def nba_scorer():
    return TrajectoryScorer.from_checkpoint("nba/denoiser").with_steps([0])


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A rebound-like scene: 10 players and the ball (agent 0), 8 steps of 0.12 s, metres,
    x along the court's 28.65 m length. Returns history [11, 8, 2] and agent_type [11]."""
    rng = np.random.default_rng(seed)
    start = rng.uniform([2.0, 2.0], [12.0, 13.0], size=(11, 2))  # [11, 2] one half-court
    velocity = rng.normal(0.0, 0.1, size=(11, 2))  # [11, 2] metres per step
    velocity[0] *= 3  # the ball moves faster
    history = start[:, None] + velocity[:, None] * np.arange(8)[None, :, None]  # [11, 8, 2]
    types = np.zeros(11, np.int64)
    types[0] = 1
    return history, types


def _messages(call) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    return [str(w.message) for w in caught]


# 4. float agent types


def test_float_flags_from_pandas_are_types(nba, nba_scorer):
    history, types = _scene()
    as_ints = predict_scene(nba, history, 20, agent_type=types)
    for floats in (types.astype(np.float64), types.astype(np.float32).tolist(),
                   torch.tensor(types, dtype=torch.float64)):  # fmt: skip
        np.testing.assert_array_equal(predict_scene(nba, history, 20, agent_type=floats), as_ints)
    order, residual = rank_samples(nba_scorer, history, as_ints, agent_type=types)
    order_f, residual_f = rank_samples(nba_scorer, history, as_ints, types.astype(np.float64))
    np.testing.assert_array_equal(order_f, order)
    np.testing.assert_array_equal(residual_f, residual)


@pytest.mark.parametrize(
    "value, message",
    [
        (np.r_[0.5, np.zeros(10)], r"got float64 values that are not whole numbers \(the first, "
                                   r"0.5, at index 0\)"),
        (np.r_[np.zeros(10), np.nan], r"float64 values .*the first, nan, at index 10"),
        (np.r_[2.0, np.zeros(10)], r"flags must be 0 \(person\) or 1 \(ball\), got \[0.0, 2"),
        (np.zeros((11, 1)), r"expected 11 integer flags \[P\], got \[11, 1\] of float64"),
        (torch.full((11,), 0.25), r"got torch.float32 values that are not whole numbers"),
    ],
)  # fmt: skip
def test_other_floats_are_refused_naming_their_dtype(nba, value, message):
    history, _ = _scene()
    with pytest.raises(DataError, match=message) as raised:
        predict_scene(nba, history, 20, agent_type=value)
    whole = "flags must be" in message  # a whole number that is no flag
    assert str(raised.value).startswith("agent_type: " + ("" if whole else "expected 11 "))


# 3. a scene with no ball or two balls


def test_predict_and_rank_say_a_scene_without_one_ball(nba, nba_scorer):
    history, types = _scene()
    samples = predict_scene(nba, history, 20, agent_type=types)
    assert not _messages(lambda: predict_scene(nba, history, 20, agent_type=types))
    assert not _messages(lambda: rank_samples(nba_scorer, history, samples, types))
    two = types.copy()
    two[5] = 1
    for flags, found in ((np.zeros(11, np.int64), "no ball"), (two, "2 balls")):
        got = _messages(lambda f=flags: predict_scene(nba, history, 20, agent_type=f))
        assert got == [f"predict_scene: agent_type flags {found} (agent_type 1) in this scene; "
                       "this model was trained on nba with the ball flagged (agent_type 1; one "
                       "in every scene of NBA's splits), so its futures of such a scene are of "
                       "one it never saw: flag the ball 1 and each player 0"]  # fmt: skip
        got = _messages(lambda f=flags: rank_samples(nba_scorer, history, samples, f))
        assert len(got) == 1 and got[0].startswith(f"rank_samples: agent_type flags {found}")
        assert "this scorer was trained on nba" in got[0] and "its scores of" in got[0]
    scenes = [history, history, history, history[:0]]
    flags = [types, two, np.zeros(11), None]
    got = _messages(lambda: predict_scenes(nba, scenes, 20, agent_types=flags))
    assert len(got) == 1
    assert got[0].startswith(
        "predict_scenes: agent_types flag no ball in 1 and two or more "
        "balls in 1 of the 3 scenes given types (histories[1], "
        "histories[2]); this model was trained on nba"
    )


def test_a_model_trained_without_types_says_nothing_of_balls():
    zara1 = load_predictor("zara1/generator", device="cpu")
    history, _ = _scene()
    assert not [m for m in _messages(lambda: predict_scene(zara1, history, 20,
                                                           agent_type=np.zeros(11, np.int64)))
                if "ball" in m]  # fmt: skip


def _typed(walks: Path, balls: list[int]) -> TrajectoryDataset:
    """The walks' test scenes with ``balls[i]`` of scene i's agents flagged as the ball."""
    data = load_dataset(str(walks), "test")
    scenes = []
    for scene, n in zip(data.scenes, balls, strict=False):
        flags = np.zeros(len(scene.history), np.int64)
        flags[:n] = 1
        scenes.append(dataclasses.replace(scene, agent_type=flags))
    assert len(scenes) == len(balls) and all(len(s.history) >= 2 for s in scenes)
    return TrajectoryDataset(scenes, data.info)


def test_a_split_with_scenes_of_no_ball_or_two_says_how_many(nba, walks):
    checked = [("nba/generator", nba)]
    assert not _messages(lambda: warn_untyped_data(checked, _typed(walks, [1, 1, 1, 1])))
    got = _messages(lambda: warn_untyped_data(checked, _typed(walks, [1, 0, 2, 0])))
    assert got == ["nba/generator was trained with the ball flagged (agent_type 1; one in every "
                   "scene of NBA's splits), and of this data's 4 scenes, 2 flag no ball and 1 "
                   "flags two or more (up to 2): it reads each as flagged, a scene it never saw; "
                   "the ball is one agent, flagged BALL in a 5th column and seen in every frame "
                   "of a window (docs/data_format.md)"]  # fmt: skip
    got = _messages(lambda: warn_untyped_data(checked, _typed(walks, [0, 0, 0, 0])))
    assert len(got) == 1 and "this data flag no ball: every agent is read as a person" in got[0]
    zara1 = load_predictor("zara1/generator", device="cpu")
    assert not _messages(lambda: warn_untyped_data([("z", zara1)], _typed(walks, [1, 0, 2, 0])))


def test_evaluate_says_a_folder_scene_with_two_balls(capsys, tmp_path):
    history, types = _scene()
    xy = history[:, :1] + (history[:, 1:2] - history[:, :1]) * np.arange(20)[None, :, None]
    rows = ["time,agent,x,y,type"]
    for t in range(20):
        for i in range(11):
            rows.append(f"{t * 0.12:.2f},{i},{xy[i, t, 0]:.4f},{xy[i, t, 1]:.4f},"
                        f"{'BALL' if types[i] else 'PLAYER'}")  # fmt: skip
        rows.append(f"{t * 0.12:.2f},99,{xy[0, t, 0] + 2:.4f},{xy[0, t, 1] + 2:.4f},BALL")
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / "game.csv").write_text("\n".join(rows) + "\n")
    code = main(["evaluate", "--dataset", str(tmp_path), "--model", "nba/generator", "--units",
                 "m", "--samples", "20", "--no-progress", "--device", "cpu"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 0
    assert "of this data's 1 scene, 1 flags two or more (up to 2)" in err, err


def test_the_published_nba_splits_have_one_ball_a_scene(nba, data_root):
    scorer = TrajectoryScorer.from_checkpoint("nba/denoiser")
    for split in ("test", "val"):
        data = load_dataset("nba", split, data_root)
        assert not _messages(lambda d=data: warn_untyped_data([("g", nba), ("s", scorer)], d))


# 2. feet for a metre model


def test_feet_for_a_metre_model_are_told_the_factor(nba):
    model = {"units": "m", "step": None}
    assert timing_problems(model, None, "ft", None) == [
        "this data is in ft, the model's in m (units are named, not converted: multiply x and "
        "y by 0.3048 to give m before reading them, and the futures, in m, by 3.281 for ft)"
    ]
    cm = timing_problems(model, None, "cm", None)[0]
    assert cm.endswith("by 0.01 to give m before reading them, and the futures, in m, by 100 "
                       "for cm)")  # fmt: skip
    assert timing_problems(model, None, "px", None) == ["this data is in px, the model's in m"]
    history, types = _scene()
    got = _messages(lambda: predict_scene(nba, history / 0.3048, 20, agent_type=types,
                                          units="ft"))  # fmt: skip
    assert any(
        "this data is in ft, the model's in m (units are named, not converted: "
        "multiply x and y by 0.3048" in m
        for m in got
    ), got


# 1. what the cards say


def test_the_nba_cards_say_the_axes_and_the_inputs():
    generator = (CARDS / "generator.md").read_text(encoding="utf-8")
    for said in ("x along the court's 94 ft (28.65 m) length", "any origin", "`agent_type` (1 "
                 "the ball, 0 a player); no team, no court or basket position",
                 "`data.rotate: false`", "(+57 %)", "--agents persons",
                 "0.180 / 0.322 m (0.59 / 1.06 ft)"):  # fmt: skip
        assert said in generator, said
    denoiser = (CARDS / "denoiser.md").read_text(encoding="utf-8")
    assert "94 ft length" in denoiser and "changed in 50 of 50" in denoiser
    index = json.loads((CARDS.parent / "index.json").read_text())
    limits = {row["name"]: " ".join(row["limits"]) for row in index["models"]
              if row["dataset"] == "nba"}  # fmt: skip
    assert all("94 ft" in text for text in limits.values()), limits


def test_select_for_scene_warns_of_a_scene_without_its_ball():
    """select_for_scene reads the same NBA scorer as rank_samples, which warns of a scene
    whose agent types flag no ball; it said nothing (the fixer's open item)."""
    from trajpref.score.scorer import TrajectoryScorer, predict_scene
    from trajpref.score.selection import SelectionConfig, select_for_scene

    scene = load_dataset("nba", "test").scenes[0]
    model = load_predictor("nba/generator")
    scorer = TrajectoryScorer.from_checkpoint("nba/denoiser").with_steps([0])
    samples = predict_scene(model, scene.history, 20, agent_type=scene.agent_type)  # [K, P, T_f, 2]
    cfg = SelectionConfig(keep=5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        select_for_scene(scorer, scene.history, samples, cfg, agent_type=scene.agent_type)
    with pytest.warns(UserWarning, match="select_for_scene: agent_type flags no ball"):
        select_for_scene(scorer, scene.history, samples, cfg,
                         agent_type=np.zeros_like(scene.agent_type))  # fmt: skip
