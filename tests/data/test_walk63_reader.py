"""Reader messages and formats a researcher with their own files met (walkthrough 63-B,
findings 3, 11 and 12): a header without an agent column, ``.tsv`` files, millisecond time
columns, extra columns, and the mean speed's plausibility note."""

import pytest

from trajpref.data import load_dataset
from trajpref.data.registry import USER_TEXT, sgan_folds
from trajpref.data.text import read_tracks
from trajpref.errors import DataError


def _rows(count: int = 30, step: float = 1.0, first: float = 0.0, sep: str = ",") -> str:
    """Rows of two walkers, ``count`` frames ``step`` apart from ``first``, 0.1 units a frame."""
    return "".join(f"{round(first + k * step, 6)}{sep}{a}{sep}{0.1 * k:.3f}{sep}{a}\n"
                   for k in range(count) for a in (1, 2))  # fmt: skip


def test_a_header_without_an_agent_column_says_so_rather_than_asking_to_reorder(tmp_path):
    # "frame,x,y" was told to reorder its columns, which cannot give it a fourth one
    path = tmp_path / "a.csv"
    path.write_text("frame,x,y\n" + "".join(f"{f},{0.1 * f:.2f},0.4\n" for f in range(30)))
    with pytest.raises(DataError) as info:
        read_tracks(path)
    message = str(info.value)
    assert "reorder" not in message and info.value.line == 1
    assert message.endswith(
        "a.csv:1: the header names 3 columns (frame x y), where 4 are needed (frame agent x y, "
        "read by position): no agent column was found; add it as column 2 (a file of one "
        "agent: the same agent id on every row)"
    )
    # a two-column header names both missing columns
    path.write_text("frame,x\n0,1\n")
    with pytest.raises(DataError, match=r"names 2 columns \(frame x\), where 4 are needed .*: "
                       r"no agent or y column was found"):  # fmt: skip
        read_tracks(path)
    # a short header with a name the reader does not know is left to the column count
    path.write_text("frame,pid,xy\n0,1,2,3\n")
    assert read_tracks(path).num_rows == 1


def test_extra_columns_say_how_to_proceed(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("frame,id,x,y,label\n" + "".join(f"{f},5,{f},0,ped\n" for f in range(3)))
    with pytest.raises(DataError) as info:
        read_tracks(path)
    message = str(info.value)
    assert "found 5; only frame agent x y are read" in message  # the start, as docs quote it
    assert ("the first 4 columns, by position, not by header name: drop the other column "
            "(keep frame agent x y, in that order)") in message  # fmt: skip
    path.write_text("0 1 2.0 3.0 7 8\n")
    with pytest.raises(DataError, match="drop the other 2 columns"):
        read_tracks(path)


def test_tsv_files_are_read_like_txt_files(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "a.tsv").write_text("frame\tid\tx\ty\n" + _rows(sep="\t"))
    (tmp_path / "d" / "b.TSV").write_text(_rows(sep="\t"))
    ds = load_dataset(str(tmp_path / "d"), "test")
    assert {s.scene_id.split("@")[0] for s in ds.scenes} == {"a.tsv", "b.TSV"}
    assert "*.tsv" in USER_TEXT
    # a folder of other files names every accepted suffix
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "a.dat").write_text(_rows())
    with pytest.raises(DataError, match=r"no \*\.txt or \*\.csv or \*\.tsv files in folder"):
        load_dataset(str(tmp_path / "e"), "test")
    # a .tsv beside .ndjson files is two formats in one folder, as a .txt is
    (tmp_path / "d" / "s.ndjson").write_text("")
    with pytest.raises(DataError, match=r"holds both text \(\*\.txt, \*\.csv, \*\.tsv\) and "
                       r"\*\.ndjson files"):  # fmt: skip
        load_dataset(str(tmp_path / "d"), "test")
    # a copy of a Social-GAN test file saved as .tsv is still that fold's data
    (tmp_path / "f" / "test").mkdir(parents=True)
    (tmp_path / "f" / "test" / "crowds_zara01.tsv").write_text(_rows(sep="\t"))
    assert sgan_folds(tmp_path / "f") == ("zara1",)


@pytest.mark.parametrize("header", ["timestamp_ms,track,u,v", "time_ms,id,x,y"])
def test_millisecond_time_columns_give_the_interval_in_seconds(tmp_path, header):
    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "log.csv").write_text(f"{header}\n" + _rows(step=100, first=2800))
    info = load_dataset(str(folder), "test").info
    assert (info.frame_interval, info.interval_from) == (0.1, "timestamps")
    assert load_dataset(str(folder), "test", frame_interval=0.2).info.frame_interval == 0.2


def test_a_millisecond_column_of_an_implausible_step_keeps_the_default_and_says_so(tmp_path):
    from trajpref.data import FrameRateWarning

    folder = tmp_path / "d"
    folder.mkdir()
    (folder / "log.csv").write_text("time_ms,id,x,y\n" + _rows(step=0.1))  # seconds, misnamed
    with pytest.warns(FrameRateWarning, match=r"the files' time column, in milliseconds, steps "
                      r"0\.1 ms \(0\.0001 s\), which is no plausible number of seconds between "
                      r"frames: 0\.4 s between frames is assumed"):  # fmt: skip
        info = load_dataset(str(folder), "test").info
    assert info.interval_from == "default"
    # files in seconds and in milliseconds that step alike agree
    (folder / "log.csv").write_text("time_ms,id,x,y\n" + _rows(step=100))
    (folder / "b.csv").write_text("time,id,x,y\n" + _rows(step=0.1))
    assert load_dataset(str(folder), "test").info.frame_interval == 0.1
    (folder / "b.csv").write_text("frame,id,x,y\n" + _rows(step=1))
    with pytest.warns(FrameRateWarning, match=r"log\.csv's frame column is a time in "
                      r"milliseconds, b\.csv's is not"):  # fmt: skip
        load_dataset(str(folder), "test")


def test_speed_text_says_when_the_units_are_unknown():
    from trajpref.data.stats import speed_text

    assert speed_text(1.25, "m") == "1.25 m/s"
    assert speed_text(0.3022, "unknown") == "0.3022 units/s (units unknown: name them with --units)"
    assert speed_text(float("nan"), "m") == "nan m/s"


NOTE = (
    "{shown} is not a walking pace (pedestrians: about 0.5-2 m/s): is --frame-interval "
    "(or --units) right? It is the seconds between consecutive rows of an agent (now "
    "{now}), not per frame number: at 1.3 m/s these rows would be {then} s apart"
)


@pytest.mark.parametrize("speed, units, interval, time_step, shown, now, then", [
    (1.2, "m", 0.4, 1, None, None, None),
    (0.35, "m", 0.4, 1, None, None, None),
    # 25 fps video annotated every 10th frame, read at 1/25 s: about 0.4 s is named
    (11.92, "m", 0.04, 1, "11.92 m/s", "0.04 s", "0.3668"),
    (0.1, "m", 1.6, 4, "0.1 m/s", "0.4 s, read every 4", "0.03077"),
    (12.0, "cm", 0.4, 1, "12 cm/s (0.12 m/s)", "0.4 s", "0.03692"),
    (4.0, "ft", 0.4, 1, None, None, None),  # 1.2 m/s
    (1.2, "unknown", 0.4, 1, None, None, None),  # nothing to compare with
    (1.2, "px", 0.04, 1, None, None, None),
    (float("nan"), "m", 0.4, 1, None, None, None),
    (0.0, "m", 0.4, 1, None, None, None),  # nobody moved: no interval would change that
])  # fmt: skip
def test_speed_note_flags_implausible_walking_speeds(speed, units, interval, time_step, shown,
                                                     now, then):  # fmt: skip
    from trajpref.data.stats import speed_note

    got = speed_note(speed, units, interval, time_step=time_step)
    assert got == (None if shown is None else NOTE.format(shown=shown, now=now, then=then))
    # a built-in dataset's interval is its own: nothing to question
    assert speed_note(speed, units, interval, "dataset", time_step) is None


def test_speed_note_says_when_the_interval_is_assumed():
    from trajpref.data.stats import speed_note

    note = speed_note(0.1, "m", 1.6, "default", 4)
    assert note is not None and "(now 0.4 s, assumed, read every 4)" in note
