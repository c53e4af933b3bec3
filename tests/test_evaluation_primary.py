"""evaluate(agents="primary") (the CLI's ``--agents primary``): every metric over each TrajNet++
scene's primary pedestrian, the one agent per scene TrajNet++'s evaluator scores, while the model
reads the whole scene; refused for data that are not TrajNet++ scenes."""

import json

import numpy as np
import pytest
import torch

from trajpref.cli import main
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.evaluation import evaluate, first_agents, trajnet_scenes
from trajpref.types import DatasetInfo, Scene, TrajectoryDataset, collate

FRAMES = range(0, 210, 10)  # 21 frames, step 10

# scene id -> (primary, start, end): primaries that are not the smallest id of their scene
SCENES = {5: (9, 0, 200), 6: (4, 0, 190), 7: (4, 10, 200)}


def _write(path, tracks: dict[int, tuple[float, float]], scenes=SCENES):
    """A TrajNet++ file: ``tracks`` maps agent -> (x at frame 0, y); x grows 0.1 per frame step."""
    lines = [json.dumps({"scene": {"id": sid, "p": p, "s": s, "e": e, "fps": 2.5,
                                   "tag": [1, []]}})
             for sid, (p, s, e) in scenes.items()]  # fmt: skip
    lines += [json.dumps({"track": {"f": f, "p": p, "x": x + f / 100, "y": y}})
              for f in FRAMES for p, (x, y) in sorted(tracks.items())]  # fmt: skip
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def folder(tmp_path):
    """Agents 2, 4 and 9, 3 m apart, each in all three scenes."""
    _write(tmp_path / "a.ndjson", {2: (2.0, 0.0), 4: (4.0, 3.0), 9: (9.0, 6.0)})
    return tmp_path


class Shift:
    """Two samples per agent: the truth moved up by s and 2 s, s = 0.01 x (the agent's first
    observed x), so that every agent's minADE = minFDE = its s."""

    name = "shift"

    def __init__(self) -> None:
        self.seen: list[int] = []

    def predict(self, batch, num_samples, generator=None):
        self.seen.append(batch.num_agents)
        s = 0.01 * batch.history[:, 0, 0]  # [N]
        step = torch.stack([torch.zeros_like(s), s], -1)[:, None]  # [N, 1, 2]
        return torch.stack([batch.future + step * (k + 1) for k in range(num_samples)])


def _primaries_by_hand(path) -> float:
    """The mean of s over the scenes' primaries, from the file's rows alone."""
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    x = {(r["track"]["f"], r["track"]["p"]): r["track"]["x"] for r in rows if "track" in r}
    shifts = []
    for r in rows:
        if "scene" in r:
            sc = r["scene"]
            own = sorted(f for f, p in x if p == sc["p"] and sc["s"] <= f <= sc["e"])[-20:]
            shifts.append(0.01 * x[(own[0], sc["p"])])  # its window's first observed x
    return float(np.mean(shifts))


def test_primary_only_equals_a_hand_computation_over_the_primaries(folder):
    ds = load_dataset(str(folder), "test")
    assert trajnet_scenes(ds)
    model = Shift()
    out = evaluate(model, ds, 2, progress=False, agents="primary")
    want = _primaries_by_hand(folder / "a.ndjson")  # (9.1 + 4.0 + 4.1) / 3 / 100
    assert want == pytest.approx(0.0573333, abs=1e-6)
    assert out["min_ade"] == pytest.approx(want, abs=1e-6)
    assert out["min_fde"] == pytest.approx(want, abs=1e-6)
    assert out["joint_min_ade"] == pytest.approx(want, abs=1e-6)  # one agent per scene
    assert out["agents"] == 3 and out["scenes"] == 3 and out["agent_set"] == "primary"
    assert model.seen == [9]  # the model read every agent of the three scenes
    every = evaluate(Shift(), ds, 2, progress=False)
    assert every["agents"] == 9 and every["min_ade"] != pytest.approx(want, abs=1e-3)


def test_first_agents_marks_each_scenes_first_agent():
    def scene(p):
        return Scene(np.zeros((p, 8, 2), np.float32), np.zeros((p, 12, 2), np.float32),
                     np.zeros(p, np.int64), "x")  # fmt: skip

    batch = collate([scene(3), scene(1), scene(2)])
    assert first_agents(batch).tolist() == [True, False, False, True, True, False]


def test_the_primarys_collisions_are_tested_against_every_neighbour(tmp_path):
    # agent 3 walks 0.15 m beside primary 9 (their ground truths touch at 2 x 0.1 m); agent 1
    # is 5 m away and is the primary of scene 2
    _write(tmp_path / "a.ndjson", {9: (0.0, 0.0), 3: (0.0, 0.15), 1: (0.0, 5.0)},
           scenes={1: (9, 0, 200), 2: (1, 0, 200)})  # fmt: skip
    out = evaluate(Shift(), load_dataset(str(tmp_path), "test"), 2, progress=False,
                   agents="primary")  # fmt: skip
    assert out["col_agents"] == 2  # both primaries have neighbours (the scene's other agents)
    assert out["col_gt_pct"] == pytest.approx(50.0)  # scene 1's primary, not scene 2's


def test_data_that_are_not_trajnet_scenes_and_bins_are_refused(folder):
    track = np.zeros((2, 20, 2), np.float32)
    toy = TrajectoryDataset([Scene(track[:, :8], track[:, 8:], np.zeros(2, np.int64),
                                   "crowds_zara01.txt@frame=10")],
                            DatasetInfo("toy", "test", "m", 0.4))  # fmt: skip
    assert not trajnet_scenes(toy)
    with pytest.raises(ConfigError, match="toy/test is not TrajNet\\+\\+ data"):
        evaluate(Shift(), toy, 2, progress=False, agents="primary")
    with pytest.raises(ConfigError, match="does not combine with bins"):
        evaluate(Shift(), load_dataset(str(folder), "test"), 2, progress=False,
                 agents="primary", bins=(5,))  # fmt: skip


def test_cli_evaluate_agents_primary(folder, walks, capsys):
    common = ["evaluate", "--dataset", str(folder), "--model", "cv", "--samples", "3",
              "--no-progress"]  # fmt: skip
    assert main([*common, "--agents", "primary", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["agent_set"] == "primary" and out["agents"] == 3 and out["scenes"] == 3
    assert main([*common, "--agents", "primary"]) == 0
    text = capsys.readouterr().out
    assert "primary agents only" in text and "(3 primary agents, 3 scenes" in text
    code = main(["evaluate", "--dataset", str(walks), "--model", "cv", "--no-progress",
                 "--agents", "primary"])  # fmt: skip
    assert code == 2 and "is not TrajNet++ data" in capsys.readouterr().err
