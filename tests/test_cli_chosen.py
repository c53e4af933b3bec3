"""``evaluate`` / ``predict --keep K' --chosen [cheap]``: the selection setting chosen on
validation for a published generator (``score.selection.chosen_selection``) from the command
line, scored by the model's own denoiser as it was chosen (robotics walkthrough of
2026-12-06: ``--keep`` alone ran the generic defaults, not the chosen setting)."""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from helpers import _run

import trajpref.cli as cli
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo
from trajpref.score.selection import CHOSEN, SelectingPredictor, chosen_selection

pytestmark = pytest.mark.skipif("zara1/generator" not in zoo.published(),
                                reason="the package was built without its models")  # fmt: skip


@pytest.fixture
def built(monkeypatch):
    """The SelectingPredictors the CLI builds (their config and scorer)."""
    made = []

    class Recording(SelectingPredictor):
        def __init__(self, base, cfg, candidates=20, scorer=None):
            made.append(self)
            super().__init__(base, cfg, candidates, scorer)

    monkeypatch.setattr(cli, "SelectingPredictor", Recording)
    return made


@pytest.mark.parametrize("command", ["evaluate", "predict"])
@pytest.mark.parametrize(("flags", "cheap", "per"), [
    (["--chosen"], False, "agent"),
    (["--chosen", "cheap", "--select-per", "scene"], True, "scene"),
])  # fmt: skip
def test_chosen_selects_with_exactly_chosen_selections_config(
    capsys, walks, tmp_path, built, command, flags, cheap, per
):
    out = tmp_path / ("r.json" if command == "evaluate" else "p.npz")
    argv = [command, "--dataset", walks, "--model", "zara1/generator", "--keep", "3", *flags,
            "--seed", "4", "--max-scenes", "2", "--no-progress", "--device", "cpu",
            "--out", out]  # fmt: skip
    code, _, err = _run(capsys, *argv)
    assert code == 0, err
    (selector,) = built
    expected = dataclasses.replace(chosen_selection("zara1/generator", 3, cheap, per=per), seed=4)
    assert selector.cfg == expected
    assert selector.candidates == 20
    # scored by the model's own denoiser (zara1/denoiser), which the setting was chosen with
    own = ckpt.load(zoo.resolve("zara1/denoiser"))["hash"]
    assert ckpt.state_hash(selector.scorer.denoiser.state_dict()) == own
    if command == "evaluate":  # the result records the settings that ran
        result = json.loads(out.read_text())
        assert result["chosen"] == ("cheap" if cheap else "full")
        assert (result["select"], result["drop"], result["bandwidth"], result["trust_speed"],
                result["score_every"], result["score_from"], result["select_per"]) == (
            expected.method, expected.drop, expected.bandwidth, expected.trust_speed,
            expected.score_every, expected.score_from, per)  # fmt: skip


def test_without_chosen_keep_runs_the_options_defaults_as_before(capsys, walks, built):
    argv = ["evaluate", "--dataset", walks, "--model", "zara1/generator", "--keep", "3",
            "--max-scenes", "2", "--no-progress", "--device", "cpu"]  # fmt: skip
    code, _, err = _run(capsys, *argv)
    assert code == 0, err
    (selector,) = built
    assert selector.cfg == cli.SelectionConfig(keep=3)  # the options' defaults
    assert selector.cfg != chosen_selection("zara1/generator", 3)


EVAL = ["evaluate", "--dataset", "{walks}", "--model", "zara1/generator", "--no-progress",
        "--device", "cpu"]  # fmt: skip


@pytest.mark.parametrize(("extra", "message"), [
    (["--chosen"], r"--chosen needs --keep K'"),
    (["--chosen", "cheap"], r"--chosen cheap needs --keep K'"),
    (["--keep", "3", "--chosen", "--drop", "0.3"],  # the default's value, given: refused too
     r"--chosen sets --drop \(the setting chosen for zara1/generator\): leave it out"),
    (["--keep", "3", "--chosen", "--select", "fps", "--bandwidth", "1", "--select-temperature",
      "2", "--trust-speed", "0.1", "--score-every", "3", "--score-from", "0"],
     r"--chosen sets --select, --trust-speed, --bandwidth, --select-temperature, "
     r"--score-every, --score-from \(.*\): leave them out"),
    (["--keep", "3", "--chosen", "--samples", "10"], r"--chosen: .*give --samples 20"),
    (["--keep", "3", "--chosen", "--scorer", "eth/denoiser"],
     r"--chosen: the setting was chosen with zara1/generator's own denoiser as the scorer"),
])  # fmt: skip
def test_chosen_refuses_what_it_cannot_honour(capsys, walks, extra, message):
    argv = [a.replace("{walks}", str(walks)) for a in EVAL] + extra
    code, out, err = _run(capsys, *argv)
    assert (code, out) == (2, "")
    assert err.startswith("trajpref: error: ") and err.count("\n") == 1, err
    assert re.search(message, err), err


@pytest.mark.parametrize("model", ["cv", "nba/generator", "{run}/generator.safetensors"])
def test_a_model_without_a_chosen_setting_is_chosen_selections_error(capsys, walks, tiny_run,
                                                                     model):  # fmt: skip
    model = model.replace("{run}", str(tiny_run))
    code, out, err = _run(capsys, "evaluate", "--dataset", walks, "--model", model, "--keep",
                          "3", "--chosen", "--no-progress", "--device", "cpu")  # fmt: skip
    assert (code, out) == (2, "")
    assert f"trajpref: error: --chosen: no chosen selection setting for {model!r}" in err
    assert "published generators with one: " + ", ".join(sorted(CHOSEN)) in err
    # a model of its own K (the tiny run's 4) heard about --samples 20 first (walkthrough 70)
    code, _, err = _run(capsys, "evaluate", "--dataset", walks, "--model", model, "--keep", "2",
                        "--samples", "4", "--chosen", "--no-progress")  # fmt: skip
    assert code == 2 and "no chosen selection setting for" in err and "--samples" not in err
    code, _, err = _run(capsys, "evaluate", "--dataset", walks, "--model", "eth/generator-pace",
                        "--keep", "3", "--chosen", "cheap", "--no-progress")  # fmt: skip
    assert code == 2 and "no chosen cheap selection setting for 'eth/generator-pace'" in err


@pytest.mark.realdata
def test_chosen_runs_on_zara1(capsys, data_root):
    argv = ["evaluate", "--dataset", "zara1", "--data-root", data_root, "--model",
            "zara1/generator", "--keep", "5", "--chosen", "--max-scenes", "10", "--json",
            "--no-progress", "--device", "cpu"]  # fmt: skip
    code, out, err = _run(capsys, *argv)
    assert code == 0, err
    result = json.loads(out)
    chosen = chosen_selection("zara1/generator", 5)
    got = (result["select"], result["drop"], result["trust_speed"], result["score_every"])
    assert got == (chosen.method, chosen.drop, chosen.trust_speed, chosen.score_every)
    assert result["samples"] == 5 and result["candidates"] == 20 and result["agents"] > 0
