"""TrajNet++ test files that hold the observations alone (the scene rows span 9 + 12 frames,
the tracks stop after the 9 observed): read with a NaN future, predicted at the hidden frames,
and refused wherever the future is read (evaluate, data stats, predict --truth)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import trajnetplusplustools as tnt

from trajpref import cli
from trajpref.cli import main
from trajpref.data.trajnet import ObservedOnlyWarning, read_trajnet, write_trajnet_scenes
from trajpref.errors import DataError

FRAMES = list(range(1000, 1310, 10))  # step 10
# scene 2 starts 3 frames after scene 1, as TrajNet++'s test scenes overlap: its observed frames
# 1030..1110 put rows in scene 1's hidden future (1090..1200)
SCENES = [{"id": 1, "p": 7, "s": 1000, "e": 1200, "fps": 2.5, "tag": [1, []]},
          {"id": 2, "p": 12, "s": 1030, "e": 1230, "fps": 2.5, "tag": [3, [1]]}]  # fmt: skip


def _tracks() -> list[tuple[int, int, float, float]]:
    """Every row of a full recording: 7, 3 and 12 walk all the time, 5 enters at 1040, 9
    leaves after 1050. Coordinates are multiples of 0.25 (exact in float32)."""
    rows = []
    for i, f in enumerate(FRAMES):
        rows += [(f, 7, 0.5 * i, 0.0), (f, 3, 0.25 * i, 2.0), (f, 12, 10 - 0.5 * i, 1.0)]
        if f >= 1040:
            rows.append((f, 5, 3.0, -2.0 + 0.5 * i))
        if f <= 1050:
            rows.append((f, 9, -1.0 + 0.5 * i, 1.0))
    return sorted(rows)


def _observed(scenes) -> set[int]:
    """The frames TrajNet++'s test files keep: each scene's first 9."""
    return {f for s in scenes for f in range(s["s"], s["e"] - 12 * 10 + 1, 10)}


def _write(path, scenes=SCENES, tracks=None) -> set[tuple[int, int, float, float]]:
    """A scene file; ``tracks`` default: a test file's, the rows at the frames some scene
    shows as observed. Returns the track rows written."""
    if tracks is None:
        shown = _observed(scenes)
        tracks = [r for r in _tracks() if r[0] in shown]
    lines = [json.dumps({"scene": s}) for s in scenes]
    lines += [json.dumps({"track": {"f": f, "p": p, "x": x, "y": y}}) for f, p, x, y in tracks]
    path.write_text("\n".join(lines) + "\n")
    return set(tracks)


def test_an_observation_only_file_reads_with_a_nan_future(tmp_path):
    _write(tmp_path / "a.ndjson")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a file of one kind: no warning
        read = read_trajnet(tmp_path / "a.ndjson")
    assert read.observed_only == 2
    one, two = read.scenes
    # the last 8 of the 9 observed frames, then the 12 hidden ones, computed at the file's step
    np.testing.assert_array_equal(one.frames, FRAMES[1:21])
    np.testing.assert_array_equal(two.frames, FRAMES[4:24])
    # targets: the primary, then the agents in all 8 observed frames, by id; 7's rows at
    # 1090..1110 (scene 2's observed frames) are no future of scene 1
    assert one.agent_id.tolist() == [7, 3, 12] and two.agent_id.tolist() == [12, 3, 5, 7]
    assert one.future.shape == (3, 12, 2) and np.isnan(one.future).all()
    assert two.future.shape == (4, 12, 2) and np.isnan(two.future).all()
    np.testing.assert_array_equal(one.history[0, :, 0], 0.5 * np.arange(1, 9))
    np.testing.assert_array_equal(two.history[2, :, 1], -2.0 + 0.5 * np.arange(4, 12))
    # context: 5 (entered at 1040) is seen at the last observed frame 1080, 9 (left) is not
    assert one.context.shape == (1, 8, 2)
    assert np.isnan(one.context[0, :3]).all() and np.isfinite(one.context[0, 3:]).all()
    assert two.context is None


def test_a_partly_hidden_primary_is_an_error_naming_the_scene(tmp_path):
    # primary 7 has 4 of its 12 future frames, at frames no scene shows as observed
    rows = [r for r in _tracks() if r[0] <= 1120]
    _write(tmp_path / "a.ndjson", SCENES[:1], rows)
    with pytest.raises(DataError, match=r"scene 1: its primary agent 7 has 4 of its 12 future "
                       r"frames 1090\.\.1200 \(step 10; frames 1130, 1140, 1150 and 5 more "
                       r"missing\)") as info:  # fmt: skip
        read_trajnet(tmp_path / "a.ndjson")
    assert info.value.line == 1
    # an observed frame missing: neither a window nor an observation-only scene
    rows = [r for r in _tracks() if r[0] <= 1080 and r[0] != 1040]
    _write(tmp_path / "b.ndjson", SCENES[:1], rows)
    with pytest.raises(DataError, match=r"scene 1: .* an observation-only scene a row at every "
                       r"frame 1000\.\.1080 \(step 10\): frame 1040 missing"):  # fmt: skip
        read_trajnet(tmp_path / "b.ndjson")


def test_a_file_of_both_kinds_warns_and_reads_the_complete_scenes_as_before(tmp_path):
    # scene 1 complete (all 21 frames), scene 3 observation-only (frames 1210..1290)
    scenes = [SCENES[0], {"id": 3, "p": 3, "s": 1210, "e": 1410, "fps": 2.5, "tag": [1, []]}]
    rows = [r for r in _tracks() if r[0] <= 1290]
    _write(tmp_path / "mixed.ndjson", scenes, rows)
    _write(tmp_path / "full.ndjson", scenes[:1], rows)
    with pytest.warns(ObservedOnlyWarning, match=r"mixed.ndjson: 1 of its 2 scenes \(the "
                      r"first: 3\) hold their primary agent's observed frames alone"):  # fmt: skip
        read = read_trajnet(tmp_path / "mixed.ndjson")
    assert read.observed_only == 1
    complete, hidden = read.scenes
    (alone,) = read_trajnet(tmp_path / "full.ndjson").scenes
    for key in ("history", "future", "context", "agent_id", "frames"):
        np.testing.assert_array_equal(getattr(complete, key), getattr(alone, key))
    assert np.isfinite(complete.future).all() and np.isnan(hidden.future).all()
    np.testing.assert_array_equal(hidden.frames, range(1220, 1420, 10))


def _predict(data, out, *flags, model="cv") -> list[str]:
    return [str(a) for a in ["predict", "--dataset", data, "--model", model, "--samples", "3",
                             "--no-progress", "--out", out, *flags]]  # fmt: skip


def test_predict_writes_the_hidden_frames_and_the_input_rows_alone(tiny_run, tmp_path, capsys):
    written = _write(tmp_path / "a.ndjson")
    out = tmp_path / "pred.ndjson"
    model = tiny_run / "generator.safetensors"  # a tiny model, trained for a second
    code = main(_predict(tmp_path / "a.ndjson", out, "--format", "trajnet", model=model))
    assert code == 0, capsys.readouterr().err
    text = out.read_text()
    assert "nan" not in text.lower()
    lines = text.splitlines()
    assert [json.loads(line) for line in lines[:2]] == [{"scene": s} for s in SCENES]
    rows = [json.loads(line)["track"] for line in lines[2:]]
    observed = {(r["f"], r["p"], r["x"], r["y"]) for r in rows if "prediction_number" not in r}
    assert observed <= written  # rows of the input, none made up
    guesses = [r for r in rows if "prediction_number" in r]
    hidden = {1: FRAMES[9:21], 2: FRAMES[12:24]}
    agents = {1: [7, 3, 12], 2: [12, 3, 5, 7]}
    # one row per target agent, sample and hidden frame: nothing else
    want = sorted((sid, p, k, f) for sid in (1, 2) for p in agents[sid] for k in range(3)
                  for f in hidden[sid])  # fmt: skip
    assert sorted((r["scene_id"], r["p"], r["prediction_number"], r["f"]) for r in guesses) == want
    # trajnetplusplustools' Reader reads it: each scene's primary predicted at its hidden frames
    reader = tnt.Reader(str(out), scene_type="paths")
    for sid, paths in reader.scenes():
        first = [t for t in paths[0] if t.prediction_number == 0 and t.scene_id == sid]
        assert [t.frame for t in first] == hidden[sid]
    # --format npz: the future is NaN there
    assert main(_predict(tmp_path / "a.ndjson", tmp_path / "p.npz")) == 0
    with np.load(tmp_path / "p.npz") as saved:
        assert saved["pred"].shape == (3, 7, 12, 2) and np.isfinite(saved["pred"]).all()
        assert np.isnan(saved["future"]).all()


def test_a_folder_of_test_files_is_predicted_as_a_folder(tmp_path, capsys):
    (tmp_path / "test").mkdir()
    _write(tmp_path / "test" / "a.ndjson")
    _write(tmp_path / "test" / "b.ndjson", [dict(SCENES[0], id=0)])
    out = tmp_path / "pred.ndjson"
    assert main(_predict(tmp_path / "test", out, "--format", "trajnet")) == 0
    for name in ("a", "b"):
        reader = tnt.Reader(str(tmp_path / "pred" / f"{name}.ndjson"), scene_type="paths")
        assert all(any(t.prediction_number == 2 for t in paths[0]) for _, paths in
                   reader.scenes())  # fmt: skip


def test_truth_is_refused_before_any_model_is_read(tmp_path, capsys, monkeypatch):
    _write(tmp_path / "a.ndjson")

    def no_model(args):
        raise AssertionError("a model was read")

    monkeypatch.setattr(cli, "_predictor", no_model)
    argv = _predict(tmp_path / "a.ndjson", tmp_path / "p.ndjson", "--format", "trajnet",
                    "--truth", tmp_path / "gt.ndjson")  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'a.ndjson'}: predict --truth reads each window's future" in err
    assert "hold the observed frames alone (the first: a.ndjson#1)" in err
    assert not (tmp_path / "p.ndjson").exists() and not (tmp_path / "gt.ndjson").exists()
    # the writer itself writes no NaN truth either
    scenes = read_trajnet(tmp_path / "a.ndjson").scenes
    pred, scene = np.zeros((1, 7, 12, 2), np.float32), np.array([0, 0, 0, 1, 1, 1, 1])
    with pytest.raises(DataError, match="2 scene.* hold the observed frames alone"):
        write_trajnet_scenes(tmp_path / "p.ndjson", scenes, pred, scene, tmp_path / "gt.ndjson")
    assert not (tmp_path / "p.ndjson").exists() and not (tmp_path / "gt.ndjson").exists()


@pytest.mark.parametrize(("command", "name"),
                         [(["evaluate", "--model", "cv", "--no-progress"], "evaluate"),
                          (["data", "stats"], "data stats")])  # fmt: skip
def test_what_reads_the_future_refuses_the_file(tmp_path, capsys, command, name):
    (tmp_path / "test").mkdir()
    _write(tmp_path / "test" / "a.ndjson")
    assert main([*command, "--dataset", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'test' / 'a.ndjson'}: {name} reads each window's future" in err
    assert "and 2 of the 2 scenes hold the observed frames alone" in err
    assert "nan" not in err.lower()


def test_the_library_refuses_to_score_or_train_on_hidden_futures(tmp_path):
    """The Python entry points that read the future say so too, not only the CLI: the
    evaluation loop (NaN metrics otherwise), in-context evaluation, and a training run's splits
    (NaN losses otherwise)."""
    from trajpref.adapt import evaluate_in_context
    from trajpref.config import DataConfig
    from trajpref.data import load_dataset
    from trajpref.data.registry import run_splits
    from trajpref.evaluation import evaluate
    from trajpref.models.baseline import ConstantVelocity

    for split in ("train", "val", "test"):
        (tmp_path / split).mkdir()
        _write(tmp_path / split / "a.ndjson")
    data = load_dataset(str(tmp_path), "test")
    with pytest.raises(DataError, match="evaluate reads each window's future"):
        evaluate(ConstantVelocity(), data, progress=False)
    with pytest.raises(DataError, match="evaluate_in_context reads each window's future"):
        evaluate_in_context(None, data)
    with pytest.raises(DataError, match=r"training \(its validation split\) reads"):
        run_splits(DataConfig(dataset=str(tmp_path)))


@pytest.mark.parametrize("third", [1110, 1130])
def test_a_test_scene_whose_future_other_scenes_fill_but_for_a_frame_is_observation_only(
    tmp_path, third
):
    """Scenes at 1030 and ``third`` show 11 of scene 1's 12 hidden frames as observed (all but
    1200, or all but 1120), so its primary has 20 rows in its span: still a test scene, read at
    its own frames, not a window shifted off them (silently, or across the gap with a
    GapWarning)."""
    scenes = [SCENES[0], SCENES[1], {"id": 3, "p": 3, "s": third, "e": third + 200, "fps": 2.5}]
    _write(tmp_path / "a.ndjson", scenes)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no GapWarning, and every scene observation-only
        read = read_trajnet(tmp_path / "a.ndjson")
    assert read.observed_only == 3
    one = read.scenes[0]
    np.testing.assert_array_equal(one.frames, FRAMES[1:21])
    np.testing.assert_array_equal(one.history[0, :, 0], 0.5 * np.arange(1, 9))
    assert np.isnan(one.future).all()


def test_a_test_scene_whose_whole_future_leaked_is_read_as_a_test_scene(tmp_path):
    """Scenes at 1030 and 1120 show every frame of scene 1's hidden future (1090..1200) as
    observed, so its primary has all 21 rows: in a test file it is still read as a test scene,
    its targets the agents of its observed frames (it read as a complete window, whose targets
    had to be seen in the leaked future too)."""
    scenes = [SCENES[0], SCENES[1], {"id": 3, "p": 3, "s": 1120, "e": 1320, "fps": 2.5}]
    _write(tmp_path / "a.ndjson", scenes)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # one kind: every scene a test scene
        read = read_trajnet(tmp_path / "a.ndjson")
    assert read.observed_only == 3
    one = read.scenes[0]
    np.testing.assert_array_equal(one.frames, FRAMES[1:21])
    assert one.agent_id.tolist() == [7, 3, 12] and np.isnan(one.future).all()


@pytest.mark.parametrize(("t_hist", "t_fut"), [(5, 10), (8, 16)])
def test_a_test_file_read_at_another_horizon_says_it_hides_12_frames(tmp_path, t_hist, t_fut):
    """Read at 5 + 10 (a model's own lengths), the cut fell inside the hidden future and the
    error spoke of missing frames alone (walkthrough 70)."""
    _write(tmp_path / "a.ndjson")
    with pytest.raises(DataError, match=rf"TrajNet\+\+ test files hide their last 12 frames, "
                       rf"and this read cuts {t_fut} future frames"):  # fmt: skip
        read_trajnet(tmp_path / "a.ndjson", t_hist, t_fut)
    read_trajnet(tmp_path / "a.ndjson", 5, 12)  # a shorter history reads
