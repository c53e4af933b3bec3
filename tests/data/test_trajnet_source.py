"""TrajNet++ input read and written back as its own files: partial neighbours kept as context
(as the text reader keeps them), predictions written per source scene (its row, ids and frames)
so that the official evaluator's loop scores them against the user's own files, and ids of any
size written exactly."""

from __future__ import annotations

import json

import numpy as np
import trajnetplusplustools as tnt

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.data.trajnet import read_trajnet, trajnet_agent_ids, write_trajnet

FRAMES = list(range(1000, 1310, 10))  # 31 frames, step 10


def _tracks() -> list[tuple[int, int, float, float]]:
    """Agents 7 and 3 walk all the time, 12 too; 5 enters at frame 1060, 9 leaves after 1140."""
    rows = []
    for i, f in enumerate(FRAMES):
        rows += [(f, 7, 0.5 * i, 0.0), (f, 3, 0.45 * i, 2.0), (f, 12, 10 - 0.5 * i, 1.0)]
        if f >= 1060:
            rows.append((f, 5, 3.0 + 0.1 * i, -2.0 + 0.4 * i))
        if f <= 1140:
            rows.append((f, 9, -1.0 + 0.5 * i, 1.0))
    return sorted(rows)


SCENES = [{"id": 1, "p": 7, "s": 1000, "e": 1200, "fps": 2.5, "tag": [1, []]},
          {"id": 2, "p": 12, "s": 1100, "e": 1300, "fps": 2.5, "tag": [3, [1]]}]  # fmt: skip


def _write(path, scenes=SCENES, tracks=None) -> list[str]:
    lines = [json.dumps({"scene": s}) for s in scenes]
    lines += [json.dumps({"track": {"f": f, "p": p, "x": x, "y": y}})
              for f, p, x, y in (tracks or _tracks())]  # fmt: skip
    path.write_text("\n".join(lines) + "\n")
    return lines


def test_partial_neighbours_are_context_as_the_text_reader_keeps_them(tmp_path):
    _write(tmp_path / "a.ndjson")
    (tmp_path / "txt").mkdir()
    (tmp_path / "txt" / "a.txt").write_text("".join(f"{f} {p} {x} {y}\n" for f, p, x, y in
                                                   _tracks()))  # fmt: skip
    (scene, _) = read_trajnet(tmp_path / "a.ndjson").scenes
    assert scene.agent_id.tolist() == [7, 3, 12]  # 5 and 9 are not in all 20 frames
    # the same window of the same tracks as a text file: the same context, NaN where unseen
    text = load_dataset(str(tmp_path / "txt"), "test", frame_interval=0.4, units="m")
    (same,) = [s for s in text.scenes if s.scene_id == "a.txt@frame=1010"]
    assert scene.context is not None and scene.context.shape == (2, 8, 2)  # agents 5, 9
    np.testing.assert_array_equal(scene.context, same.context)
    assert np.isnan(scene.context[0, :5]).all() and not np.isnan(scene.context[0, 5:]).any()
    np.testing.assert_array_equal(scene.frames, FRAMES[1:21])


def _official_loop(gt_path, sub_path, k: int):
    """The scoring loop of trajnetplusplusbaselines' evaluator/trajnet_evaluator.py: scenes
    paired in order, a scene's predictions are the rows carrying its id, and the primary's
    predicted frames must be the truth's last 12 ("frame numbers are not consistent")."""
    gt = tnt.Reader(str(gt_path), scene_type="paths")
    sub = tnt.Reader(str(sub_path), scene_type="paths")
    neighbours, top = [], []
    for (sid, truth), (_, paths) in zip(gt.scenes(), sub.scenes(), strict=True):
        primary = [t for t in paths[0] if t.scene_id == sid]
        first = [t for t in primary if t.prediction_number == 0]
        assert [t.frame for t in truth[0]][-12:] == [t.frame for t in first], sid
        neighbours.append(sum(1 for p in paths[1:] for t in p if t.scene_id == sid
                              and t.prediction_number == 0))  # fmt: skip
        top.append(tnt.metrics.topk(primary, truth[0], n_predictions=12, k_samples=k)[0])
    return neighbours, top


def test_predictions_are_scored_against_the_source_file(tmp_path, capsys):
    source = _write(tmp_path / "a.ndjson")
    pred, truth = tmp_path / "pred.ndjson", tmp_path / "gt.ndjson"
    argv = ["predict", "--dataset", str(tmp_path / "a.ndjson"), "--model", "cv", "--samples",
            "3", "--no-progress", "--format", "trajnet", "--out", str(pred), "--truth",
            str(truth)]  # fmt: skip
    assert main(argv) == 0
    lines = pred.read_text().splitlines()
    assert lines[:2] == source[:2]  # the source scene rows, unchanged
    rows = [json.loads(line)["track"] for line in lines[2:]]
    guesses = [r for r in rows if "prediction_number" in r]
    assert {(r["scene_id"], r["p"]) for r in guesses} == {(1, 7), (1, 3), (1, 12), (2, 12),
                                                          (2, 3), (2, 5), (2, 7)}  # fmt: skip
    assert sorted({r["f"] for r in guesses if r["scene_id"] == 1}) == FRAMES[9:21]
    assert {r["prediction_number"] for r in guesses} == {0, 1, 2}
    # the official loop against the user's own file: every scene has neighbour predictions
    neighbours, top = _official_loop(tmp_path / "a.ndjson", pred, 3)
    assert neighbours == [2 * 12, 3 * 12]  # agent 5 is in all of scene 2
    assert _official_loop(truth, pred, 3)[1] == top  # the truth written scores alike
    assert json.loads(truth.read_text().splitlines()[0]) == {"scene": SCENES[0]}


def test_a_folder_of_files_is_written_as_a_folder_of_files(tmp_path, capsys):
    (tmp_path / "data").mkdir()
    _write(tmp_path / "data" / "a.ndjson")
    _write(tmp_path / "data" / "b.ndjson", [dict(SCENES[0], id=0)])  # scene ids are per file
    out = tmp_path / "pred.ndjson"
    argv = ["predict", "--dataset", str(tmp_path / "data"), "--model", "cv", "--samples", "1",
            "--no-progress", "--format", "trajnet", "--out", str(out), "--json"]  # fmt: skip
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["out"] == str(tmp_path / "pred")
    assert not out.exists()
    for name in ("a", "b"):
        _official_loop(tmp_path / "data" / f"{name}.ndjson", tmp_path / "pred" / f"{name}.ndjson",
                       1)  # fmt: skip


def test_ids_beyond_int64_are_written_exactly(tmp_path):
    big = 2**64 + 1
    scene = np.array([0, 0, 1])
    ids = trajnet_agent_ids(np.array([str(big), "42", "1"]), scene)
    assert ids.tolist() == [big, 42, 1]
    history = np.zeros((3, 8, 2), np.float32)
    write_trajnet(tmp_path / "p.ndjson", history, np.zeros((1, 3, 12, 2)), scene,
                  agent_id=np.array([str(big), "42", "1"]))  # fmt: skip
    rows = [json.loads(line) for line in (tmp_path / "p.ndjson").read_text().splitlines()]
    assert [r["scene"]["p"] for r in rows if "scene" in r] == [big, 42, 1]
    # and read from a TrajNet++ file, the same id comes back out exactly
    tracks = [(f, p, 0.1 * i, float(p == 7)) for i, f in enumerate(FRAMES[:21]) for p in (7, big)]
    _write(tmp_path / "big.ndjson", [dict(SCENES[0], p=big)], sorted(tracks))
    out = tmp_path / "out.ndjson"
    argv = ["predict", "--dataset", str(tmp_path / "big.ndjson"), "--model", "cv", "--samples",
            "1", "--no-progress", "--format", "trajnet", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    written = [json.loads(line)["track"] for line in out.read_text().splitlines()[1:]]
    assert {r["p"] for r in written if "prediction_number" in r} == {big, 7}
