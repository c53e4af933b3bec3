"""benchmarks/zoo_index.py: a card's test-row command names no machine's data path
(walkthrough 67, F6)."""

import re
from pathlib import Path

from bench import load_benchmark

ROOT = Path(__file__).resolve().parent.parent


def test_an_absolute_data_root_becomes_the_portable_one():
    zoo = load_benchmark("zoo_index")
    cmd = (
        "python benchmarks/pretrain.py --dataset sdd --run-dir runs/x --data-root /work/shared/data"
    )
    assert zoo.portable_command(cmd) == (
        "python benchmarks/pretrain.py --dataset sdd --run-dir runs/x --data-root ../shared/data"
    )
    assert zoo.portable_command("score.py --data-root=/home/me/data --x 1") == (
        "score.py --data-root=../shared/data --x 1"
    )
    relative = "python benchmarks/score.py --dataset eth --data-root ../shared/data"
    assert zoo.portable_command(relative) == relative
    assert zoo.portable_command("trajpref evaluate --dataset data/x") == (
        "trajpref evaluate --dataset data/x"
    )
    assert zoo.portable_command(None) is None


def test_the_card_and_index_show_the_portable_command_and_the_row_keeps_its_own():
    zoo = load_benchmark("zoo_index")
    cmd = "python benchmarks/score.py --dataset zara2 --data-root /work/shared/data"
    row = {"dataset": "zara2", "method": "pretrained", "seed": 0, "split": "test",
           "samples": 20, "min_ade": 0.1, "min_fde": 0.2, "joint_min_ade": 0.3,
           "joint_min_fde": 0.4, "date": "2026-12-06", "machine": "m", "command": cmd}  # fmt: skip
    test = zoo._test_row(row)
    assert (
        test["command"] == "python benchmarks/score.py --dataset zara2 --data-root ../shared/data"
    )
    assert row["command"] == cmd  # the results row is not rewritten


def test_no_published_card_or_index_names_an_absolute_data_root():
    zoo_dir = ROOT / "src" / "trajpref" / "zoo"
    for path in [zoo_dir / "index.json", *sorted(zoo_dir.glob("*/*.md"))]:
        text = path.read_text()
        assert "--data-root /" not in text and "--data-root=/" not in text, path


def test_the_readme_shows_no_machine_specific_data_root():
    """The README's generated footnotes showed the measuring machine's --data-root
    (/work/shared/data); update_readme.py now shows each command as the cards do."""
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    assert not re.search(r"--data-root[ =]/", readme)
