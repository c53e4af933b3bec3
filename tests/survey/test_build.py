"""survey build: the scene draw, what a panel shows and its scores, the study folder, blinding."""

import hashlib
import json

import numpy as np
import pytest
from helpers import _run
from starlette.testclient import TestClient
from survey.helpers import METHODS

from trajpref.cli import main
from trajpref.errors import ConfigError, DataError, TrajprefError
from trajpref.survey.build import BuildConfig, build_study, select_scenes
from trajpref.survey.manifest import (
    GROUND_TRUTH,
    MANIFEST,
    load_study,
)
from trajpref.survey.server import create_app
from trajpref.survey.store import AnswerStore
from trajpref.survey.study import (
    shown_predictions,
)


def test_select_scenes_is_seeded_and_stratified_by_size():
    sizes = np.array([1] * 40 + [2] * 30 + [3] * 20 + [5] * 10 + [12] * 5)  # [105]
    a = select_scenes(sizes, 9, seed=3, strata=3, max_agents=8)
    assert a == select_scenes(sizes, 9, seed=3, strata=3, max_agents=8)
    assert a != select_scenes(sizes, 9, seed=4, strata=3, max_agents=8)
    idx = [i for i, _ in a]
    assert len(set(idx)) == 9 and all(sizes[i] <= 8 for i in idx)  # 12-agent scenes excluded
    # strata cut the eligible sizes {1: 40, 2: 30, 3: 20, 5: 10} by share: 1 | 2 | 3 and 5
    strata = {g: sorted({int(sizes[i]) for i, s in a if s == g}) for g in range(3)}
    assert strata[0] == [1] and strata[1] == [2] and set(strata[2]) <= {3, 5}
    assert [sum(s == g for _, s in a) for g in range(3)] == [3, 3, 3]  # equal allocation


def test_select_scenes_keeps_the_gap_and_says_when_it_cannot():
    sizes = np.full(100, 2)
    picks = [i for i, _ in select_scenes(sizes, 4, seed=0, min_gap=20)]
    assert all(abs(a - b) >= 20 for a in picks for b in picks if a != b)
    with pytest.raises(ConfigError, match="min-gap"):
        select_scenes(sizes, 6, seed=0, min_gap=20)  # at most 5 fit in 100 positions
    with pytest.raises(ConfigError, match="only 100 scenes"):
        select_scenes(sizes, 101)
    with pytest.raises(ConfigError, match="agents"):
        select_scenes(sizes, 1, min_agents=3)


def test_shown_predictions_picks_each_agents_top_samples_and_scores_them():
    # K = 3 samples, P = 2 agents, T_f = 2 steps
    pred = np.zeros((3, 2, 2, 2))
    pred[:, :, :, 0] = np.arange(3)[:, None, None]  # sample k is k metres off in x
    future = np.zeros((2, 2, 2))
    d_gt = np.ones((2, 2))  # [P, T_f]
    d_pred = np.array([[[2, 2], [1, 1]], [[1, 1], [4, 4]], [[3, 3], [2, 2]]], float)  # [K,P,T]
    s = shown_predictions(pred, d_pred, d_gt, future, top=2)
    # agent 0: residual sums 4, 2, 6 -> best samples 1 then 0; agent 1: 2, 8, 4 -> 0 then 2
    assert [(e["agent"], e["sample"], e["rank"]) for e in s.shown] == [
        (0, 1, 0),
        (0, 0, 1),
        (1, 0, 0),
        (1, 2, 1),
    ]
    assert s.shown[0]["ats"] == pytest.approx(1 - 2 / 2)  # agent ATS = 1 - sum d / sum d_gt
    # panel ATS: the shown residuals (2 + 4 + 2 + 4 = 12) over R = 2 times the truth's (4)
    assert s.ats == pytest.approx(1 - 12 / (2 * 4))
    assert s.fts == pytest.approx(1 - (1 + 2 + 1 + 2) / (2 * 2))
    assert s.ade == pytest.approx(np.mean([1, 0, 0, 2]))  # samples 1, 0, 0, 2 are k m off
    assert s.max_ats == pytest.approx(1 - 6 / 4)  # sample 0: sum 2+2+1+1 = 6
    assert s.paths.shape == (2, 2, 2, 2) and s.weights.shape == (2, 2)
    assert s.weights.max() <= 1 and s.weights[0, 0] == 1  # the best is darkest


def test_build_writes_a_blinded_study_whose_key_names_every_method(tiny_study):
    study = load_study(tiny_study)
    assert len(study.scenes) == 3 and study.methods == (GROUND_TRUTH, *METHODS)
    for scene in study.scenes:
        assert sorted(p.key.method for p in scene.panels) == sorted(study.methods)
        assert [p.id for p in scene.panels] == ["A", "B", "C"]
        for p in scene.panels:
            assert (tiny_study / "images" / p.image).read_bytes()[:4] == b"\x89PNG"
            assert p.image == f"{scene.id}-{p.id}.png"  # the file name says nothing either
            if p.key.method == GROUND_TRUTH:
                assert p.key.ats == 0 and p.key.ade == 0
            else:
                assert len(p.key.shown) == 2 * scene.agents  # top-2 per agent
                assert np.isfinite([p.key.ats, p.key.fts, p.key.max_ats]).all()
    manifest = json.loads((tiny_study / "manifest.json").read_text())
    assert manifest["build"]["scorer"].endswith("generator.safetensors")  # the first checkpoint


def test_build_is_deterministic_under_a_seed(tiny_run, walks, tiny_study, tmp_path):
    cfg = BuildConfig(
        dataset=str(walks),
        units="m",
        scenes=3,
        samples=4,
        min_gap=0,
        device="cpu",
        models={METHODS[0]: "cv", METHODS[1]: str(tiny_run / "generator.safetensors")},
    )
    again = build_study(cfg, tmp_path / "again", progress=False)
    first = load_study(tiny_study)
    assert again.study_id == first.study_id  # same scenes, panels and hidden key
    assert [s.index for s in again.scenes] == [s.index for s in first.scenes]
    for a, b in zip(again.scenes, first.scenes, strict=True):
        assert [p.key for p in a.panels] == [p.key for p in b.panels]
    digest = lambda f: hashlib.sha256(f.read_bytes()).hexdigest()  # noqa: E731
    assert {f.name: digest(f) for f in (tmp_path / "again" / "images").iterdir()} == {
        f.name: digest(f) for f in (tiny_study / "images").iterdir()
    }
    other = build_study(BuildConfig(**{**cfg.__dict__, "seed": 1}), tmp_path / "s1", False)
    assert other.study_id != first.study_id


def _png_text(data: bytes) -> bytes:
    """The text chunks (tEXt, zTXt, iTXt) of a PNG: where a name could hide in an image."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, pos = b"", 8
    while pos < len(data):
        length = int.from_bytes(data[pos : pos + 4], "big")
        kind = data[pos + 4 : pos + 8]
        if kind in (b"tEXt", b"zTXt", b"iTXt"):
            out += data[pos + 8 : pos + 8 + length]
        pos += 12 + length
    return out


def test_the_images_have_no_text_chunk(tiny_study):
    # docs/survey.md, "Blinding", says so (they are written uncompressed, chunk by chunk)
    for image in (tiny_study / "images").iterdir():
        assert _png_text(image.read_bytes()) == b""


def test_the_served_page_never_names_a_method(tiny_study, tmp_path):
    study = load_study(tiny_study)
    store = AnswerStore(tmp_path / "a.sqlite", study)
    client = TestClient(create_app(study, store))
    bodies = [
        client.get(u).content
        for u in ("/", "/static/app.js", "/static/style.css", "/api/study", "/api/raters/r1")
    ]
    images = [client.get(f"/images/{name}") for name in study.image_files()]
    assert len(images) == 9 and all(r.status_code == 200 for r in images)
    bodies += [_png_text(r.content) for r in images]
    for body in bodies:
        for name in (*METHODS, GROUND_TRUTH, "generator", "safetensors", "truth"):
            assert name.encode() not in body.lower()
    public = client.get("/api/study").json()
    assert [p["id"] for p in public["scenes"][0]["panels"]] == ["A", "B", "C"]
    assert set(public["scenes"][0]) == {"id", "reference", "panels"}
    store.close()


def test_build_refuses_to_overwrite_and_leaves_nothing_on_failure(
    tiny_study, tiny_run, walks, tmp_path
):
    cfg = BuildConfig(
        dataset=str(walks),
        models={"a": "cv"},
        scorer="missing.safetensors",
        min_gap=0,
        scenes=2,
        device="cpu",
    )
    with pytest.raises(ConfigError, match="already exists"):
        build_study(cfg, tiny_study, progress=False)
    with pytest.raises(TrajprefError):
        build_study(cfg, tmp_path / "new", progress=False)  # no such scorer
    assert not (tmp_path / "new").exists() and list(tmp_path.iterdir()) == []
    with pytest.raises(ConfigError, match="--scorer"):
        build_study(BuildConfig(**{**cfg.__dict__, "scorer": None}), tmp_path / "n", False)
    with pytest.raises(DataError):
        build_study(
            BuildConfig(
                **{
                    **cfg.__dict__,
                    "dataset": str(tmp_path / "nothing"),
                    "scorer": str(tiny_run / "denoiser.safetensors"),
                }
            ),
            tmp_path / "n",
            False,
        )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "change, message",
    [
        ({"models": {}}, "at least one"),
        ({"models": {"ground truth": "cv"}}, "reserved"),
        ({"models": {"a/b": "cv"}}, "bad method name"),
        ({"top": 5, "samples": 4}, "exceeds"),
        ({"scenes": 0}, "scenes"),
        ({"max_agents": 0}, "max-agents"),
        ({"ground_truth": "hidden"}, "ground-truth"),
    ],
)
def test_build_config_checks_its_values(change, message):
    with pytest.raises(ConfigError, match=message):
        BuildConfig(**{"dataset": "zara1", "models": {"a": "cv"}, **change})


def test_a_study_folder_is_owner_only_whatever_the_umask(tmp_path):
    import os

    from trajpref.survey.study import make_synthetic_study

    old = os.umask(0o002)  # a shared-group umask: 0775 folders
    try:
        (tmp_path / "empty").mkdir()  # an existing empty --out is replaced
        for out in (tmp_path / "new", tmp_path / "empty"):
            study = make_synthetic_study(out, scenes=1)
            assert oct(study.folder.stat().st_mode & 0o777) == "0o700"
    finally:
        os.umask(old)


# ---- review of walkthrough 66: a built-in dataset's ignored options are warned of once -------


def test_read_data_gives_the_frame_interval_and_units_to_a_folder_dataset_only(monkeypatch, walks):
    from trajpref.survey import build

    calls = []

    def fake_load(name, split, root, frame_interval, units, **kwargs):
        calls.append((name, split, frame_interval, units))
        return split

    monkeypatch.setattr(build, "load_dataset", fake_load)
    monkeypatch.setattr(build, "hold_out_scene", lambda train, val, scene: (train, val))
    cfg = BuildConfig(dataset="zara1", models={"a": "cv"}, units="m", frame_interval=0.4,
                      split="val", holdout_scene="crowds_zara02")  # fmt: skip
    assert build.read_data(cfg) == "val"
    assert calls == [("zara1", "train", None, None), ("zara1", "val", None, None)]
    calls.clear()
    cfg = BuildConfig(dataset=str(walks), models={"a": "cv"}, units="m", frame_interval=0.4)
    build.read_data(cfg)
    assert calls == [(str(walks), "test", 0.4, "m")]


def test_survey_build_warns_once_of_a_built_in_datasets_ignored_options(
    capsys, data_root, tmp_path
):
    from trajpref.cli import main

    code = main(["survey", "build", "--dataset", "zara1", "--units", "m", "--frame-interval",
                 "0.4", "--split", "val", "--holdout-scene", "crowds_zara02", "--models",
                 "a=cv", "--scorer", "zara1/denoiser", "--scenes", "2", "--samples", "2",
                 "--data-root", str(data_root), "--no-progress",
                 "--out", str(tmp_path / "s")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 0, err
    assert err.count("describe a folder dataset") == 1, err
    assert "--frame-interval and --units describe a folder dataset" in err


# Walkthrough 63-B's survey findings: the analysis of an unfinished pilot, the ground truth
# above the best method, unknown units, the study's reproducibility record, consent, rater ids
# in the access log, and the export's details.


def test_build_warns_of_unknown_units_names_the_models_units_and_records_hashes(
    capsys, walks, tmp_path, saved_labels
):
    consent = tmp_path / "consent.txt"
    consent.write_text("I agree to take part.\n\nMy answers are kept for a year.\n")
    out = tmp_path / "study"
    code, _, err = _run(capsys, "survey", "build", "--dataset", walks, "--models", "c=cv",
                        "gen=zara1/generator", "--scorer", "zara1/denoiser", "--scenes", "1",
                        "--samples", "2", "--min-gap", "0", "--device", "cpu", "--no-progress",
                        "--consent", consent, "--out", out)  # fmt: skip
    assert code == 0
    assert (f"trajpref: warning: {walks}: the data's units are unknown (no --units): the raters' "
            "pictures show axes without a unit and the analysis gives ADE/FDE in unknown units; "
            "the models recorded units m (zara1/generator, zara1/denoiser): pass --units m"
            ) in err  # fmt: skip
    assert saved_labels and {t for t, _ in saved_labels} == {"x", "y"}  # no "x [unknown]"
    study = load_study(out)
    build = json.loads((out / MANIFEST).read_text())["build"]
    assert build["study_id"] == study.study_id
    assert build["trajpref_version"] and build["torch_version"]
    methods = build["hashes"]["methods"]
    assert methods["c"] == {"weights_hash": None, "model_hash": None}
    assert len(methods["gen"]["weights_hash"]) == 16 and len(methods["gen"]["model_hash"]) == 12
    assert build["hashes"]["scorer"]["weights_hash"]
    assert "consent" not in build  # the text is the manifest's own key
    assert study.consent == "I agree to take part.\n\nMy answers are kept for a year."


# Walkthrough 66's survey findings: every rater saw the scenes and panels in one order (a
# position effect fell on the same method for every rater), and the ground truth's PNG was the
# smallest of its scene (a rater comparing image sizes could find it). Now each rater sees an
# order of their own, each answer is stored with where it was shown, analyze checks for a
# position effect, and the pictures of a scene have one byte size.


def test_build_fixed_order_writes_a_fixed_study(tmp_path, tiny_run, walks, capsys):
    out = tmp_path / "fixed"
    code = main(["survey", "build", "--dataset", str(walks), "--units", "m", "--models",
                 "a=cv", f"b={tiny_run / 'generator.safetensors'}", "--scenes", "2",
                 "--samples", "2", "--min-gap", "0", "--device", "cpu", "--no-progress",
                 "--fixed-order", "--out", str(out)])  # fmt: skip
    assert code == 0
    study = load_study(out)
    assert study.order == "fixed" and study.build["fixed_order"] is True
    assert json.loads((out / MANIFEST).read_text())["order"] == "fixed"
    assert study.rater_order("x") == study.rater_order("y")
