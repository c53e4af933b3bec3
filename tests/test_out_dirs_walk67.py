"""Walkthrough 67, fixer F9: ``reproduce.py --out DIR`` in full mode left its training in the
repository (finetune.py and pretrain.py wrote ``runs/``, ``benchmarks/results/`` and
``models/`` of the repository whatever the folder). Both scripts now take ``--runs``,
``--results`` and ``--models``, and reproduce.py passes them under ``--out``."""

import json
import shutil
from pathlib import Path

import pytest
from bench import load_benchmark

from trajpref.models import checkpoint
from trajpref.results import make_row, write_rows

METRICS = dict.fromkeys(("min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "max_ats",
                         "max_fts", "top1_recall_ats", "top5_recall_ats"), 0.5)  # fmt: skip


def _files(*folders: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for f in folders if f.is_dir() for p in f.rglob("*") if p.is_file()}


@pytest.fixture
def repo(tiny_run, tmp_path):
    """A repository of one published dataset, ``walks`` (the tiny run's generator)."""
    root = tmp_path / "repo"
    checkpoint.publish(tiny_run / "generator.safetensors",
                       root / "models" / "walks" / "generator.safetensors")  # fmt: skip
    (root / "benchmarks" / "results").mkdir(parents=True)
    return root


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


def _pretrain(monkeypatch, root: Path, *argv: str):
    pre = load_benchmark("pretrain")
    monkeypatch.setattr(pre, "ROOT", root)
    monkeypatch.setattr(pre, "load_dataset", lambda *a, **k: None)
    monkeypatch.setattr(pre, "time_predictors", lambda *a, **k: {"leapfrog": 1.0, "full": 9.0})
    monkeypatch.setattr(pre, "evaluate", lambda *a, **k: METRICS)
    monkeypatch.setattr("sys.argv", ["pretrain.py", "--dataset", "walks", "--no-full-eval",
                                     *argv])  # fmt: skip
    pre.main()


def test_pretrain_writes_its_rows_meta_and_models_where_it_is_told(
    repo, tiny_run, tmp_path, monkeypatch, capsys
):
    """HEAD's pretrain.py has no --runs/--results/--models: it published into the
    repository's models/ and wrote its rows there."""
    out = tmp_path / "out"
    shutil.copytree(tiny_run, out / "runs" / "walks")
    before = _files(repo)
    elsewhere = ["--runs", str(out / "runs"), "--results", str(out / "results")]
    with pytest.raises(SystemExit):  # it publishes: not into the repository's models/
        _pretrain(monkeypatch, repo, *elsewhere)
    assert "--models missing" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # names the repository's commits
        _pretrain(monkeypatch, repo, *elsewhere, "--models", str(out / "models"),
                  "--keep-replaced", "old")  # fmt: skip
    assert "--keep-replaced keeps a row of the repository's" in capsys.readouterr().err
    _pretrain(monkeypatch, repo, *elsewhere, "--models", str(out / "models"))
    assert _files(repo) == before
    published = out / "models" / "walks" / "generator.safetensors"
    assert published.is_file() and (published.parent / "denoiser.safetensors").is_file()
    (row,) = json.loads((out / "results" / "pretrained_walks.json").read_text())
    assert row["checkpoint"] == str(published)
    assert (out / "results" / "meta" / "pretrained_walks.json").is_file()


# ----------------------------------------------------------------------------- reproduce.py


reproduce = load_benchmark("reproduce")


@pytest.fixture
def setup(repo, walks, tmp_path):
    (tmp_path / "configs").mkdir()
    return reproduce.Setup(
        models=repo / "models", results=repo / "benchmarks" / "results",
        configs=tmp_path / "configs", doc=repo / "docs" / "reproduce.md",
        logs=repo / "runs" / "logs", sources={"walks": str(walks), "bare": str(walks)},
    )  # fmt: skip


def _option(cmd: list[str], name: str) -> str | None:
    return cmd[cmd.index(name) + 1] if name in cmd else None


def test_full_mode_with_out_trains_into_the_folder_and_reads_its_rows_from_there(
    setup, repo, tmp_path, monkeypatch
):
    """HEAD passed no folders: the fine-tuning wrote runs/ and rows in the repository, and
    the tables read the repository's rows only."""
    out = tmp_path / "elsewhere"
    commands = []

    def fake_run(cmd, log):
        """Stand in for finetune.py: write its row where the command says."""
        commands.append(cmd)
        assert cmd[1].endswith("finetune.py")
        method, tag = _option(cmd, "--methods"), _option(cmd, "--tag")
        path = Path(_option(cmd, "--results")) / f"finetune_walks{'_' + tag if tag else ''}.json"
        rows = json.loads(path.read_text()) if path.is_file() else []
        row = make_row(dataset="walks", split="test", method=f"{method}-{tag}" if tag else method,
                       seed=0, samples=4, min_ade=0.4, min_fde=0.8, date="2026-12-07")  # fmt: skip
        write_rows(path, [*rows, row])
        return 0

    monkeypatch.setattr(reproduce, "run_command", fake_run)
    before = _files(repo)
    args = ["--datasets", "walks", "--samples", "4", "--out", str(out)]
    summary = reproduce.main(args, setup)
    assert len(commands) == 3
    for cmd in commands:
        assert _option(cmd, "--runs") == str(out / "runs")
        assert _option(cmd, "--results") == str(out / "results")
        assert _option(cmd, "--models") == str(setup.models)  # the start the tables evaluate
    assert _files(repo) == before
    cell = summary["cells"]["walks"]["rlhf"]
    assert cell["source"] == "rows" and cell["min_fde"] == 0.8
    assert str(out / "results" / "finetune_walks.json") in cell["detail"]
    commands.clear()
    assert reproduce.main(args, setup)["jobs"]["run"] == [] and commands == []  # read back
    # without --out nothing changes: the rows of the repository, the commands of before
    opts = reproduce.parse_args(["--datasets", "walks"], setup)
    cmd = reproduce.training_command(reproduce.Job("finetune", "walks", "rlhf"), opts, setup)
    assert "--runs" not in cmd and "--results" not in cmd and "--models" not in cmd


def test_full_mode_with_out_pretrains_into_the_folder_and_evaluates_that_generator(
    setup, tiny_run, tmp_path
):
    (setup.configs / "bare.yaml").write_text("{}\n")
    out = tmp_path / "elsewhere"
    trained = reproduce.replace(setup, out=out, trained=out)
    opts = reproduce.parse_args(["--datasets", "bare", "--out", str(out)], trained)
    job = reproduce.plan(opts, trained)[0]
    assert job.label == "pretrain bare pretrained"
    cmd = reproduce.training_command(job, opts, trained)
    assert cmd[1].endswith("pretrain.py") and cmd[cmd.index("--device") + 2:] == [
        "--runs", str(out / "runs"), "--results", str(out / "results"),
        "--models", str(out / "models")]  # fmt: skip
    # what the pretraining publishes there is the dataset's generator from then on
    gen = out / "models" / "bare" / "generator.safetensors"
    checkpoint.publish(tiny_run / "generator.safetensors", gen)
    assert reproduce.is_done(job, opts, trained, [])
    assert reproduce.generator_path(trained, "bare") == gen
    assert reproduce.denoiser_path(trained, "bare") == gen.parent / "denoiser.safetensors"
    tune = reproduce.Job("finetune", "bare", "rlhf")
    assert _option(reproduce.training_command(tune, opts, trained), "--models") == str(
        out / "models")  # fmt: skip
    assert not (setup.models / "bare").exists()


def test_the_reports_row_sources_read_as_before_without_out(setup):
    write_rows(setup.results / "finetune_walks.json", [make_row(
        dataset="walks", split="test", method="rlhf", seed=0, samples=4, min_ade=0.4,
        min_fde=0.8, date="2026-12-07")])  # fmt: skip
    summary = reproduce.main(["--report", "--datasets", "walks", "--samples", "4"], setup)
    assert "method `rlhf` in `benchmarks/results/finetune_walks.json`, mean over 1 seed (0)" in (
        summary["cells"]["walks"]["rlhf"]["detail"])  # fmt: skip


def test_a_row_of_the_out_folder_replaces_the_repositorys_of_the_same_measurement(setup, tmp_path):
    def row(method: str, min_fde: float) -> dict:
        return make_row(dataset="walks", split="test", method=method, seed=0, samples=4,
                        min_ade=0.4, min_fde=min_fde, date="2026-12-07")  # fmt: skip

    write_rows(setup.results / "finetune_walks.json", [row("rlhf", 0.9), row("rlhf-res", 0.7)])
    out = tmp_path / "elsewhere"
    write_rows(out / "results" / "finetune_walks.json", [row("rlhf", 0.8)])
    assert [r["min_fde"] for r in reproduce.result_rows(setup)] == [0.9, 0.7]  # no --out
    rows = reproduce.result_rows(reproduce.replace(setup, trained=out))
    assert sorted((r["method"], r["min_fde"], r["_file"]) for r in rows) == [
        ("rlhf", 0.8, str(out / "results" / "finetune_walks.json")),
        ("rlhf-res", 0.7, "benchmarks/results/finetune_walks.json"),
    ]


# ----------------------------------------------------- --runs, --results, --models: all or none
# (walkthrough 67 review: ``--models`` alone still wrote the repository's rows and start
# records, naming a start or a checkpoint outside it)


SOME_BUT_NOT_ALL = [("models",), ("runs",), ("results",), ("runs", "models"), ("results", "models")]


def _options(out: Path, names: tuple[str, ...]) -> list[str]:
    return [arg for name in names for arg in (f"--{name}", str(out / name))]


def test_pretrain_with_models_alone_is_refused_and_leaves_the_repository_as_it_is(
    repo, tiny_run, tmp_path, monkeypatch, capsys
):
    """The review's reproducer (``--run-dir /tmp/fr --models /tmp/m``): HEAD's pretrain.py
    published into /tmp/m and replaced the repository's ``pretrained`` row with that
    checkpoint, and its meta/pretrained_walks.json."""
    out = tmp_path / "out"
    shutil.copytree(tiny_run, out / "fr")
    before = _files(repo)
    with pytest.raises(SystemExit) as exit_:
        _pretrain(monkeypatch, repo, "--run-dir", str(out / "fr"), "--models", str(out / "m"))
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "--runs, --results and --models go together" in err
    assert "--runs and --results missing" in err
    assert _files(repo) == before
    assert not (out / "m").exists()


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
