"""``data stats``: the mean speed in words (``speed_text``), a warning when it is no walking
pace (``speed_note``), and where a millisecond time column's interval comes from."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from trajpref.cli import main

STEP = 0.52  # metres per row: 1.3 m/s at 0.4 s between rows


def _walk(folder: Path, header: str = "", frame_step: float = 10) -> Path:
    """One agent walking +x ``STEP`` per row for 20 rows, frames ``frame_step`` apart."""
    folder.mkdir()
    rows = [f"{f * frame_step:g},1,{STEP * f:.4f},0.0\n" for f in range(20)]
    (folder / "walk.csv").write_text(header + "".join(rows))
    return folder


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main(["data", "stats", *(str(a) for a in argv)])
    out, err = capsys.readouterr()
    return code, out, err


def test_unknown_units_print_a_speed_in_units_per_second(capsys, tmp_path):
    folder = _walk(tmp_path / "w")
    code, out, err = _run(capsys, "--dataset", folder, "--frame-interval", "0.4")
    assert code == 0 and err == ""  # no units: no pace to judge
    assert "mean_speed: 1.3 units/s (units unknown: name them with --units)" in out
    assert "unknown/s" not in out  # before: "1.3 unknown/s"
    code, out, err = _run(capsys, "--dataset", folder, "--frame-interval", "0.4", "--units", "m")
    assert (code, err) == (0, "") and "mean_speed: 1.3 m/s" in out


@pytest.mark.parametrize("json_out", [False, True])
def test_a_speed_no_pedestrian_walks_is_warned_about(capsys, tmp_path, json_out):
    # rows 0.4 s apart read as 0.04 s (the video's frame period): ten times too fast
    folder = _walk(tmp_path / "w")
    flags = ["--dataset", folder, "--frame-interval", "0.04", "--units", "m"]
    code, out, err = _run(capsys, *flags, *(["--json"] if json_out else []))
    assert code == 0
    assert err == (f"trajpref: warning: {folder}: 13 m/s is not a walking pace (pedestrians: "
                   "about 0.5-2 m/s): is --frame-interval (or --units) right? It is the "
                   "seconds between consecutive rows of an agent (now 0.04 s), not per frame "
                   "number: at 1.3 m/s these rows would be 0.4 s apart\n")  # fmt: skip
    if json_out:
        assert json.loads(out)["mean_speed"] == pytest.approx(13.0, rel=1e-3)


def test_a_millisecond_time_column_is_not_said_to_be_in_seconds(capsys, tmp_path):
    folder = _walk(tmp_path / "ms", "timestamp_ms,track,x,y\n", frame_step=400)
    code, out, err = _run(capsys, "--dataset", folder, "--units", "m")
    assert (code, err) == (0, "")
    assert "frame_interval: 0.4 s (the step of the files' time column)\n" in out
    assert "in seconds" not in out  # before: "0.4 s (the files' time column, in seconds)"
    assert "mean_speed: 1.3 m/s" in out
