"""The data statistics' words: mean speeds with their units, and the note on an
implausible walking pace."""

import pytest

# Reader messages and formats a researcher with their own files met (walkthrough 63-B,
# findings 3, 11 and 12): a header without an agent column, ``.tsv`` files, millisecond time
# columns, extra columns, and the mean speed's plausibility note.


def test_speed_text_says_when_the_units_are_unknown():
    from trajpref.data.stats import speed_text

    assert speed_text(1.25, "m") == "1.25 m/s"
    assert speed_text(0.3022, "unknown") == "0.3022 units/s (units unknown: name them with --units)"
    assert speed_text(float("nan"), "m") == "nan m/s"


NOTE = (
    "{shown} is not a walking pace (pedestrians: about 0.5-2 m/s): is --frame-interval "
    "(or --units) right? It is the seconds between consecutive rows of an agent (now "
    "{now}), not per frame number: at 1.3 m/s these rows would be {then} s apart"
)


@pytest.mark.parametrize("speed, units, interval, time_step, shown, now, then", [
    (1.2, "m", 0.4, 1, None, None, None),
    (0.35, "m", 0.4, 1, None, None, None),
    # 25 fps video annotated every 10th frame, read at 1/25 s: about 0.4 s is named
    (11.92, "m", 0.04, 1, "11.92 m/s", "0.04 s", "0.3668"),
    (0.1, "m", 1.6, 4, "0.1 m/s", "0.4 s, read every 4", "0.03077"),
    (12.0, "cm", 0.4, 1, "12 cm/s (0.12 m/s)", "0.4 s", "0.03692"),
    (4.0, "ft", 0.4, 1, None, None, None),  # 1.2 m/s
    (1.2, "unknown", 0.4, 1, None, None, None),  # nothing to compare with
    (1.2, "px", 0.04, 1, None, None, None),
    (float("nan"), "m", 0.4, 1, None, None, None),
    (0.0, "m", 0.4, 1, None, None, None),  # nobody moved: no interval would change that
])  # fmt: skip
def test_speed_note_flags_implausible_walking_speeds(speed, units, interval, time_step, shown,
                                                     now, then):  # fmt: skip
    from trajpref.data.stats import speed_note

    got = speed_note(speed, units, interval, time_step=time_step)
    assert got == (None if shown is None else NOTE.format(shown=shown, now=now, then=then))
    # a built-in dataset's interval is its own: nothing to question
    assert speed_note(speed, units, interval, "dataset", time_step) is None


def test_speed_note_says_when_the_interval_is_assumed():
    from trajpref.data.stats import speed_note

    note = speed_note(0.1, "m", 1.6, "default", 4)
    assert note is not None and "(now 0.4 s, assumed, read every 4)" in note
