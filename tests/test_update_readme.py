"""benchmarks/update_readme.py: which rows the README's results table keeps."""

from pathlib import Path

from bench import load_benchmark

ROOT = Path(__file__).resolve().parent.parent


def _module():
    module = load_benchmark("update_readme")
    return module


def test_old_equal_budget_rows_stay_only_until_a_newer_start_has_rows():
    keep = _module()._latest_equal_budget
    old = {("robo", "control-ancestral"), ("robo", "rlhf-ancestral"),
           ("robo", "pretrained-ancestral"), ("robo", "rlhf-res-steps36-ancestral")}  # fmt: skip
    assert keep({"dataset": "robo", "method": "rlhf-ancestral"}, old)
    assert keep({"dataset": "robo", "method": "pretrained-ancestral"}, old)
    assert not keep({"dataset": "robo", "method": "rlhf-res-steps36-ancestral"}, old)  # ablation
    newer = old | {("robo", "control")}
    assert not keep({"dataset": "robo", "method": "rlhf-ancestral"}, newer)
    # a dataset that never had the table keeps no old rows
    assert not keep({"dataset": "hotel", "method": "pretrained-ancestral"},
                    {("hotel", "pretrained-ancestral")})  # fmt: skip
