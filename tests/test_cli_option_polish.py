"""Command-line polish: long options are never abbreviated (in every command, nested ones
included), the number-or-none options share one parser, progress bars stay quiet in log
files, the two --max-agents say which one they are, and the README names every key that
``evaluate --json`` prints."""

from __future__ import annotations

import argparse
import io
import json
import re
import sys
import time
from pathlib import Path

import pytest
from tqdm import tqdm

from trajpref import cli
from trajpref.cli import build_parser, main
from trajpref.errors import ConfigError
from trajpref.io import LOG_REDRAW_SECONDS, bar_options

README = Path(__file__).resolve().parents[1] / "README.md"


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _parsers(parser: argparse.ArgumentParser, path: tuple[str, ...] = ("trajpref",)):
    """Every parser of the command line, with its command path."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, (*path, name))


def test_no_parser_of_the_command_line_takes_abbreviations():
    found = dict(_parsers(build_parser()))
    # the top level, a command, a nested command of cli.py and one of survey/cli.py
    assert {("trajpref",), ("trajpref", "evaluate"), ("trajpref", "data", "stats"),
            ("trajpref", "survey", "build")} <= set(found)  # fmt: skip
    assert [path for path, p in found.items() if p.allow_abbrev] == []


SURVEY = ["survey", "build", "--dataset", "zara1", "--models", "a=cv", "--out", "{out}/s"]


@pytest.mark.parametrize(
    ("argv", "short"),
    [
        (["evaluate", "--dataset", "zara1", "--max-sc", "3"], "--max-sc"),  # --max-scenes
        (["data", "stats", "--dataset", "zara1", "--js"], "--js"),  # --json, nested
        ([*SURVEY, "--max-ag", "3"], "--max-ag"),  # --max-agents, added by survey/cli.py
        (["config", "show", "--conf", "zara1"], "--conf"),  # --config
    ],
    ids=["evaluate", "data stats", "survey build", "config show"],
)
def test_an_abbreviated_option_is_refused(capsys, tmp_path, argv, short):
    """argparse took `--max-sc 3` for `--max-scenes 3` (and would have refused it, as
    ambiguous, once another option starting --max-sc came along)."""
    code, out, err = _run(capsys, *(a.format(out=tmp_path) for a in argv))
    assert code == 2 and out == ""
    assert err.startswith(f"trajpref: error: unrecognized arguments: {short}"), err
    assert err.count("\n") == 1
    assert not (tmp_path / "s").exists()


def test_the_full_option_still_parses():
    args = build_parser().parse_args(["evaluate", "--dataset", "zara1", "--max-scenes=3"])
    assert args.max_scenes == 3


@pytest.mark.parametrize(
    ("name", "text", "expected"),
    [
        ("max_log_sigma", None, (False, None)),
        ("max_log_sigma", "none", (True, None)),
        ("max_log_sigma", " NONE ", (True, None)),
        ("max_log_sigma", "1e6", (True, 1e6)),
        ("max_log_sigma", "-8", (True, -8.0)),
        ("neighbour_radius", None, (False, None)),
        ("neighbour_radius", "None", (True, None)),
        ("neighbour_radius", "6.5", (True, 6.5)),
    ],
)
def test_one_parser_reads_both_number_or_none_options(name, text, expected):
    assert cli._number_or_none(argparse.Namespace(**{name: text}), name) == expected


def test_the_cap_leaves_its_number_to_the_generator_and_the_radius_checks_its_own():
    """A non-finite cap is refused where the generator takes it (``--max-log-sigma:
    model.max_log_sigma must be a finite number``, tests/test_cli_errors.py); a radius must
    be a distance > 0 at once."""
    given, value = cli._number_or_none(argparse.Namespace(max_log_sigma="nan"), "max_log_sigma")
    assert given and value != value  # nan, passed on
    for text in ("nan", "inf", "0", "-1"):
        with pytest.raises(ConfigError, match="--neighbour-radius takes a distance > 0"):
            cli._number_or_none(argparse.Namespace(neighbour_radius=text), "neighbour_radius")


def test_a_cap_that_is_not_a_number_is_the_same_one_line_error_as_a_bad_radius(capsys):
    """It was argparse's form, `argument --max-log-sigma: takes ...`, and came before any
    other check; now it is checked with the radius, before any model or data is read."""
    code, out, err = _run(capsys, "evaluate", "--dataset", "zara1", "--max-log-sigma", "off")
    assert code == 2 and out == ""
    assert err == ("trajpref: error: --max-log-sigma takes a number (model units) or none "
                   "(no cap), got 'off'\n")  # fmt: skip


def test_progress_bars_are_hidden_by_no_progress():
    assert bar_options(False) == {"disable": True}


def test_progress_bars_redraw_rarely_where_stderr_is_not_a_terminal(capsys):
    """Under capsys stderr is not a terminal, as in `trajpref train ... 2> log` or nohup:
    tqdm's own 0.1 s wrote ten carriage-return updates a second into the log. Since the
    batch walkthrough of 2026-12-06 a bar there waits LOG_REDRAW_SECONDS before its first
    line (it drew its 0 % state, then cleared it, leaving the log's last line open)."""
    options = bar_options(True)
    assert {k: options[k] for k in ("disable", "mininterval", "maxinterval", "delay")} == {
        "disable": False, "mininterval": LOG_REDRAW_SECONDS, "maxinterval": LOG_REDRAW_SECONDS,
        "delay": LOG_REDRAW_SECONDS}  # fmt: skip
    draws = {}
    for name, kwargs in (("tqdm's own", {"file": io.StringIO()}), ("ours", options)):
        capsys.readouterr()
        for _ in tqdm(range(40), leave=False, **kwargs):
            time.sleep(0.01)  # 0.4 s: four redraws or more at tqdm's own 0.1 s
        log = kwargs["file"].getvalue() if name != "ours" else capsys.readouterr().err
        draws[name] = log.count("/40 [")
    assert draws["tqdm's own"] >= 3
    assert draws["ours"] == 0  # a pass shorter than a minute leaves nothing in a log


def test_progress_bars_keep_tqdms_pace_on_a_terminal(monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stderr", Terminal())
    assert bar_options(True) == {"disable": False}


def _help(*command: str) -> dict[str, str]:
    """The help text of each long option of a (nested) command."""
    parser = dict(_parsers(build_parser()))[("trajpref", *command)]
    return {s: a.help for a in parser._actions for s in a.option_strings}


@pytest.mark.parametrize("command", ["evaluate", "predict", "plot"])
def test_max_agents_help_says_it_is_a_batch_size_not_a_scene_filter(command):
    """`survey build --max-agents 8` skips scenes of more agents; evaluate's, predict's and
    plot's --max-agents batches them and skips none: their help said only 'agents per batch'."""
    text = _help(command)["--max-agents"]
    assert text.startswith("a batch size, not a scene filter")
    assert "survey build's --max-agents, by contrast, skips larger scenes" in text


def _documented_keys() -> set[str]:
    section = README.read_text().split("### `evaluate --json`: every key", 1)[1]
    section = section.split("\n## ", 1)[0]
    return set(re.findall(r"`([a-z_0-9]+)`", section))


def test_the_readme_names_every_key_evaluate_json_prints(capsys, walks, tiny_run):
    documented = _documented_keys()
    printed: set[str] = set()
    base = ["evaluate", "--dataset", walks, "--samples", "4", "--no-progress", "--device",
            "cpu", "--json"]  # fmt: skip
    for extra in (["--model", "cv", "--max-scenes", "2"],
                  ["--model", tiny_run / "generator.safetensors", "--scorer",
                   tiny_run / "denoiser.safetensors", "--keep", "2", "--bins", "2,4",
                   "--slots"]):  # fmt: skip
        code, out, err = _run(capsys, *base, *extra)
        assert code == 0, err
        printed |= set(json.loads(out))
    assert {"candidates", "scorer_score_steps", "top5_recall_fts", "bins", "slots"} <= printed
    assert printed - documented == set()


@pytest.mark.parametrize(("flags", "said"), [
    (["--history", "6", "--set", "model.t_hist=5"],
     "--history 6 and --set model.t_hist=5 both set model.t_hist: give it once"),
    (["--time-step", "4", "--set", "data.time_step=2"],
     "--time-step 4.0 and --set data.time_step=2 both set data.time_step: give it once"),
    (["--dataset", "a", "--set", "data.dataset=b"],
     "--dataset a and --set data.dataset=b both set data.dataset: give it once"),
])  # fmt: skip
def test_a_train_shortcut_and_a_set_of_another_value_are_refused(capsys, monkeypatch, tmp_path,
                                                                  flags, said):  # fmt: skip
    """``train --history 6 --set model.t_hist=5`` trained at 6 without a word (walkthrough
    70); the same value twice is no conflict."""
    import trajpref.cli as cli
    from trajpref.errors import ConfigError

    ran = []

    def stand_in(stage, cfg, *args, **kwargs):  # records the config, trains nothing
        ran.append(cfg)
        raise ConfigError("stopped here")

    monkeypatch.setattr(cli, "train_stage", stand_in)
    code, out, err = _run(capsys, "train", "diffusion", "--out", tmp_path / "r", *flags)
    assert (code, out, ran) == (2, "", []) and err == f"trajpref: error: {said}\n"
    _run(capsys, "train", "diffusion", "--out", tmp_path / "s", "--history", "6", "--set",
         "model.t_hist=6")  # fmt: skip
    assert [cfg.model.t_hist for cfg in ran] == [6]
