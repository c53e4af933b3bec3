"""A security review's findings on config values (walkthrough 67-M): a string, integer or
float setting took any YAML value (``--set 'data.dataset=[zara1]'`` read as the dataset
``"['zara1']"``), and an error named the value it got in full, which a few hundred bytes of
YAML aliases make megabytes long."""

import pytest

from trajpref.config import load_config
from trajpref.errors import ConfigError


@pytest.mark.parametrize("value", ["[zara1]", "{a: 1}"])
def test_a_list_or_mapping_for_a_scalar_setting_is_refused(value):
    with pytest.raises(ConfigError, match=r"config data.dataset must be str, got a (list|dict)"):
        load_config(None, [f"data.dataset={value}"])


def test_an_error_names_a_long_value_in_brief(tmp_path):
    """6 levels of 9 aliases in the value itself: a file of a few hundred bytes whose value
    is about 4 MB of text when written out."""
    levels = ["&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    levels += [f"&a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 6)]
    path = tmp_path / "bomb.yaml"
    path.write_text(f"data:\n  max_agents: [{', '.join(levels)}]\n")
    assert path.stat().st_size < 600
    with pytest.raises(ConfigError, match="config data.max_agents must be int") as err:
        load_config(str(path))
    assert len(str(err.value)) < 400
