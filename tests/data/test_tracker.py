"""A tracker's rows -> the models' history at "now" (walkthrough 63-A, finding 8):
``data.tracks_to_history`` resamples per-agent timestamps and positions to the model's step,
splits fully seen agents (history) from partly seen ones (context, NaN where unseen), and
never extrapolates."""

import warnings

import numpy as np
import pytest

from trajpref.data import TrackHistory, tracks_to_history
from trajpref.data.tracker import LeftOutWarning
from trajpref.errors import ConfigError, DataError

T0 = 1_700_000_000.0  # Unix seconds: the frame times must survive a large clock origin


def _walk(agent, start: float, stop: float, y: float, rate: float = 10.0, speed: float = 1.3):
    """Rows (times, ids, xy) of one agent walking +x at ``speed`` m/s from x = 0 at t = 0, seen
    at ``rate`` Hz from ``start`` to ``stop`` seconds (inclusive) after T0."""
    k = np.arange(round(start * rate), round(stop * rate) + 1)
    t = k / rate  # [n] seconds after T0
    xy = np.stack([speed * t, np.full_like(t, y)], -1)  # [n, 2]
    return T0 + t, [agent] * len(t), xy


def _rows(*walks):
    """Concatenated rows of several ``_walk``s."""
    times = np.concatenate([w[0] for w in walks])
    ids = [i for w in walks for i in w[1]]
    xy = np.concatenate([w[2] for w in walks])
    return times, ids, xy


FRAMES = np.array([0.2, 0.6, 1.0, 1.4, 1.8, 2.2, 2.6, 3.0])  # now = 3.0 s, step 0.4 s


def test_a_10hz_straight_walk_resampled_at_04s_gives_its_exact_positions():
    res = tracks_to_history(*_walk(5, 0.0, 3.0, y=2.0), now=T0 + 3.0, step=0.4)
    assert isinstance(res, TrackHistory)
    assert res.history.shape == (1, 8, 2) and res.context.shape == (0, 8, 2)
    assert res.ids == [5] and res.context_ids == [] and res.left_out_ids == []
    want = np.stack([1.3 * FRAMES, np.full(8, 2.0)], -1)  # 0.26, 0.78, ..., 3.90 m
    np.testing.assert_allclose(res.history[0], want, atol=1e-6)
    np.testing.assert_allclose(res.frame_times - T0, FRAMES, atol=1e-6)


def test_positions_between_observations_are_interpolated_linearly_per_agent():
    # 1 Hz, x = 0, 1, 4, 9 at t = 0, 1, 2, 3; frames at 1.8, 2.2, 2.6, 3.0
    times, xy = np.array([0.0, 1.0, 2.0, 3.0]), np.array([[0, 0], [1, 0], [4, 0], [9, 1]])
    res = tracks_to_history(times, [1] * 4, xy, now=3.0, step=0.4, t_hist=4, max_gap=1.0)
    # 1 + 0.8 * 3 = 3.4; 4 + 0.2 * 5 = 5.0; 4 + 0.6 * 5 = 7.0; 9 (y: 0.2, 0.6 of the way to 1)
    want = [[3.4, 0.0], [5.0, 0.2], [7.0, 0.6], [9.0, 1.0]]
    np.testing.assert_allclose(res.history[0], want, atol=1e-9)


def test_a_track_starting_mid_window_is_context_with_leading_nans():
    rows = _rows(_walk(1, 0.0, 3.0, y=0.0), _walk(2, 1.9, 3.0, y=3.0))
    res = tracks_to_history(*rows, now=T0 + 3.0, step=0.4)
    assert res.ids == [1] and res.context_ids == [2]
    assert res.context.shape == (1, 8, 2)
    assert np.isnan(res.context[0, :5]).all()  # frames at 0.2 .. 1.8 s: before t = 1.9
    want = np.stack([1.3 * FRAMES[5:], np.full(3, 3.0)], -1)  # 2.2, 2.6, 3.0 s
    np.testing.assert_allclose(res.context[0, 5:], want, atol=1e-6)


def test_a_gap_longer_than_max_gap_is_not_bridged_and_a_shorter_one_is():
    gap = _rows(_walk(1, 0.0, 1.0, y=0.0), _walk(1, 2.1, 3.0, y=0.0))  # unseen 1.0 -> 2.1 s
    res = tracks_to_history(*gap, now=T0 + 3.0, step=0.4)  # default max_gap 0.8 s
    assert res.ids == [] and res.context_ids == [1]
    seen = np.isfinite(res.context[0]).all(-1)
    assert seen.tolist() == [True, True, True, False, False, True, True, True]  # 1.4, 1.8 NaN
    bridged = tracks_to_history(*gap, now=T0 + 3.0, step=0.4, max_gap=1.2)
    assert bridged.ids == [1]
    np.testing.assert_allclose(bridged.history[0, :, 0], 1.3 * FRAMES, atol=1e-6)
    short = _rows(_walk(1, 0.0, 1.2, y=0.0), _walk(1, 1.7, 3.0, y=0.0))  # 0.5 s <= 0.8 s
    assert tracks_to_history(*short, now=T0 + 3.0, step=0.4).ids == [1]


def test_unsorted_rows_give_the_same_result_and_ids_come_back_in_ascending_order():
    rows = _rows(_walk(7, 0.0, 3.0, y=0.0), _walk(3, 0.0, 3.0, y=2.0), _walk(5, 1.0, 3.0, y=4.0))
    res = tracks_to_history(*rows, now=T0 + 3.0, step=0.4)
    perm = np.random.default_rng(0).permutation(len(rows[0]))
    times, ids, xy = rows[0][perm], np.asarray(rows[1])[perm], rows[2][perm]
    shuffled = tracks_to_history(times, ids, xy, now=T0 + 3.0, step=0.4)
    assert res.ids == shuffled.ids == [3, 7] and res.context_ids == shuffled.context_ids == [5]
    assert all(type(i) is int for i in shuffled.ids)  # numpy ids come back as Python values
    np.testing.assert_array_equal(res.history, shuffled.history)
    np.testing.assert_array_equal(res.context, shuffled.context)
    np.testing.assert_allclose(res.history[:, 0, 1], [2.0, 0.0])  # rows follow the ids
    named = _rows(_walk("bob", 0.0, 3.0, y=0.0), _walk("amy", 0.0, 3.0, y=1.0))
    assert tracks_to_history(*named, now=T0 + 3.0, step=0.4).ids == ["amy", "bob"]


def test_agents_unseen_at_now_are_left_out_unless_held_and_later_rows_are_not_read():
    rows = _rows(_walk(1, 0.0, 3.0, y=0.0), _walk(2, 0.0, 2.5, y=2.0), _walk(3, 3.5, 4.0, y=0))
    res = tracks_to_history(*rows, now=T0 + 3.0, step=0.4)
    assert res.ids == [1] and res.context_ids == [] and res.left_out_ids == [2]  # 3: not yet
    held = tracks_to_history(*rows, now=T0 + 3.0, step=0.4, hold=0.5)
    assert held.ids == [1, 2]
    np.testing.assert_allclose(held.history[1, -2:], [[1.3 * 2.5, 2.0]] * 2)  # 2.6, 3.0 held
    # replaying the log at now = 2.0 s reads only the rows up to 2.0 s
    past = tracks_to_history(*rows, now=T0 + 2.0, step=0.4)
    assert past.ids == [] and past.context_ids == [1, 2]  # frames from -0.8 s: leading NaNs
    np.testing.assert_allclose(past.context[0, -1], [1.3 * 2.0, 0.0], atol=1e-6)


def test_duplicate_rows_count_once_and_conflicting_ones_are_refused():
    times, ids, xy = _walk(1, 0.0, 3.0, y=0.0)
    dup = tracks_to_history(np.r_[times, times[5]], ids + [1], np.r_[xy, xy[5:6]],
                            now=T0 + 3.0, step=0.4)  # fmt: skip
    np.testing.assert_allclose(dup.history[0, :, 0], 1.3 * FRAMES, atol=1e-6)
    with pytest.raises(DataError, match=r"agent 1 has two rows at time .* different positions"):
        tracks_to_history(np.r_[times, times[5]], ids + [1], np.r_[xy, xy[5:6] + 1.0],
                          now=T0 + 3.0, step=0.4)  # fmt: skip


def test_an_empty_view_gives_empty_arrays():
    res = tracks_to_history(np.zeros(0), [], np.zeros((0, 2)), now=10.0, step=0.4)
    assert res.history.shape == (0, 8, 2) and res.context.shape == (0, 8, 2)
    assert res.ids == res.context_ids == res.left_out_ids == []


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        ({"times": np.zeros((3, 1))}, DataError, r"times: expected \[R\]"),
        ({"xy": np.zeros((3, 3))}, DataError, r"xy: expected \[R, 2\] with R = 3"),
        ({"ids": [1, 1]}, DataError, r"ids: expected one id per row \(3\), got 2"),
        ({"times": [0.0, np.nan, 0.2]}, DataError, r"times: row 1 is not finite"),
        ({"xy": [[0, 0], [0, np.inf], [0, 0]]}, DataError, r"xy: row 1 is not finite"),
        ({"ids": [1, "a", 2]}, DataError, r"agent ids must sort among themselves"),
        ({"now": -1.0}, DataError, r"now \(-1.0\) is before every observation"),
        ({"now": float("nan")}, DataError, r"now must be finite"),
        ({"step": 0.0}, ConfigError, r"step must be > 0 seconds"),
        ({"step": -0.4}, ConfigError, r"step must be > 0 seconds"),
        ({"t_hist": 1}, ConfigError, r"t_hist must be an integer >= 2 \(model.t_hist: a model "),
        ({"max_gap": 0.0}, ConfigError, r"max_gap must be > 0 seconds"),
        ({"hold": -0.1}, ConfigError, r"hold must be >= 0 seconds"),
    ],
)
def test_bad_input_is_a_clear_error(change, error, match):
    args = {"times": [0.0, 0.1, 0.2], "ids": [1, 1, 1], "xy": np.zeros((3, 2)), "now": 0.2,
            "step": 0.1}  # fmt: skip
    args.update(change)
    with pytest.raises(error, match=match):
        tracks_to_history(**args)


def test_its_output_runs_through_predict_scene_with_context():
    from trajpref.models.registry import load_predictor
    from trajpref.score import predict_scene

    model = load_predictor("zara1/generator", device="cpu")
    rows = _rows(_walk(1, 0.0, 3.0, y=0.0), _walk(2, 0.0, 3.0, y=1.5), _walk(3, 1.9, 3.0, y=4.0))
    res = tracks_to_history(*rows, now=T0 + 3.0, step=model.frame_interval, t_hist=model.t_hist)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        futures = predict_scene(model, res.history, 20, context=res.context, frame_interval=0.4)
    assert futures.shape == (20, 2, 12, 2) and np.isfinite(futures).all()
    # the partly seen agent is counted as a context row the model does not read
    assert any("context rows ignored" in str(w.message) for w in caught)


def _jittered(cycles: int = 40, agents: int = 5, spread: float = 0.008, seed: int = 0):
    """Rows of ``agents`` walkers seen by a 10 Hz tracker that stamps each detection on its
    own, 1 ms to ``spread`` seconds into its cycle (walkthrough 65, robot finding 2)."""
    rng = np.random.default_rng(seed)
    k = np.repeat(np.arange(cycles), agents)  # [R] cycle of each row
    a = np.tile(np.arange(agents), cycles)  # [R]
    times = T0 + k * 0.1 + rng.uniform(0.001, spread, len(k))  # off the 0.4 ms tolerance
    xy = np.stack([a + 1.0 * (times - T0), 0.5 * a], -1)  # [R, 2]
    return times, a, xy


def _left_out_warnings(record) -> list[str]:
    from trajpref.data.tracker import LeftOutWarning

    return [str(w.message) for w in record if issubclass(w.category, LeftOutWarning)]


def test_agents_with_per_detection_stamps_are_not_dropped_without_a_word():
    times, ids, xy = _jittered()
    latest = float(times.max())  # now: the latest stamp; the others a few ms before it
    nominal = T0 + 3.9  # now: the last cycle's nominal time; its stamps a few ms after it
    for now, dropped in ((latest, 4), (nominal, 5)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = tracks_to_history(times, ids, xy, now=now, step=0.4)
        assert len(res.left_out_ids) == dropped
        (text,) = _left_out_warnings(caught)  # one per call
        assert "agents seen in the tracker's current cycle" in text
        assert len(caught[0].message.ages) == dropped
        assert "hold=" in text and caught[0].filename == __file__  # the user's line
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            held = tracks_to_history(times, ids, xy, now=now, step=0.4, hold=0.1)
        assert held.ids == [0, 1, 2, 3, 4] and not _left_out_warnings(caught)


def test_input_on_the_time_grid_and_agents_long_gone_give_no_warning():
    rows = _rows(_walk(1, 0.0, 3.0, y=0.0), _walk(2, 0.0, 2.5, y=2.0), _walk(3, 3.5, 4.0, y=0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = tracks_to_history(*rows, now=T0 + 3.0, step=0.4)  # agent 2 gone 0.5 s ago
        assert res.left_out_ids == [2]
        tracks_to_history(*_rows(_walk(1, 0.0, 3.0, y=0.0), _walk(2, 0.0, 2.9, y=2.0)),
                          now=T0 + 3.0, step=0.4)  # agent 2 gone one 10 Hz cycle ago  # fmt: skip
        assert tracks_to_history(*_jittered(), now=T0 + 3.9, step=0.4, hold=0.1).left_out_ids == []


def test_a_now_a_day_after_every_observation_is_an_error_naming_two_clocks():
    # a tracker on simulation time, now on wall-clock time: every agent was left out, no word
    t = np.arange(0, 3.2, 0.4)  # [8] 0.0 .. 2.8 s
    rows = (t, np.ones(8, int), np.c_[t, 0 * t])
    with pytest.raises(
        DataError, match=r"now \(1700000000\.0\) is after every observation by more than a day"
    ) as info:
        tracks_to_history(*rows, now=1.7e9, step=0.4)
    assert "the newest is at 2.8" in str(info.value) and "two clocks" in str(info.value)
    # a view empty for a while (its old rows still passed, as a planner's buffer does): an
    # empty scene, not an error, up to a day
    for later in (5.0, 3600.0, 86_000.0):
        res = tracks_to_history(*rows, now=2.8 + later, step=0.4)
        assert res.history.shape == (0, 8, 2) and res.left_out_ids == [1]
    # a hold longer than the window reaches that far: the agent is held
    held = tracks_to_history(*rows, now=2.8 + 5.0, step=0.4, hold=6.0)
    assert held.ids == [1]
    np.testing.assert_allclose(held.history[0], [[2.8, 0.0]] * 8)
    # one stale agent beside a current one is left out, as before
    both = _rows(_walk(1, 0.0, 3.0, y=0.0), (np.array([T0 - 100.0]), [2], np.zeros((1, 2))))
    assert tracks_to_history(*both, now=T0 + 3.0, step=0.4).left_out_ids == [2]


@pytest.mark.parametrize(
    ("dtype", "origin", "spacing"), [(np.float32, T0, "128"), (np.float16, 1000.0, "0.5")]
)
def test_unix_times_in_a_narrow_float_type_are_an_error_not_two_clashing_rows(
    dtype, origin, spacing
):
    # float32 Unix seconds are 128 s apart and were blamed as "two rows at time 1700000000.0
    # with different positions"; float16 (up to 65504) is 0.5 s apart from 512 s
    unix, ids, xy = _walk(1, 0.0, 3.0, y=0.0)  # 10 Hz from T0
    narrow = (rf"times: {np.dtype(dtype).name} holds times as large as .* only to the nearest "
              rf"{spacing} s, coarser than step=0\.4 s")  # fmt: skip
    with pytest.raises(DataError, match=narrow) as info:
        tracks_to_history((unix - T0 + origin).astype(dtype), ids, xy, now=origin + 3.0, step=0.4)
    assert "pass float64 times" in str(info.value) and "subtract a start time" in str(info.value)
    with pytest.raises(DataError, match=r"now: float32 holds times as large as 1\.7e\+09 s"):
        tracks_to_history(unix, ids, xy, now=np.float32(T0 + 3.0), step=0.4)
    # times from a start: float32 resolves them to well within a step, read as in float64
    local = (unix - T0).astype(np.float32)
    res = tracks_to_history(local, ids, xy, now=np.float32(3.0), step=0.4)
    np.testing.assert_allclose(res.history[0, :, 0], 1.3 * FRAMES, atol=1e-5)


# ``tracks_to_history`` with ``hold=`` (walkthrough 67, finding 1): a 10 Hz tracker's stamps
# some ms off the frame grid keep an agent at ``now`` without a velocity bias (interpolated
# toward a stamp just after ``now``, else extrapolated at its last velocity, never its stale
# position placed at ``now``), and the ``LeftOutWarning`` gives each agent's age and a ``hold``
# above it.


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
    res, caught = _call_caught(*rows, **kwargs)
    return res, [str(w) for w in caught]


def _call_caught(*rows, now=104.0, **kwargs):
    """The result and the LeftOutWarning instances raised (``always``: each call's own)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = tracks_to_history(*rows, now=now, step=0.4, **kwargs)
    return res, [w.message for w in caught if issubclass(w.category, LeftOutWarning)]


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
        res, (warning,) = _call_caught(*_walker(), hold=hold)
        text = str(warning)
        assert res.left_out_ids == [0]
        assert "agents seen in the tracker's current cycle" in text
        assert f"older than hold={hold:g} s" in text
        assert "Pass hold=0.14 " in text  # above the age (1.25 times it, to 10 ms)
        # the age at now of its latest stamp at or before now, on the warning, not in its text
        assert warning.ages == {0: pytest.approx(0.111)} and warning.suggested_hold == 0.14
        assert "0.111" not in text
    res, left = _call(*_walker(after_now=False), hold=0.14)  # keeps it without a later row
    assert res.ids == [0] and not left


def test_many_left_out_agents_are_all_on_the_warning():
    times, _, xy = _walker()
    rows = (np.tile(times, 7), np.repeat(np.arange(7), len(times)), np.tile(xy, (7, 1)))
    _, (warning,) = _call_caught(*rows)
    assert list(warning.ages) == list(range(7))


def test_a_planners_loop_is_warned_once_not_every_call():
    # per-detection stamps jittered every cycle: each call's ages differ, the text must not,
    # or Python's default filter prints every call and its registry grows without end
    rng = np.random.default_rng(0)
    texts = set()
    for cycle in range(100):
        now = 104.0 + 0.1 * cycle
        times = now - 4.0 + 0.1 * np.arange(41)  # 10 Hz up to now ...
        times[-1] -= rng.uniform(0.002, 0.03)  # ... the current cycle's stamp a little early
        xy = np.stack([SPEED * (times - 100), np.zeros_like(times)], -1)
        _, caught = _call_caught(times, np.zeros(len(times), dtype=int), xy, now=now)
        assert len(caught) == 1
        texts.add(str(caught[0]))
    assert len(texts) <= 4  # the suggested hold only (0.01 .. 0.04 s), not each call's ages


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
