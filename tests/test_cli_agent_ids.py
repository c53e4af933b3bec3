"""``trajpref predict`` on a tracker's text files: each predicted agent keeps the id it has in
its file (the .npz's ``agent_id``, the TrajNet++ rows' ``"p"``), so a planner maps the futures
back to its tracks."""

from __future__ import annotations

import json
import warnings

import numpy as np
from synthetic import write_tracks

from trajpref.cli import main

BIG = 2**53 + 1  # float64 reads it as 2**53


def _tracker_folder(root):
    """test/cam.txt: agents listed 17, 42, 9 (unsorted), 42 leaving after frame 21, each at
    y = its id; test/lab.txt: two agents whose ids float64 cannot hold (y = 0 and 1)."""
    rows = [(f * 10, a, 0.3 * f, float(a)) for f in range(25) for a in (17, 42, 9)
            if not (a == 42 and f > 21)]  # fmt: skip
    write_tracks(root / "test" / "cam.txt", rows)
    rows = [(f * 10, a, 0.3 * f, float(k)) for f in range(21) for k, a in enumerate((BIG, BIG + 2))]
    write_tracks(root / "test" / "lab.txt", rows)
    return root


# the windows' agents in predict's order: cam.txt's 6 windows (agents by id), then lab.txt's 2
IDS = [9, 17, 42] * 3 + [9, 17] * 3 + [BIG, BIG + 2] * 2


def _predict(*argv) -> int:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the tiny model's pace and units
        return main([str(a) for a in ["predict", *argv, "--no-progress", "--device", "cpu"]])


def test_predict_saves_each_agents_id_in_its_text_file(tmp_path, tiny_run, capsys):
    data = _tracker_folder(tmp_path / "tracks")
    gen = tiny_run / "generator.safetensors"
    out = tmp_path / "p.npz"
    assert _predict("--dataset", data, "--model", gen, "--samples", "4", "--out", out) == 0
    with np.load(out) as z:  # no pickle needed
        assert z["agent_id"].dtype == np.int64 and z["agent_id"].tolist() == IDS
        cam = z["scene"] < 6  # cam.txt's windows: each agent walks at y = its id
        np.testing.assert_array_equal(z["history"][cam, 0, 1], z["agent_id"][cam])
        assert z["pred"].shape[:2] == (4, len(IDS))
    pred = tmp_path / "p.ndjson"
    argv = ["--dataset", data, "--model", gen, "--samples", "3", "--format", "trajnet"]
    assert _predict(*argv, "--out", pred) == 0
    rows = [json.loads(line) for line in pred.read_text().splitlines()]
    assert [r["scene"]["p"] for r in rows if "scene" in r] == IDS
    capsys.readouterr()


def test_ids_no_integer_type_holds_are_saved_as_their_exact_text(tmp_path, capsys):
    rows = [(f * 10, a, 0.3 * f, float(k)) for f in range(21)
            for k, a in enumerate((7, 2**64 + 1))]  # fmt: skip
    write_tracks(tmp_path / "d" / "test" / "a.txt", rows)
    rows = [(f * 10, a, 0.3 * f, float(k)) for f in range(20) for k, a in enumerate((3, 2.5))]
    write_tracks(tmp_path / "d" / "test" / "b.txt", rows)
    out = tmp_path / "p.npz"
    assert _predict("--dataset", tmp_path / "d", "--model", "cv", "--samples", "1",
                    "--out", out) == 0  # fmt: skip
    with np.load(out) as z:  # strings load without pickle
        assert z["agent_id"].dtype.kind == "U"
        assert z["agent_id"].tolist() == ["7", str(2**64 + 1)] * 2 + ["2.5", "3"]
    capsys.readouterr()


def test_python_predict_dataset_returns_the_same_ids(tmp_path):
    """The Python API gives what the CLI saves: ``predict_dataset`` adds ``agent_id``."""
    from trajpref.data import load_dataset
    from trajpref.evaluation import predict_dataset
    from trajpref.models.registry import load_predictor

    data = _tracker_folder(tmp_path / "tracks")
    ds = load_dataset(str(data), "test")
    arrays = predict_dataset(load_predictor("cv"), ds, 2, progress=False)
    assert arrays["agent_id"].tolist() == IDS
    cam = arrays["scene"] < 6
    np.testing.assert_array_equal(arrays["history"][cam, 0, 1], arrays["agent_id"][cam])


def test_ids_from_2_53_on_beside_a_fraction_stay_apart(tmp_path):
    """One file's integer ids from 2**53 on, another's 2.5: float64 would round 2**53 + 1 into
    2**53, so the ids are kept as their exact text."""
    from trajpref.data import load_dataset
    from trajpref.evaluation import predict_dataset
    from trajpref.models.registry import load_predictor

    rows = [(f * 10, a, 0.3 * f, float(k)) for f in range(20)
            for k, a in enumerate((2**53, 2**53 + 1))]  # fmt: skip
    write_tracks(tmp_path / "d" / "test" / "a.txt", rows)
    write_tracks(
        tmp_path / "d" / "test" / "b.txt", [(f * 10, 2.5, 0.3 * f, 0.0) for f in range(20)]
    )
    ds = load_dataset(str(tmp_path / "d"), "test")
    ids = predict_dataset(load_predictor("cv"), ds, 1, progress=False)["agent_id"]
    assert ids.tolist() == [str(2**53), str(2**53 + 1), "2.5"]
    rows = [(f * 10, a, 0.3 * f, float(k)) for f in range(20) for k, a in enumerate((7, 8))]
    write_tracks(tmp_path / "e" / "test" / "a.txt", rows)  # small ids beside 2.5: numbers
    write_tracks(
        tmp_path / "e" / "test" / "b.txt", [(f * 10, 2.5, 0.3 * f, 0.0) for f in range(20)]
    )
    ds = load_dataset(str(tmp_path / "e"), "test")
    ids = predict_dataset(load_predictor("cv"), ds, 1, progress=False)["agent_id"]
    assert ids.dtype == np.float64 and ids.tolist() == [7.0, 8.0, 2.5]
