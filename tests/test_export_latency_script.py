"""benchmarks/export_latency.py: the exported program beside predict_scene on real scenes."""

import json

from bench import load_benchmark


def test_the_record_has_each_size_both_medians_and_no_difference(tmp_path, data_root):
    latency = load_benchmark("export_latency")
    record = latency.main(["--dataset", "zara1", "--sizes", "1", "3", "--calls", "1",
                           "--data-root", str(data_root), "--out-dir", str(tmp_path)])  # fmt: skip
    rows = json.loads((tmp_path / "export_latency_zara1.json").read_text())["rows"]
    assert rows == record["rows"] and [r["agents"] for r in rows] == [1, 3]
    for row in rows:
        assert row["predict_scene"] > 0 and row["exported"] > 0 and row["ratio"] > 0
        assert row["max_difference"] == 0.0  # the very futures, not nearly
        assert row["rank_exported"] > 0 and row["same_order"] is True
        assert row["rank_max_relative"] == 0.0  # summed as rank_samples sums: the same bits
    assert {"machine", "threads", "date", "command"} <= set(record)
