"""The pace check's messages for a planner's arrays (walkthrough 67, findings 2-3): a
frame interval in milliseconds is asked about, the resampling names its public call, and
the pixel names have one definition."""

import types

import pytest

from trajpref.models.timing import check_pace

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
    import numpy as np

    from trajpref.models.registry import load_predictor
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
