"""The study folder as written: the raters' pictures, their axes and their bytes."""

import io
import zlib

import numpy as np
import pytest
from PIL import Image
from survey.helpers import METHODS, _write

from trajpref.survey.manifest import (
    GROUND_TRUTH,
    load_study,
)
from trajpref.survey.study import (
    SceneData,
    ground_truth_panel,
    make_synthetic_study,
    png_chunks,
    scene_limits,
    shown_predictions,
    stored_png,
    write_study,
)
from trajpref.viz.plot import plot_panel

# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


# ---- finding 6: unknown units ---------------------------------------------------------


@pytest.mark.parametrize("units", ["unknown", ""])
def test_the_rater_pictures_of_data_in_unknown_units_show_no_unit(tmp_path, saved_labels, units):
    _write(tmp_path / "study", units=units)
    assert len(saved_labels) == 2 * 4  # 2 scenes x 2 panels, x and y
    visible = [text for text, colour in saved_labels if colour != "none"]
    assert visible == []  # before: "x [unknown]", "y [unknown]" on every picture


def test_the_rater_pictures_of_data_in_metres_name_the_unit(tmp_path, saved_labels):
    _write(tmp_path / "study", units="m")
    assert {t for t, c in saved_labels if c != "none"} == {"x [m]", "y [m]"}


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


# ---- 6. the pictures of a scene have one byte size -----------------------------------------


def _decode(data: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


def _layout(data: bytes) -> list[tuple[bytes, int]]:
    """A PNG's chunks as (type, length): everything of its bytes but the pixels."""
    return [(kind, len(body)) for kind, body, _ in png_chunks(data)]


@pytest.mark.parametrize("which", ["tiny", "reference"])
def test_a_scenes_pictures_have_one_size_and_one_chunk_layout(which, tiny_study, tmp_path):
    """Review of walkthrough 66: a zero-filled padding chunk gave every picture one size, but
    its length (and IDAT's) still told the ground truth's (the smallest IDAT, the most
    padding) in every scene: now no chunk length differs, and the pixels are stored, not
    compressed."""
    folder = (tiny_study if which == "tiny" else make_synthetic_study(
        tmp_path / "ref", scenes=2, methods=METHODS, ground_truth="reference").folder)  # fmt: skip
    study = load_study(folder)
    for s in study.scenes:
        files = [folder / "images" / p.image for p in s.panels]
        files += [folder / "images" / s.reference] if s.reference else []
        data = [f.read_bytes() for f in files]
        assert len({len(d) for d in data}) == 1, [len(d) for d in data]
        layouts = [_layout(d) for d in data]  # well formed, every CRC right
        assert all(lay == layouts[0] for lay in layouts), layouts
        assert [k for k, _ in layouts[0]] == [b"IHDR", b"IDAT", b"IEND"]  # no text chunk
        for d in data:
            chunks = dict((k, body) for k, body, _ in png_chunks(d))
            w, h = int.from_bytes(chunks[b"IHDR"][:4], "big"), int.from_bytes(
                chunks[b"IHDR"][4:8], "big")  # fmt: skip
            assert chunks[b"IHDR"][8:] == bytes([8, 2, 0, 0, 0])  # 8-bit RGB
            raw = zlib.decompress(chunks[b"IDAT"])
            assert len(raw) == h * (1 + 3 * w)
            assert chunks[b"IDAT"] == zlib.compress(raw, 0)  # deflate stored blocks
            assert _decode(d).shape == (h, w, 3)


def test_stored_pictures_keep_the_pixels_of_the_render(tmp_path):
    """The uncompressed pictures decode to the pixels matplotlib drew (its PNG's, opaque)."""
    rng = np.random.default_rng(3)
    history = rng.normal(0, 1, (3, 8, 2)).cumsum(1)  # [P, T_h, 2]
    future = history[:, -1:] + rng.normal(0, 1, (3, 12, 2)).cumsum(1)  # [P, T_f, 2]
    pred = future[None] + rng.normal(0, 0.3, (6, 3, 12, 2)).cumsum(2)  # [K, P, T_f, 2]
    d_pred = 1 + rng.random((6, 3, 12))  # [K, P, T_f]
    panels = {"alpha": shown_predictions(pred, d_pred, np.ones((3, 12)), future, 2),
              GROUND_TRUTH: ground_truth_panel(future)}  # fmt: skip
    scene = SceneData(history, future, panels, "made#0", 0, 0)
    study = write_study(tmp_path / "s", [scene], [GROUND_TRUTH, "alpha"])
    limits = scene_limits(history, future, list(panels.values()))
    for p in study.scenes[0].panels:
        shown = panels[p.key.method]
        plot_panel(history, shown.paths, shown.weights, tmp_path / "own.png", limits, "m")
        drawn = np.asarray(Image.open(tmp_path / "own.png").convert("RGBA"))
        assert (drawn[..., 3] == 255).all()  # opaque: RGB loses nothing
        assert np.array_equal(_decode((study.folder / "images" / p.image).read_bytes()),
                              drawn[..., :3])  # fmt: skip


def test_a_stored_png_is_a_function_of_its_pixel_size_alone():
    a = stored_png(np.zeros((40, 30, 3), np.uint8))
    b = stored_png(np.random.default_rng(0).integers(0, 256, (40, 30, 3), dtype=np.uint8))
    assert len(a) == len(b) and _layout(a) == _layout(b)
    assert np.array_equal(_decode(b), np.asarray(Image.open(io.BytesIO(b))))
    with pytest.raises(ValueError, match="wrong CRC"):
        png_chunks(a[:-5] + b"\x00" + a[-4:])


def test_a_panel_of_unknown_units_hides_its_axis_titles_without_touching_rcparams(
    tmp_path, monkeypatch
):
    """The study's panels of data without a unit keep the axis titles' room but draw them in
    no colour: the same image as matplotlib's ``axes.labelcolor: none`` gave, now without
    ``rc_context``, which sets (and puts back) every key for the whole process."""
    import matplotlib as mpl

    from trajpref.survey.study import _panel_image

    rng = np.random.default_rng(0)
    history = np.cumsum(rng.normal(0, 0.3, (2, 8, 2)), 1)  # [P, T_h, 2]
    paths = history[None, :, -1:] + np.cumsum(rng.normal(0, 0.3, (3, 2, 12, 2)), 2)
    weights = np.linspace(1, 0, 3)[:, None].repeat(2, 1)  # [R, P]
    limits = (-5.0, 5.0, -5.0, 5.0)
    with mpl.rc_context({"axes.labelcolor": "none"}):  # how the panel was drawn before
        before = plot_panel(history, paths, weights, tmp_path / "before.png", limits, "")

    def refused(*args, **kwargs):
        raise AssertionError("rc_context: process-wide")

    monkeypatch.setattr(mpl, "rc_context", refused)
    out = tmp_path / "now.png"
    _panel_image(history, paths, weights, out, limits, "unknown")
    assert out.read_bytes() == before.read_bytes()
    shown = tmp_path / "shown.png"
    _panel_image(history, paths, weights, shown, limits, "m")  # titles drawn where units known
    assert shown.read_bytes() != out.read_bytes()
