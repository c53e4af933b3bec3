"""Without a data root, the message names how to give one from Python too (``root=``), not
only the CLI's ``--data-root``."""

import pytest

from trajpref.data import load_dataset
from trajpref.errors import TrajprefError


def test_no_data_root_names_the_cli_option_the_argument_and_the_variable(monkeypatch):
    monkeypatch.delenv("TRAJPREF_DATA", raising=False)
    with pytest.raises(TrajprefError) as err:
        load_dataset("zara1", "test")
    text = str(err.value)
    assert "--data-root" in text and "root=" in text and "TRAJPREF_DATA" in text
