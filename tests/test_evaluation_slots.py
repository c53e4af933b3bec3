"""evaluate(slots=R) / ``trajpref evaluate --slots``: the metrics per agent's place in its
scene (Robo's leader, follower, approacher), and ``metrics.agent_slot`` / ``SlotMetrics``."""

import json

import numpy as np
import pytest
import torch

from trajpref.errors import ConfigError
from trajpref.evaluation import evaluate
from trajpref.metrics import SlotMetrics, agent_slot, collision_flags, slot_labels
from trajpref.types import AGENT_PERSON, DatasetInfo, Scene, TrajectoryDataset


def _scene(p: int, name: str) -> Scene:
    """p agents 5 m apart in y, walking in x (agent j at y = 5 j)."""
    start = np.stack([np.zeros(p), 5.0 * np.arange(p)], 1)  # [P, 2]
    steps = np.stack([0.4 * np.arange(20), np.zeros(20)], 1)  # [20, 2]
    track = (start[:, None] + steps[None]).astype(np.float32)  # [P, 20, 2]
    return Scene(track[:, :8], track[:, 8:], np.full(p, AGENT_PERSON, np.int64), name)


DATA = TrajectoryDataset([_scene(3, "a"), _scene(2, "b"), _scene(5, "c")],
                         DatasetInfo("toy", "test", "m", 0.4))  # fmt: skip


class ByPlace:
    """K samples: the truth moved in y by 0.1 (j + 1) m for the agent listed j-th in its scene
    (read from its y, 5 j), the k-th sample by k + 1 times that."""

    name = "by-place"

    def predict(self, batch, num_samples, generator=None):
        shift = 0.1 * (1 + batch.history[:, -1, 1] / 5)  # [N]
        step = torch.stack([torch.zeros_like(shift), shift], -1)[:, None]  # [N, 1, 2]
        return torch.stack([batch.future + step * (k + 1) for k in range(num_samples)])


def test_agent_slot_counts_each_scene_in_batch_order_even_when_interleaved():
    scene = torch.tensor([0, 0, 0, 1, 1, 2])
    assert agent_slot(scene, 3).tolist() == [0, 1, 2, 0, 1, 0]
    assert agent_slot(torch.tensor([1, 0, 1, 0, 0]), 2).tolist() == [0, 0, 1, 1, 2]
    assert agent_slot(torch.tensor([], dtype=torch.long), 0).tolist() == []


def test_slot_labels_and_bad_counts():
    assert slot_labels(3) == ["1", "2", "3", ">3"]
    for bad in (0, -1, 2.0, True):
        with pytest.raises(ValueError, match="slots must be an integer >= 1"):
            slot_labels(bad)


@pytest.mark.parametrize("max_agents", [1024, 5])
def test_each_place_gets_its_own_agents_errors(max_agents):
    out = evaluate(ByPlace(), DATA, 2, progress=False, max_agents=max_agents, slots=3)
    slots = out["slots"]
    assert list(slots) == ["1", "2", "3", ">3"]
    assert [slots[k]["agents"] for k in slots] == [3, 3, 2, 2]
    for label, err in (("1", 0.1), ("2", 0.2), ("3", 0.3), (">3", 0.45)):  # >3: 0.4 and 0.5
        assert slots[label]["min_ade"] == pytest.approx(err, abs=1e-5)
        assert slots[label]["min_fde"] == pytest.approx(err, abs=1e-5)
    weighted = sum(r["agents"] * r["min_ade"] for r in slots.values()) / out["agents"]
    assert weighted == pytest.approx(out["min_ade"], abs=1e-6)
    assert slots["1"]["col_agents"] == 3 and slots["1"]["col_i_pct"] == 0.0  # 5 m apart


def test_an_empty_place_and_no_collision_keys_without_a_radius():
    out = evaluate(ByPlace(), DATA, 1, progress=False, slots=5, collision_radius=None)
    assert out["slots"][">5"] == {"agents": 0}
    assert set(out["slots"]["1"]) == {"agents", "min_ade", "min_fde"}
    assert "slots" not in evaluate(ByPlace(), DATA, 1, progress=False)


def test_bad_slots_and_primary_are_refused(monkeypatch):
    with pytest.raises(ConfigError, match="slots must be an integer >= 1"):
        evaluate(ByPlace(), DATA, 1, progress=False, slots=0)
    monkeypatch.setattr("trajpref.evaluation.trajnet_scenes", lambda ds: True)  # as TrajNet++
    with pytest.raises(ConfigError, match="does not combine with bins .* or slots"):
        evaluate(ByPlace(), DATA, 1, progress=False, slots=3, agents="primary")


def test_slot_metrics_with_a_radius_needs_the_flags():
    pred = torch.zeros(1, 2, 3, 2)
    future, scene = torch.zeros(2, 3, 2), torch.tensor([0, 0])
    acc = SlotMetrics(2, collision_radius=0.1)
    with pytest.raises(ValueError, match="needs each batch's flags"):
        acc.update(pred, future, scene, 1)
    acc.update(pred, future, scene, 1, collision_flags(pred, future, scene, 0.1))
    assert acc.compute()["1"]["col_i_pct"] == 100.0  # both agents at the same place


def _cli(args, capsys):
    from trajpref.cli import main

    rc = main(args)
    return rc, capsys.readouterr()


def test_cli_slots_table_json_and_errors(tmp_path, capsys):
    folder = tmp_path / "toy"
    folder.mkdir()
    rows = []
    for s, scene in enumerate(DATA.scenes):  # one frame block per scene, far apart in time
        track = np.concatenate([scene.history, scene.future], 1)  # [P, 20, 2]
        for j, path in enumerate(track):
            rows += [f"{1000 * s + 10 * t} {10 * s + j} {x:.3f} {y:.3f}"
                     for t, (x, y) in enumerate(path)]  # fmt: skip
    (folder / "toy.txt").write_text("\n".join(rows) + "\n")
    base = ["evaluate", "--dataset", str(folder), "--model", "cv", "--no-progress",
            "--units", "m", "--frame-interval", "0.4"]  # fmt: skip
    rc, out = _cli([*base, "--slots"], capsys)
    assert rc == 0 and "place" in out.out and "\n        >3 " in out.out  # auto: 3 for cv
    rc, out = _cli([*base, "--slots", "2", "--json"], capsys)
    result = json.loads(out.out)
    assert list(result["slots"]) == ["1", "2", ">2"]
    assert sum(r["agents"] for r in result["slots"].values()) == result["agents"]
    for bad in ("0", "two"):
        rc, out = _cli([*base, "--slots", bad], capsys)
        assert rc == 2 and "--slots takes an integer >= 1" in out.err and not out.out
    rc, out = _cli([*base, "--slots", "--in-context", "40"], capsys)
    assert rc == 2 and "--scorer, --bins or --slots" in out.err


def test_the_flag_alone_counts_the_models_roles():
    from trajpref.cli import _parse_slots

    class Roles:
        agent_roles = 2

    assert _parse_slots("auto", Roles()) == 2
    assert _parse_slots("auto", object()) == 3  # no roles (cv, a user's predictor): 3
    assert _parse_slots("4", Roles()) == 4 and _parse_slots(None, Roles()) is None
