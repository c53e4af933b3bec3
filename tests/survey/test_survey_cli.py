"""The survey commands end to end, and bad input as one line on stderr with exit status 2."""

import contextlib
import json
import os
import shutil
import socket
from pathlib import Path

import pytest
from helpers import _run
from survey.helpers import DOCS, _read_only, _simulated

from trajpref.cli import main
from trajpref.survey.manifest import (
    DATABASE,
    load_study,
)
from trajpref.survey.store import AnswerStore


def _one_line_error(code, err, text):
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("trajpref: error: ") and text in err


def test_simulate_then_analyze_end_to_end(capsys, tiny_study, tmp_path):

    study = shutil.copytree(tiny_study, tmp_path / "study")
    code, out, _ = _run(capsys, "survey", "simulate", study, "--raters", "5")
    assert code == 0 and "SYNTHETIC" in out
    code, out, _ = _run(capsys, "survey", "analyze", study)
    assert code == 0 and "| Method | Human score (↑) | ATS (↑) | FTS (↑) |" in out
    assert "SYNTHETIC RATERS" in out and (study / "analysis.png").is_file()
    code, out, _ = _run(capsys, "survey", "analyze", study, "--json", "--out", tmp_path / "r")
    assert code == 0 and json.loads(out)["raters"] == 5
    assert (tmp_path / "r" / "analysis.md").is_file()


def test_a_missing_study_folder(capsys, tmp_path):
    for cmd in ("serve", "analyze", "simulate"):
        code, _, err = _run(capsys, "survey", cmd, tmp_path / "nope")
        _one_line_error(code, err, "no such study folder")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "damage, text",
    [
        (lambda s: "{not json", "not valid JSON"),
        (lambda s: s.replace('"format": "trajpref-survey/1"', '"format": "x"'), "format"),
        (
            lambda s: s.replace('"image": "s01-A.png"', '"image": "../manifest.json"'),
            "not a valid name",
        ),
        (lambda s: s.replace('"image": "s01-A.png"', '"image": "s09-Z.png"'), "missing image"),
        (
            lambda s: s.replace('"method": "methodalpha"', '"method": "other"', 1),
            "not one of the methods",
        ),
        # the number moves to a key that comes again later (JSON: the last one counts)
        (lambda s: s.replace('"ats": ', '"ats": "high", "max_ats": ', 1), "expected a number"),
        (lambda s: s.replace('"ats": ', '"ats": 0.5, "atz": ', 1), "unknown key 'atz'"),
        (lambda s: "[]", "expected an object"),
    ],
)
def test_a_corrupt_manifest_is_one_line_and_nothing_is_written(
    capsys, monkeypatch, synthetic_study, damage, text
):
    import uvicorn

    def started(*args, **kwargs):  # a manifest that loads would serve until killed: fail instead
        raise AssertionError("serve started on a corrupt manifest")

    monkeypatch.setattr(uvicorn.Server, "run", started)
    manifest = synthetic_study / "manifest.json"
    manifest.write_text(damage(manifest.read_text()))
    before = sorted(p.name for p in synthetic_study.iterdir())
    for cmd in ("serve", "analyze", "simulate"):
        code, _, err = _run(capsys, "survey", cmd, synthetic_study)
        _one_line_error(code, err, text)
        assert "corrupt manifest" in err
    assert sorted(p.name for p in synthetic_study.iterdir()) == before  # no database, no report


def test_serve_says_when_the_port_is_taken(capsys, synthetic_study):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        code, _, err = _run(capsys, "survey", "serve", synthetic_study, "--port", port)
    _one_line_error(code, err, f"cannot listen on 127.0.0.1:{port}")


def test_analyze_before_any_answer(capsys, synthetic_study):
    code, _, err = _run(capsys, "survey", "analyze", synthetic_study)
    _one_line_error(code, err, "no answers yet")
    assert not (synthetic_study / "analysis.md").exists()


@pytest.mark.parametrize(
    "args, text",
    [
        (["--models", "a=cv", "a=cv"], "given twice"),
        (["--models", "mine"], "NAME=MODEL"),
        (["--models", "=cv"], "NAME=MODEL"),
        (["--models", "cv", "--scenes", "0"], "--scenes"),
        (["--models", "x=missing.safetensors"], "no such model"),
        (["--models", "cv"], "--scorer"),
        (["--models", "cv", "--time-step", "0"], "time_step must be a number of frame steps"),
        (["--models", "cv", "--max-gap", "-1"], "max_gap must be None or an integer >= 0"),
        (["--models", "cv", "--delimiter", "colon"], "delimiter 'colon': choose one of"),
        (["--models", "cv", "--holdout-scene", "walk0"], "--holdout-scene selects a validation"),
    ],
)
def test_build_errors(capsys, walks, tmp_path, args, text):
    code, _, err = _run(
        capsys,
        "survey",
        "build",
        "--dataset",
        walks,
        "--min-gap",
        "0",
        "--out",
        tmp_path / "s",
        "--device",
        "cpu",
        *args,
    )
    _one_line_error(code, err, text)
    assert not (tmp_path / "s").exists()


def test_build_refuses_an_existing_study(capsys, tiny_study, walks):
    code, _, err = _run(
        capsys, "survey", "build", "--dataset", walks, "--models", "cv", "--out", tiny_study
    )
    _one_line_error(code, err, "already exists")


def test_simulate_errors(capsys, synthetic_study):
    code, _, err = _run(capsys, "survey", "simulate", synthetic_study, "--raters", "0")
    _one_line_error(code, err, "--raters")


def test_serve_refuses_a_tiny_body_limit_before_writing(capsys, synthetic_study):
    code, _, err = _run(capsys, "survey", "serve", synthetic_study, "--max-body", "10")
    _one_line_error(code, err, "--max-body")
    assert not (synthetic_study / "answers.sqlite").exists()


def test_build_reads_data_with_evaluates_options(capsys, walks, tiny_run, tmp_path):
    out = tmp_path / "my study"  # a space: the printed serve command must paste back
    code, printed, err = _run(capsys, "survey", "build", "--dataset", walks, "--units", "m",
                        "--delimiter", "tab", "--max-gap", "0", "--max-coord", "1000",
                        "--time-step", "0.5", "--models", "a=cv",
                        f"b={tiny_run / 'generator.safetensors'}", "--scenes", "1",
                        "--samples", "2", "--min-gap", "0", "--device", "cpu", "--no-progress",
                        "--out", out)  # fmt: skip
    # the model trained on these very files read as recorded (its checkpoint says so): read
    # every 0.5 steps they step 0.2 s against its 0.4 s, which the build says as evaluate does
    model = tiny_run / "generator.safetensors"
    assert (code, err) == (0, f"trajpref: warning: {model} was trained on {walks}: this data "
                              "steps 0.2 s, the model's 0.4 s (--time-step 1 reads it at the "
                              "model's step (the same files))\n")  # fmt: skip
    assert f"`trajpref survey serve '{out}'`" in printed
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["dataset"]["frame_interval"] == pytest.approx(0.2)  # 0.4 s read every 0.5
    assert {k: manifest["build"][k] for k in ("delimiter", "max_gap", "max_coord", "time_step",
                                               "protocol", "holdout_scene")} == {
        "delimiter": "tab", "max_gap": 0, "max_coord": 1000.0, "time_step": 0.5,
        "protocol": "all", "holdout_scene": None}  # fmt: skip


def test_build_warns_as_evaluate_when_a_model_was_trained_in_other_units_or_steps(
    capsys, walks, tmp_path
):
    code, _, err = _run(capsys, "survey", "build", "--dataset", walks, "--units", "ft",
                        "--frame-interval", "0.1", "--models", "cv", "gen=zara1/generator",
                        "--scorer", "zara1/denoiser", "--scenes", "1", "--samples", "2",
                        "--min-gap", "0", "--device", "cpu", "--no-progress", "--out",
                        tmp_path / "study")  # fmt: skip
    assert code == 0
    problems = ("this data is in ft, the model's in m (units are named, not converted: multiply "
                "x and y by 0.3048 to give m before reading them, and the futures, in m, by "
                "3.281 for ft); this data steps 0.1 s, the model's 0.4 s "
                "(--time-step 4 reads it at the model's step)")  # fmt: skip
    assert err.splitlines() == [
        f"trajpref: warning: zara1/generator was trained on the zara1 fold (leave-one-out: the "
        f"other four scenes): {problems}",
        f"trajpref: warning: zara1/denoiser was trained on the zara1 fold (leave-one-out: the "
        f"other four scenes): {problems}",
    ]


def test_a_database_in_a_missing_folder(capsys, synthetic_study, tmp_path):
    db = tmp_path / "nodir" / "answers.sqlite"
    for cmd in (["serve", "--port", "0"], ["simulate"]):
        code, _, err = _run(capsys, "survey", cmd[0], synthetic_study, *cmd[1:], "--db", db)
        _one_line_error(code, err, f"{db}: cannot create the answers database: there is no "
                        f"folder {db.parent}")  # fmt: skip
    assert not db.parent.exists()


def test_analyze_refuses_a_database_it_cannot_read_in_one_line(capsys, synthetic_study, tmp_path):
    import sqlite3

    db = tmp_path / "imported.sqlite"  # what `.import --csv answers.csv answers` makes
    with sqlite3.connect(db) as con:
        con.execute(
            "CREATE TABLE answers (rater TEXT, scene TEXT, panel TEXT, social TEXT, "
            "kinetics TEXT, revision TEXT, created_at TEXT, updated_at TEXT)"
        )
        con.execute(
            "CREATE TABLE raters (rater TEXT, kind TEXT, created_at TEXT, submitted_at TEXT)"
        )
        con.execute("INSERT INTO answers VALUES ('p1', 's01', 'A', '4', '3', '1', 'x', 'x')")
    con.close()
    before = db.read_bytes()
    code, _, err = _run(capsys, "survey", "analyze", synthetic_study, "--db", db)
    _one_line_error(code, err, f"{db}: 1 answer with ratings that are not integers from 1 to 5")
    assert db.read_bytes() == before and not (synthetic_study / "analysis.md").exists()
    code, _, err = _run(capsys, "survey", "analyze", synthetic_study, "--db", db, "--out",
                        synthetic_study / "manifest.json")  # fmt: skip
    _one_line_error(code, err, f"--out {synthetic_study / 'manifest.json'}: exists and is not a "
                    "folder")  # fmt: skip


def _survey_commands(text: str) -> list[str]:
    """The ``trajpref survey`` lines of a Markdown text's bash blocks, continuations joined,
    comments dropped."""
    import re

    lines = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("trajpref survey"):
                lines.append(line)
    return lines


def test_the_documented_survey_commands_parse_and_name_published_models():
    import shlex
    from pathlib import Path

    from trajpref.cli import build_parser

    root = Path(__file__).resolve().parents[2]
    readme = (root / "README.md").read_text().split("## Human study", 1)[1].split("\n## ", 1)[0]
    docs = (root / "docs" / "survey.md").read_text()
    commands = _survey_commands(readme) + _survey_commands(docs)
    assert len(commands) >= 8
    for command in commands:
        build_parser().parse_args(shlex.split(command)[1:])  # SystemExit(2) on a typo
        assert " models/" not in command and "=models/" not in command, command
    # every option of `survey build` is in the options table of docs/survey.md
    table = docs.split("| option | default | what it does |", 1)[1].split("\n\n", 1)[0]
    sub = next(a for a in build_parser()._subparsers._actions if a.dest == "command")
    survey = next(
        a for a in sub.choices["survey"]._subparsers._actions if a.dest == "survey_command"
    )
    options = [o for a in survey.choices["build"]._actions for o in a.option_strings]
    assert [o for o in options if f"`{o}" not in table] == ["-h", "--help"]


def test_analyze_leaves_out_the_raters_named_by_exclude_rater(capsys, synthetic_study):
    code, _, _ = _run(capsys, "survey", "simulate", synthetic_study, "--raters", "4")
    excluded = ["--exclude-rater", "synthetic-01", "--exclude-rater", "Synthetic-03"]
    code, out, _ = _run(capsys, "survey", "analyze", synthetic_study, "--json", *excluded)
    data = json.loads(out)
    assert code == 0 and data["raters"] == 2
    assert data["excluded"] == ["synthetic-01", "synthetic-03"] and data["excluded_answers"] == 18
    code, _, err = _run(capsys, "survey", "analyze", synthetic_study, "--exclude-rater", "nobody")
    _one_line_error(code, err, "--exclude-rater nobody: no such rater in ")


def test_export_writes_one_csv_row_per_answer_with_the_method_behind_each_panel(
    capsys, synthetic_study, tmp_path
):
    import csv

    study = load_study(synthetic_study)
    store = AnswerStore(synthetic_study / DATABASE, study)
    for rater, social in (("Alice", 5), ("bob", 2), ("test-run", 1)):
        store.save_many(rater, [(s.id, p.id, {"social": social, "kinetics": 3})
                                for s in study.scenes for p in s.panels])  # fmt: skip
    store.close()
    _run(capsys, "survey", "simulate", synthetic_study, "--raters", "2")
    path = tmp_path / "out" / "answers.csv"
    old = os.umask(0o022)
    try:
        code, out, _ = _run(capsys, "survey", "export", synthetic_study, "--csv", path,
                            "--exclude-rater", "TEST-RUN")  # fmt: skip
    finally:
        os.umask(old)
    assert code == 0 and f"wrote 18 answers of 2 raters (human) to {path}" in out
    assert oct(path.stat().st_mode & 0o777) == "0o600"
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * 9 and {r["rater"] for r in rows} == {"alice", "bob"}
    method = {(s.id, p.id): p.key for s in study.scenes for p in s.panels}
    for r in rows:
        key = method[(r["scene"], r["panel"])]
        gt = key.method == "ground truth"  # its ATS is 0 by definition: empty (NA)
        assert r["method"] == key.method and r["ats"] == ("" if gt else str(key.ats))
        assert float(r["ade"]) == key.ade and r["units"] == "m" and r["kind"] == "human"
        assert float(r["human_score"]) == (int(r["social"]) + 3) / 2
    # where that rater was shown the picture: each rater's own order (alice and bob differ)
    shown = {r: study.positions(r) for r in ("alice", "bob")}
    for r in rows:
        got = (int(r["scene_position"]), int(r["panel_position"]), int(r["position"]))
        assert got == shown[r["rater"]][(r["scene"], r["panel"])]
    assert shown["alice"] != shown["bob"]
    code, out, _ = _run(capsys, "survey", "export", synthetic_study, "--csv", path, "--raters",
                        "synthetic")  # fmt: skip
    assert code == 0 and "SYNTHETIC" in out


def test_export_errors_write_nothing(capsys, synthetic_study, tmp_path):
    code, _, err = _run(capsys, "survey", "export", synthetic_study, "--csv", tmp_path / "a.csv")
    _one_line_error(code, err, "no answers yet")
    code, _, err = _run(capsys, "survey", "export", synthetic_study, "--csv", tmp_path)
    _one_line_error(code, err, f"--csv {tmp_path}: is an existing folder, not a file")
    _run(capsys, "survey", "simulate", synthetic_study, "--raters", "1")
    code, _, err = _run(capsys, "survey", "export", synthetic_study, "--csv",
                        tmp_path / "new" / "a.csv", "--exclude-rater", "synthetic-9")  # fmt: skip
    _one_line_error(code, err, "(did you mean synthetic-01?)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]


def test_build_refuses_the_sgan_protocol_on_sdd(capsys, tmp_path):
    """sgan is Social-GAN's ETH/UCY counting: a study of SDD under it would drop half its
    agents, as evaluate refuses (checked before any data is read, so no data is needed)."""
    code, _, err = _run(capsys, "survey", "build", "--dataset", "sdd", "--protocol", "sgan",
                        "--models", "cv", "--out", tmp_path / "study")  # fmt: skip
    assert code == 2 and "--protocol sgan is Social-GAN's ETH/UCY counting" in err
    assert not (tmp_path / "study").exists()


# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


def test_build_refuses_an_empty_or_missing_consent_file(capsys, walks, tmp_path):
    empty = tmp_path / "empty.txt"
    empty.write_text("  \n")
    for path, text in ((empty, "the file is empty"), (tmp_path / "no.txt", "cannot read it")):
        code, _, err = _run(capsys, "survey", "build", "--dataset", walks, "--models", "cv",
                            "--scorer", "zara1/denoiser", "--consent", path, "--out",
                            tmp_path / "study")  # fmt: skip
        assert code == 2 and f"--consent {path}: {text}" in err
        assert not (tmp_path / "study").exists()


# ---- finding 12: the docs' --frame-interval default -------------------------------------


def test_the_docs_give_the_frame_interval_default_as_the_code_takes_it():
    docs = (Path(__file__).resolve().parents[2] / "docs" / "survey.md").read_text()
    row = next(line for line in docs.splitlines() if line.startswith("| `--frame-interval`"))
    assert "| 0.4, unknown |" not in row
    assert "`time` or `timestamp`" in row and "else 0.4 (assumed)" in row


# Walkthrough 65's survey findings: a SIGTERM stop, a study in a read-only folder, rater ids
# with a trailing newline, the study folder deleted while serving, a database write that fails,
# the docs against the code, and the page's resumed session on a shared machine.


# ---- 2. a study in a read-only folder -------------------------------------------------------


def test_analyze_and_export_read_a_study_in_a_read_only_folder(capsys, synthetic_study, tmp_path):
    _simulated(synthetic_study)
    before = {p.name: p.read_bytes() for p in synthetic_study.iterdir() if p.is_file()}
    with _read_only(synthetic_study):
        code, out, err = _run(capsys, "survey", "analyze", synthetic_study, "--out",
                              tmp_path)  # fmt: skip
        assert code == 0, err
        assert "raters: 3 synthetic" in out
        code, out, err = _run(capsys, "survey", "export", synthetic_study, "--csv",
                              tmp_path / "answers.csv")  # fmt: skip
        assert code == 0, err
    assert (tmp_path / "answers.csv").read_text().count("synthetic-0") == 27
    assert {p.name: p.read_bytes() for p in synthetic_study.iterdir() if p.is_file()} == before


def _option_help(help_text: str, option: str) -> str:
    """The help of ``option`` in argparse's ``--help`` output, on one line."""
    lines = help_text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip().startswith(option + " "))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].strip().startswith("-")),
               len(lines))  # fmt: skip
    return " ".join(" ".join(lines[start:end]).split())


def test_the_help_gives_the_defaults_of_seed_and_title(capsys):
    with contextlib.suppress(SystemExit):
        main(["survey", "build", "--help"])
    out = capsys.readouterr().out
    assert _option_help(out, "--seed").endswith("(default 0)")
    assert _option_help(out, "--title").endswith("(default 'Which predicted paths look human?')")


def test_the_docs_name_simulate_db_sigterm_line_breaks_and_the_blinding_limits():
    text = " ".join(DOCS.read_text().split())
    assert "`survey simulate study/ --raters 20 [--seed 0 --prefix synthetic --db PATH]`" in text
    assert "a blank line starts a new paragraph" not in text
    assert "SIGTERM" in text and "SIGKILL" in text
    assert "drawn differently" in text  # the one limit of the blinding left
    assert "an order of their own" in text and "one byte size" in text  # the two lifted
