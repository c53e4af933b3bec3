"""``results.SELECTION_FREE`` (the selection table's columns) is a copy of the score-free
selection methods that ``results`` may not import (``score`` is above it in the layers):
this test is what keeps the two the same when a selection method is added."""

from trajpref.results import SELECTION_FREE
from trajpref.score.selection import METHODS, USES_SCORE


def test_the_selection_tables_columns_are_the_score_free_methods():
    assert len(set(SELECTION_FREE)) == len(SELECTION_FREE)
    assert set(SELECTION_FREE) == {m for m in METHODS if not USES_SCORE[m]}
    # in the order of score.selection.Method, as --select lists them
    assert list(SELECTION_FREE) == [m for m in METHODS if not USES_SCORE[m]]
