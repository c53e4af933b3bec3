"""``require_future`` on scenes built by hand: one whose agent misses part of its future was
refused as a TrajNet++ observation-only scene, at a path that pasted the text reader's scene
id (``walk0.txt@frame=0``) onto the folder."""

import numpy as np
import pytest
from synthetic import make_scene, write_dataset

from trajpref.data import load_dataset
from trajpref.data.trajnet import require_future, source_file_of
from trajpref.errors import DataError
from trajpref.evaluation import evaluate
from trajpref.models.baseline import ConstantVelocity
from trajpref.types import DatasetInfo, Scene, TrajectoryDataset


@pytest.fixture(scope="module")
def text_data(tmp_path_factory):
    root = write_dataset(tmp_path_factory.mktemp("walks"))
    return root, load_dataset(str(root), "test")


def _with_future(data: TrajectoryDataset, index: int, fn) -> TrajectoryDataset:
    scenes = list(data.scenes)
    s = scenes[index]
    future = s.future.copy()
    fn(future)
    scenes[index] = Scene(s.history, future, s.agent_type, s.scene_id, context=s.context)
    return TrajectoryDataset(scenes, data.info)


def test_part_of_an_agents_future_missing_says_so_and_names_the_file(text_data):
    root, data = text_data

    def cut(future):
        future[1, 8:] = np.nan  # agent 1 unseen over the last 4 future frames

    bad = _with_future(data, 2, cut)
    sid = data.scenes[2].scene_id
    with pytest.raises(DataError) as err:
        evaluate(ConstantVelocity(), bad, progress=False)
    text = str(err.value)
    assert text.startswith(f"{root / 'test' / 'walk0.txt'}: evaluate reads each window's future")
    assert (
        f"1 of the {len(data)} scenes have an agent without a position at some future frames "
        f"(the first: {sid}, its agent 1 of 3, NaN at future steps 9..12 of 12)"
    ) in text
    assert "context-only neighbour" in text and "Scene.context" in text
    assert "TrajNet++" not in text and "hidden" not in text


def test_a_text_scene_whose_future_is_all_nan_is_hidden_at_the_right_file(text_data):
    root, data = text_data

    def hide(future):
        future[:] = np.nan

    with pytest.raises(DataError) as err:
        require_future(_with_future(data, 0, hide), "evaluate")
    text = str(err.value)
    assert text.startswith(f"{root / 'test' / 'walk0.txt'}: evaluate reads each window's future")
    assert "hold the observed frames alone" in text and "TrajNet++'s test files" in text


def test_scattered_steps_and_no_source():
    scene = make_scene(2)
    future = scene.future.copy()
    future[0, [1, 4, 6, 7, 9, 11]] = np.nan
    scenes = [Scene(scene.history, future, scene.agent_type, "x.npz#0")]
    with pytest.raises(DataError, match=r"^check reads .*\(the first: x\.npz#0, its agent 0 of 2, "
                       r"NaN at future steps 2, 5, 7, 8 and 2 more of 12\)"):  # fmt: skip
        require_future(TrajectoryDataset(scenes, DatasetInfo("toy", "test", "m", 0.4)), "check")


def test_source_file_of_reads_both_id_forms():
    assert source_file_of("crowds_zara01.txt@frame=1110") == "crowds_zara01.txt"
    assert source_file_of("a#b.ndjson#12") == "a#b.ndjson"
    assert source_file_of("biwi_eth.ndjson#3") == "biwi_eth.ndjson"
    assert source_file_of("plain") == "plain"
