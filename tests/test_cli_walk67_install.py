"""The installed user's walkthrough (67): a shipped config written out as a YAML file to edit
(``config show --yaml``), where a built-in dataset lies under an empty data root, the
fine-tuning presets offered by the CLI, and the question on milliseconds in the CLI's advice
on a frame interval above 10 s."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from trajpref.cli import build_parser, main
from trajpref.config import builtin_configs, load_config
from trajpref.data import load_dataset
from trajpref.data.registry import SECONDS_STEPS
from trajpref.errors import DataError
from trajpref.evaluation import CLI_WORDS, PYTHON_WORDS, step_hint
from trajpref.models.timing import model_timing
from trajpref.rl.presets import PRESETS
from trajpref.types import DatasetInfo

README = Path(__file__).resolve().parents[1] / "README.md"
DATA_SECTION = "Data: where each dataset comes from"


def _yaml_out(capsys, *argv: str) -> str:
    code = main(["config", "show", *argv, "--yaml"])
    out = capsys.readouterr().out
    assert code == 0
    return out


@pytest.mark.parametrize("name", builtin_configs())
def test_config_show_yaml_reads_back_to_the_same_config(name, tmp_path, capsys):
    """Every shipped config, printed as YAML, is read back by --config FILE to an equal
    config; the file starts with a comment saying what it was resolved from."""
    text = _yaml_out(capsys, "--config", name)
    assert text.startswith(f"# trajpref config show --config {name} --yaml ")
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    assert load_config(str(path)) == load_config(name)


def test_config_show_yaml_applies_set_and_defaults(tmp_path, capsys):
    text = _yaml_out(capsys, "--config", "zara1", "--set", "seed=3",
                     "--set", "denoiser.epochs=7")  # fmt: skip
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    cfg = load_config(str(path))
    assert cfg == load_config("zara1", ["seed=3", "denoiser.epochs=7"])
    assert (cfg.seed, cfg.denoiser.epochs) == (3, 7)
    assert "--set seed=3 --set denoiser.epochs=7 --yaml" in text.splitlines()[0]
    defaults = tmp_path / "defaults.yaml"
    defaults.write_text(_yaml_out(capsys))
    assert load_config(str(defaults)) == load_config(None)


def test_config_show_without_yaml_is_unchanged(capsys):
    assert main(["config", "show", "--config", "zara1"]) == 0
    out = capsys.readouterr().out
    assert "data.dataset = zara1\n" in out and "  dataset: zara1" not in out


ROOT_DATASETS = ["eth", "hotel", "univ", "zara1", "zara2", "sdd", "nba", "robo", "robo-mix"]
LAYOUT = {"sdd": "sdd/{train,test}.npz", "nba": "nba/rebound/{train,test}/*.txt",
          "robo": "robo/{val,test}.npz", "robo-mix": "robo/{val,test}.npz"}  # fmt: skip


@pytest.mark.parametrize("name", ROOT_DATASETS)
def test_a_built_in_dataset_missing_under_the_root_says_where_it_lies(name, tmp_path):
    layout = LAYOUT.get(name, f"eth_ucy/{name}/{{train,val,test}}/*.txt")
    with pytest.raises(DataError) as caught:
        load_dataset(name, "test", tmp_path)
    message = str(caught.value)
    assert re.search(r": no such (folder|file); ", message), message
    assert f"{name} is read from {layout} under the data root ({tmp_path};" in message
    assert f'"{DATA_SECTION}"' in message
    assert "\n" not in message


def test_the_readme_has_the_section_the_error_names():
    assert f"## {DATA_SECTION}\n" in README.read_text()


def test_a_users_missing_folder_keeps_its_message(tmp_path, capsys):
    missing = tmp_path / "nope"
    with pytest.raises(DataError) as caught:
        load_dataset(str(missing), "test")
    assert str(caught.value) == f"{missing}: no such folder"


def test_the_cli_error_on_an_empty_data_root(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("TRAJPREF_DATA", str(tmp_path))
    code = main(["data", "stats", "--dataset", "zara1", "--split", "test"])
    err = capsys.readouterr().err
    assert code != 0
    assert f"{tmp_path / 'eth_ucy' / 'zara1' / 'test'}: no such folder; zara1 is read" in err


def _option(parser, *path: str, flag: str):
    for name in path:
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        parser = sub.choices[name]
    return next(a for a in parser._actions if flag in a.option_strings)


def test_finetune_preset_choices_come_from_presets():
    assert _option(build_parser(), "finetune", flag="--preset").choices == list(PRESETS)


def _folder_info(frame: float, every: float = 1.0, given: bool = True) -> DatasetInfo:
    return DatasetInfo("/data/mine", "test", "m", frame * every, source="/data/mine/test",
                       interval_from="given" if given else "default", time_step=every,
                       text_tracks=True)  # fmt: skip


ZARA1 = model_timing({"config": {"data": {"dataset": "zara1"}}})


@pytest.mark.parametrize("every", [1.0, 4.0])
def test_the_step_hint_asks_milliseconds_above_ten_seconds(every):
    hint = step_hint(_folder_info(400, every), ZARA1)
    assert hint.startswith("milliseconds? pass seconds, --frame-interval 0.4; else "), hint
    python = step_hint(_folder_info(400, every), ZARA1, PYTHON_WORDS)
    assert python.startswith("milliseconds? pass seconds, frame_interval=0.4; else "), python


def test_the_step_hint_does_not_ask_at_or_below_ten_seconds():
    assert SECONDS_STEPS[1] == 10.0
    for frame in (0.1, 2.0, SECONDS_STEPS[1]):
        assert "milliseconds" not in step_hint(_folder_info(frame), ZARA1, CLI_WORDS)
    assert "milliseconds" not in step_hint(_folder_info(400, given=False), ZARA1)


def test_the_cli_warning_asks_milliseconds(tmp_path, capsys, monkeypatch):
    """--frame-interval 400 is not refused (any number > 0 is a frame interval): the
    warning that the data steps otherwise asks whether it is in milliseconds."""
    test = tmp_path / "ds" / "test"
    test.mkdir(parents=True)
    rows = [f"{10 * f}\t{a}\t{0.4 * f + a:.2f}\t{a:.2f}" for f in range(24) for a in (1, 2)]
    (test / "a.txt").write_text("\n".join(rows) + "\n")
    code = main(["evaluate", "--model", "zara1/generator", "--dataset", str(tmp_path / "ds"),
                 "--frame-interval", "400", "--units", "m", "--samples", "4", "--device",
                 "cpu", "--no-progress"])  # fmt: skip
    err = " ".join(capsys.readouterr().err.split())
    assert code == 0, err
    assert (
        "this data steps 400 s, the model's 0.4 s (milliseconds? pass seconds, "
        "--frame-interval 0.4; else no --time-step reads it"
    ) in err, err
