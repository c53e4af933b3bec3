"""A checkpoint written by a newer trajpref (walkthrough 62, item 1): a config key this
version does not know is named as such, not taken for a typo."""

from __future__ import annotations

import pytest

from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt


@pytest.fixture()
def newer_file(tiny_run, tmp_path):
    """The tiny generator, its header holding a key added by a newer trajpref."""
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["model"]["history_jitter"] = 0.0
    path = tmp_path / "generator.safetensors"
    ckpt.save(path, payload)
    return path


def test_a_key_this_version_lacks_is_said_to_come_from_a_newer_trajpref(newer_file):
    with pytest.raises(ConfigError) as err:
        ckpt.load_predictor(newer_file)
    message = str(err.value)
    assert message.startswith("unknown config key model.history_jitter in a checkpoint's "
                              "config: probably written by a newer trajpref")  # fmt: skip
    assert "did you mean" not in message and "upgrade trajpref" in message


def test_the_same_key_typed_by_the_user_keeps_the_typo_hint():
    from trajpref.config import load_config

    with pytest.raises(ConfigError, match=r"model\.history_jiter \(did you mean model\.history"):
        load_config(None, ["model.history_jiter=0"])  # model.history_encoder, today
    with pytest.raises(ConfigError) as err:
        load_config(None, ["model.history_jiter=0"])
    assert "newer trajpref" not in str(err.value)
