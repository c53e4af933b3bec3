"""benchmarks/selection.py: options that select a validation split refuse a test split; the
rows a run writes."""

import json
import sys
from pathlib import Path

import pytest
from bench import load_benchmark


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--split", "test", "--holdout-scene", "biwi_hotel"], "--holdout-scene"),
        (["--split", "val", "--holdout-scene", ""], "--holdout-scene"),
        (["--split", "test", "--stretch", "1.6"], "--stretch"),
    ],
)
def test_validation_only_options_refuse_before_reading_anything(argv, message, monkeypatch, capsys):
    sel = load_benchmark("selection")
    monkeypatch.setattr(sys, "argv", ["selection.py", "--dataset", "eth", *argv])
    with pytest.raises(SystemExit) as exc:
        sel.main()
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def _run(tmp_path, monkeypatch, tiny_run, walks, *extra) -> Path:
    """Run the script on the test split of the tiny fixture; its results folder."""
    sel = load_benchmark("selection")
    monkeypatch.setattr(sel, "ROOT", tmp_path)
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    argv = ["selection.py", "--dataset", str(walks), "--model",
            str(tiny_run / "generator.safetensors"), "--split", "test", "--samples", "4",
            "--keep", "2", "--drop", "0.3", "--temperature", "2", "--score-every", "3",
            *extra]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    sel.main()
    return results


def _test_rows(tmp_path, monkeypatch, tiny_run, walks, *extra) -> tuple[list[dict], dict]:
    """The rows and the meta record of one run (``_run``)."""
    results = _run(tmp_path, monkeypatch, tiny_run, walks, *extra)
    (rows_file,) = results.glob("select_*.json")
    (meta_file,) = (results / "meta").glob("*.json")
    return json.loads(rows_file.read_text()), json.loads(meta_file.read_text())


def test_speed_normalised_scoring_names_the_score_rows_only(tmp_path, monkeypatch, tiny_run, walks):
    extra = ["--methods", "kmeans", "score-facility", "--speed-norm", "0.5"]
    rows, _ = _test_rows(tmp_path, monkeypatch, tiny_run, walks, *extra)
    methods = {r["method"]: r["uses_score"] for r in rows}
    assert methods == {"select-kmeans": False, "select-score-facility-d30-t2-sn50": True}


def test_trust_quantile_gates_the_score_rows_only(tmp_path, monkeypatch, tiny_run, walks):
    rows, meta = _test_rows(tmp_path, monkeypatch, tiny_run, walks,
                            "--methods", "facility", "score-facility", "--bandwidth", "0.5",
                            "--trust-quantile", "0.0")  # fmt: skip
    rows = {r["method"]: r for r in rows}
    assert set(rows) == {"select-facility", "select-score-facility-d30-t2-gate"}
    assert rows["select-score-facility-d30-t2-gate"]["uses_score"] is True
    # at the 0-quantile nearly every walker is faster than the slowest: the gated rows are
    # the score-free facility selection (same bandwidth)
    gated, free = rows["select-score-facility-d30-t2-gate"], rows["select-facility"]
    assert gated["min_fde"] == pytest.approx(free["min_fde"], rel=0.05)
    assert meta["trust_quantile"] == 0.0 and meta["trust_speed"] >= 0.0


def test_pace_bins_split_the_agents_and_write_no_rows(tmp_path, monkeypatch, tiny_run, walks):
    extra = ["--methods", "kmeans", "score-kmeans", "--pace-bins", "0.5", "--tag", "pace"]
    results = _run(tmp_path, monkeypatch, tiny_run, walks, *extra)
    assert not list(results.glob("select_*.json"))  # a diagnosis: no result rows
    meta = json.loads(next((results / "meta").glob("*.json")).read_text())
    pace = meta["pace_bins"]
    assert len(pace["bins"]) == 2 and min(pace["agents"]) > 0
    # the agent-weighted mean of the bins is the overall per-agent minFDE
    for row in meta["rows"]:
        per_bin = pace["min_fde"][f"{row['method']}@{row['samples']}"]
        total = sum(v * n for v, n in zip(per_bin, pace["agents"], strict=True)) / sum(
            pace["agents"]
        )
        assert total == pytest.approx(row["min_fde"], rel=1e-5)


def test_the_pace_gate_reads_the_training_split_the_model_was_trained_on():
    """``robo`` has no public training split; its models train on ``robo-sim``, and the gate's
    quantile must come from there (it failed with an error before)."""
    sel = load_benchmark("selection")
    root = Path(__file__).resolve().parent.parent / "models"
    assert sel.training_dataset(root / "robo" / "generator.safetensors") == "robo-sim"
    assert sel.training_dataset(root / "robo-mix" / "generator.safetensors") == "robo-mix"
    assert sel.training_dataset(root / "zara1" / "generator.safetensors") == "zara1"


def test_rows_name_their_score_steps_and_bandwidth_when_not_the_papers(
    tmp_path, monkeypatch, tiny_run, walks
):
    rows, meta = _test_rows(tmp_path, monkeypatch, tiny_run, walks,
                            "--methods", "facility", "score-facility", "--bandwidth", "1",
                            "--score-every", "50")  # fmt: skip
    from trajpref.models import checkpoint as ckpt
    from trajpref.score.scorer import score_timesteps

    model = ckpt.load_predictor(tiny_run / "generator.safetensors", sampler="leapfrog")
    steps = len(score_timesteps(model.schedule.num_steps, 50))
    methods = {r["method"]: r["uses_score"] for r in rows}
    # the number of score steps and the bandwidth name the row; the score-free rows as before
    assert methods == {"select-facility": False,
                       f"select-score-facility-d30-t2-b1-s{steps}": True}  # fmt: skip
    assert meta["score_every"] == 50


def test_rows_scored_from_a_later_step_name_it(tmp_path, monkeypatch, tiny_run, walks):
    rows, meta = _test_rows(tmp_path, monkeypatch, tiny_run, walks,
                            "--methods", "facility", "score-facility", "--bandwidth", "1",
                            "--score-every", "3", "--score-from", "4")  # fmt: skip
    methods = {r["method"] for r in rows}
    # the paper's spacing, but not its chain (the tiny run's 10 steps: 4, 7): the step count
    # and the first step name the row
    assert methods == {"select-facility", "select-score-facility-d30-t2-b1-s2f4"}
    assert meta["score_from"] == 4 and "from step 4" in meta["header"]


def test_another_scorer_names_the_score_rows_and_the_same_denoiser_scores_alike(
    tmp_path, monkeypatch, tiny_run, walks
):
    extra = ["--methods", "kmeans", "score-facility", "--trust-quantile", "0.5"]
    own, _ = _test_rows(tmp_path / "own", monkeypatch, tiny_run, walks, *extra)
    den = str(tiny_run / "denoiser.safetensors")  # the generator's own denoiser, by path
    other, meta = _test_rows(tmp_path / "other", monkeypatch, tiny_run, walks, *extra,
                             "--scorer", den)  # fmt: skip
    own = {r["method"]: r["min_fde"] for r in own}
    other = {r["method"]: r["min_fde"] for r in other}
    label = tiny_run.name
    assert set(other) == {"select-kmeans", f"select-score-facility-d30-t2-scorer-{label}-gate"}
    assert other["select-kmeans"] == own["select-kmeans"]
    assert other[f"select-score-facility-d30-t2-scorer-{label}-gate"] == pytest.approx(
        own["select-score-facility-d30-t2-gate"])  # fmt: skip
    assert meta["scorer"] == den


def test_a_scorers_label_is_its_run_folder_or_its_published_name():
    sel = load_benchmark("selection")
    assert sel.scorer_label("runs/pace/eth-den/denoiser.safetensors") == "eth-den"
    assert sel.scorer_label("eth/denoiser") == "eth-denoiser"


def test_a_scorers_gate_reads_its_training_windows_with_their_paced_copy(tmp_path, monkeypatch):
    from synthetic import write_dataset

    from trajpref.data import ReadOptions, load_dataset

    sel = load_benchmark("selection")
    root = write_dataset(tmp_path / "long", frames=44)  # long enough for windows at step 2
    data = {"dataset": str(root), "extra_time_step": 2.0}
    monkeypatch.setattr(sel.ckpt, "resolve_path", lambda p: p)
    monkeypatch.setattr(sel, "read_checkpoint_header", lambda p: {"config": {"data": data}})
    plain = load_dataset(str(root), "train")
    paced = load_dataset(str(root), "train", options=ReadOptions(time_step=2.0))
    both = sel.scorer_training_split("den.safetensors", None)
    assert both.num_agents == plain.num_agents + paced.num_agents > plain.num_agents
    data["extra_time_step"] = 0.0  # a scorer trained at one pace: its split as read
    assert sel.scorer_training_split("den.safetensors", None).num_agents == plain.num_agents


def test_which_methods_sweep_the_drop_follows_dropping_not_their_names(monkeypatch):
    """A method drops the worst-scored first when it is in ``DROPPING``, whatever its name
    (``score.selection``: a name's prefix means nothing): the sweep and the row names follow
    that list; they had followed the ``score-`` prefix."""
    import argparse

    sel = load_benchmark("selection")
    monkeypatch.setattr(sel, "DROPPING", ("facility",))  # as if facility dropped first
    args = argparse.Namespace(methods=["facility", "score-kmeans"], keep=[5], drop=[0.2, 0.5],
                              temperature=[2.0], free_bandwidth=None, bandwidth=1.0,
                              final=False)  # fmt: skip
    drops = {(c.method, c.drop) for c in sel.settings(args)}
    assert drops == {("facility", 0.2), ("facility", 0.5), ("score-kmeans", 0.0)}
    named = {sel.name_of(c) for c in sel.settings(args)}
    assert "select-facility-d20" in named and "select-score-kmeans" in named


def test_a_scorers_gate_reads_its_training_windows_at_its_own_lengths(tmp_path, monkeypatch):
    """A denoiser trained on 6 + 16 windows: its training split was read at 8 + 12."""
    from synthetic import write_dataset

    sel = load_benchmark("selection")
    root = write_dataset(tmp_path / "long", frames=40)
    header = {"config": {"data": {"dataset": str(root)}, "model": {"t_hist": 6, "t_fut": 16}}}
    monkeypatch.setattr(sel.ckpt, "resolve_path", lambda p: p)
    monkeypatch.setattr(sel, "read_checkpoint_header", lambda p: header)
    split = sel.scorer_training_split("den.safetensors", None)
    assert (split.info.t_hist, split.info.t_fut) == (6, 16)
    assert split.scenes[0].future.shape[1] == 16
