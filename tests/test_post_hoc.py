"""benchmarks/post_hoc.py: which published generators a post-training setting study covers, the
payload copy it evaluates a setting on, and its ``--apply`` step, which writes nothing unless
the stored decision allows it."""

import json

import pytest
from bench import load_benchmark
from synthetic import TINY_OVERRIDES

from trajpref.config import load_config
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator


@pytest.fixture
def models(tmp_path):
    """models/{a,b}/generator.safetensors and models/a/generator-long.safetensors; c is empty."""
    cfg = load_config(None, TINY_OVERRIDES)
    den = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 1.0, {})
    payload = ckpt.generator_payload(Generator(cfg.model), den, cfg, {})
    root = tmp_path / "models"
    for name in ("a/generator", "a/generator-long", "b/generator"):
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        ckpt.save(root / f"{name}.safetensors", payload)
    (root / "c").mkdir()
    return root


def test_the_covered_generators_are_every_file_or_only_the_defaults_of_the_named_folders(models):
    ph = load_benchmark("post_hoc")
    names = [(d, p.name) for d, p in ph.published_generators(models)]
    assert names == [("a", "generator-long.safetensors"), ("a", "generator.safetensors"),
                     ("b", "generator.safetensors")]  # fmt: skip
    only = ph.published_generators(models, ["b", "a"], variants=False)
    assert [(d, p.name) for d, p in only] == [("a", "generator.safetensors"),
                                              ("b", "generator.safetensors")]  # fmt: skip
    with pytest.raises(SystemExit, match="no published models for zz"):
        ph.published_generators(models, ["a", "zz"])


def _study(path, allowed: bool) -> dict:
    """A stored study as ``write_study`` writes it, read back."""
    rows = [{"checkpoint": "models/a/generator.safetensors", "max_speed": 0.25},
            {"checkpoint": "models/b/generator.safetensors", "max_speed": 0.5}]  # fmt: skip
    path.write_text(json.dumps({"rows": rows, "decision": {"apply": allowed}}))
    return json.loads(path.read_text())


def test_apply_writes_each_rows_value_only_when_the_decision_allows_it(models, tmp_path):
    ph = load_benchmark("post_hoc")
    study = tmp_path / "study.json"
    stored = _study(study, allowed=False)
    assert ph.apply_setting(tmp_path, stored, "apply", "max_speed", lambda r: r["max_speed"],
                            "n") == []  # fmt: skip
    assert ckpt.config_of(ckpt.load(models / "a" / "generator.safetensors")).model.max_speed == 0
    stored = _study(study, allowed=True)
    done = ph.apply_setting(tmp_path, stored, "apply", "max_speed", lambda r: r["max_speed"], "n")
    assert done == [("models/a/generator.safetensors", True),
                    ("models/b/generator.safetensors", True)]  # fmt: skip
    speeds = [ckpt.config_of(ckpt.load(models / d / "generator.safetensors")).model.max_speed
              for d in "ab"]  # fmt: skip
    assert speeds == [0.25, 0.5]
    # the variant no row names is untouched, and a second apply changes nothing
    assert (
        ckpt.config_of(ckpt.load(models / "a" / "generator-long.safetensors")).model.max_speed == 0
    )
    again = ph.apply_setting(tmp_path, stored, "apply", "max_speed", lambda r: r["max_speed"], "n")
    assert [changed for _, changed in again] == [False, False]


def test_a_study_record_names_its_machine_command_and_split(tmp_path):
    ph = load_benchmark("post_hoc")
    out = tmp_path / "meta" / "x_val.json"
    ph.write_study(out, "python x.py", [{"a": 1}], {"apply": True}, seed=3)
    record = json.loads(out.read_text())
    assert record["split"] == "val" and record["command"] == "python x.py"
    assert record["seed"] == 3 and record["rows"] == [{"a": 1}] and record["machine"]


def test_with_model_setting_copies_the_config_and_leaves_the_payload_alone():
    ph = load_benchmark("post_hoc")
    payload = {"config": {"model": {"spread_scale": 1.0, "hidden": 8}, "seed": 0}, "kind": "g"}
    out = ph.with_model_setting(payload, "spread_scale", 1.2)
    assert out["config"]["model"] == {"spread_scale": 1.2, "hidden": 8}
    assert payload["config"]["model"]["spread_scale"] == 1.0 and out["kind"] == "g"
