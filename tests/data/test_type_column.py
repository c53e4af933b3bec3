"""A 5th column of agent types (BALL, PLAYER, PERSON) is read in any folder's files, as in the
NBA files, so one's own SportVU export keeps its ball flag; a 5th column of anything else is
refused, naming the accepted values."""

import numpy as np
import pytest

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.data.text import read_tracks
from trajpref.errors import DataError
from trajpref.types import AGENT_BALL, AGENT_PERSON


def _rows(sep: str = " ", ball: str = "BALL", player: str = "PLAYER") -> str:
    """20 frames of a ball (id -1) and two players (ids 5 and 7), types in a 5th column."""
    out = []
    for f in range(20):
        for agent, kind in ((-1, ball), (5, player), (7, player)):
            out.append(sep.join([str(f * 12), str(agent), f"{0.3 * f + agent:.2f}", "1.5", kind]))
    return "\n".join(out) + "\n"


def test_a_folder_file_with_a_ball_row_flags_the_ball(tmp_path):
    (tmp_path / "test").mkdir()
    (tmp_path / "test" / "game.txt").write_text(_rows())
    ds = load_dataset(str(tmp_path), "test")
    assert len(ds) == 1
    scene = ds[0]
    assert scene.agent_id.tolist() == [-1, 5, 7]
    assert scene.agent_type.tolist() == [AGENT_BALL, AGENT_PERSON, AGENT_PERSON]


@pytest.mark.parametrize(("header", "sep", "ball", "player"),
                         [("", "\t", "ball", "player"), ("frame,id,x,y,type\n", ",", "Ball",
                                                          "PERSON")])  # fmt: skip
def test_headers_separators_and_any_case(tmp_path, header, sep, ball, player):
    path = tmp_path / "a.csv"
    path.write_text(header + _rows(sep, ball, player))
    tracks = read_tracks(path)
    assert tracks.agents.tolist() == [-1, 5, 7]
    assert tracks.agent_type.tolist() == [AGENT_BALL, AGENT_PERSON, AGENT_PERSON]


def test_a_5th_column_of_anything_else_is_refused_naming_the_accepted_values(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("0 1 2.0 3.0 7\n")
    with pytest.raises(DataError, match=r"a.txt:1: expected 4 columns .* found 5; only frame "
                       r"agent x y are read.*a 5th column is read only as agent types, BALL, "
                       r"PLAYER or PERSON \(any case\), not '7'$"):  # fmt: skip
        read_tracks(path)
    path.write_text("0 1 2.0 3.0 car\n")
    with pytest.raises(DataError, match=r"BALL, PLAYER or PERSON \(any case\), not 'car'$"):
        read_tracks(path)
    path.write_text("0 -1 1.0 2.0 BALL\n0 7 3.0 4.0 PLAYER\n12 7 1 1 REFEREE\n")
    with pytest.raises(DataError, match=r"a.txt:3: unknown agent type 'REFEREE' \(BALL, "
                       r"PLAYER or PERSON, any case\)"):  # fmt: skip
        read_tracks(path)
    path.write_text("0 7 3.0 4.0\n0 -1 1.0 2.0 BALL\n")  # the first row says: no types
    with pytest.raises(DataError, match=r"a.txt:2: .*found 5.*a 5th column of agent types "
                       r"is read when the first data row has one: give every row its "
                       r"type"):  # fmt: skip
        read_tracks(path)
    path.write_text("0 -1 1.0 2.0 BALL\n0 7 3.0 4.0\n")  # typed, then a row without
    with pytest.raises(DataError, match=r"a.txt:2: expected 5 columns \(frame agent x y "
                       r"BALL\|PLAYER\|PERSON\) separated by whitespace, found 4"):  # fmt: skip
        read_tracks(path)


def test_predict_on_the_folder_saves_the_ball_flag(tmp_path, capsys):
    (tmp_path / "d" / "test").mkdir(parents=True)
    (tmp_path / "d" / "test" / "game.txt").write_text(_rows())
    out = tmp_path / "p.npz"
    assert main(["predict", "--dataset", str(tmp_path / "d"), "--model", "cv", "--samples", "1",
                 "--out", str(out), "--no-progress", "--frame-interval", "0.12",
                 "--units", "m"]) == 0  # fmt: skip
    with np.load(out) as saved:
        assert saved["agent_type"].tolist() == [AGENT_BALL, AGENT_PERSON, AGENT_PERSON]
        assert saved["agent_id"].tolist() == [-1, 5, 7]
