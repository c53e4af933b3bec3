"""benchmarks/planner_latency.py and the README table that update_readme.py makes of it."""

import json
from types import SimpleNamespace

import numpy as np
from bench import load_benchmark


def test_each_call_keeps_its_median_after_a_warm_up_round(monkeypatch):
    latency = load_benchmark("planner_latency")
    clock = [0.0]
    monkeypatch.setattr(latency.time, "perf_counter", lambda: clock[0])
    costs = {"a": iter([5.0, 0.001, 0.003, 0.002]), "b": iter([9.0, 0.010, 0.030, 0.020])}

    def call(name):  # advances the fake clock by its next cost (seconds)
        def run():
            clock[0] += next(costs[name])

        return run

    ms = latency.median_ms({"a": call("a"), "b": call("b")}, rounds=3)
    assert ms == {"a": 2.0, "b": 20.0}  # the warm-up's 5 s and 9 s left out


def test_scenes_are_the_first_with_enough_agents_cut_to_p():
    latency = load_benchmark("planner_latency")
    scenes = [SimpleNamespace(num_agents=n, history=np.full((n, 8, 2), float(n)))
              for n in (2, 5, 9)]  # fmt: skip
    data = SimpleNamespace(scenes=scenes, info=SimpleNamespace(name="x", split="val"))
    got = latency.scene_histories(data, [1, 3, 9])
    assert {p: h.shape for p, h in got.items()} == {1: (1, 8, 2), 3: (3, 8, 2), 9: (9, 8, 2)}
    assert got[1][0, 0, 0] == 2 and got[3][0, 0, 0] == 5 and got[9][0, 0, 0] == 9


def test_the_readme_table_gives_each_call_and_the_ratios(tmp_path):
    update = load_benchmark("update_readme")
    assert update.planner_table(tmp_path / "none.json") is None
    row = {"predict_scene": 2.0, "rank_34": 30.0, "rank_1": 2.5, "select_default": 12.0,
           "chosen": 31.0, "chosen_cheap": 3.0, "facility": 0.5}  # fmt: skip
    rec = {"dataset": "zara1", "split": "val", "samples": 20, "keep": 5, "calls": 15,
           "rows": [{"agents": 1, **row}, {"agents": 7, **row, "predict_scene": 3.0}],
           "command": "python benchmarks/planner_latency.py", "date": "2026-12-06",
           "machine": "m"}  # fmt: skip
    path = tmp_path / "planner_latency_zara1.json"
    path.write_text(json.dumps(rec))
    table = update.planner_table(path)
    lines = table.splitlines()
    assert lines[2] == "| 1 | 2.0 | 30.0 | 2.5 | 12.0 | 31.0 | 3.0 | 0.5 |"
    assert lines[3].startswith("| 7 | 3.0 | 30.0 |")
    assert "costs 10-15x the prediction" in table  # 30 / 3 and 30 / 2
    assert "cheap chosen setting 1.0-1.5x" in table


def test_the_calls_and_the_readme_columns_are_the_ones_of_calls(monkeypatch):
    """``timed_calls`` keys each call by ``CALLS`` (the one list of keys), in its order, each
    key on the call it names, and the README's columns read those keys."""
    latency = load_benchmark("planner_latency")
    monkeypatch.setattr(latency, "predict_scene", lambda model, history, k: ("predict", k))
    monkeypatch.setattr(latency, "rank_samples", lambda scorer, h, s: ("rank", scorer))
    monkeypatch.setattr(latency, "select_for_scene", lambda scorer, h, s, cfg: ("select", cfg))
    monkeypatch.setattr(latency, "chosen_selection", lambda name, keep, cheap=False:
                        ("cheap" if cheap else "chosen", name))  # fmt: skip
    monkeypatch.setattr(latency, "SelectionConfig", lambda **kw: kw)
    scorer = SimpleNamespace(with_steps=lambda steps: ("scorer", steps))
    calls = latency.timed_calls("model", scorer, np.zeros((1, 8, 2)), "zara1")
    assert tuple(calls) == latency.CALLS
    got = {name: call() for name, call in calls.items()}
    assert got == {
        "predict_scene": ("predict", 20),
        "rank_34": ("rank", scorer),
        "rank_1": ("rank", ("scorer", [0])),
        "select_default": ("select", {"keep": 5}),
        "chosen": ("select", ("chosen", "zara1/generator")),
        "chosen_cheap": ("select", ("cheap", "zara1/generator")),
        "facility": ("select", {"keep": 5, "method": "facility"}),
    }
    update = load_benchmark("update_readme")
    assert tuple(key for key, _ in update.PLANNER_COLUMNS) == latency.CALLS
