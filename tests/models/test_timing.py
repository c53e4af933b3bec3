"""The pace and units check of a model against its data (``models.timing``)."""

import types

import numpy as np
import pytest
from helpers import _messages, _scene

from trajpref.models.registry import load_predictor
from trajpref.models.timing import check_pace, timing_problems
from trajpref.score import predict_scene

# The pace check's messages for a planner's arrays (walkthrough 67, findings 2-3): a
# frame interval in milliseconds is asked about, the resampling names its public call, and
# the pixel names have one definition.


ROBO = {"trained_on": "robo-sim", "step": 0.5, "known": True, "units": "m"}


def _model():
    return types.SimpleNamespace(timing=dict(ROBO), frame_interval=0.5)


def test_a_frame_interval_in_milliseconds_is_asked_about():
    want = (r"this data steps 400 s, the model's 0\.5 s \(milliseconds\? pass seconds, "
            r"frame_interval=0\.4; else resample")  # fmt: skip
    with pytest.warns(UserWarning, match=want):
        check_pace(_model(), 400, None)


@pytest.mark.parametrize("step", [0.4, 10.0])
def test_a_step_in_seconds_is_not_taken_for_milliseconds(step):
    with pytest.warns(UserWarning) as caught:
        check_pace(_model(), step, None)
    assert "milliseconds" not in str(caught[0].message)


def test_the_resampling_advice_names_the_public_resampler():
    import trajpref.data

    with pytest.warns(UserWarning) as caught:
        check_pace(_model(), 0.4, None)
    text = str(caught[0].message)
    assert "resample the history to one position every 0.5 s, e.g. with " in text
    assert "trajpref.data.tracks_to_history(times, ids, xy, now, step=0.5)" in text
    assert callable(trajpref.data.tracks_to_history)  # the path it names exists


def test_predict_scene_gives_the_hint_for_a_published_model():

    from trajpref.score import predict_scene

    model = load_predictor("zara1/generator", device="cpu")
    t = np.arange(8) * 0.4
    history = np.stack([np.stack([1.2 * t, 0 * t], -1)]).astype(np.float32)
    with pytest.warns(UserWarning, match=r"steps 400 s, the model's 0\.4 s \(milliseconds\?"):
        predict_scene(model, history, frame_interval=400)


def test_the_pixel_names_are_the_registrys_one_set():
    from trajpref.data.registry import PIXEL_NAMES
    from trajpref.models.timing import PIXEL_UNITS, same_units

    assert PIXEL_UNITS is PIXEL_NAMES
    assert same_units("px", "Pixels") and not same_units("px", "m")


# A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
# and inputs the models read; feet given to a metre model are told the factor; a scene with no
# ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
# are types.


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
