"""The survey commands end to end, and bad input as one line on stderr with exit status 2."""

import json
import socket

import pytest

from trajpref.cli import main


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(code, err, text):
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("trajpref: error: ") and text in err


def test_simulate_then_analyze_end_to_end(capsys, tiny_study, tmp_path):
    import shutil

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
        (lambda s: s.replace('"ats": ', '"ats": "high", "x": ', 1), "expected a number"),
        (lambda s: "[]", "expected an object"),
    ],
)
def test_a_corrupt_manifest_is_one_line_and_nothing_is_written(
    capsys, synthetic_study, damage, text
):
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
