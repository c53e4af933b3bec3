"""Top-k recall counts a sample tied for the least joint error as best (walkthrough 67, F6)."""

import torch

from trajpref.score.scorer import ScoreAccumulator, ScoreResult, recall_hits
from trajpref.types import Batch


def _batch(num_agents=1, t_f=2):
    return Batch(
        history=torch.zeros(num_agents, 8, 2),
        future=torch.zeros(num_agents, t_f, 2),
        scene=torch.zeros(num_agents, dtype=torch.int64),
        agent_type=torch.zeros(num_agents, dtype=torch.int64),
        num_scenes=1,
    )


def _tied_pred(batch):
    """K = 3: samples 0 and 1 identical and perfect, sample 2 off by 1 m."""
    pred = batch.future[None].repeat(3, 1, 1, 1)  # [3, N, T_f, 2]
    pred[2] += 1.0
    return pred


def test_the_second_of_two_tied_best_samples_ranked_first_is_a_hit():
    batch = _batch()
    order = torch.tensor([[1], [0], [2]])  # [K, B]: sample 1, tied for best, first
    hits = recall_hits(_tied_pred(batch), batch, order, order, ks=(1, 2))
    assert all(bool(v.all()) for v in hits.values()), hits


def test_a_worse_sample_ranked_first_is_still_a_miss():
    batch = _batch()
    order = torch.tensor([[2], [1], [0]])
    hits = recall_hits(_tied_pred(batch), batch, order, order, ks=(1, 2))
    assert not hits["top1_recall_ats"].any() and not hits["top1_recall_fts"].any()
    assert hits["top2_recall_ats"].all() and hits["top2_recall_fts"].all()


def test_a_near_best_but_distinct_sample_is_not_best():
    batch = _batch()
    pred = _tied_pred(batch)
    pred[0] += 1e-3  # 1 mm off: sample 1 alone is best
    order = torch.tensor([[0], [1], [2]])
    hits = recall_hits(pred, batch, order, order, ks=(1,))
    assert not hits["top1_recall_ats"].any()


def test_accumulator_counts_a_tie_for_best_as_a_hit():
    """64 identical perfect samples (equal scores: they share their noise) and a bad one: the
    top-ranked sample is best whichever of the tied ones comes first."""
    k = 65
    batch = _batch(num_agents=2)
    pred = batch.future[None].repeat(k, 1, 1, 1)  # [K, N, T_f, 2]
    pred[-1] += 1.0
    ats = torch.full((k, 1), 0.9)  # [K, B]
    ats[-1] = -3.0
    zeros = torch.zeros(k, 2, 2)
    res = ScoreResult(d_pred=zeros, d_gt=zeros[0], r=zeros, ats=ats, fts=ats.clone(),
                      ats_mean_of_ratios=ats, fts_mean_of_ratios=ats)  # fmt: skip
    acc = ScoreAccumulator()
    acc.update(None, batch, pred, result=res)
    out = acc.compute()
    assert out["top1_recall_ats"] == 1.0 and out["top1_recall_fts"] == 1.0
    assert out["top5_recall_ats"] == 1.0 and out["top5_recall_fts"] == 1.0


def test_accumulator_sort_is_stable_for_many_tied_samples(monkeypatch):
    """With many equal scores an unstable sort may reorder them; the stable one keeps the
    drawn order, so the first-ranked sample is the first drawn."""
    import trajpref.score.scorer as scorer_mod

    seen = {}

    def spy(pred, batch, order_ats, order_fts, ks=(1, 5)):
        seen["ats"], seen["fts"] = order_ats, order_fts
        return {}

    monkeypatch.setattr(scorer_mod, "recall_hits", spy)
    k = 64
    ats = torch.zeros(k, 1)  # [K, B] every sample scores the same
    ats[-1] = -1.0
    zeros = torch.zeros(k, 1, 2)
    res = ScoreResult(d_pred=zeros, d_gt=zeros[0], r=zeros, ats=ats, fts=ats.clone(),
                      ats_mean_of_ratios=ats, fts_mean_of_ratios=ats)  # fmt: skip
    batch = _batch()
    ScoreAccumulator().update(None, batch, torch.zeros(k, 1, 2, 2), result=res)
    assert seen["ats"][:, 0].tolist() == list(range(k))
    assert seen["fts"][:, 0].tolist() == list(range(k))
