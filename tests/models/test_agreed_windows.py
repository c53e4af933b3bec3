"""``checkpoint.agreed_windows``: the window lengths a command cuts its data into, from the
checkpoints that read them and the lengths given (hand-made cases)."""

from __future__ import annotations

import pytest

from trajpref.errors import ConfigError
from trajpref.models.checkpoint import agreed_windows


def test_the_readers_lengths_win_and_given_ones_fill_in_where_none_says():
    assert agreed_windows({"--model g": (6, 16), "--scorer d": (6, 16)}) == (6, 16)
    assert agreed_windows({"--model g": (6, 16)}, (6, None)) == (6, 16)
    assert agreed_windows({"--model cv": None}) == (8, 12)
    assert agreed_windows({"--model cv": None}, (None, 20)) == (8, 20)
    assert agreed_windows({}, (4, 6)) == (4, 6)


def test_readers_that_disagree_are_named_with_their_lengths():
    with pytest.raises(ConfigError) as err:
        agreed_windows({"--model g": (6, 16), "--model cv": None, "--scorer z": (8, 12)})
    assert str(err.value).startswith(
        "--model g reads windows of 6 observed + 16 future frames, "
        "--scorer z of 8 + 12: they must read the same lengths"
    )


@pytest.mark.parametrize(("given", "flag"), [((8, None), "--history 8"), ((6, 12), "--future 12")])
def test_a_given_length_that_differs_from_the_readers_is_refused(given, flag):
    said = rf"^{flag}: --model g reads windows of 6 observed \+ 16 future frames \(its "
    with pytest.raises(ConfigError, match=said + r"model.t_hist and model.t_fut\); leave "):
        agreed_windows({"--model g": (6, 16)}, given)
