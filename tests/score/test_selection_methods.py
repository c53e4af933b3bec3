"""Each selection method has its own branch, matched by its exact name (walkthrough 62, items 3
and 6): no name falls through to k-means or is routed by a prefix or suffix, and the docs list
exactly ``METHODS``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch

from trajpref.config import field_docs
from trajpref.errors import ConfigError
from trajpref.score import selection
from trajpref.score.selection import METHODS, USES_SCORE, SelectionConfig, select_indices

K, KEEP = 6, 2
RESIDUAL = torch.tensor([[5.0], [4.0], [3.0], [2.0], [1.0], [0.0]])  # [K, 1]: the last is best
"""Samples 0-2 are the worst-scored: ``drop=0.5`` leaves 3, 4 and 5."""
FEATURES = torch.tensor([[[float(i), float(i % 2)]] for i in range(K)])  # [K, 1, 2]

COVERAGE = {  # method -> (helper it calls, whether it drops the worst-scored, weighted targets)
    "kmeans": ("_kmeans", False, None), "score-kmeans": ("_kmeans", True, None),
    "fps": ("_farthest_points", False, None), "score-fps": ("_farthest_points", True, None),
    "facility": ("_facility", False, False), "score-facility": ("_facility", True, True),
    "medoids": ("_medoids", False, False), "score-medoids": ("_medoids", True, True),
}  # fmt: skip
DIRECT = {  # method -> the indices it keeps of FEATURES / RESIDUAL, computed by hand
    "first": [0, 1], "top": [5, 4], "score-first": [3, 4],
}  # fmt: skip
"""``random`` is checked apart (a seeded draw)."""


def _recording(monkeypatch) -> list[tuple[str, bool, bool | None]]:
    """Replace the coverage helpers by recorders: each call appends (helper, whether it was
    given fewer than all samples, whether its target weights vary) and keeps the first KEEP."""
    calls: list[tuple[str, bool, bool | None]] = []

    def recorder(name):
        def helper(x, valid, third, keep, *_):
            weighted = None
            if name in ("_facility", "_medoids"):  # third: the targets' weights [K, M]
                weighted = bool((third != third[0]).any())
            calls.append((name, not bool(valid.all()), weighted))
            return torch.arange(keep)[:, None].expand(-1, x.shape[1])

        return helper

    for name in ("_kmeans", "_farthest_points", "_facility", "_medoids"):
        monkeypatch.setattr(selection, name, recorder(name))
    return calls


def test_every_method_reaches_its_own_branch(monkeypatch):
    assert set(COVERAGE) | set(DIRECT) | {"random"} == set(METHODS)  # a new method: add it here
    calls = _recording(monkeypatch)
    for method in METHODS:
        cfg = SelectionConfig(method=method, keep=KEEP, drop=0.5)
        idx = select_indices(FEATURES, KEEP, cfg, RESIDUAL, torch.Generator().manual_seed(0))
        if method in COVERAGE:
            assert calls.pop() == COVERAGE[method], method
        else:
            assert not calls, method
        if method in DIRECT:
            assert idx[:, 0].tolist() == DIRECT[method], method
    draws = [select_indices(FEATURES, KEEP, SelectionConfig(method="random", keep=KEEP), None,
                            torch.Generator().manual_seed(seed))[:, 0].tolist()
             for seed in range(8)]  # fmt: skip
    assert len({tuple(d) for d in draws}) > 1  # drawn, not a fixed order


@pytest.mark.parametrize("name", ["stride", "stride-fps", "score-every4", "every-4th-facility"])
def test_a_method_without_a_branch_is_an_error_not_another_method(name):
    # a name added to Method without its branch in _select; its prefix or suffix routes nothing
    cfg = SelectionConfig(keep=KEEP)
    cfg.method = name  # past the Literal check, as a name added to Method alone would be
    with pytest.raises(ConfigError, match=rf"selection method '{name}' has no branch in "
                       r"score\.selection\._select \(the methods: first, random,"):  # fmt: skip
        select_indices(FEATURES, KEEP, cfg, RESIDUAL)


def test_the_method_tables_name_every_method_and_only_those():
    assert set(USES_SCORE) == set(METHODS)
    assert set(selection.SCORE_FREE) == {m for m in METHODS if USES_SCORE[m]}
    assert set(selection.DROPPING) | {"top"} == set(selection.SCORE_FREE)
    assert set(selection.WEIGHTED) <= set(selection.DROPPING)
    assert set(selection.FACILITY) <= set(METHODS)


def test_top_does_not_read_drop():
    # top keeps the K' best-scored: it drops nothing, so a --drop given to it is unread
    assert SelectionConfig(method="top", drop=0.2).unread() == ["drop"]
    assert SelectionConfig(method="score-fps", drop=0.2).unread() == []


def _methods_section() -> str:
    text = (Path(__file__).resolve().parents[2] / "docs" / "selection.md").read_text()
    return text.split("\n## Methods\n", 1)[1].split("\n## ", 1)[0]


def test_the_docs_methods_section_lists_exactly_the_methods():
    # each bullet starts with the methods it describes, in backticks, before its colon
    listed = []
    for line in _methods_section().splitlines():
        if line.startswith("- "):
            listed += re.findall(r"`([^`]+)`", line.split(":", 1)[0])
    assert sorted(listed) == sorted(METHODS)


def test_the_docs_say_how_to_add_a_method():
    text = (Path(__file__).resolve().parents[2] / "docs" / "selection.md").read_text()
    note = text.split("\n### Adding a method\n", 1)[1].split("\n#", 1)[0]
    for needed in ("Method", "_select", "USES_SCORE", "test_selection_methods.py"):
        assert needed in note, needed


def test_the_method_fields_docstring_names_every_method():
    doc = field_docs(SelectionConfig)["method"]
    assert [m for m in METHODS if f"``{m}``" not in doc] == []
