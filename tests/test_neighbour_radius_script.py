"""benchmarks/neighbour_radius.py: the rule's choice of a radius."""

from bench import load_benchmark


def _row(ade: float, fde: float) -> dict:
    return {"min_ade": ade, "min_fde": fde}


def test_the_smallest_radius_within_the_tolerance_on_every_dataset_is_chosen():
    script = load_benchmark("neighbour_radius")
    table = {
        "a": {"none": _row(0.20, 0.30), "4.0": _row(0.21, 0.31), "8.0": _row(0.2009, 0.3012),
              "12.0": _row(0.20, 0.30)},
        "b": {"none": _row(0.10, 0.20), "4.0": _row(0.10, 0.20), "8.0": _row(0.1004, 0.2011),
              "12.0": _row(0.099, 0.199)},
    }  # fmt: skip
    assert script.chosen_radius(table, [12.0, 8.0, 4.0], 0.005) == 12.0  # b's FDE at 8: +0.55 %
    assert script.chosen_radius(table, [4.0, 8.0, 12.0], 0.006) == 8.0
    assert script.chosen_radius(table, [4.0], 0.005) is None  # a at 4 m: +5 %
