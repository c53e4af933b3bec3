"""TrajNet++ .ndjson: reading scene files as a dataset, and writing predictions that
trajnetplusplustools (the real package from PyPI) reads and scores like we do."""

import json
import resource
import time
import warnings

import numpy as np
import pytest
import torch
import trajnetplusplustools as tnt
from synthetic import make_scene

from trajpref.data import load_dataset
from trajpref.data.trajnet import read_trajnet, write_trajnet, write_trajnet_truth
from trajpref.errors import DataError
from trajpref.metrics import ade_fde, min_ade_fde
from trajpref.types import collate


def _scene_file(path, tracks, scenes):
    lines = [json.dumps({"scene": s}) for s in scenes]
    lines += [json.dumps({"track": {"f": f, "p": p, "x": x, "y": y}}) for f, p, x, y in tracks]
    path.write_text("\n".join(lines) + "\n")
    return path


def _three_agents(path):
    """Frames 0, 10, ..., 200 (21 = 9 + 12); agent 1 is the primary, agent 2 is there all the
    time, agent 3 misses frame 100, agent 4 only appears at frame 10 (before the window)."""
    frames = range(0, 210, 10)
    tracks = [(f, 1, f / 10, 0.0) for f in frames]
    tracks += [(f, 2, f / 10, 1.0) for f in frames]
    tracks += [(f, 3, 0.5, f / 10) for f in frames if f != 100]
    tracks += [(10, 4, 9.0, 9.0)]
    scenes = [{"id": 7, "p": 1, "s": 0, "e": 200, "fps": 2.5, "tag": [1, []]},
              {"id": 8, "p": 3, "s": 0, "e": 90, "fps": 2.5, "tag": [1, []]}]  # fmt: skip
    return _scene_file(path, tracks, scenes)


def test_reading_a_scene_file(tmp_path):
    path = _three_agents(tmp_path / "a.ndjson")
    with pytest.raises(DataError, match="scene 8: its primary agent 3 has 10 frames in 0..90; "
                       "a window needs 20") as info:  # fmt: skip
        read_trajnet(path)
    assert info.value.line == 2
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:1] + lines[2:]))
    read = read_trajnet(path)
    (scene,) = read.scenes
    assert read.fps == {2.5}
    assert scene.scene_id == "a.ndjson#7"
    # the last 20 of 21 frames: history frames 10..80, future 90..200; primary first
    np.testing.assert_array_equal(scene.history[:, :, 0], [np.arange(1, 9)] * 2)
    np.testing.assert_array_equal(scene.history[:, 0, 1], [0.0, 1.0])
    np.testing.assert_array_equal(scene.future[0, :, 0], np.arange(9, 21))


def test_a_folder_or_a_file_is_a_dataset(tmp_path):
    (tmp_path / "test").mkdir()
    path = _three_agents(tmp_path / "test" / "a.ndjson")
    path.write_text("\n".join(l for l in path.read_text().splitlines() if '"id": 8' not in l))
    (tmp_path / "train").mkdir()
    (tmp_path / "train" / "b.ndjson").write_text(path.read_text())
    ds = load_dataset(str(tmp_path), "test")
    assert len(ds) == 1 and ds.info.units == "m" and ds.info.frame_interval == 0.4
    assert load_dataset(str(path), "test").num_agents == 2
    (tmp_path / "test" / "c.txt").write_text("0 1 2 3\n")
    with pytest.raises(DataError, match=r"both text \(\*.txt, \*.csv, \*.tsv\) and \*.ndjson"):
        load_dataset(str(tmp_path), "test")


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("{nope", "not a JSON object"),
        ('{"row": {}}', 'expected {"scene": {...}} or {"track": {...}}'),
        ('{"track": {"f": 0, "p": 1, "x": 2}}', "track row without 'y'"),
        ('{"track": {"f": 0.5, "p": 1, "x": 2, "y": 3}}', "frame 'f' must be an integer"),
        ('{"track": {"f": 0, "p": 1, "x": NaN, "y": 3}}', "'x' is NaN or infinite"),
        ('{"track": {"f": 0, "p": 1, "x": "2", "y": 3}}', "'x' must be a number"),
        ('{"track": {"f": 0, "p": 1, "x": 1e20, "y": 3}}', "1e\\+20 m is beyond the sane bound"),
        ('{"track": {"f": 0, "p": 1, "x": 0.0, "y": 0.0}}', "duplicate row for frame 0, agent 1"),
        ('{"scene": {"id": 7, "p": 1, "s": 0, "e": 200}}', "scene id 7 appears twice"),
        ('{"scene": {"id": 9, "p": 1, "s": 5, "e": 2}}', "start frame 5 is after end frame 2"),
    ],
)
def test_bad_lines_name_the_line(tmp_path, line, message):
    path = tmp_path / "bad.ndjson"
    _three_agents(path)
    good = [l for l in path.read_text().splitlines() if '"id": 8' not in l]
    path.write_text("\n".join([*good, line]) + "\n")
    with pytest.raises(DataError, match=message) as info:
        read_trajnet(path)
    assert info.value.line == len(good) + 1


def _predictions(seed: int = 0, k: int = 4):
    scenes = [make_scene(n, seed=seed + i) for i, n in enumerate((2, 3, 1))]
    batch = collate(scenes)
    gen = torch.Generator().manual_seed(seed)
    noise = 0.3 * torch.randn(k, *batch.future.shape, generator=gen)  # [K, N, T_f, 2]
    return scenes, batch, batch.future[None] + noise.cumsum(2)


def test_trajnetplusplustools_scores_our_file_like_we_do(tmp_path):
    scenes, batch, pred = _predictions(k=4)
    hist, fut, scene = batch.history.numpy(), batch.future.numpy(), batch.scene.numpy()
    assert write_trajnet(tmp_path / "pred.ndjson", hist, pred.numpy(), scene) == 6
    assert write_trajnet_truth(tmp_path / "gt.ndjson", hist, fut, scene) == 6

    # what trajnetplusplusbaselines' evaluator does with the two files, per scene
    gt = tnt.Reader(str(tmp_path / "gt.ndjson"), scene_type="paths")
    sub = tnt.Reader(str(tmp_path / "pred.ndjson"), scene_type="paths")
    gt_ids, gt_scenes = zip(*gt.scenes(), strict=True)
    sub_scenes = [paths for _, paths in sub.scenes()]
    ade, fde, top_ade, top_fde = [], [], [], []
    for sid, truth, paths in zip(gt_ids, gt_scenes, sub_scenes, strict=True):
        primary_all = [t for t in paths[0] if t.scene_id == sid]
        primary = [t for t in primary_all if t.prediction_number == 0]
        assert [t.frame for t in truth[0]][-12:] == [t.frame for t in primary]
        ade.append(tnt.metrics.average_l2(truth[0], primary, n_predictions=12))
        fde.append(tnt.metrics.final_l2(truth[0], primary))
        a, f = tnt.metrics.topk(primary_all, truth[0], n_predictions=12, k_samples=4)
        top_ade.append(a)
        top_fde.append(f)
        for other in truth[1:]:  # the evaluator's collision check runs on these paths
            tnt.metrics.collision(primary, other, n_predictions=12)
    assert len(ade) == batch.num_agents == 6

    ours_ade, ours_fde = ade_fde(pred, batch.future)  # [K, N]
    min_ade, _ = min_ade_fde(pred, batch.future)  # [N]
    best = ours_ade.argmin(0)  # [N] TrajNet++'s Top-k reports the FDE of the best-ADE sample
    np.testing.assert_allclose(ade, ours_ade[0].numpy(), rtol=1e-5)
    np.testing.assert_allclose(fde, ours_fde[0].numpy(), rtol=1e-5)
    np.testing.assert_allclose(top_ade, min_ade.numpy(), rtol=1e-5)
    np.testing.assert_allclose(top_fde, ours_fde[best, torch.arange(6)].numpy(), rtol=1e-5)
    assert np.mean(top_ade) < np.mean(ade)  # the samples differ: min over 4 helps


def test_our_reader_reads_the_truth_file_back(tmp_path):
    scenes, batch, _ = _predictions()
    write_trajnet_truth(tmp_path / "gt.ndjson", batch.history, batch.future, batch.scene, 0.5)
    ds = load_dataset(str(tmp_path / "gt.ndjson"), "test")
    assert ds.info.frame_interval == 0.5 and len(ds) == 6
    # agent n's TrajNet++ scene is its own scene with n first, then the others by id
    n = 0
    for scene in scenes:
        for i in range(scene.num_agents):
            got = ds[n]
            order = [i, *[j for j in range(scene.num_agents) if j != i]]
            np.testing.assert_array_equal(got.history, scene.history[order])
            np.testing.assert_array_equal(got.future, scene.future[order])
            n += 1


def test_writer_checks_its_input(tmp_path):
    _, batch, pred = _predictions(k=2)
    hist, scene = batch.history.numpy(), batch.scene.numpy()
    two = tmp_path.parent / f"{tmp_path.name}-k2.ndjson"  # K = 2 is written (Top-1 alone)
    assert write_trajnet(two, hist, pred.numpy(), scene) == len(scene)
    with pytest.raises(DataError, match="pred must be"):
        write_trajnet(tmp_path / "p.ndjson", hist, pred[:1, :2].numpy(), scene)
    bad = pred[:1].numpy().copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(DataError, match="pred holds NaN"):
        write_trajnet(tmp_path / "p.ndjson", hist, bad, scene)
    with pytest.raises(DataError, match="scene must number"):
        write_trajnet(tmp_path / "p.ndjson", hist, pred[:1].numpy(), scene + 1)
    assert not list(tmp_path.iterdir())  # nothing written


def test_decimals_round_like_trajnet_files(tmp_path):
    _, batch, pred = _predictions(k=1)
    write_trajnet(tmp_path / "p.ndjson", batch.history, pred, batch.scene, decimals=2)
    rows = [json.loads(l) for l in (tmp_path / "p.ndjson").read_text().splitlines()]
    xs = [r["track"]["x"] for r in rows if "track" in r]
    assert all(round(x, 2) == x for x in xs)
    first = next(r["track"] for r in rows if "track" in r)
    assert first["x"] == round(float(batch.history[0, 0, 0]), 2)


def test_cli_predict_format_trajnet_scores_like_evaluate(walks, tmp_path, capsys):
    from trajpref.cli import main

    common = ["--dataset", str(walks), "--model", "cv", "--samples", "5", "--no-progress"]
    assert main(["evaluate", *common, "--json"]) == 0
    ours = json.loads(capsys.readouterr().out)
    pred, truth = tmp_path / "pred.ndjson", tmp_path / "gt.ndjson"
    code = main(["predict", *common, "--format", "trajnet", "--out", str(pred),
                 "--truth", str(truth)])  # fmt: skip
    assert code == 0
    gt = tnt.Reader(str(truth), scene_type="paths")
    sub = tnt.Reader(str(pred), scene_type="paths")
    top_ade = []
    for (sid, paths_gt), (_, paths) in zip(gt.scenes(), sub.scenes(), strict=True):
        primary = [t for t in paths[0] if t.scene_id == sid]
        top_ade.append(tnt.metrics.topk(primary, paths_gt[0], n_predictions=12, k_samples=5)[0])
    # every agent is the primary of its own TrajNet++ scene: the mean over scenes is ours
    assert np.mean(top_ade) == pytest.approx(ours["min_ade"], rel=1e-5)
    # a wrong suffix or --truth without the format is one line, exit 2, before any compute
    assert main(["predict", *common, "--format", "trajnet", "--out", str(tmp_path / "p.npz")]) == 2
    assert main(["predict", *common, "--out", str(tmp_path / "p.npz"), "--truth", str(truth)]) == 2
    assert not (tmp_path / "p.npz").exists()


def test_a_file_saved_with_a_byte_order_mark_reads_as_without(tmp_path):
    path = _three_agents(tmp_path / "a.ndjson")
    good = [l for l in path.read_text().splitlines() if '"id": 8' not in l]
    path.write_text("\n".join(good) + "\n")
    plain = read_trajnet(path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    marked = read_trajnet(path)
    assert [s.scene_id for s in marked.scenes] == [s.scene_id for s in plain.scenes]
    np.testing.assert_array_equal(marked.scenes[0].history, plain.scenes[0].history)


def test_a_window_across_a_frame_its_primary_agent_misses_is_reported(tmp_path):
    from trajpref.data.text import GapWarning

    path = _three_agents(tmp_path / "a.ndjson")
    good = [l for l in path.read_text().splitlines() if '"id": 8' not in l]
    path.write_text("\n".join(good) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_trajnet(path)  # complete: no warning
    holed = [l for l in good if not ('"f": 100,' in l and '"p": 1,' in l)]
    assert len(holed) == len(good) - 1
    path.write_text("\n".join(holed) + "\n")
    with pytest.warns(GapWarning, match=r"1 scene\(s\) \(the first: 7\) have windows whose "
                      "primary agent misses a frame"):  # fmt: skip
        read_trajnet(path)


def _rated(path, rates):
    """One scene per rate in ``rates`` (fps), each with its own primary agent on 21 frames."""
    tracks, scenes = [], []
    for i, fps in enumerate(rates):
        tracks += [(100 * i + f, i, f / 10, 0.0) for f in range(21)]
        scenes.append({"id": i, "p": i, "s": 100 * i, "e": 100 * i + 20, "fps": fps})
    return _scene_file(path, tracks, scenes)


def test_frame_rates_that_disagree_are_refused_or_named(tmp_path):
    from trajpref.data import FrameRateWarning

    # scenes at 2.5 and 5 fps were read at the 0.4 s default without a word
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    _rated(mixed / "m.ndjson", [2.5, 5])
    with pytest.raises(DataError, match=r"declare different frame rates \(2.5 fps in m.ndjson, "
                       r"5 fps in m.ndjson\).*pass --frame-interval"):  # fmt: skip
        load_dataset(str(mixed), "test")
    with pytest.warns(FrameRateWarning, match=r"different frame rates .*all are read at the "
                      r"frame interval given, 0.4 s"):  # fmt: skip
        assert load_dataset(str(mixed), "test", frame_interval=0.4).info.frame_interval == 0.4
    # one rate: the files' own, silently unless a different interval was given
    five = tmp_path / "five"
    five.mkdir()
    _rated(five / "f.ndjson", [5, 5])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_dataset(str(five), "test").info.frame_interval == 0.2
        assert load_dataset(str(five), "test", frame_interval=0.2).info.frame_interval == 0.2
    with pytest.warns(FrameRateWarning, match=r"declare 5 fps in f.ndjson \(0.2 s between "
                      r"frames\), which is used: the frame interval given \(0.5 s, "
                      r"--frame-interval\) is ignored"):  # fmt: skip
        assert load_dataset(str(five), "test", frame_interval=0.5).info.frame_interval == 0.2


def test_old_mac_line_ends_and_an_upper_case_suffix(tmp_path):
    path = _rated(tmp_path / "a.ndjson", [2.5, 2.5])
    plain = read_trajnet(path)
    mac = tmp_path / "B.NDJSON"  # CR-only line ends: one line, "not a JSON object" on line 1
    mac.write_bytes(path.read_bytes().replace(b"\n", b"\r"))
    read = read_trajnet(mac)
    np.testing.assert_array_equal(read.scenes[1].future, plain.scenes[1].future)
    assert load_dataset(str(mac), "test").num_agents == 2  # .NDJSON: a TrajNet++ file
    path.unlink()
    assert len(load_dataset(str(tmp_path), "test")) == 2  # a folder of one B.NDJSON
    mac.write_bytes(mac.read_bytes().replace(b'"x": 0.5', b'"x": "0.5"'))  # row 6, line 8
    with pytest.raises(DataError, match="'x' must be a number") as info:
        read_trajnet(mac)
    assert info.value.line == 8


def _raw_file(path, scenes: list[str], tracks: list[tuple[str, str, float, float]]):
    """A scene file whose numbers are written as given (``"3.0"``, ``"9007199254740993"``)."""
    lines = [f'{{"scene": {{{s}}}}}' for s in scenes]
    lines += [f'{{"track": {{"f": {f}, "p": {p}, "x": {x}, "y": {y}}}}}' for f, p, x, y in tracks]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_ids_and_frames_written_as_floats_beyond_2_53_stay_exact(tmp_path):
    big = 2**53  # 9007199254740993.0 is read by json as the float 9007199254740992.0
    # agent big on frames 0..190, agent big + 1 on 200..300: float ids merged them into one
    # track of 31 frames and its scene read half of another agent's walk without a word
    tracks = [(str(f), f"{big}.0", f / 10, 0.0) for f in range(0, 200, 10)]
    tracks += [(str(f), f"{big + 1}.0", 100 + f / 10, 5.0) for f in range(200, 310, 10)]
    path = _raw_file(tmp_path / "a.ndjson", [f'"id": 1, "p": {big + 1}.0, "s": 0, "e": 300'],
                     tracks)  # fmt: skip
    with pytest.raises(DataError, match=f"scene 1: its primary agent {big + 1} has 11 frames"):
        read_trajnet(path)
    # both at the same frames: two agents (it was "duplicate row"), the float-written ids and
    # frames read as the integers they are
    tracks = [(f"{f}.0", f"{p}.0", f / 10, y) for f in range(0, 200, 10)
              for p, y in ((big, 0.0), (big + 1, 1.0))]  # fmt: skip
    path = _raw_file(tmp_path / "b.ndjson", [f'"id": 1, "p": {big + 1}.0, "s": 0, "e": 190.0'],
                     tracks)  # fmt: skip
    (scene,) = read_trajnet(path).scenes
    np.testing.assert_array_equal(scene.history[:, 0, 1], [1, 0])  # the primary first
    # nanosecond frames written as floats: 100 ns apart, two frames, not one
    ns = 1_700_000_000_000_000_000
    tracks = [(f"{ns + 10**8 * k + 100 * a}.0", str(a + 1), k / 10, a) for k in range(20)
              for a in (0, 1)]  # fmt: skip
    path = _raw_file(tmp_path / "c.ndjson", [f'"id": 1, "p": 1, "s": {ns}, "e": {ns + 10**10}'],
                     tracks)  # fmt: skip
    from trajpref.data.text import GapWarning

    with pytest.warns(GapWarning, match="the file steps 100 frames"):  # 100 ns, 1e8 - 100, ...
        (scene,) = read_trajnet(path).scenes
    assert scene.num_agents == 1  # agent 2 is never at agent 1's frames


def test_integers_too_large_for_float64_or_int64_are_read_or_refused_as_data(tmp_path):
    # frames of 1e20 overflowed int64 and ids of 400 digits overflowed float (OverflowError)
    huge = 10**20
    tracks = [(str(huge + 10 * k), str(10**400), k / 10, 0.0) for k in range(20)]
    path = _raw_file(tmp_path / "a.ndjson", [f'"id": 1, "p": {10**400}, "s": {huge}, '
                     f'"e": {huge + 190}'], tracks)  # fmt: skip
    (scene,) = read_trajnet(path).scenes
    np.testing.assert_allclose(scene.future[0, :, 0], np.arange(8, 20) / 10)
    path.write_text(path.read_text().replace('"x": 0.0', '"x": 1e400'))
    with pytest.raises(DataError, match="'x' is NaN or infinite"):
        read_trajnet(path)


# A TrajNet++ scene row whose frame span is huge (``"e": 1e20``, or a billion frames: a typo
# or a corrupt file) made the reader list every frame of it: an OverflowError past 2**63, and
# 24 GB of memory (the machine's OOM killer) for a span of a few billion frames, found by the
# reader's fuzz test. The span is now checked by arithmetic, and only the first missing frames
# are listed.


def _file(tmp_path, end) -> str:
    """One observation-only scene spanning frames 10..``end`` and three complete ones."""
    rows = [{"scene": {"id": 9, "p": 0, "s": 10, "e": end}}]
    rows += [{"scene": {"id": i, "p": i, "s": 0, "e": 6, "fps": 2.5}} for i in range(3)]
    rows += [{"track": {"f": f, "p": p, "x": 0.5 * f, "y": p - 0.25 * f}}
             for f in range(6) for p in range(3)]  # fmt: skip
    path = tmp_path / "f.ndjson"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return str(path)


@pytest.mark.parametrize("end", [1.792172702896576e20, 10**9 + 10, 3 * 10**9])
def test_a_huge_scene_span_is_a_data_error_at_once(tmp_path, end):
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (8 * 2**30, hard))  # a listed span fails, not OOM
    try:
        t0 = time.perf_counter()
        with pytest.raises(DataError, match=r"scene 9: .*frames? 10, 11, 12 and \d+ more missing"):
            read_trajnet(_file(tmp_path, end), 2, 3)
        assert time.perf_counter() - t0 < 30  # no walk over the span (a generous bound)
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
