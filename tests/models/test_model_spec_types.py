"""``load_predictor`` and the checkpoint functions take a name or a path; anything else (None,
a number, a loaded model) is a ``ConfigError`` naming what they take, not ``pathlib``'s bare
``TypeError`` (walkthrough 69)."""

from __future__ import annotations

from pathlib import Path

import pytest

from trajpref.errors import ConfigError
from trajpref.models import checkpoint, zoo
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import TrajectoryScorer

TAKES = (
    r"expected a str or a path \(os\.PathLike\) naming 'cv', a published model such as "
    r"'zara1/generator' \(`trajpref models` lists them\) or a checkpoint file; got "
)


@pytest.mark.parametrize(("spec", "got"), [(None, "None"), (3, "int 3"), (2.5, "float 2.5"),
                                           (["zara1/generator"], "list"),
                                           ({"model": "cv"}, "dict")])  # fmt: skip
def test_load_predictor_names_what_it_takes(spec, got):
    with pytest.raises(ConfigError, match=rf"^load_predictor: {TAKES}{got}$"):
        load_predictor(spec)


def test_a_loaded_model_is_told_to_pass_its_name(zara1):
    with pytest.raises(ConfigError, match=r"got DiffusionPredictor, a loaded model: pass its "
                       r"name, 'zara1/generator'$"):  # fmt: skip
        load_predictor(zara1)
    scorer_message = (r"^TrajectoryScorer\.from_checkpoint: expected a str or a path.*a loaded "
                      r"model: pass its name, 'zara1/generator'$")  # fmt: skip
    with pytest.raises(ConfigError, match=scorer_message):
        TrajectoryScorer.from_checkpoint(zara1)


@pytest.mark.parametrize("call", [checkpoint.resolve_path, checkpoint.load,
                                  checkpoint.load_predictor, checkpoint.model_hash])  # fmt: skip
def test_the_checkpoint_functions_name_what_they_take(call):
    message = (r"^checkpoint: expected a str or a path \(os\.PathLike\) naming a published "
               r"model such as 'zara1/generator'.*; got None$")  # fmt: skip
    with pytest.raises(ConfigError, match=message):
        call(None)


def test_names_and_paths_still_load():
    assert load_predictor("cv").__class__.__name__ == "ConstantVelocity"
    file = zoo.resolve("zara1/generator")
    assert checkpoint.resolve_path(file) == file
    assert checkpoint.resolve_path(str(file)) == Path(file)
    assert load_predictor(file).checkpoint == str(file)
