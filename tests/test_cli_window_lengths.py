"""A model of other window lengths than the published 8 + 12 frames, end to end: trained on a
folder with ``--history 6 --future 16``, then evaluated, predicted, plotted, scored, carded
and put in a study, each reading the data at the model's own lengths without being told;
lengths that disagree with a model (given by hand, or a scorer's) are refused in one line."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from helpers import _run
from synthetic import TINY_OVERRIDES, write_dataset

from trajpref.data import ReadOptions, load_dataset
from trajpref.errors import ConfigError, DataError
from trajpref.evaluation import evaluate, predict_dataset
from trajpref.models import checkpoint
from trajpref.models.registry import load_predictor

WINDOWS = (6, 16)


@pytest.fixture(scope="module")
def long_walks(tmp_path_factory):
    """Walks of 40 frames: room for windows of 6 + 16 frames (19 per file)."""
    return write_dataset(tmp_path_factory.mktemp("long_walks"), frames=40)


@pytest.fixture(scope="module")
def long_run(tmp_path_factory, long_walks):
    """Both stages of a tiny model trained through the command line at 6 + 16 frames."""
    from trajpref.cli import main

    out = tmp_path_factory.mktemp("long_run")
    sets = [a for o in TINY_OVERRIDES for a in ("--set", o)]
    for stage in ("diffusion", "generator"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the tiny validation split's warning
            code = main(["train", stage, "--dataset", str(long_walks), "--history", "6",
                         "--future", "16", "--out", str(out), "--no-progress", *sets])  # fmt: skip
        assert code == 0
    return out


def test_training_reads_the_folder_at_the_lengths_given_and_records_them(long_run):
    generator = long_run / "generator.safetensors"
    assert checkpoint.windows_of(generator) == WINDOWS
    assert checkpoint.windows_of(long_run / "denoiser.safetensors") == WINDOWS
    model = load_predictor(str(generator))
    assert (model.t_hist, model.t_fut) == WINDOWS
    assert checkpoint.windows_of("zara1/generator") == (8, 12)


def test_evaluate_reads_the_data_at_the_models_lengths_by_itself(capsys, long_run, long_walks):
    code, out, err = _run(capsys, "evaluate", "--model", long_run / "generator.safetensors",
                          "--dataset", long_walks, "--samples", "4", "--no-progress", "--json",
                          "--scorer", long_run / "denoiser.safetensors")  # fmt: skip
    assert code == 0, err
    result = json.loads(out)
    assert (result["t_hist"], result["t_fut"]) == WINDOWS
    assert result["scenes"] == 40 - 22 + 1 and result["agents"] == 3 * 19
    assert np.isfinite(result["min_fde"]) and np.isfinite(result["max_ats"])
    code, out, _ = _run(capsys, "evaluate", "--model", long_run / "generator.safetensors",
                        "--dataset", long_walks, "--samples", "4", "--no-progress")  # fmt: skip
    assert code == 0 and "units unknown, windows of 6 + 16 frames)" in out.splitlines()[0]


def test_predict_writes_futures_of_the_models_horizon(capsys, long_run, long_walks, tmp_path):
    path = tmp_path / "pred.npz"
    code, _, err = _run(capsys, "predict", "--model", long_run / "generator.safetensors",
                        "--dataset", long_walks, "--samples", "4", "--no-progress",
                        "--out", path)  # fmt: skip
    assert code == 0, err
    arrays = np.load(path)
    assert arrays["history"].shape == (57, 6, 2) and arrays["pred"].shape == (4, 57, 16, 2)
    meta = json.loads(str(arrays["meta"]))
    assert (meta["t_hist"], meta["t_fut"]) == WINDOWS


def test_plot_and_the_model_card_work_at_the_models_lengths(capsys, long_run, long_walks,
                                                            tmp_path):  # fmt: skip
    code, _, err = _run(capsys, "plot", "--model", long_run / "generator.safetensors",
                        "--dataset", long_walks, "--samples", "4", "--out",
                        tmp_path / "scene.png")  # fmt: skip
    assert code == 0, err
    assert (tmp_path / "scene.png").stat().st_size > 0
    code, out, _ = _run(capsys, "models", long_run / "generator.safetensors")
    assert code == 0
    assert "- Windows: 6 observed + 16 future frames" in out
    assert "`--history 6 --future 16`" in out
    code, out, _ = _run(capsys, "models", "zara1/generator")
    assert code == 0 and "- Windows:" not in out  # the published lengths go without saying


@pytest.mark.parametrize(("flags", "said"), [
    (["--history", "8"], "--history 8: --model {gen} reads windows of 6 observed + 16 future "
                         "frames (its model.t_hist and model.t_fut); leave --history out"),
    (["--future", "12"], "--future 12: --model {gen} reads windows of 6 observed + 16 future"),
    (["--scorer", "zara1/generator"], "--model {gen} reads windows of 6 observed + 16 future "
                                      "frames, --scorer zara1/generator of 8 + 12: they must "
                                      "read the same lengths"),
])  # fmt: skip
def test_lengths_that_disagree_with_the_model_are_refused(capsys, long_run, long_walks,
                                                          flags, said):  # fmt: skip
    gen = long_run / "generator.safetensors"
    code, out, err = _run(capsys, "evaluate", "--model", gen, "--dataset", long_walks,
                          "--samples", "4", "--no-progress", *flags)  # fmt: skip
    assert code == 2 and out == ""
    assert err.startswith("trajpref: error: " + said.format(gen=gen))


def test_the_lengths_given_read_the_data_where_no_checkpoint_says(capsys, long_walks):
    code, out, err = _run(capsys, "data", "stats", "--dataset", long_walks, "--history", "6",
                          "--future", "16", "--json")  # fmt: skip
    assert code == 0, err
    stats = json.loads(out)
    assert (stats["t_hist"], stats["t_fut"]) == WINDOWS and stats["scenes"] == 19
    code, out, err = _run(capsys, "evaluate", "--model", "cv", "--dataset", long_walks,
                          "--future", "16", "--no-progress", "--json")  # fmt: skip
    assert code == 0, err
    assert (json.loads(out)["t_hist"], json.loads(out)["t_fut"]) == (8, 16)
    code, _, err = _run(capsys, "data", "stats", "--dataset", long_walks, "--history", "1")
    assert code == 2 and "--history must be an integer >= 2" in err


def test_python_evaluation_of_other_lengths_says_how_to_read_them(long_run, long_walks):
    model = load_predictor(str(long_run / "generator.safetensors"))
    usual = load_dataset(str(long_walks), "test")  # 8 + 12
    said = (
        r"the model reads windows of 6 observed \+ 16 future frames, but .*/test was read "
        r"in windows of 8 \+ 12: .*ReadOptions\(t_hist=6, t_fut=16\)"
    )
    with pytest.raises(DataError, match=said):
        evaluate(model, usual, 4, progress=False)
    with pytest.raises(DataError, match=said):
        predict_dataset(model, usual, 4, progress=False)
    own = load_dataset(str(long_walks), "test", options=ReadOptions(t_hist=6, t_fut=16))
    assert evaluate(model, own, 4, progress=False)["agents"] == 57


def test_a_study_reads_its_models_lengths_and_refuses_a_mix(long_run, long_walks, tmp_path):
    from trajpref.survey.build import BuildConfig, build_study

    gen = str(long_run / "generator.safetensors")
    cfg = BuildConfig(dataset=str(long_walks), models={"g": gen, "cv": "cv"}, scenes=3,
                      samples=4, device="cpu", min_gap=0)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # units unknown
        study = build_study(cfg, tmp_path / "study", progress=False)
        assert len(study.scenes) == 3 and study.scenes[0].agents == 3
        assert (study.dataset["t_hist"], study.dataset["t_fut"]) == WINDOWS
        assert (study.build["min_gap"], study.build["t_hist"], study.build["t_fut"]) == (0, 6, 16)
        # by default no two scenes share a frame: a window's 22 frames apart, not 20
        apart = BuildConfig(dataset=str(long_walks), models={"g": gen}, scenes=3, samples=4,
                            device="cpu")  # fmt: skip
        with pytest.raises(ConfigError, match=r"eligible scenes are --min-gap 22 apart; .* "
                           r"\(--min-gap 22 by default: a window's 6 \+ 16 frames"):  # fmt: skip
            build_study(apart, tmp_path / "apart", progress=False)
    mixed = BuildConfig(dataset=str(long_walks), models={"g": gen, "z": "zara1/generator"},
                        scenes=3, samples=4, device="cpu")  # fmt: skip
    with pytest.raises(ConfigError, match=r"method g reads windows of 6 observed \+ 16 future "
                       r"frames, method z of 8 \+ 12, the scorer of 6 \+ 16: they must read "
                       "the same lengths"):  # fmt: skip
        build_study(mixed, tmp_path / "mixed", progress=False)
    told = BuildConfig(dataset=str(long_walks), models={"g": gen}, scenes=3, samples=4,
                       device="cpu", t_fut=12)  # fmt: skip
    with pytest.raises(ConfigError, match=r"--future 12: method g reads windows of 6 observed "
                       r"\+ 16 future frames .*; leave --future out"):  # fmt: skip
        build_study(told, tmp_path / "told", progress=False)


def test_an_export_reads_the_models_own_lengths(capsys, long_run, tmp_path):
    out = tmp_path / "long.pt2"
    code, said, err = _run(capsys, "export", long_run / "generator.safetensors", "--out", out)
    assert code == 0, err
    assert "history [P, 6, 2]" in said and "futures [4, P, 16, 2]" in said
