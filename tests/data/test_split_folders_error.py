"""A user folder with some of the train/ val/ test/ sub-folders but not the one asked for: the
error names the remedies that work (for val/, the same ones as the warning for a folder
without sub-folders, less the held-out scene, which needs a val/ too)."""

import pytest
from synthetic import straight_rows, write_tracks

from trajpref.config import DataConfig
from trajpref.data import load_dataset, run_splits
from trajpref.errors import DataError


@pytest.fixture
def no_val(tmp_path):
    """train/ and test/, no val/."""
    write_tracks(tmp_path / "train" / "a.txt", straight_rows(25))
    write_tracks(tmp_path / "test" / "b.txt", straight_rows(21))
    return tmp_path


def test_a_folder_without_val_names_the_remedies(no_val):
    with pytest.raises(DataError) as caught:
        run_splits(DataConfig(dataset=str(no_val)))
    message = str(caught.value)
    assert "no val/ sub-folder (found test, train)" in message
    assert "--set data.val_dataset=FOLDER" in message
    assert "add a val/ sub-folder" in message
    # the remedy named works: a validation folder of its own
    write_tracks(no_val.parent / "held" / "c.txt", straight_rows(22))
    train, val = run_splits(
        DataConfig(dataset=str(no_val), val_dataset=str(no_val.parent / "held"))
    )
    assert len(train) and len(val)


def test_a_folder_without_test_says_what_it_has(no_val):
    (no_val / "test" / "b.txt").rename(no_val / "b.txt")
    (no_val / "test").rmdir()
    write_tracks(no_val / "val" / "c.txt", straight_rows(22))
    with pytest.raises(DataError, match=r"no test/ sub-folder \(found train, val\)$"):
        load_dataset(str(no_val), "test")  # the validation remedies are val/'s alone
