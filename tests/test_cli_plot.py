"""`trajpref plot` for a paper's figures: the format its suffix names at the dpi and width
given, the samples that predict and evaluate draw, a title that says what changes the
picture (or none), the scorer named and checked, and the scene's own minADE/minFDE."""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch
from helpers import _run
from PIL import Image
from synthetic import write_tracks

from trajpref.metrics import min_ade_fde


@pytest.fixture
def base(walks):
    return ["plot", "--dataset", walks, "--device", "cpu", "--samples", "4", "--no-progress"]


@pytest.fixture
def drawn(plot_calls):
    """What cmd_plot hands to the figure functions (conftest's ``plot_calls``)."""
    return plot_calls


def test_plot_writes_the_format_its_suffix_names_at_the_dpi_and_width_given(capsys, base,
                                                                           tmp_path):  # fmt: skip
    """`plot --out fig.pdf` was refused (PNG only, 120 dpi)."""
    for name, magic in (("f.pdf", b"%PDF"), ("f.svg", b"<svg"), ("f.png", b"\x89PNG")):
        code, out, err = _run(capsys, *base, "--out", tmp_path / name)
        assert (code, err) == (0, ""), err
        assert magic in (tmp_path / name).read_bytes()[:400]
    code, _, _ = _run(capsys, *base, "--out", tmp_path / "hi.png", "--dpi", "240")
    assert code == 0
    ratio = Image.open(tmp_path / "hi.png").size[0] / Image.open(tmp_path / "f.png").size[0]
    assert 1.9 < ratio < 2.1
    code, _, _ = _run(capsys, *base, "--out", tmp_path / "col.png", "--width", "3.3", "--dpi",
                      "100", "--no-title")  # fmt: skip  # (a long title widens the canvas)
    assert code == 0 and 300 <= Image.open(tmp_path / "col.png").size[0] <= 350
    for flags, message in (
        (["--out", tmp_path / "f.jpg"], r"must be a \.png file, or \.pdf or \.svg"),
        (["--out", tmp_path / "f.png", "--dpi", "0"], r"--dpi"),
        (["--out", tmp_path / "f.png", "--width", "-1"], r"--width"),
        (["--out", tmp_path / "f.png", "--limits", "1,2"], r"--limits takes auto, all or"),
        (["--out", tmp_path / "f.png", "--limits=2,1,0,1"], r"--limits .*x0 < x1"),
        (["--out", tmp_path / "f.png", "--draw-samples", "0"], r"--draw-samples must be >= 1"),
    ):  # fmt: skip
        code, _, err = _run(capsys, *base, *flags)
        assert code == 2 and re.search(message, err), (flags, err)
    assert not (tmp_path / "f.jpg").exists()


def test_plot_draws_the_samples_predict_draws_and_prints_their_metrics(capsys, base, walks,
                                                                      tmp_path, drawn):  # fmt: skip
    """cv's figure differed from `predict`'s samples by metres (the scene was predicted
    alone, not in predict's batches), and --max-agents was ignored."""
    scene = 3
    seen = {}
    for agents in ("1024", "3"):
        npz = tmp_path / f"p{agents}.npz"
        code, _, _ = _run(capsys, "predict", "--dataset", walks, "--device", "cpu", "--samples",
                          "4", "--no-progress", "--max-agents", agents, "--out", npz)  # fmt: skip
        assert code == 0
        z = np.load(npz)
        mine = z["scene"] == scene
        code, out, err = _run(capsys, *base, "--scene", scene, "--max-agents", agents,
                              "--out", tmp_path / f"f{agents}.png")  # fmt: skip
        assert (code, err) == (0, "")
        pred = drawn[-1][1][2]  # plot_scene(history, future, pred, ...)
        np.testing.assert_allclose(pred, z["pred"][:, mine], atol=1e-6)
        seen[agents] = pred
        # the scene's minADE/minFDE over all K, as evaluate computes them, in the text
        ade, fde = min_ade_fde(torch.as_tensor(z["pred"][:, mine]),
                               torch.as_tensor(z["future"][mine]))  # fmt: skip
        found = re.search(r"minADE_4 (\d+\.\d+)(?: \S+)?, minFDE_4 (\d+\.\d+)", out)
        assert found, out
        assert float(found[1]) == pytest.approx(float(ade.mean()), abs=1e-4)
        assert float(found[2]) == pytest.approx(float(fde.mean()), abs=1e-4)
        assert len(re.findall(r"^  agent \d+: minADE", out, re.M)) == int(mine.sum())
    assert not np.allclose(seen["1024"], seen["3"])  # other batches, other draws


def test_plot_names_the_settings_that_change_the_picture_or_takes_the_title_given(
        capsys, base, tmp_path, drawn):  # fmt: skip
    out = tmp_path / "f.png"
    code, _, _ = _run(capsys, *base, "--out", out, "--seed", "7", "--max-agents", "3")
    title = drawn[-1][1][5]
    assert code == 0
    assert "/test scene 0" in title and "cv, K=4, seed 7, max-agents 3" in title
    code, _, _ = _run(capsys, *base, "--out", out, "--title", "Fig. 3")
    assert code == 0 and drawn[-1][1][5] == "Fig. 3"
    code, _, _ = _run(capsys, *base, "--out", out, "--no-title")
    assert code == 0 and drawn[-1][1][5] == ""
    code, _, err = _run(capsys, *base, "--out", out, "--no-title", "--title", "x")
    assert code == 2 and "not allowed with" in err


def test_a_folder_without_split_folders_is_not_titled_test(capsys, tmp_path, drawn):
    rows = [(10 * f, a, 0.5 * f, float(a)) for a in (1, 2) for f in range(20)]
    write_tracks(tmp_path / "flat" / "a.txt", rows)
    code, _, _ = _run(capsys, "plot", "--dataset", tmp_path / "flat", "--device", "cpu",
                      "--samples", "2", "--out", tmp_path / "f.png")  # fmt: skip
    title = drawn[-1][1][5]
    assert code == 0 and title.startswith(f"{tmp_path / 'flat'} scene 0 (a.txt")


def test_the_ranked_figure_names_its_scorer_and_warns_of_one_trained_otherwise(
        capsys, base, tmp_path, drawn):  # fmt: skip
    """--scorer sdd/denoiser (pixels) on data in metres was silent, and the title did not say
    which scorer ranked the samples."""
    code, _, err = _run(capsys, *base, "--units", "px", "--scorer", "zara1/denoiser", "--out",
                        tmp_path / "f.png", "--draw-samples", "3")  # fmt: skip
    assert code == 0
    assert err == ("trajpref: warning: zara1/denoiser was trained on the zara1 fold "
                   "(leave-one-out: the other four scenes): this data is in px, the model's "
                   "in m\n")  # fmt: skip
    name, args, kwargs = drawn[-1]
    assert name == "plot_scene_scored" and args[6].endswith("; ranked by zara1/denoiser")
    assert args[7] == 3  # --draw-samples: the best 3 per agent


def test_plot_passes_its_limits_and_the_samples_to_draw(capsys, base, tmp_path, drawn):
    out = tmp_path / "f.png"
    for flags, want in ((["--limits", "all"], "all"), (["--limits=-1,2,-3,4.5"], (-1, 2, -3, 4.5)),
                        ([], "auto")):  # fmt: skip
        code, _, _ = _run(capsys, *base, "--out", out, *flags)
        assert code == 0 and drawn[-1][2]["limits"] == want
    code, _, _ = _run(capsys, *base, "--out", out, "--draw-samples", "2")
    assert code == 0 and drawn[-1][2]["max_samples"] == 2


def _page_inches(path) -> float:
    """The width in inches of a PDF's page (its MediaBox) or an SVG."""
    data = path.read_bytes()
    if path.suffix == ".pdf":
        box = [float(v) for v in re.search(rb"/MediaBox \[ ?([^\]]+?) ?\]", data)[1].split()]
        return (box[2] - box[0]) / 72
    return float(re.search(rb'<svg[^>]* width="([\d.]+)pt"', data)[1]) / 72


@pytest.mark.parametrize(("flags", "width"), [
    (["--width", "3.3", "--no-title"], 3.3),
    (["--width", "3.3"], 3.3),  # the long title plot makes
    (["--width", "3.3", "--scorer", "zara1/denoiser"], 3.3),  # stacked panels
    (["--width", "5.5", "--scorer", "zara1/denoiser", "--title", "x" * 150], 5.5),
    (["--width", "4", "--units", "px"], 4.0),  # image rows: y down
    ([], 6.4),
    (["--scorer", "zara1/denoiser"], 7.0),
])  # fmt: skip
def test_the_figure_is_as_wide_as_width_says(capsys, base, tmp_path, flags, width):
    """--width 3.3 gave a 3.41-inch PDF page without a title, 3.75 with the one made, 3.27
    with --scorer and no title: the saved canvas was cropped or grown to its content."""
    for name, dpi in (("f.pdf", []), ("f.svg", []), ("f.png", ["--dpi", "150"])):
        out = tmp_path / name
        code, _, err = _run(capsys, *base, "--out", out, *flags, *dpi)
        assert code == 0, err
        if out.suffix == ".png":
            with Image.open(out) as im:
                assert im.size[0] == round(width * 150), (flags, im.size)
        else:
            assert _page_inches(out) == pytest.approx(width, abs=1e-3), flags
