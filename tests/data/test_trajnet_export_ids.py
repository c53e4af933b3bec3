"""Exports that link back to the user's data: ``write_trajnet`` writes the source agent ids
as TrajNet++'s agent ids where the format allows, ``predict`` saves the split and the source
ids in its .npz, and a TrajNet++ export of data not in metres is flagged."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import trajnetplusplustools as tnt
from synthetic import make_scene

from trajpref import cli
from trajpref.cli import main
from trajpref.data.trajnet import trajnet_agent_ids, write_trajnet, write_trajnet_truth
from trajpref.errors import DataError
from trajpref.metrics import ade_fde
from trajpref.types import collate


def _arrays(k: int = 3):
    scenes = [make_scene(n, seed=i) for i, n in enumerate((2, 3))]
    batch = collate(scenes)
    noise = 0.2 * torch.randn(k, *batch.future.shape, generator=torch.Generator().manual_seed(0))
    pred = batch.future[None] + noise  # [K, N, T_f, 2]
    return batch.history.numpy(), batch.future.numpy(), pred.numpy(), batch.scene.numpy()


def _rows(path) -> tuple[list[dict], list[dict]]:
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    return [r["scene"] for r in rows if "scene" in r], [r["track"] for r in rows if "track" in r]


def test_source_ids_become_trajnet_agent_ids(tmp_path):
    hist, fut, pred, scene = _arrays()
    ids = np.array([7.0, 12.0, 7.0, 40.0, 1001.0])  # agent 7 in both scenes: other frames
    write_trajnet(tmp_path / "pred.ndjson", hist, pred, scene, agent_id=ids)
    write_trajnet_truth(tmp_path / "gt.ndjson", hist, fut, scene, agent_id=ids)
    scenes, tracks = _rows(tmp_path / "pred.ndjson")
    assert [s["id"] for s in scenes] == [0, 1, 2, 3, 4]  # one TrajNet++ scene per agent
    assert [s["p"] for s in scenes] == [7, 12, 7, 40, 1001]
    assert {t["p"] for t in tracks} == {7, 12, 40, 1001}
    predicted = [t for t in tracks if "prediction_number" in t]
    assert {(t["scene_id"], t["p"]) for t in predicted} == set(enumerate([7, 12, 7, 40, 1001]))
    # trajnetplusplustools reads the pair as before: each scene's primary is the agent
    gt = tnt.Reader(str(tmp_path / "gt.ndjson"), scene_type="paths")
    sub = tnt.Reader(str(tmp_path / "pred.ndjson"), scene_type="paths")
    got = []
    for (sid, truth), (_, paths) in zip(gt.scenes(), sub.scenes(), strict=True):
        assert truth[0][0].pedestrian == ids[sid]
        primary = [t for t in paths[0] if t.scene_id == sid and t.prediction_number == 0]
        got.append(tnt.metrics.average_l2(truth[0], primary, n_predictions=12))
    ours, _ = ade_fde(torch.from_numpy(pred), torch.from_numpy(fut))  # [K, N]
    np.testing.assert_allclose(got, ours[0].numpy(), rtol=1e-5)


def test_ids_the_format_cannot_take_fall_back_to_indices():
    scene = np.array([0, 0, 1])
    np.testing.assert_array_equal(trajnet_agent_ids(None, scene), [0, 1, 2])
    np.testing.assert_array_equal(trajnet_agent_ids(np.array([3, 9, 3]), scene), [3, 9, 3])
    for ids in (np.array(["a", "b", "c"]), np.array([1.5, 2.0, 3.0]), np.array([4, 4, 5])):
        np.testing.assert_array_equal(trajnet_agent_ids(ids, scene), [0, 1, 2])  # 4 twice in 0
    with pytest.raises(DataError, match=r"agent_id must be \[N=3\]"):
        trajnet_agent_ids(np.array([1, 2]), scene)


def _px_folder(root):
    """One test file of three walkers, in pixels (ids 11, 22, 33)."""
    rows = []
    for t in range(20):
        rows += [f"{10 * t} {a} {5.0 * t + a} {2.0 * a}" for a in (11, 22, 33)]
    (root / "test").mkdir(parents=True)
    (root / "test" / "cam.txt").write_text("\n".join(rows) + "\n")
    return root


def test_predict_flags_trajnet_pixels_and_saves_the_split(tmp_path, capsys):
    data = _px_folder(tmp_path / "cam")
    out = tmp_path / "p.ndjson"
    argv = ["predict", "--dataset", data, "--units", "px", "--model", "cv", "--samples", "3",
            "--format", "trajnet", "--out", out, "--no-progress"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    err = capsys.readouterr().err
    assert "--format trajnet writes this data's coordinates as they are, in px" in err
    assert "TrajNet++'s tools assume metres" in err
    argv[4] = "m"
    assert main([str(a) for a in argv]) == 0
    assert "assume metres" not in capsys.readouterr().err
    npz = tmp_path / "p.npz"
    assert main([str(a) for a in [*argv[:9], "--out", npz, "--no-progress"]]) == 0
    with np.load(npz) as saved:
        assert str(saved["split"]) == "test"
        # the reader keeps the file's ids (Scene.agent_id): 11, 22, 33 in every window
        np.testing.assert_array_equal(saved["agent_id"], [11, 22, 33] * (len(saved["scene"]) // 3))


def test_predict_saves_source_ids_the_scenes_carry(tmp_path, capsys, monkeypatch):
    data = _px_folder(tmp_path / "cam")
    load = cli._load

    def with_ids(args):  # scenes carrying their source ids, as the readers would give them
        ds = load(args)
        for s in ds.scenes:
            s.agent_id = np.array([11, 22, 33])
        return ds

    monkeypatch.setattr(cli, "_load", with_ids)
    base = ["predict", "--dataset", data, "--units", "m", "--model", "cv", "--samples", "3",
            "--no-progress"]  # fmt: skip
    assert main([str(a) for a in [*base, "--out", tmp_path / "p.npz"]]) == 0
    with np.load(tmp_path / "p.npz") as saved:
        n = len(saved["scene"])
        assert saved["agent_id"].dtype == np.int64
        np.testing.assert_array_equal(saved["agent_id"], np.tile([11, 22, 33], n // 3))
    out = tmp_path / "p.ndjson"
    assert main([str(a) for a in [*base, "--format", "trajnet", "--out", out]]) == 0
    scenes, _ = _rows(out)
    assert [s["p"] for s in scenes] == [11, 22, 33] * (len(scenes) // 3)
