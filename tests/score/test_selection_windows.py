"""A selection's scorer must read the model's window lengths: refused when built, not at the
first prediction (walkthrough 70: an 8 + 12 scorer on a 5 + 10 model failed inside predict)."""

from __future__ import annotations

import types

import pytest

from trajpref.errors import ConfigError
from trajpref.score.selection import SelectingPredictor, SelectionConfig


def test_a_scorer_of_other_lengths_is_refused_when_the_selector_is_built():
    model = types.SimpleNamespace(t_hist=5, t_fut=10, predict=lambda *a: None)
    scorer = types.SimpleNamespace(t_hist=8, t_fut=12)
    cfg = SelectionConfig(keep=2, method="score-facility")
    with pytest.raises(ConfigError, match=r"the model reads windows of 5 observed \+ 10 future "
                       r"frames, the scorer 8 \+ 12"):  # fmt: skip
        SelectingPredictor(model, cfg, candidates=4, scorer=scorer)
    same = types.SimpleNamespace(t_hist=5, t_fut=10)
    assert SelectingPredictor(model, cfg, candidates=4, scorer=same).t_fut == 10
    baseline = types.SimpleNamespace(t_hist=None, predict=lambda *a: None)  # any lengths
    assert SelectingPredictor(baseline, cfg, candidates=4, scorer=scorer).t_hist is None
