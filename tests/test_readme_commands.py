"""The README's command-line block: every ``trajpref`` line in it parses with today's options
(docs that match the code). Parsing only: nothing is trained, read or evaluated."""

import shlex
from pathlib import Path

import pytest

from trajpref.cli import build_parser

README = Path(__file__).resolve().parents[1] / "README.md"


def _commands() -> list[str]:
    text = README.read_text()
    block = text.split("## Command line", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    lines, joined = [], ""
    for line in block.splitlines():
        joined += line.rstrip("\\").strip() + " " if line.rstrip().endswith("\\") else line
        if not line.rstrip().endswith("\\"):
            lines.append(joined.split("#", 1)[0].strip())
            joined = ""
    return [line for line in lines if line.startswith("trajpref ")]


def test_the_block_is_found_and_holds_the_main_commands():
    heads = {shlex.split(c)[1] for c in _commands()}
    assert {"data", "evaluate", "predict", "plot", "train", "finetune", "config"} <= heads


@pytest.mark.parametrize("command", _commands())
def test_each_readme_command_parses(command):
    build_parser().parse_args(shlex.split(command)[1:])  # SystemExit(2) on an unknown option
