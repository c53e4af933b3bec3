"""benchmarks/update_readme.py: which rows the README's results table keeps."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _module():
    spec = importlib.util.spec_from_file_location(
        "bench_update_readme", ROOT / "benchmarks" / "update_readme.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
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
