"""``chosen_selection`` takes a published model's checkpoint path as well as its name, and
checks ``keep`` at once (walkthrough 63-A, finding 9)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from trajpref.errors import ConfigError
from trajpref.models import zoo
from trajpref.score import selection
from trajpref.score.selection import CHOSEN, chosen_selection

REPO = Path(__file__).resolve().parents[2]


def test_a_published_models_file_is_its_name():
    expected = chosen_selection("zara1/generator", keep=3)
    file = zoo.resolve("zara1/generator")  # .../trajpref/zoo/zara1/generator.safetensors
    assert chosen_selection(file, keep=3) == expected
    assert chosen_selection(str(file), keep=3, cheap=True) == chosen_selection(
        "zara1/generator", keep=3, cheap=True)  # fmt: skip
    repo_path = REPO / "models" / "zara1" / "generator.safetensors"  # the repository's link
    if repo_path.is_file():
        assert chosen_selection(repo_path, keep=3) == expected


def test_a_copy_of_a_published_file_is_its_name_and_another_file_is_not(tmp_path):
    copy = tmp_path / "zara1" / "generator.safetensors"
    copy.parent.mkdir()
    shutil.copyfile(zoo.resolve("eth/generator"), copy)  # eth's weights under zara1's name
    with pytest.raises(ConfigError, match="no chosen selection setting for"):
        chosen_selection(copy)
    shutil.copyfile(zoo.resolve("zara1/generator"), copy)
    assert chosen_selection(copy) == chosen_selection("zara1/generator")


def test_a_path_that_is_not_here_names_the_published_model(tmp_path):
    missing = tmp_path / "zara1" / "generator.safetensors"
    with pytest.raises(ConfigError, match=r"no chosen selection setting for '.*zara1/generator"
                       r"\.safetensors' \(no such file here; the published model is named "
                       r"zara1/generator\); published generators with one: "):  # fmt: skip
        chosen_selection(missing)
    with pytest.raises(ConfigError, match="published generators with one: eth/generator, "):
        chosen_selection("hotel/generator")


@pytest.mark.parametrize("keep", [0, -1, 21, 25, True, 2.0, "5"])
def test_keep_is_checked_at_once(keep):
    text = r"chosen_selection keep: how many of the K = 20 samples zara1/generator emits to keep"
    with pytest.raises(ConfigError, match=text + r", an integer in 1\.\.20"):
        chosen_selection("zara1/generator", keep=keep)
    assert chosen_selection("zara1/generator", keep=20).keep == 20


def test_every_chosen_generator_emits_the_k_that_keep_is_checked_against():
    for name in CHOSEN:
        if name in zoo.published():
            samples = zoo.header(zoo.resolve(name))["config"]["model"]["samples"]
            assert samples == selection.CHOSEN_SAMPLES


def test_keep_from_a_planners_arrays_counts_as_an_integer():
    import numpy as np

    from trajpref.score.selection import chosen_selection

    assert chosen_selection("zara1/generator", keep=np.int64(3)).keep == 3
    assert type(chosen_selection("zara1/generator", keep=np.int64(3)).keep) is int
