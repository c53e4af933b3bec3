"""Training on one's own tracking data (walkthrough of 2026-12-06): a config section written
twice trained on the built-in zara1, ``train`` said nothing of a pace that ``data stats``
flags, a generator took a feet-trained denoiser's data scale for metres without a word,
training never said what it read, progress bars in logs were redrawn every step, a resume
after the folder's denoiser was replaced was advised into the same error, and some errors
named no way out (split folders under other names, a key in the wrong section, a relative
dataset path beside the config file)."""

from __future__ import annotations

import dataclasses
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from synthetic import TINY_OVERRIDES

from trajpref.cli import main
from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.errors import ConfigError, DataError
from trajpref.train.run import train_stage

# --------------------------------------------------------------------------- config files


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_section_written_twice_is_refused_with_the_key_the_file_and_the_line(tmp_path):
    """yaml.safe_load kept the second data: section alone: the run trained on zara1."""
    text = "data:\n  dataset: ds10\n  units: m\ndata:\n  time_step: 4\n"
    cfg = _write(tmp_path / "w4.yaml", text)
    with pytest.raises(ConfigError) as err:
        load_config(cfg)
    message = str(err.value)
    assert message.startswith(f"{cfg}, line 4: data is given twice (first on line 1)")
    assert "write one data: section holding all its keys" in message


def test_a_key_written_twice_inside_a_section_is_refused_too(tmp_path):
    cfg = _write(tmp_path / "w5.yaml", "data:\n  dataset: ds10\n  time_step: 4\n  time_step: 1\n")
    with pytest.raises(ConfigError, match=r"w5.yaml, line 4: data.time_step is given twice "
                       r"\(first on line 3\)"):  # fmt: skip
        load_config(cfg)


def test_a_set_value_with_a_key_twice_is_refused_and_bad_yaml_is_a_config_error():
    with pytest.raises(ConfigError, match="data.dataset is given twice"):
        load_config(None, ["data={dataset: a, dataset: b}"])
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(None, ["data.dataset=[a"])


def test_a_file_without_repeats_loads_as_before(tmp_path):
    text = "data:\n  dataset: eth\n  rotate: false\ndenoiser:\n  epochs: 3\n"
    cfg = _write(tmp_path / "ok.yaml", text)
    loaded = load_config(cfg)
    assert (loaded.data.dataset, loaded.denoiser.epochs) == ("eth", 3)


@pytest.mark.parametrize(("text", "suggested"), [
    ("data:\n  epochs: 3\n", "did you mean denoiser.epochs, generator.epochs or finetune.epochs?"),
    ("units: m\n", "did you mean data.units? it is a key of another section"),
    ("model:\n  units: m\n", "did you mean data.units?"),
    ("dataset: eth\n", "did you mean data.dataset?"),
    ("denoiser:\n  epoch: 3\n", "did you mean denoiser.epochs?)"),  # its own section's first
])  # fmt: skip
def test_a_key_in_the_wrong_section_is_pointed_to_the_section_it_belongs_to(
    tmp_path, text, suggested
):
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path / "c.yaml", text))
    assert suggested in str(err.value)


def test_a_relative_dataset_beside_the_config_file_says_where_it_is_read_from(
    tmp_path, monkeypatch, capsys, walks
):
    """``dataset: ds10`` in a config file is read from the current folder: 'unknown dataset
    ds10' did not say that it lay beside the file."""
    home = tmp_path / "project"
    home.mkdir()
    (home / "ds10").symlink_to(walks)
    cfg = _write(home / "rel.yaml", "data:\n  dataset: ds10\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    code = main(["train", "diffusion", "--config", str(cfg), "--out", str(tmp_path / "o"),
                 "--device", "cpu", "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err
    assert code != 0
    assert "ds10: no such folder in the current folder" in err
    assert f"not the config file's ({cfg}), beside which {home / 'ds10'} is" in err
    assert not (tmp_path / "o").exists()


def test_split_folders_under_other_names_are_listed_with_the_names_to_give_them(tmp_path, walks):
    data = tmp_path / "vt"
    for split, other in (("train", "train"), ("val", "validation"), ("test", "testing")):
        (data / other).mkdir(parents=True)
        for f in (walks / split).iterdir():
            (data / other / f.name).write_bytes(f.read_bytes())
    with pytest.raises(DataError) as err:
        load_dataset(str(data), "val")
    text = str(err.value)
    assert "no val/ sub-folder (found train, and testing/, validation/, which are not" in text
    assert "rename testing/ to test/ and validation/ to val/" in text


# ------------------------------------------------------------------------- what training reads


def _timed_folder(root: Path, speed: float = 1.0, header: str = "timestamp") -> Path:
    """A 10 Hz metre folder whose time column (``header``) steps 0.1 s (frame numbers
    ``frame`` step 1): walkers at ``speed`` m/s, 90 rows each; train/ of two files, val/ of
    one."""
    rng = np.random.default_rng(0)
    for split, files in (("train", 2), ("val", 1)):
        for f in range(files):
            rows = [f"{header},track_id,x,y"]
            for a in range(3):
                pos, angle = rng.uniform(-3, 3, 2), rng.uniform(0, 2 * np.pi)
                vel = speed * 0.1 * np.array([np.cos(angle), np.sin(angle)])
                for t in range(90):
                    frame = f"{t / 10:.1f}" if header == "timestamp" else str(t)
                    x, y = pos + vel * t
                    rows.append(f"{frame},{a + 1},{x:.4f},{y:.4f}")
            path = root / split / f"walk{f}.csv"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text("\n".join(rows) + "\n")
    return root


def _cfg(data: Path, *extra: str):
    return load_config(None, [*TINY_OVERRIDES, f"data.dataset={data}", "denoiser.epochs=1",
                              "generator.epochs=1", *extra])  # fmt: skip


def _train(stage, cfg, out, **kwargs) -> tuple[list[str], str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        train_stage(stage, cfg, out, device="cpu", progress=False, **kwargs)
    return [str(w.message) for w in caught], ""


def test_training_says_what_it_read_one_line_per_split(tmp_path, capsys):
    data = _timed_folder(tmp_path / "d")
    _train("diffusion", _cfg(data, "data.units=m", "data.time_step=4"), tmp_path / "o")
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if re.match(r"\[denoiser\] (train|val): ", line)]
    assert len(lines) == 2
    assert re.fullmatch(rf"\[denoiser\] train: {re.escape(str(data))} \(train split\): \d+ "
                        r"scenes, \d+ agents, 0.4 s per step \(0.1 s between frames: the step "
                        r"of the files' time column; read every 4\), units m",
                        lines[0])  # fmt: skip
    assert lines[1].startswith(f"[denoiser] val: {data} (val split): ")


def test_a_tiny_validation_split_is_named_as_noise(tmp_path):
    data = _timed_folder(tmp_path / "d")
    messages, _ = _train("diffusion", _cfg(data, "data.units=m", "data.time_step=4"),
                         tmp_path / "o")  # fmt: skip
    tiny = [m for m in messages if m.startswith("validation has ")]
    assert len(tiny) == 1 and "the choice is mostly noise" in tiny[0]


def test_a_frame_interval_that_overrides_the_time_column_is_named_with_the_pace(tmp_path):
    """--frame-interval 0.4 on 10 Hz timestamp files: 1.6 s per step recorded without a word
    (data stats flagged the pace)."""
    data = _timed_folder(tmp_path / "d")
    cfg = _cfg(data, "data.units=m", "data.time_step=4", "data.frame_interval=0.4")
    messages, _ = _train("diffusion", cfg, tmp_path / "o")
    override = [m for m in messages if "overrides the files' time column" in m]
    assert len(override) == 1
    assert "--frame-interval 0.4 (data.frame_interval)" in override[0]
    assert "walk0.csv's timestamp column steps 0.1 s between rows" in override[0]
    assert "the model records 1.6 s per step where the files say 0.4 s" in override[0]
    pace = [m for m in messages if "is not a walking pace" in m]
    assert len(pace) == 1 and pace[0].startswith(f"{data}: 0.25") and "read every 4" in pace[0]


def test_an_assumed_interval_read_every_fourth_row_is_named(tmp_path):
    data = _timed_folder(tmp_path / "d", header="frame")  # frame numbers: 0.4 s assumed
    messages, _ = _train("diffusion", _cfg(data, "data.time_step=4"), tmp_path / "o")
    assumed = [m for m in messages if "the seconds between rows are assumed" in m]
    assert len(assumed) == 1
    assert "data.time_step 4 reads every 4 rows" in assumed[0]
    assert "the model records 1.6 s per step" in assumed[0]


def test_data_read_as_they_are_get_no_pace_warning(tmp_path):
    data = _timed_folder(tmp_path / "d")
    messages, _ = _train("diffusion", _cfg(data, "data.units=m", "data.time_step=4"),
                         tmp_path / "o")  # fmt: skip
    assert not [m for m in messages if "walking pace" in m or "time column" in m
                or "assumed" in m]  # fmt: skip


def test_a_generator_through_a_denoiser_of_other_units_and_pace_says_what_it_costs(tmp_path):
    """A feet-trained denoiser's data scale (5.02) was used for metres (1.53) silently."""
    feet = _timed_folder(tmp_path / "ft", speed=3.3)  # the same walks in feet
    metres = _timed_folder(tmp_path / "m")
    _train("diffusion", _cfg(feet, "data.units=ft"), tmp_path / "den")
    den = tmp_path / "den" / "denoiser.safetensors"
    messages, _ = _train("generator", _cfg(metres, "data.units=m", "data.time_step=4"),
                         tmp_path / "gen", denoiser=str(den))  # fmt: skip
    found = [m for m in messages if m.startswith(f"--denoiser {den} was trained on {feet}")]
    assert len(found) == 1
    text = found[0]
    assert "this data is in m, the model's in ft" in text
    assert "this data steps 0.4 s, the model's 0.1 s" in text
    assert re.search(r"takes the denoiser's data scale \([\d.]+ ft\) for this data, whose own "
                     r"is [\d.]+ m", text)  # fmt: skip
    assert "train a denoiser on this data first" in text


def test_a_generator_through_its_own_folders_denoiser_gets_no_such_warning(tiny_run, tmp_path):
    cfg = load_config(tiny_run / "config.yaml", ["generator.epochs=1"])
    messages, _ = _train("generator", cfg, tmp_path / "g",
                         denoiser=str(tiny_run / "denoiser.safetensors"))  # fmt: skip
    assert not [m for m in messages if m.startswith("--denoiser")]


# ----------------------------------------------------------------------- progress and resume


def test_progress_bars_in_a_log_are_not_redrawn_every_step(tiny_cfg, tmp_path, capsys):
    """set_postfix refreshed the bar on each step whatever its mininterval: 500 redraws for
    488 steps in a log."""
    cfg = dataclasses.replace(tiny_cfg, denoiser=dataclasses.replace(tiny_cfg.denoiser,
                                                                     epochs=2))  # fmt: skip
    capsys.readouterr()
    summary = train_stage("diffusion", cfg, tmp_path / "o", device="cpu", progress=True)
    out, err = capsys.readouterr()  # not a terminal: bars at LOG_REDRAW_SECONDS
    steps = int(re.findall(r"step=(\d+)", out)[-1]) if "step=" in out else None
    draws = err.count("denoiser epoch ")
    assert summary["best"]
    assert steps is not None and steps >= 6
    assert draws <= 2 * 2  # each epoch's first state (and at most its end), not every step


def test_a_resume_after_the_denoiser_was_replaced_names_the_set_aside_file(
    tiny_cfg, tmp_path, capsys
):
    out = tmp_path / "a"
    one = dataclasses.replace(tiny_cfg, generator=dataclasses.replace(tiny_cfg.generator,
                                                                      epochs=1))  # fmt: skip
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False)
    train_stage("generator", one, out, device="cpu", progress=False)
    capsys.readouterr()
    other = dataclasses.replace(tiny_cfg, denoiser=dataclasses.replace(tiny_cfg.denoiser,
                                                                       epochs=1))  # fmt: skip
    train_stage("diffusion", other, out, device="cpu", progress=False)  # another denoiser
    err = capsys.readouterr().err
    old = out / "denoiser.replaced-1.safetensors"
    assert old.is_file()
    assert (
        "the folder's generator files (generator.safetensors and generator_last.pt) were "
        "trained through the old denoiser, now denoiser.replaced-1.safetensors"
    ) in err
    with pytest.raises(ConfigError) as exc:
        train_stage("generator", tiny_cfg, out, device="cpu", progress=False,
                    resume=str(out / "generator_last.pt"))  # fmt: skip
    assert f"{old} is that checkpoint" in str(exc.value)
    assert str(exc.value).endswith(f"resume with --denoiser {old}")
    summary = train_stage("generator", tiny_cfg, out, device="cpu", progress=False,
                          resume=str(out / "generator_last.pt"), denoiser=str(old))  # fmt: skip
    assert summary["best"]


def test_the_data_scale_leaves_unseen_future_steps_out():
    """data.partial_future's targets hold NaN future steps: the scale came out 0.001, and every
    generator run through its own folder's denoiser was told the scale was wrong."""
    from trajpref.train.stages import data_scale
    from trajpref.types import DatasetInfo, Scene, TrajectoryDataset

    history = np.zeros((1, 8, 2), np.float32)
    future = np.array([[[3.0, 4.0], [np.nan, np.nan]]], np.float32)  # one seen step, 5 m away
    scene = Scene(history, future, np.zeros(1, np.int64), "s")
    data = TrajectoryDataset([scene], DatasetInfo("toy", "train", "m", 0.4))
    assert data_scale(data) == pytest.approx(5 / 2**0.5)  # RMS over the seen step's x and y


def test_a_time_column_in_another_unit_than_seconds_is_not_said_to_be_overridden(tmp_path):
    """A 'timestamp' column in nanoseconds: data stats asks for --frame-interval, and training
    then told the user to leave it out ('the files say 4e+08 s')."""
    data = _timed_folder(tmp_path / "d")
    for path in data.rglob("*.csv"):
        lines = path.read_text().splitlines()
        rows = [lines[0]] + [
            f"{round(float(t) * 1e9)},{rest}"
            for t, rest in (line.split(",", 1) for line in lines[1:])
        ]
        path.write_text("\n".join(rows) + "\n")
    cfg = _cfg(data, "data.units=m", "data.time_step=4", "data.frame_interval=0.1")
    messages, _ = _train("diffusion", cfg, tmp_path / "o")
    assert not [m for m in messages if "overrides the files' time column" in m]
