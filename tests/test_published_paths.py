"""A published model's repository path (``models/zara1/generator.safetensors``) given where
there is no such file (an installed package, another folder): every way of loading it names
the published name, which works in any folder, by one rule (``zoo.not_here_message``):
``--model``, ``--scorer``, ``--from`` and ``train --denoiser`` on the command line, and
``load_predictor``, ``TrajectoryScorer.from_checkpoint``, ``checkpoint.load`` and
``train_stage(denoiser=...)`` in Python (walkthrough of a wheel install, 2026-12-06)."""

from __future__ import annotations

import pytest

from trajpref.cli import main
from trajpref.config import load_config
from trajpref.errors import TrajprefError
from trajpref.models import checkpoint as ckpt
from trajpref.models import registry, zoo
from trajpref.score import TrajectoryScorer
from trajpref.train.run import train_stage

pytestmark = pytest.mark.skipif("zara1/denoiser" not in zoo.published(),
                                reason="the package was built without its models")  # fmt: skip

GEN, DEN = "models/zara1/generator.safetensors", "models/zara1/denoiser.safetensors"


def _api(spec: str, name: str) -> str:
    return (f"{spec}: no such checkpoint here; the published model is named {name} ({name} "
            "works in any folder)")  # fmt: skip


def test_train_denoiser_given_the_repository_path_names_the_published_denoiser(
    capsys, monkeypatch, tmp_path
):
    monkeypatch.chdir(tmp_path)
    argv = ["train", "generator", "--config", "zara1", "--out", "rg", "--denoiser", DEN]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.err == (f"trajpref: error: --denoiser {DEN}: no such checkpoint here; the "
                            "published model is named zara1/denoiser (--denoiser zara1/denoiser "
                            "works in any folder)\n")  # fmt: skip
    assert list(tmp_path.iterdir()) == []


def test_train_generator_without_a_denoiser_suggests_the_published_name(
    capsys, monkeypatch, tmp_path
):
    """Its advice works where it is read: a published name, not a repository path."""
    monkeypatch.chdir(tmp_path)
    assert main(["train", "generator", "--config", "zara1", "--out", "rg"]) == 2
    err = capsys.readouterr().err
    assert "pass --denoiser FILE (or a published denoiser's name, e.g. zara1/denoiser" in err
    assert "models/zara1" not in err
    # an eth run is pointed at eth's denoiser, not zara1's (a CLI walkthrough, 2026-12-06)
    assert main(["train", "generator", "--config", "eth", "--out", "re"]) == 2
    assert "published denoiser's name, e.g. eth/denoiser" in capsys.readouterr().err


def test_the_python_api_names_the_published_model_for_a_repository_path(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(TrajprefError) as err:
        registry.load_predictor(GEN)
    assert str(err.value) == _api(GEN, "zara1/generator")
    with pytest.raises(TrajprefError) as err:
        TrajectoryScorer.from_checkpoint(DEN)
    assert str(err.value) == _api(DEN, "zara1/denoiser")
    with pytest.raises(TrajprefError) as err:  # a legacy suffix too
        ckpt.load("models/zara1/generator.pt")
    assert str(err.value) == _api("models/zara1/generator.pt", "zara1/generator")
    with pytest.raises(TrajprefError) as err:
        train_stage("generator", load_config("zara1"), tmp_path / "rg", denoiser=DEN)
    assert str(err.value) == _api(DEN, "zara1/denoiser")
    assert list(tmp_path.iterdir()) == []


def test_the_rule_leaves_files_names_and_other_paths_alone(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    assert zoo.not_here_message("zara1/generator") is None  # a name, not a path
    assert zoo.not_here_message("models/zara9/generator.safetensors") is None  # no such model
    assert zoo.not_here_message("models/zara1/generator.txt") is None  # not a checkpoint
    # a run's own output folder, not yet written, is not the zoo's place
    assert zoo.not_here_message("/home/me/runs/zara1/generator.safetensors") is None
    assert zoo.not_here_message("runs/zara1/generator.safetensors") is None
    assert zoo.not_here_message("/somewhere/src/trajpref/zoo/zara1/generator.safetensors")
    (tmp_path / "zara1").mkdir()
    (tmp_path / "zara1" / "generator.safetensors").write_bytes(b"")
    assert zoo.not_here_message("zara1/generator.safetensors") is None  # a file here
    assert zoo.not_here_message("zara1/generator.pt") is None  # its .safetensors file is here
    assert zoo.not_here_message(GEN, "--model") == (
        f"--model {GEN}: no such checkpoint here; the published model is named zara1/generator "
        "(--model zara1/generator works in any folder)"
    )
    with pytest.raises(TrajprefError, match=r"nope\.safetensors: no such checkpoint$"):
        ckpt.load("nope.safetensors")  # an unknown path keeps the plain message
