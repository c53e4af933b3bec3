"""TrajNet++ input read and written back as its own files: partial neighbours kept as context
(as the text reader keeps them), predictions written per source scene (its row, ids and frames)
so that the official evaluator's loop scores them against the user's own files, and ids of any
size written exactly."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import trajnetplusplustools as tnt

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.data.trajnet import read_trajnet, trajnet_agent_ids, write_trajnet
from trajpref.train.run import data_fingerprint

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
    """The scoring loop of trajnetplusplusbaselines' evaluator/trajnet_evaluator.py as of its
    HEAD (99a6e9d, after PR #27; read, not run): scenes paired in order, a scene's predictions
    are the rows carrying its id, the primary's predicted frames must be the truth's last 12
    ("frame numbers are not consistent"), the truth's neighbours are the tracks first seen
    before the primary's first future frame (its ``drop_post_obs``), and Col-I is turned off
    for the whole file (-1) when in any scene the predicted neighbours are not that many ("The
    model does not predict all neighbours in the scene"). Returns each scene's predicted
    neighbour rows (prediction 0), its Top-k ADE, and whether Col-I stays on."""
    gt = tnt.Reader(str(gt_path), scene_type="paths")
    sub = tnt.Reader(str(sub_path), scene_type="paths")
    neighbours, top, col1 = [], [], True
    for (sid, truth), (_, paths) in zip(gt.scenes(), sub.scenes(), strict=True):
        primary = [t for t in paths[0] if t.scene_id == sid]
        first = [t for t in primary if t.prediction_number == 0]
        assert [t.frame for t in truth[0]][-12:] == [t.frame for t in first], sid
        predicted = [p for p in paths[1:] if any(t.scene_id == sid for t in p)]
        neighbours.append(sum(1 for p in predicted for t in p if t.scene_id == sid
                              and t.prediction_number == 0))  # fmt: skip
        end = truth[0][9].frame  # the first future frame of TrajNet++'s 9 + 12
        kept = [path for path in truth[1:] if path[0].frame < end]  # drop_post_obs
        col1 = col1 and len(kept) == len(predicted)
        top.append(tnt.metrics.topk(primary, truth[0], n_predictions=12, k_samples=k)[0])
    return neighbours, top, col1


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
    # the official loop against the user's own file: every scene has neighbour predictions,
    # but its Col-I is off: scene 1's truth counts 4 neighbours (5 and 9 are partial, seen
    # before the future), we predict the 2 in all 20 frames (docs/social.md)
    neighbours, top, col1 = _official_loop(tmp_path / "a.ndjson", pred, 3)
    assert neighbours == [2 * 12, 3 * 12] and not col1  # agent 5 is in all of scene 2
    # against the truth written with it the Top-k scores are the same, and Col-I stays on here
    # (it holds the predicted agents alone; overlapping scenes can still add neighbours)
    assert _official_loop(truth, pred, 3)[1:] == (top, True)
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


def _digests(folder) -> dict[str, str]:
    return {p.name: hashlib.md5(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _predict(*flags) -> int:
    return main(["predict", "--model", "cv", "--samples", "1", "--no-progress", "--format",
                 "trajnet", *map(str, flags)])  # fmt: skip


def test_outputs_that_would_replace_or_join_the_source_are_refused(tmp_path, capsys):
    root = tmp_path / "tn"  # root/test/{a,b}.ndjson, root/train/a.ndjson
    for split, names in (("test", "ab"), ("train", "a")):
        (root / split).mkdir(parents=True)
        for name in names:
            _write(root / split / f"{name}.ndjson")
    flat = tmp_path / "data"  # a folder without split sub-folders
    flat.mkdir()
    _write(flat / "a.ndjson")
    before = {folder: _digests(folder) for folder in (root / "test", flat)}
    refused = [
        # the output folder (--out without its suffix) is the source folder
        (["--dataset", root, "--split", "test", "--out", root / "test.ndjson"], "source folder"),
        (["--dataset", flat, "--out", tmp_path / "data.ndjson"], "the source folder"),
        (["--dataset", flat, "--out", flat / "p.ndjson"], "inside the source folder"),
        # one source file given: the file itself
        (["--dataset", flat / "a.ndjson", "--out", flat / "a.ndjson"], "source file"),
        (
            [
                "--dataset",
                flat / "a.ndjson",
                "--out",
                tmp_path / "p.ndjson",
                "--truth",
                flat / "a.ndjson",
            ],
            "source file",
        ),  # fmt: skip
        # --out and --truth the same, or (as folders) one the other's
        (
            [
                "--dataset",
                flat / "a.ndjson",
                "--out",
                tmp_path / "p.ndjson",
                "--truth",
                tmp_path / "p.ndjson",
            ],
            "the same path",
        ),  # fmt: skip
        (
            [
                "--dataset",
                flat,
                "--out",
                tmp_path / "x" / "p.ndjson",
                "--truth",
                tmp_path / "x" / "p.NDJSON",
            ],
            "the same path",
        ),  # fmt: skip
        (
            [
                "--dataset",
                flat,
                "--out",
                tmp_path / "x" / "p.ndjson",
                "--truth",
                tmp_path / "x" / "p" / "g.ndjson",
            ],
            "one inside the other",
        ),  # fmt: skip
    ]
    for flags, message in refused:
        assert _predict(*flags) == 2, flags
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, (flags, err)
    (tmp_path / "q").write_text("not a folder")  # the output folder's name, taken by a file
    assert _predict("--dataset", flat, "--out", tmp_path / "q.ndjson") == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    assert {folder: _digests(folder) for folder in (root / "test", flat)} == before
    assert not (tmp_path / "p.ndjson").exists() and not (tmp_path / "x").exists()


def test_the_layout_follows_the_input_not_the_scenes_chosen(tmp_path, capsys):
    one = tmp_path / "one"  # a folder of one file: a folder
    one.mkdir()
    _write(one / "a.ndjson")
    assert _predict("--dataset", one, "--out", tmp_path / "p1.ndjson") == 0
    assert sorted(p.name for p in (tmp_path / "p1").iterdir()) == ["a.ndjson"]
    two = tmp_path / "two"  # two files, one scene chosen: a folder, of that scene's file
    two.mkdir()
    _write(two / "a.ndjson")
    _write(two / "b.ndjson")
    assert _predict("--dataset", two, "--max-scenes", "1", "--out", tmp_path / "p2.ndjson",
                    "--truth", tmp_path / "g2.ndjson") == 0  # fmt: skip
    assert len(list((tmp_path / "p2").iterdir())) == len(list((tmp_path / "g2").iterdir())) == 1
    # one file given: one file
    assert _predict("--dataset", one / "a.ndjson", "--out", tmp_path / "p3.ndjson") == 0
    assert (tmp_path / "p3.ndjson").is_file() and not (tmp_path / "p3").exists()
    assert not (tmp_path / "p1.ndjson").exists() and not (tmp_path / "p2.ndjson").exists()


def test_two_predictions_are_written_the_evaluator_reads_top_1(tmp_path, capsys):
    _write(tmp_path / "a.ndjson")
    pred = tmp_path / "p.ndjson"
    assert main(["predict", "--dataset", str(tmp_path / "a.ndjson"), "--model", "cv",
                 "--samples", "2", "--no-progress", "--format", "trajnet", "--out",
                 str(pred)]) == 0  # fmt: skip
    rows = [json.loads(line).get("track", {}) for line in pred.read_text().splitlines()]
    assert {r["prediction_number"] for r in rows if "prediction_number" in r} == {0, 1}
    assert len(_official_loop(tmp_path / "a.ndjson", pred, 1)[1]) == 2  # both scenes scored


def test_windows_without_context_keep_their_fingerprint(tmp_path):
    # every agent in every frame: no context, so the data fingerprint is that of windows
    # read without context (as before the reader kept partial neighbours): a run resumes
    full = [(f, p, 0.1 * i + p, 0.2 * p) for i, f in enumerate(FRAMES) for p in (7, 3, 12)]
    _write(tmp_path / "full.ndjson", tracks=sorted(full))
    ds = load_dataset(str(tmp_path / "full.ndjson"), "test")
    assert [s.context for s in ds.scenes] == [None, None]
    bare = dataclasses.replace(ds, scenes=[dataclasses.replace(s, context=None)
                                           for s in ds.scenes])  # fmt: skip
    assert data_fingerprint(ds, ds) == data_fingerprint(bare, bare)
    # with partial neighbours the context is there (test_partial_neighbours_are_context_...)
    _write(tmp_path / "a.ndjson")
    assert read_trajnet(tmp_path / "a.ndjson").scenes[0].context.shape == (2, 8, 2)


def test_a_source_file_linked_from_the_output_folder_is_not_overwritten(tmp_path, capsys):
    """A data folder's file that is a link to a file of the output folder: writing the output
    folder's file would replace the source's data (a review's case, 2026-12-06)."""
    real = tmp_path / "real"
    real.mkdir()
    _write(real / "a.ndjson")
    data = tmp_path / "data3"
    data.mkdir()
    (data / "a.ndjson").symlink_to(real / "a.ndjson")
    before = _digests(real)
    assert _predict("--dataset", data, "--out", tmp_path / "real.ndjson") == 2
    assert "the source file" in capsys.readouterr().err
    assert _digests(real) == before


def test_an_output_beside_the_split_folders_is_allowed_one_in_them_refused(tmp_path, capsys):
    """With split sub-folders, only those are read: an output in the data folder beside them
    is fine (it was refused), one in any split folder, read or not, is not."""
    root = tmp_path / "tn"
    (root / "test").mkdir(parents=True)
    _write(root / "test" / "a.ndjson")
    assert _predict("--dataset", root, "--split", "test", "--out", root / "preds.ndjson") == 0
    capsys.readouterr()
    for out in (root / "test" / "p.ndjson", root / "train.ndjson", root / "val" / "p.ndjson"):
        assert _predict("--dataset", root, "--split", "test", "--out", out) == 2, out
        assert "source folder" in capsys.readouterr().err


def test_an_output_folder_holding_other_files_is_refused(tmp_path, capsys):
    """The evaluator pairs a folder's files by name: a file an earlier run left there would be
    scored beside this run's. Rewriting this run's own files is fine."""
    data = tmp_path / "data"
    data.mkdir()
    _write(data / "a.ndjson")
    assert _predict("--dataset", data, "--out", tmp_path / "p.ndjson") == 0
    assert _predict("--dataset", data, "--out", tmp_path / "p.ndjson") == 0  # its own again
    (tmp_path / "p" / "old.ndjson").write_text("")
    capsys.readouterr()
    assert _predict("--dataset", data, "--out", tmp_path / "p.ndjson") == 2
    assert "holds .ndjson files this run does not write (old.ndjson" in capsys.readouterr().err
