"""evaluate(agents="persons"): every metric over the persons alone (NBA's players, as SocialVAE
scores its split), while the model still reads the whole scene, the ball included."""

import numpy as np
import pytest
import torch

from trajpref.errors import ConfigError, DataError
from trajpref.evaluation import _agent_mask, evaluate, select_agents
from trajpref.score.scorer import ScoreResult, relative_score
from trajpref.types import AGENT_BALL, AGENT_PERSON, DatasetInfo, Scene, TrajectoryDataset, collate


def _scene(types: list[int], name: str) -> Scene:
    """Agents 5 m apart walking in x, one scene, with the given agent types."""
    p = len(types)
    start = np.stack([np.zeros(p), 5.0 * np.arange(p)], 1)  # [P, 2]
    steps = np.stack([0.4 * np.arange(20), np.zeros(20)], 1)  # [20, 2]
    track = (start[:, None] + steps[None]).astype(np.float32)  # [P, 20, 2]
    return Scene(track[:, :8], track[:, 8:], np.array(types, np.int64), name)


def _dataset(*scenes: Scene) -> TrajectoryDataset:
    return TrajectoryDataset(list(scenes), DatasetInfo("toy", "test", "m", 0.4))


class Offset:
    """Two samples per agent: the truth moved 0.1 m (persons) or ``ball`` m (the ball) in y, and
    twice that; records the agents and types of every batch it was handed."""

    name = "offset"

    def __init__(self, ball: float) -> None:
        self.ball, self.seen = ball, []

    def predict(self, batch, num_samples, generator=None):
        self.seen.append(batch.agent_type.tolist())
        shift = torch.where(batch.agent_type == AGENT_BALL, self.ball, 0.1)  # [N]
        step = torch.stack([torch.zeros_like(shift), shift], -1)[:, None]  # [N, 1, 2]
        return torch.stack([batch.future + step * (k + 1) for k in range(num_samples)])


DATA = _dataset(_scene([AGENT_BALL, AGENT_PERSON, AGENT_PERSON], "a"),
                _scene([AGENT_PERSON] * 3, "b"), _scene([AGENT_BALL], "c"))  # fmt: skip


def test_a_ball_with_a_huge_error_changes_no_persons_metric():
    far, near = Offset(ball=1000.0), Offset(ball=10.0)
    persons = evaluate(far, DATA, 2, progress=False, agents="persons")
    assert persons["min_ade"] == pytest.approx(0.1, abs=1e-5) and persons[
        "min_fde"
    ] == pytest.approx(0.1, abs=1e-5)
    assert persons["joint_min_ade"] == pytest.approx(0.1, abs=1e-5)
    assert persons["agents"] == 5 and persons["scenes"] == 2  # the ball-only scene left out
    assert persons["agent_set"] == "persons"
    assert persons["col_i_pct"] == 0.0 and persons["col_agents"] == 5
    assert far.seen == [[1, 0, 0, 0, 0, 0, 1]]  # the model read the ball, as a neighbour
    again = evaluate(near, DATA, 2, progress=False, agents="persons")
    assert {k: again[k] for k in persons} == persons
    every = evaluate(far, DATA, 2, progress=False)
    assert every["min_ade"] > 100 and every["agents"] == 7 and every["scenes"] == 3
    assert "agent_set" not in every  # the all-agents result, keyed as before


def test_bad_agent_sets_and_splits_without_a_person_are_refused():
    with pytest.raises(ConfigError, match="one of all, persons, primary, got 'players'"):
        evaluate(Offset(1.0), DATA, 2, progress=False, agents="players")
    with pytest.raises(DataError, match=r"toy/test has no agent of agent_type 0 \(person\)"):
        evaluate(Offset(1.0), _dataset(_scene([AGENT_BALL], "c")), 2, progress=False,
                 agents="persons")  # fmt: skip


def test_the_scores_are_recomputed_over_the_persons():
    batch = collate(list(DATA.scenes))  # 7 agents in 3 scenes
    gen = torch.Generator().manual_seed(0)
    d_pred, d_gt = torch.rand(4, 7, 12, generator=gen), torch.rand(7, 12, generator=gen) + 0.5
    full = ScoreResult(d_pred, d_gt, relative_score(d_pred, d_gt), *([None] * 4))
    pred = torch.zeros(4, 7, 12, 2)
    view, vpred, res = select_agents(batch, pred, _agent_mask(batch, "persons"), full)
    assert view.num_scenes == 2 and view.scene.tolist() == [0, 0, 1, 1, 1]
    assert view.scene_ids == ["a", "b"] and vpred.shape == (4, 5, 12, 2)
    mine = [[1, 2], [3, 4, 5]]  # the persons of scenes a and b in the batch
    want = torch.stack([1 - d_pred[:, m].sum((1, 2)) / d_gt[m].sum() for m in mine], 1)  # [4, 2]
    torch.testing.assert_close(res.ats, want)
    assert res.d_pred.shape == (4, 5, 12) and res.r.shape == (4, 5, 12)
