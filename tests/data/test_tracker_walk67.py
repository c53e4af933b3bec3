"""``tracks_to_history`` with ``hold=`` (walkthrough 67, finding 1): a 10 Hz tracker's stamps
some ms off the frame grid keep an agent at ``now`` without a velocity bias (interpolated
toward a stamp just after ``now``, else extrapolated at its last velocity, never its stale
position placed at ``now``), and the ``LeftOutWarning`` gives each agent's age and a ``hold``
above it."""

import warnings

import numpy as np
import pytest

from trajpref.data import tracks_to_history
from trajpref.data.tracker import LeftOutWarning

SPEED = 1.4  # m/s along x
TRUE_LAST = SPEED * np.array([3.2, 3.6, 4.0])  # x at the last three frames (now = 104 s)


def _walker(after_now: bool = True):
    """The walkthrough's rows: 10 Hz from 100 s, the stamp before now 11 ms early (103.889 s),
    and (``after_now``) the current cycle's stamped 5 ms after now (104.005 s)."""
    times = 100 + 0.1 * np.arange(40)
    times[-1] -= 0.011
    if after_now:
        times = np.r_[times, 104.005]
    xy = np.stack([SPEED * (times - 100), np.zeros_like(times)], -1)
    return times, np.zeros(len(times), dtype=int), xy


def _call(*rows, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = tracks_to_history(*rows, now=104.0, step=0.4, **kwargs)
    return res, [str(w.message) for w in caught if issubclass(w.category, LeftOutWarning)]


def test_the_hold_the_warning_suggests_keeps_the_agent_at_its_true_position():
    res, left = _call(*_walker(), hold=0.1)
    assert res.history.shape == (1, 8, 2) and res.left_out_ids == [] and not left
    # interpolated between 103.889 s and 104.005 s: the last step 0.56 m, not 0.405 m
    np.testing.assert_allclose(res.history[0, -3:, 0], TRUE_LAST, atol=1e-9)


def test_a_stale_stamp_is_extrapolated_to_now_not_placed_there():
    res, left = _call(*_walker(after_now=False), hold=0.15)
    assert res.ids == [0] and not left
    np.testing.assert_allclose(res.history[0, -3:, 0], TRUE_LAST, atol=1e-9)
    last_step = res.history[0, -1, 0] - res.history[0, -2, 0]
    assert last_step == pytest.approx(SPEED * 0.4)  # no velocity bias (0.405 m held)


def test_a_row_more_than_hold_after_now_is_not_read():
    times, ids, xy = _walker(after_now=False)
    far = (np.r_[times, 104.2], np.r_[ids, 0], np.r_[xy, [[50.0, 0.0]]])  # a jump 0.2 s later
    res, _ = _call(*far, hold=0.15)
    np.testing.assert_allclose(res.history[0, -3:, 0], TRUE_LAST, atol=1e-9)


def test_the_warning_gives_each_agents_age_and_a_hold_above_it():
    for hold in (0.0, 0.004):  # the stamp after now is 5 ms late: left out with either
        res, (text,) = _call(*_walker(), hold=hold)
        assert res.left_out_ids == [0]
        assert "1 agent(s) seen in the tracker's current cycle" in text
        assert f"older than hold={hold:g} s" in text
        assert "0: 0.111 s" in text  # the age at now of its latest stamp at or before now
        assert "Pass hold=0.14 " in text  # above that age (1.25 times it, to 10 ms)
    res, left = _call(*_walker(after_now=False), hold=0.14)  # keeps it without a later row
    assert res.ids == [0] and not left


def test_many_left_out_agents_are_named_up_to_five():
    times, _, xy = _walker()
    rows = (np.tile(times, 7), np.repeat(np.arange(7), len(times)), np.tile(xy, (7, 1)))
    _, (text,) = _call(*rows)
    assert "7 agent(s)" in text and "4: 0.111 s and 2 more" in text and "5: " not in text


def test_jittered_per_detection_stamps_at_any_now_give_unbiased_history():
    # five walkers at 1 m/s, each detection stamped 1-8 ms into its 10 Hz cycle; a planner
    # asks at times between the tracker's cycles (no row after now but within hold)
    rng = np.random.default_rng(1)
    k, a = np.repeat(np.arange(40), 5), np.tile(np.arange(5), 40)
    times = 100 + 0.1 * k + rng.uniform(0.001, 0.008, len(k))
    xy = np.stack([a + (times - 100), 0.5 * a], -1)
    for now in (103.9, 103.93, 103.96, 103.999):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            res = tracks_to_history(times, a, xy, now=now, step=0.4, hold=0.12)
        assert res.ids == [0, 1, 2, 3, 4]
        want = np.arange(5)[:, None] + (res.frame_times - 100)[None]  # [5, 8]
        np.testing.assert_allclose(res.history[..., 0], want, atol=1e-9)


def test_close_stamps_do_not_magnify_noise_in_the_extrapolation():
    # the last two stamps 2 ms apart, the last one 1 cm off: the velocity is taken over at
    # least the extrapolated time (0.05 s), so the frame at now is off by about 1 cm, not 26
    times = np.r_[100 + 0.1 * np.arange(40), 103.902]
    xy = np.stack([SPEED * (times - 100), np.zeros_like(times)], -1)
    xy[-1, 0] += 0.01
    res = tracks_to_history(times, [0] * len(times), xy, now=103.952, step=0.4, hold=0.1)
    assert abs(res.history[0, -1, 0] - SPEED * 3.952) < 0.02


def test_an_agent_missing_for_cycles_is_held_where_last_seen():
    # last seen 0.3 s (3 of its cycles) before now: its motion since is unknown (rule 3)
    times, ids, xy = _walker(after_now=False)
    res = tracks_to_history(times, ids, xy, now=104.2, step=0.4, hold=0.35)
    assert res.history[0, -1, 0] == pytest.approx(SPEED * 3.889)
