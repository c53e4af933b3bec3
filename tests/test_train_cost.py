"""benchmarks/train_cost.py: the warm probe times a second epoch and books the first one's extra
time once; estimates of other settings never overwrite the defaults' file."""

import pytest
from bench import load_benchmark


def test_a_warm_probe_times_the_second_epoch_and_books_the_first_ones_extra_time(tiny_cfg):
    cost = load_benchmark("train_cost")
    cold = cost.probe(tiny_cfg, "diffusion", None, steps=2, denoiser=None)
    warm = cost.probe(tiny_cfg, "diffusion", None, steps=2, denoiser=None, warm=True)
    assert "warmup_seconds" not in cold and warm["warmup_seconds"] >= 0.0
    for p in (cold, warm):
        assert p["rate"] > 0 and p["val_seconds"] > 0 and p["train_agents"] > 0


def test_evaluations_count_every_nth_epoch_and_the_last():
    cost = load_benchmark("train_cost")
    assert cost.evaluations(40, 5) == 8
    assert cost.evaluations(42, 5) == 9  # and once more after the last epoch


@pytest.mark.parametrize("flag", [["--set", "generator.epochs=80"], ["--warm"]])
def test_other_settings_into_the_defaults_file_are_refused_before_anything_is_timed(
    monkeypatch, capsys, flag
):
    cost = load_benchmark("train_cost")
    monkeypatch.setattr(cost, "estimate", lambda *a: pytest.fail("timed a stage"))
    monkeypatch.setattr("sys.argv", ["train_cost.py", "--datasets", "eth", *flag])
    with pytest.raises(SystemExit, match="name --out"):
        cost.main()


def test_the_printed_line_of_an_estimate_with_other_settings_names_only_the_stages():
    cost = load_benchmark("train_cost")
    entry = {"denoiser": {"minutes": 7.5}, "generator": {"minutes": 26.6}, "minutes": 34.1,
             "settings": {"set": ["data.reverse=true"], "warm": False}}  # fmt: skip
    assert cost._line(entry) == "D 7.5 + G 26.6 = 34.1 min"
