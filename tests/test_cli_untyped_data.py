"""A model that learned from agent-type flags (NBA's ball), run on data that flag none (a
folder without a type column), says so once: every agent, a ball included, is then read as
a person (NBA walkthrough, 2026-12-06: minFDE 0.256 -> 0.319 m, with no word)."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np

from trajpref.cli import _warn_untyped_data, main
from trajpref.types import AGENT_BALL, AGENT_PERSON

WORDS = "was trained with agent types"


def _data(*types):
    scenes = [SimpleNamespace(agent_type=np.array(t)) for t in types]
    return SimpleNamespace(scenes=scenes)


def _said(model, ds) -> list[str]:
    args = SimpleNamespace(model="m.safetensors", scorer=None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_untyped_data(args, model, None, ds)
    return [str(w.message) for w in caught if WORDS in str(w.message)]


def test_a_typed_model_on_data_without_flags_is_named_and_only_then():
    typed = SimpleNamespace(timing={"trained_on": "/data/court", "agent_types": [0, 1]})
    plain = SimpleNamespace(timing={"trained_on": "zara1", "agent_types": [0]})
    persons = _data([AGENT_PERSON] * 3, [AGENT_PERSON])
    assert len(_said(typed, persons)) == 1
    assert _said(typed, _data([AGENT_BALL, AGENT_PERSON], [AGENT_PERSON])) == []  # flagged
    assert _said(plain, persons) == []  # learned no flags


def test_the_published_nba_model_on_a_folder_without_types_warns(capsys, walks):
    code = main(["predict", "--dataset", str(walks), "--model", "nba/generator", "--samples",
                 "2", "--max-scenes", "2", "--out", str(walks.parent / "nba_on_walks.npz"),
                 "--no-progress", "--device", "cpu"])  # fmt: skip
    assert code == 0
    assert "nba/generator was trained with agent types" in capsys.readouterr().err
