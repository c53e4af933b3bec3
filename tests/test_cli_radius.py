"""``--neighbour-radius`` on evaluate, predict and plot: the predictor's and the scorer's
radius, recorded in the result and in its ``model_hash``; bad values are one-line errors."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from trajpref import cli
from trajpref.cli import main
from trajpref.models import checkpoint as ckpt

READ = ["--frame-interval", "0.4", "--units", "m", "--no-progress", "--device", "cpu"]


def _walkers(folder: Path, agents: int) -> Path:
    """A flat folder of one 20-frame window: agent 1 walks +x at 1.3 m/s (0.52 m per 0.4 s
    frame), agent 2 (if any) walks beside it 50 m to the side, far beyond any pair of the
    training scenes (about 16 m at most)."""
    folder.mkdir()
    rows = [f"{f * 10}\t{a + 1}\t{0.52 * f:.4f}\t{50.0 * a:.4f}\n"
            for f in range(20) for a in range(agents)]  # fmt: skip
    (folder / "walk.txt").write_text("".join(rows))
    return folder


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("radius")
    return _walkers(root / "pair", 2), _walkers(root / "alone", 1)


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _predict(capsys, tmp_path, folder, *flags) -> tuple[np.ndarray, dict]:
    out = tmp_path / f"p{len(list(tmp_path.iterdir()))}.npz"
    code, _, err = _run(capsys, "predict", "--dataset", folder, "--model", "zara1/generator",
                        *READ, "--out", out, *flags)  # fmt: skip
    # without a radius, the pair 50 m (34 model units) apart is warned of (zara1's limit, 15)
    wide = folder.name == "pair" and "--neighbour-radius" not in flags
    assert code == 0 and err.count("more than 15 model units apart") == wide
    assert err == "" or (wide and err.count("trajpref: warning:") == 1)
    with np.load(out) as f:
        return f["pred"], json.loads(str(f["meta"]))  # pred [K, N, T_f, 2]


def test_the_radius_predicts_a_far_walker_as_if_alone_and_is_recorded(capsys, tmp_path, scenes):
    pair, alone = scenes
    lone, _ = _predict(capsys, tmp_path, alone)
    every, meta = _predict(capsys, tmp_path, pair)
    near, meta8 = _predict(capsys, tmp_path, pair, "--neighbour-radius", "8")
    # every pair attends: the walker 50 m away bends agent 0's futures (by metres)
    assert np.abs(every[:, 0] - lone[:, 0]).max() > 0.1
    # within 8 m only: agent 0 is predicted as alone (to float rounding of the batching)
    np.testing.assert_allclose(near[:, 0], lone[:, 0], atol=1e-5)
    assert (meta["neighbour_radius"], meta8["neighbour_radius"]) == (None, 8.0)
    assert meta["model_hash"] == ckpt.model_hash("zara1/generator")  # the file's own
    assert meta8["model_hash"] != meta["model_hash"]
    assert meta8["weights_hash"] == meta["weights_hash"]


def test_evaluate_records_the_radius_in_json_and_out(capsys, tmp_path, scenes):
    pair, _ = scenes
    base = ["evaluate", "--dataset", pair, "--model", "zara1/generator", *READ, "--json"]
    code, out, _ = _run(capsys, *base)
    plain = json.loads(out)
    table = tmp_path / "r.csv"
    code, out, _ = _run(capsys, *base, "--neighbour-radius", "8", "--out", table,
                        "--scorer", "zara1/denoiser")  # fmt: skip
    near = json.loads(out)
    assert code == 0 and plain["neighbour_radius"] is None and near["neighbour_radius"] == 8.0
    assert near["scorer_neighbour_radius"] == 8.0  # the scorer reads the same pairs
    assert near["min_fde"] < plain["min_fde"] - 0.1  # the far walker no longer bends them
    assert near["model_hash"] != plain["model_hash"]
    with open(table, newline="") as fh:
        (record,) = csv.DictReader(fh)
    assert (record["neighbour_radius"], record["model_hash"]) == ("8.0", near["model_hash"])
    # none: every pair attends, as the published files do (the same digest as without)
    code, out, _ = _run(capsys, *base, "--neighbour-radius", "none")
    again = json.loads(out)
    assert (again["neighbour_radius"], again["model_hash"]) == (None, plain["model_hash"])
    assert again["min_fde"] == plain["min_fde"]


def test_the_radius_reaches_the_selections_scorer_and_the_full_samplers_hash(scenes):
    pair, _ = scenes
    parser = cli.build_parser()
    args = parser.parse_args(["evaluate", "--dataset", str(pair), "--model", "zara1/generator",
                              "--keep", "5", "--neighbour-radius", "6.5", *READ])  # fmt: skip
    cli._check_model_args(args)
    model, device = cli._predictor(args)
    assert model.neighbour_radius == 6.5
    selecting, kept = cli._selecting(args, model, device)
    assert kept == 5 and selecting.scorer.neighbour_radius == 6.5
    assert cli._scorer("zara1/denoiser", device).neighbour_radius is None  # the file's own
    full = parser.parse_args(["evaluate", "--dataset", str(pair), "--model", "zara1/generator",
                              "--sampler", "full"])  # fmt: skip
    digest = cli._model_fields(full)["model_hash"]
    assert digest == ckpt.model_hash("zara1/generator", "full")
    full.neighbour_radius = "6.5"
    assert cli._model_fields(full)["model_hash"] != digest


def test_plot_names_the_radius_and_scores_with_it(capsys, tmp_path, scenes, monkeypatch):
    pair, _ = scenes
    radii = []
    real = cli._scorer

    def scorer(*args, **kwargs):
        made = real(*args, **kwargs)
        radii.append(made.neighbour_radius)
        return made

    monkeypatch.setattr(cli, "_scorer", scorer)
    code, out, _ = _run(capsys, "plot", "--dataset", pair, "--model", "zara1/generator", *READ,
                        "--neighbour-radius", "8", "--scorer", "zara1/denoiser",
                        "--out", tmp_path / "s.png")  # fmt: skip
    assert code == 0 and radii == [8.0]
    title = cli._plot_title(cli.build_parser().parse_args(
        ["plot", "--dataset", str(pair), "--model", "zara1/generator", "--out", "x.png",
         "--neighbour-radius", "8"]), *_title_parts(pair), random=False)  # fmt: skip
    assert "neighbour-radius 8" in title


def _title_parts(pair):
    from trajpref.data import load_dataset

    ds = load_dataset(str(pair), "test", frame_interval=0.4, units="m")
    return ds, ds[0]


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "eight", ""])
def test_a_bad_radius_is_a_one_line_error(capsys, scenes, value):
    pair, _ = scenes
    for command in (["evaluate"], ["predict", "--out", "x.npz"], ["plot", "--out", "x.png"]):
        code, out, err = _run(capsys, *command, "--dataset", pair, "--model", "zara1/generator",
                              f"--neighbour-radius={value}", *READ)  # fmt: skip
        assert code == 2 and out == ""
        assert err == (f"trajpref: error: --neighbour-radius takes a distance > 0 in the data's "
                       f"units (the model's: metres, pixels) or none (every pair of a scene "
                       f"attends), got {value!r}\n")  # fmt: skip


def test_cv_takes_a_radius_only_for_its_scorer(capsys, scenes):
    pair, _ = scenes
    code, _, err = _run(capsys, "evaluate", "--dataset", pair, "--model", "cv",
                        "--neighbour-radius", "8", *READ)  # fmt: skip
    assert code == 2 and "--neighbour-radius applies to diffusion models and scorers" in err
    code, out, _ = _run(capsys, "evaluate", "--dataset", pair, "--model", "cv", "--json",
                        "--neighbour-radius", "8", "--scorer", "zara1/denoiser", *READ)  # fmt: skip
    result = json.loads(out)
    assert code == 0 and result["scorer_neighbour_radius"] == 8.0
    assert result["neighbour_radius"] is None  # cv has no attention across agents
