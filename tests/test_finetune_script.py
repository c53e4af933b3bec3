"""benchmarks/finetune.py: a run folder is never resumed or reused from another start."""

import json
import shutil
from pathlib import Path

import pytest
from bench import load_benchmark
from helpers import METRICS, _files, _pretrain

from trajpref.rl.presets import equal_budget_args

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture
def ft(monkeypatch):
    module = load_benchmark("finetune")
    hashes = {"a.safetensors": "aaaa", "b.safetensors": "bbbb"}
    monkeypatch.setattr(module.ckpt, "load", lambda path: {"hash": hashes[Path(path).name]})
    return module


def test_a_run_folder_remembers_its_start_and_refuses_another(ft, tmp_path):
    run = tmp_path / "zara1-rlhf-s0"
    ft.check_start(run, tmp_path / "a.safetensors")  # a new run: records its start
    (run / "finetune_last.pt").write_text("state")
    ft.check_start(run, tmp_path / "a.safetensors")  # resuming from the same start is fine
    with pytest.raises(SystemExit, match="was started from"):
        ft.check_start(run, tmp_path / "b.safetensors")


def test_an_unrecorded_old_run_folder_is_not_reused(ft, tmp_path):
    run = tmp_path / "zara1-rlhf-s0"
    run.mkdir()
    (run / "finetune.safetensors").write_text("old model")
    with pytest.raises(SystemExit, match="no record of its start"):
        ft.check_start(run, tmp_path / "a.safetensors")


# ---- review of walkthrough 66: --skip-done compares the budget -------------------------------


class _WouldRun(Exception):
    """Raised where finetune.py starts its first job (reading the test split)."""


def _skip_done(ft, tmp_path, monkeypatch, rows: list[dict], *sets: str) -> list[str]:
    """finetune.py --skip-done over ``rows``: ``["ran"]`` when it would start a job."""
    monkeypatch.setattr(ft, "ROOT", tmp_path)
    (tmp_path / "models" / "walks").mkdir(parents=True, exist_ok=True)
    (tmp_path / "models" / "walks" / "generator.safetensors").write_text("start")
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True, exist_ok=True)
    (results / "finetune_walks.json").write_text(json.dumps(rows))

    def read_the_test_split(*args, **kwargs):
        raise _WouldRun

    monkeypatch.setattr(ft, "load_dataset", read_the_test_split)
    monkeypatch.setattr("sys.argv", ["finetune.py", "--dataset", "walks", "--methods", "control",
                                     "rlhf", "--seeds", "0", "--skip-done",
                                     "--no-start-validation",
                                     *[w for s in sets for w in ("--set", s)]])  # fmt: skip
    try:
        ft.main()
    except _WouldRun:
        return ["ran"]
    return []


def test_skip_done_keeps_only_the_rows_of_the_budget_asked_for(ft, tmp_path, monkeypatch,
                                                                capsys):  # fmt: skip
    """``reproduce.py`` full mode with ``--minutes 2`` kept the 4-minute rows: ``--skip-done``
    matched rows on method and seed alone. It now compares the budget read from each row's
    command (equal_budget.py's ``row_budget``) with this invocation's ``--set``s."""
    four = equal_budget_args(4.0, 4, None)  # the published budget
    two = equal_budget_args(2.0, 4, None)
    command = " ".join(["python", "benchmarks/finetune.py", "--seeds", "0", "--skip-done", *four])
    rows = [{"method": m, "seed": 0, "command": command} for m in ("control", "rlhf")]
    sets = [b for a, b in zip(two, two[1:], strict=False) if a == "--set"]
    assert _skip_done(ft, tmp_path, monkeypatch, rows, *sets) == ["ran"]  # 2 min: to run
    sets4 = [b for a, b in zip(four, four[1:], strict=False) if a == "--set"]
    assert _skip_done(ft, tmp_path, monkeypatch, rows, *sets4) == []  # 4 min: done
    assert "every requested row is already in" in capsys.readouterr().out
    # rows and a run whose commands name no budget (the main table): done, as before
    plain = [{"method": m, "seed": 0, "command": "python x.py"} for m in ("control", "rlhf")]
    assert _skip_done(ft, tmp_path, monkeypatch, plain) == []
    assert _skip_done(ft, tmp_path, monkeypatch, plain, "finetune.max_minutes=2.0") == ["ran"]


# ---- a run folder of other settings is neither resumed nor reused ------------------------------


def _saved_run(tmp_path: Path, *sets: str) -> tuple[Path, Path]:
    """A run folder as the fine-tuning stage leaves it (``finetune_config.yaml``, its start's
    record) under ``tmp_path`` posing as the repository, from zara1's published generator."""
    from trajpref.config import save_config
    from trajpref.rl.presets import finetune_config

    start = tmp_path / "models" / "zara1" / "generator.safetensors"
    start.parent.mkdir(parents=True)
    for name in ("generator.safetensors", "denoiser.safetensors"):  # it names its denoiser
        (start.parent / name).symlink_to(ROOT / "models" / "zara1" / name)
    run = tmp_path / "runs" / "zara1-control-s0"
    save_config(finetune_config(str(start), "control", None, None, list(sets), 0),
                tmp_path / "cfg.yaml")  # fmt: skip
    return start, run


def test_a_run_folder_of_another_budget_or_setting_is_refused(tmp_path):
    ft = load_benchmark("finetune")
    from trajpref.config import load_config, save_config
    from trajpref.rl.presets import finetune_config

    start, run = _saved_run(tmp_path)
    ft.check_start(run, start)
    saved = load_config(tmp_path / "cfg.yaml")
    save_config(saved, run / "finetune_config.yaml")
    ft.check_settings(run, saved)  # the same settings: resumed or reused
    kept = finetune_config(str(start), "control", None, None, ["finetune.keep_checkpoints=true"], 0)
    ft.check_settings(run, kept)  # what it keeps on disk may differ
    other = finetune_config(str(start), "control", None, None, ["finetune.max_minutes=8"], 0)
    with pytest.raises(SystemExit, match=r"finetune\.max_minutes: None -> 8\.0.*--tag"):
        ft.check_settings(run, other)
    seed = finetune_config(str(start), "control", None, None, None, 1)
    with pytest.raises(SystemExit, match=r"other settings than these \(seed: 0 -> 1\)"):
        ft.check_settings(run, seed)
    ft.check_settings(tmp_path / "runs" / "new", other)  # no run started there: nothing to check


def test_finetune_py_refuses_a_finished_run_of_another_learning_rate(tmp_path, monkeypatch):
    """A finished run folder was taken as this invocation's row whatever its settings: a
    control fine-tuned at another learning rate (or under another budget) gave the row of
    this one. finetune.py now compares the folder's resolved config before it resumes or
    reuses it."""
    ft = load_benchmark("finetune")
    from trajpref.config import load_config, save_config

    start, run = _saved_run(tmp_path, "finetune.lr=3e-5")
    ft.check_start(run, start)
    save_config(load_config(tmp_path / "cfg.yaml"), run / "finetune_config.yaml")
    (run / "finetune_last.pt").write_text("a finished state")

    def reused(*args, **kwargs):
        raise AssertionError("the run folder was resumed or reused")

    monkeypatch.setattr(ft, "ROOT", tmp_path)
    monkeypatch.setattr(ft, "load_dataset", lambda *a, **k: None)
    monkeypatch.setattr(ft.TrajectoryScorer, "from_checkpoint", lambda *a, **k: None)
    monkeypatch.setattr(ft, "finished", reused)
    monkeypatch.setattr(ft, "finetune", reused)
    monkeypatch.setattr("sys.argv", ["finetune.py", "--dataset", "zara1", "--methods", "control",
                                     "--seeds", "0", "--no-start-validation"])  # fmt: skip
    with pytest.raises(SystemExit, match=r"finetune\.lr: 3e-05 -> "):
        ft.main()


def test_a_run_folder_of_the_sda_reward_is_its_own_settings(tmp_path):
    """The review of 34b5da7: the stage writes a config of its own for the sda reward (no
    scaled scenes, ``rl.presets.own_reward_data``), which the check compared with the
    invocation's and refused on robo (scale 0.8-1.25): every resume of the published rlhf-sda
    runs. It now compares with what the stage writes (``train.run.finetune_run_config``)."""
    ft = load_benchmark("finetune")
    from trajpref.config import save_config
    from trajpref.rl.presets import finetune_config

    start = tmp_path / "models" / "robo" / "generator.safetensors"
    start.parent.mkdir(parents=True)
    for name in ("generator.safetensors", "denoiser.safetensors"):
        (start.parent / name).symlink_to(ROOT / "models" / "robo" / name)
    cfg = finetune_config(str(start), "rlhf", None, None, ["finetune.reward=sda"], 0)
    assert (cfg.data.scale_min, cfg.data.scale_max) != (1.0, 1.0)  # robo trains scaled
    run = tmp_path / "runs" / "robo-rlhf-s0-sda"
    ft.check_start(run, start)
    save_config(ft.finetune_run_config(cfg)[0], run / "finetune_config.yaml")  # as written
    ft.check_settings(run, cfg)  # its own folder: resumed or reused
    other = finetune_config(str(start), "rlhf", None, None, ["finetune.reward=sda",
                                                              "finetune.lr=1e-5"], 0)  # fmt: skip
    with pytest.raises(SystemExit, match=r"finetune\.lr"):
        ft.check_settings(run, other)


# Walkthrough 67, fixer F9: ``reproduce.py --out DIR`` in full mode left its training in the
# repository (finetune.py and pretrain.py wrote ``runs/``, ``benchmarks/results/`` and
# ``models/`` of the repository whatever the folder). Both scripts now take ``--runs``,
# ``--results`` and ``--models``, and reproduce.py passes them under ``--out``.


# ----------------------------------------------------------------------------- finetune.py


def _finetune(monkeypatch, root: Path, tiny_run: Path, *argv: str):
    """finetune.py under ``root`` posing as the repository; the training, the test split and
    the evaluation stand in (the run's model is the tiny run's generator)."""
    ft = load_benchmark("finetune")
    monkeypatch.setattr(ft, "ROOT", root)

    def fake_finetune(cfg, start, run, *args, **kwargs):
        shutil.copy(tiny_run / "generator.safetensors", run / "finetune.safetensors")
        return {"train_seconds": 1.0, "steps": 2}

    class Stage:
        def validate(self):
            return {"min_ade": 0.5}

    monkeypatch.setattr(ft, "finetune", fake_finetune)
    monkeypatch.setattr(ft, "load_dataset", lambda *a, **k: None)
    monkeypatch.setattr(ft, "build_finetune_stage", lambda *a, **k: Stage())
    monkeypatch.setattr(ft.TrajectoryScorer, "from_checkpoint", lambda *a, **k: None)
    monkeypatch.setattr(ft.ckpt, "load_predictor", lambda *a, **k: None)
    monkeypatch.setattr(ft, "evaluate", lambda *a, **k: METRICS)
    monkeypatch.setattr("sys.argv", ["finetune.py", "--dataset", "walks", "--methods", "rlhf",
                                     "--seeds", "0", *argv])  # fmt: skip
    ft.main()
    return ft


def test_finetune_writes_its_run_rows_and_start_record_where_it_is_told(
    repo, tiny_run, tmp_path, monkeypatch
):
    """HEAD's finetune.py has no --runs/--results (argparse exits): its runs and rows always
    went into the repository."""
    before = _files(repo)
    out = tmp_path / "out"
    _finetune(monkeypatch, repo, tiny_run, "--runs", str(out / "runs"), "--results",
              str(out / "results"), "--models", str(repo / "models"))  # fmt: skip
    assert _files(repo) == before  # the repository as it was
    assert not (repo / "runs").exists()
    run = out / "runs" / "walks-rlhf-s0"
    (row,) = json.loads((out / "results" / "finetune_walks.json").read_text())
    assert row["checkpoint"] == str(run / "finetune.safetensors")  # outside: absolute
    assert (repo / row["checkpoint"]).is_file()  # as readers join it to the root
    assert json.loads((run / "start.json").read_text())["start"] == (
        "models/walks/generator.safetensors")  # fmt: skip
    meta = json.loads((out / "results" / "meta" / "finetune_start_walks.json").read_text())
    assert meta["start"] == "models/walks/generator.safetensors"


def test_finetune_without_the_options_writes_todays_rows_in_the_repository(
    repo, tiny_run, monkeypatch
):
    _finetune(monkeypatch, repo, tiny_run, "--no-start-validation")
    (row,) = json.loads((repo / "benchmarks" / "results" / "finetune_walks.json").read_text())
    assert row["checkpoint"] == "runs/walks-rlhf-s0/finetune.safetensors"  # as before
    assert (repo / "runs" / "walks-rlhf-s0" / "start.json").is_file()


def test_finetune_reads_its_start_from_models_and_publishes_only_where_told(
    repo, tiny_run, tmp_path, monkeypatch, capsys
):
    out = tmp_path / "out"
    elsewhere = ["--runs", str(out / "runs"), "--results", str(out / "results")]
    with pytest.raises(SystemExit):  # would publish into the repository's models/
        _finetune(monkeypatch, repo, tiny_run, *elsewhere, "--publish", "--no-start-validation")
    assert "--models missing" in capsys.readouterr().err
    models = out / "models"
    shutil.copytree(repo / "models", models)
    (repo / "models" / "walks" / "generator.safetensors").unlink()  # read from --models only
    _finetune(monkeypatch, repo, tiny_run, *elsewhere, "--models", str(models), "--publish",
              "--no-start-validation")  # fmt: skip
    assert (models / "walks" / "rlhf.safetensors").is_file()
    assert not (repo / "models" / "walks" / "rlhf.safetensors").exists()


# ----------------------------------------------------------------------------- pretrain.py


# ----------------------------------------------------- --runs, --results, --models: all or none
# (walkthrough 67 review: ``--models`` alone still wrote the repository's rows and start
# records, naming a start or a checkpoint outside it)


SOME_BUT_NOT_ALL = [("models",), ("runs",), ("results",), ("runs", "models"), ("results", "models")]


def _options(out: Path, names: tuple[str, ...]) -> list[str]:
    return [arg for name in names for arg in (f"--{name}", str(out / name))]


@pytest.mark.parametrize("names", SOME_BUT_NOT_ALL, ids="+".join)
@pytest.mark.parametrize("script", ["finetune", "pretrain"])
def test_some_but_not_all_of_the_three_is_refused_naming_the_missing(
    script, names, repo, tiny_run, tmp_path, monkeypatch, capsys
):
    """HEAD's finetune.py with ``--models`` alone read the start from there and wrote the
    repository's meta/finetune_start_walks.json (an absolute start) and finetune_walks.json
    (rows trained from an unpublished start); with ``--runs`` or ``--results`` alone it read
    the repository's models (refused now too: one rule, the three or none)."""
    out = tmp_path / "out"
    shutil.copytree(tiny_run, out / "runs" / "walks")
    shutil.copytree(repo / "models", out / "models")
    before = _files(repo)
    with pytest.raises(SystemExit) as exit_:
        if script == "finetune":
            _finetune(monkeypatch, repo, tiny_run, *_options(out, names))
        else:
            _pretrain(monkeypatch, repo, *_options(out, names))
    assert exit_.value.code == 2
    missing = [f"--{n}" for n in ("runs", "results", "models") if n not in names]
    assert f"{' and '.join(missing)} missing" in capsys.readouterr().err
    assert _files(repo) == before


def test_a_folder_reached_through_dotdot_is_recorded_absolute(repo, tiny_run, monkeypatch):
    """``shown`` (now benchmarks/paths.py, once a copy in each script) took ``repo/../out`` for
    a path inside the repository and recorded ``../out/...``."""
    out = repo / ".." / "out"
    _finetune(monkeypatch, repo, tiny_run, "--runs", str(out / "runs"), "--results",
              str(out / "results"), "--models", str(repo / "models"))  # fmt: skip
    (row,) = json.loads((out / "results" / "finetune_walks.json").read_text())
    assert row["checkpoint"] == str(repo.parent / "out" / "runs" / "walks-rlhf-s0"
                                    / "finetune.safetensors")  # fmt: skip
