import json
import re
import warnings

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file
from synthetic import TINY_OVERRIDES, make_scene

from trajpref.config import load_config, to_dict
from trajpref.errors import ConfigError, TrajprefError
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.models.generator import Generator
from trajpref.types import collate


@pytest.fixture(scope="module")
def cfg():
    return load_config(None, TINY_OVERRIDES)


def _denoiser(cfg, seed: int = 0) -> Denoiser:
    torch.manual_seed(seed)
    return Denoiser(cfg.model)


def _generator(cfg, seed: int = 1) -> Generator:
    torch.manual_seed(seed)
    return Generator(cfg.model)


def _outputs(model: Denoiser) -> torch.Tensor:
    """The denoiser's eps on a fixed tiny batch: [K=2, N=5, T_f, 2]."""
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    y = torch.randn(2, 5, 12, 2, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        return model(y, 3, model.context(scene_features(batch, 0.7)))


def _header(path) -> dict:
    with safe_open(str(path), "pt") as fh:
        return json.loads(fh.metadata()["trajpref"])


def _assert_same_state(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        assert torch.equal(a[key], b[key]), key


# ----------------------------------------------------------------------------- denoiser


def test_denoiser_round_trip_is_exact(tmp_path, cfg):
    model = _denoiser(cfg)
    payload = ckpt.denoiser_payload(model, cfg, scale=0.7, meta={"epoch": 1})
    ckpt.save(tmp_path / "d.safetensors", payload)
    loaded = ckpt.load(tmp_path / "d.safetensors")

    _assert_same_state(loaded["state_dict"], model.state_dict())
    assert loaded["kind"] == "denoiser" and loaded["format"] == ckpt.FORMAT
    assert loaded["scale"] == 0.7
    assert loaded["meta"] == {"epoch": 1}
    assert ckpt.config_of(loaded) == cfg
    assert loaded["hash"] == ckpt.state_hash(model.state_dict())

    rebuilt, rebuilt_cfg = ckpt.build_denoiser(loaded)
    assert rebuilt_cfg == cfg
    assert torch.equal(_outputs(rebuilt), _outputs(model))


def test_loaded_weights_are_those_at_save_time(tmp_path, cfg):
    model = _denoiser(cfg)
    at_save = {k: v.clone() for k, v in model.state_dict().items()}
    ckpt.save(tmp_path / "d.safetensors", ckpt.denoiser_payload(model, cfg, 0.7, {}))
    with torch.no_grad():
        for p in model.parameters():
            p.add_(torch.randn_like(p))  # training goes on after the save

    loaded = ckpt.load(tmp_path / "d.safetensors")
    _assert_same_state(loaded["state_dict"], at_save)
    assert not torch.equal(loaded["state_dict"]["out.1.weight"], model.out[1].weight)
    rebuilt, _ = ckpt.build_denoiser(loaded)
    fresh = _denoiser(cfg, seed=123)
    assert not torch.allclose(_outputs(fresh), _outputs(rebuilt))
    assert not torch.allclose(_outputs(model), _outputs(rebuilt))


def test_altered_weights_fail_the_hash_check(tmp_path, cfg):
    ckpt.save(tmp_path / "d.safetensors", ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {}))
    loaded = ckpt.load(tmp_path / "d.safetensors")
    loaded["state_dict"]["inp.bias"][0] += 1e-3
    with pytest.raises(TrajprefError, match="hash"):
        ckpt.build_denoiser(loaded)


def test_half_precision_save(tmp_path, cfg):
    model = _denoiser(cfg)
    ckpt.save(tmp_path / "h.safetensors", ckpt.denoiser_payload(model, cfg, 0.7, {}), half=True)
    with safe_open(str(tmp_path / "h.safetensors"), "pt") as fh:
        assert fh.get_tensor("model/inp.weight").dtype == torch.float16  # on disk
    loaded = ckpt.load(tmp_path / "h.safetensors")
    state = model.state_dict()
    assert sorted(loaded["state_dict"]) == sorted(state)
    for key, value in loaded["state_dict"].items():
        assert value.dtype == state[key].dtype, key  # float32 again
        torch.testing.assert_close(value, state[key], rtol=1e-3, atol=1e-4)
    assert loaded["hash"] == ckpt.state_hash(loaded["state_dict"])
    assert loaded["hash"] != ckpt.state_hash(state)  # it hashes the rounded weights
    ckpt.build_denoiser(loaded)  # passes its own hash check


def test_save_needs_the_safetensors_suffix(tmp_path, cfg):
    payload = ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {})
    for name in ("d.pt", "d.bin", "d"):
        with pytest.raises(TrajprefError, match="safetensors"):
            ckpt.save(tmp_path / name, payload)
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- generator


def test_generator_payload_embeds_its_denoiser(tmp_path, cfg):
    den, gen = _denoiser(cfg), _generator(cfg)
    den_payload = ckpt.denoiser_payload(den, cfg, 0.7, {"epoch": 2})
    payload = ckpt.generator_payload(gen, den_payload, cfg, {"epoch": 5}, critic=None)
    ckpt.save(tmp_path / "g.safetensors", payload)
    loaded = ckpt.load(tmp_path / "g.safetensors")

    assert loaded["kind"] == "generator" and loaded["scale"] == 0.7
    assert loaded["meta"] == {"epoch": 5} and "critic" not in loaded
    _assert_same_state(loaded["state_dict"], gen.state_dict())
    assert ckpt.denoiser_of(loaded)["meta"] == {"epoch": 2}
    _assert_same_state(ckpt.denoiser_of(loaded)["state_dict"], den.state_dict())
    rebuilt, _ = ckpt.build_generator(loaded)
    _assert_same_state(rebuilt.state_dict(), gen.state_dict())
    with pytest.raises(TrajprefError, match="expected a denoiser"):
        ckpt.build_denoiser(loaded)


def test_generator_payload_keeps_a_critic(tmp_path, cfg):
    critic = torch.nn.Linear(3, 1)
    payload = ckpt.generator_payload(_generator(cfg), ckpt.denoiser_payload(
        _denoiser(cfg), cfg, 0.7, {}), cfg, {}, critic=critic)  # fmt: skip
    ckpt.save(tmp_path / "g.safetensors", payload)
    _assert_same_state(ckpt.load(tmp_path / "g.safetensors")["critic"], critic.state_dict())


def test_a_finetuned_generator_records_its_reward_in_its_metadata(tmp_path, cfg):
    den = ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {})
    set_cfg = load_config(None, [*TINY_OVERRIDES, "finetune.reward=set"])
    for method, want in (("rlhf", "set"), ("rlhf-res", "set"), ("control", None)):
        meta = {"epoch": 1, "method": method, "from": "abc"}
        ckpt.save(tmp_path / "f.safetensors", ckpt.generator_payload(_generator(cfg), den,
                                                                     set_cfg, meta))  # fmt: skip
        header = _header(tmp_path / "f.safetensors")
        assert header["meta"] == {**meta, "reward": want}, method  # the file alone says it
        assert ckpt.finetune_reward(header) == want
        assert ckpt.finetune_reward(ckpt.load(tmp_path / "f.safetensors")) == want
    # a generator that is no fine-tune gets no reward field (pretraining's meta is as given)
    plain = ckpt.generator_payload(_generator(cfg), den, set_cfg, {"epoch": 1})
    assert plain["meta"] == {"epoch": 1} and ckpt.finetune_reward(plain) is None
    # a reward the caller records itself is kept
    given = ckpt.generator_payload(
        _generator(cfg), den, set_cfg, {"method": "rlhf", "reward": "sda"}
    )
    assert given["meta"]["reward"] == "sda"


def test_a_finetuned_file_written_before_the_reward_was_recorded_still_loads(tmp_path, cfg):
    den = ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {})
    sda_cfg = load_config(None, [*TINY_OVERRIDES, "finetune.reward=sda"])
    payload = ckpt.generator_payload(_generator(cfg), den, sda_cfg, {"method": "rlhf"})
    del payload["meta"]["reward"]  # as written before meta.reward existed
    path = tmp_path / "old.safetensors"
    ckpt.save(path, payload)
    loaded = ckpt.load(path)
    assert "reward" not in loaded["meta"] and ckpt.build_generator(loaded)[0] is not None
    assert ckpt.finetune_reward(loaded) == "sda"  # from its config's finetune section
    # older still: a config without finetune.reward (the diffusion score was the only reward)
    del payload["config"]["finetune"]["reward"]
    ckpt.save(path, payload)
    loaded = ckpt.load(path)
    assert ckpt.config_of(loaded).finetune.reward == "score"
    assert ckpt.finetune_reward(_header(path)) == "score" == ckpt.finetune_reward(loaded)
    payload["meta"]["method"] = "control"
    assert ckpt.finetune_reward(payload) is None


def _publish_generator(tmp_path, cfg, gen_seed: int, den_seed: int = 0, name: str = "g"):
    src = tmp_path / "run" / f"{name}.safetensors"
    den_payload = ckpt.denoiser_payload(_denoiser(cfg, den_seed), cfg, 0.7, {})
    ckpt.save(src, ckpt.generator_payload(_generator(cfg, gen_seed), den_payload, cfg, {}))
    return src


def test_publish_writes_the_denoiser_once_and_names_it(tmp_path, cfg):
    pub = tmp_path / "pub"
    ckpt.publish(_publish_generator(tmp_path, cfg, 1, name="a"), pub / "a.safetensors")
    den_file = pub / ckpt.DENOISER_NAME
    assert den_file.is_file()
    inode = den_file.stat().st_ino

    header = _header(pub / "a.safetensors")
    assert "denoiser" not in header
    assert header["denoiser_ref"] == {"path": ckpt.DENOISER_NAME, "hash": _header(den_file)["hash"]}
    with safe_open(str(pub / "a.safetensors"), "pt") as fh:
        assert not [k for k in fh.keys() if k.startswith("denoiser/")]

    # a second generator over the same denoiser leaves the denoiser file alone
    ckpt.publish(_publish_generator(tmp_path, cfg, 2, name="b"), pub / "b.safetensors")
    assert den_file.stat().st_ino == inode

    loaded = ckpt.load(pub / "b.safetensors")  # the denoiser is loaded in by reference
    den = _denoiser(cfg).state_dict()
    for key, value in ckpt.denoiser_of(loaded)["state_dict"].items():
        torch.testing.assert_close(value, den[key], rtol=1e-3, atol=1e-4)
    pred = ckpt.load_predictor(pub / "b.safetensors")
    assert pred.predict(collate([make_scene(2)]), 4).shape == (4, 2, 12, 2)


def test_publish_refuses_to_replace_a_different_denoiser(tmp_path, cfg):
    pub = tmp_path / "pub"
    ckpt.publish(_publish_generator(tmp_path, cfg, 1, name="a"), pub / "a.safetensors")
    other = _publish_generator(tmp_path, cfg, 2, den_seed=9, name="b")
    with pytest.raises(ckpt.DenoiserConflict):
        ckpt.publish(other, pub / "b.safetensors")
    assert not (pub / "b.safetensors").exists()
    ckpt.publish(other, pub / "b.safetensors", denoiser_name="denoiser-b.safetensors")
    assert _header(pub / "b.safetensors")["denoiser_ref"]["path"] == "denoiser-b.safetensors"
    ckpt.load(pub / "a.safetensors")  # still consistent


def test_a_tampered_denoiser_is_refused(tmp_path, cfg):
    pub = tmp_path / "pub"
    ckpt.publish(_publish_generator(tmp_path, cfg, 1), pub / "g.safetensors")
    impostor = ckpt.denoiser_payload(_denoiser(cfg, seed=9), cfg, 0.7, {})  # valid own hash
    ckpt.save(pub / ckpt.DENOISER_NAME, impostor, half=True)
    with pytest.raises(TrajprefError, match="does not match the recorded hash"):
        ckpt.load(pub / "g.safetensors")


def test_a_published_generator_copied_without_its_denoiser_says_what_to_copy(tmp_path, cfg):
    import shutil

    pub = tmp_path / "pub"
    ckpt.publish(_publish_generator(tmp_path, cfg, 1), pub / "g.safetensors")
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(pub / "g.safetensors", alone / "g.safetensors")
    with pytest.raises(TrajprefError, match=rf"needs {ckpt.DENOISER_NAME} \(hash .*\) beside it"):
        ckpt.load(alone / "g.safetensors")
    shutil.copy(pub / ckpt.DENOISER_NAME, alone / ckpt.DENOISER_NAME)
    assert ckpt.load(alone / "g.safetensors")["denoiser"]["kind"] == "denoiser"


def test_a_denoiser_named_by_its_old_pt_name_is_found_as_safetensors(tmp_path, cfg):
    # generators published before the .safetensors switch name "denoiser.pt"; beside the
    # converted denoiser they still load, with the rename's warning
    pub = tmp_path / "pub"
    ckpt.publish(_publish_generator(tmp_path, cfg, 1), pub / "g.safetensors")
    payload = ckpt._read_file(pub / "g.safetensors")
    payload["denoiser_ref"] = {**payload["denoiser_ref"], "path": "denoiser.pt"}
    ckpt.save(pub / "old.safetensors", payload, half=True)
    with pytest.warns(FutureWarning, match="is now"):
        assert ckpt.load(pub / "old.safetensors")["denoiser"]["kind"] == "denoiser"


# ----------------------------------------------------------------------------- legacy


def test_legacy_pt_checkpoint_still_loads(tmp_path, cfg):
    model = _denoiser(cfg)
    state = {k: v.clone() for k, v in model.state_dict().items()}
    old = to_dict(cfg)
    old["generator"]["samples"] = old["model"].pop("samples")  # the old layout ...
    old["generator"]["tau"] = old["model"].pop("tau")
    old["generator"]["samples"] = 3  # ... with a K that differs from today's default
    legacy = {"format": ckpt.LEGACY_FORMAT, "kind": "denoiser", "config": old, "scale": 0.7,
              "state_dict": state, "hash": ckpt.state_hash(state), "meta": {}}  # fmt: skip
    torch.save(legacy, tmp_path / "old.pt")

    with pytest.warns(FutureWarning, match="legacy"):
        payload = ckpt.load(tmp_path / "old.pt")
    with warnings.catch_warnings():  # the old config layout may warn again (or was upgraded)
        warnings.simplefilter("ignore", FutureWarning)
        assert ckpt.config_of(payload).model.samples == 3
        rebuilt, rebuilt_cfg = ckpt.build_denoiser(payload)
    assert rebuilt_cfg.model.tau == cfg.model.tau
    _assert_same_state(payload["state_dict"], model.state_dict())
    assert torch.equal(_outputs(rebuilt), _outputs(model))


def test_legacy_path_resolves_to_the_safetensors_file(tmp_path, cfg):
    model = _denoiser(cfg)
    ckpt.save(tmp_path / "x.safetensors", ckpt.denoiser_payload(model, cfg, 0.7, {}))
    with pytest.warns(FutureWarning, match="x.safetensors"):
        payload = ckpt.load(tmp_path / "x.pt")
    _assert_same_state(payload["state_dict"], model.state_dict())


# ----------------------------------------------------------------------------- bad files


def test_missing_file(tmp_path):
    for name in ("nope.safetensors", "nope.pt"):
        with pytest.raises(TrajprefError, match="no such checkpoint"):
            ckpt.load(tmp_path / name)


@pytest.mark.parametrize(
    "content",
    [b"", b"garbage bytes, not a checkpoint", (20).to_bytes(8, "little") + b"{not json" * 4],
    ids=["empty", "garbage", "bad-header"],
)
def test_garbage_is_a_trajpref_error(tmp_path, content):
    (tmp_path / "bad.safetensors").write_bytes(content)
    with pytest.raises(TrajprefError, match="not a trajpref checkpoint"):
        ckpt.load(tmp_path / "bad.safetensors")
    (tmp_path / "bad.pt").write_bytes(content)
    with warnings.catch_warnings():  # a broken .pt is one error, not a "legacy" warning first
        warnings.simplefilter("error")
        with pytest.raises(TrajprefError):
            ckpt.load(tmp_path / "bad.pt")


@pytest.mark.parametrize(
    "metadata",
    [None, {"other": "x"}, {"trajpref": "{not json"}, {"trajpref": '{"format": "other/9"}'},
     {"trajpref": "[1, 2]"}],
    ids=["none", "no-trajpref", "bad-json", "wrong-format", "not-a-mapping"],
)  # fmt: skip
def test_safetensors_without_the_trajpref_header(tmp_path, metadata):
    path = tmp_path / "plain.safetensors"
    save_file({"model/w": torch.zeros(2)}, str(path), metadata=metadata)
    with pytest.raises(TrajprefError, match="not a trajpref checkpoint"):
        ckpt.load(path)


def test_legacy_file_missing_fields_is_a_trajpref_error(tmp_path):
    torch.save({"format": "trajpref-checkpoint/1", "kind": "denoiser"}, tmp_path / "x.pt")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TrajprefError, match="without config"):
            ckpt.load(tmp_path / "x.pt")


def test_unknown_kind_is_refused(tmp_path, cfg):
    payload = ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {})
    payload["kind"] = "critic"
    ckpt.save(tmp_path / "c.safetensors", payload)
    with pytest.raises(TrajprefError, match="unknown checkpoint kind"):
        ckpt.load(tmp_path / "c.safetensors")


# ----------------------------------------------------------------------------- sampling setting


def test_set_stochastic_steps_rewrites_only_the_setting(tmp_path, cfg):
    stochastic_cfg = load_config(None, [*TINY_OVERRIDES, "model.stochastic_steps=true"])
    src = tmp_path / "run" / "g.safetensors"
    den = ckpt.denoiser_payload(_denoiser(stochastic_cfg), stochastic_cfg, 0.7, {})
    gen = ckpt.generator_payload(_generator(stochastic_cfg), den, stochastic_cfg, {"epoch": 3})
    ckpt.save(src, gen)
    pub = tmp_path / "pub" / "g.safetensors"
    ckpt.publish(src, pub)  # half precision, denoiser by reference
    with safe_open(str(pub), "pt") as fh:
        before = {k: fh.get_tensor(k) for k in fh.keys()}
    header_before = _header(pub)
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    old = ckpt.load_predictor(pub)
    assert old.stochastic
    old.stochastic = False  # what --deterministic does at evaluation
    expected = old.predict(batch, 4, torch.Generator().manual_seed(5))

    assert ckpt.set_stochastic_steps(pub, False, note="test switch", date="2026-11-24")
    header = _header(pub)
    assert header["config"]["model"]["stochastic_steps"] is False
    assert header["hash"] == header_before["hash"]
    assert header["denoiser_ref"] == header_before["denoiser_ref"]
    assert header["meta"]["epoch"] == 3
    assert header["meta"]["changes"] == [
        {"stochastic_steps": False, "previous": True, "date": "2026-11-24", "note": "test switch"}
    ]
    with safe_open(str(pub), "pt") as fh:
        after = {k: fh.get_tensor(k) for k in fh.keys()}
    _assert_same_state(before, after)  # same tensors, still half precision
    assert all(v.dtype != torch.float32 for v in after.values())

    new = ckpt.load_predictor(pub)
    assert not new.stochastic
    torch.testing.assert_close(new.predict(batch, 4, torch.Generator().manual_seed(5)), expected,
                               rtol=0, atol=0)  # fmt: skip
    # stochastic again: the noise is back, so the same seed gives other samples
    noisy = ckpt.load_predictor(pub)
    noisy.stochastic = True
    assert not torch.equal(noisy.predict(batch, 4, torch.Generator().manual_seed(5)), expected)

    mtime = pub.stat().st_mtime_ns
    assert not ckpt.set_stochastic_steps(pub, False, note="again")  # nothing to do
    assert pub.stat().st_mtime_ns == mtime


def test_set_stochastic_steps_refuses_a_denoiser(tmp_path, cfg):
    path = tmp_path / "d.safetensors"
    ckpt.save(path, ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {}))
    with pytest.raises(TrajprefError, match="generator setting"):
        ckpt.set_stochastic_steps(path, False, note="x")


def test_the_speed_clamp_can_be_set_after_training_and_changes_only_fast_agents(tmp_path, cfg):
    src = tmp_path / "g.safetensors"
    den = ckpt.denoiser_payload(_denoiser(cfg), cfg, 1.0, {})
    ckpt.save(src, ckpt.generator_payload(_generator(cfg), den, cfg, {"epoch": 1}))
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    before = ckpt.load_predictor(src).predict(batch, 4, torch.Generator().manual_seed(5))
    hash_before = _header(src)["hash"]

    assert ckpt.set_generator_setting(src, "max_speed", 1e6, note="above every agent")
    stamped = _header(src)["meta"]["changes"][0]["date"]  # today's, stamped by the function
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", stamped), stamped
    with pytest.raises(TrajprefError, match="YYYY-MM-DD"):
        ckpt.set_generator_setting(src, "max_speed", 2.0, note="x", date="27 Nov")
    assert ckpt.config_of(ckpt.load(src)).model.max_speed == 1e6
    assert _header(src)["hash"] == hash_before
    same = ckpt.load_predictor(src).predict(batch, 4, torch.Generator().manual_seed(5))
    torch.testing.assert_close(same, before)
    assert ckpt.set_generator_setting(src, "max_speed", 1e-3, note="below every agent")
    clamped = ckpt.load_predictor(src).predict(batch, 4, torch.Generator().manual_seed(5))
    assert not torch.allclose(clamped, before)
    assert [c["max_speed"] for c in _header(src)["meta"]["changes"]] == [1e6, 1e-3]


def test_only_sampling_settings_can_change_after_training(tmp_path, cfg):
    src = tmp_path / "g.safetensors"
    den = ckpt.denoiser_payload(_denoiser(cfg), cfg, 1.0, {})
    ckpt.save(src, ckpt.generator_payload(_generator(cfg), den, cfg, {}))
    with pytest.raises(TrajprefError, match="hidden cannot change after training"):
        ckpt.set_generator_setting(src, "hidden", 64, note="x")
    with pytest.raises(ConfigError, match="max_speed must be >= 0"):
        ckpt.set_generator_setting(src, "max_speed", -1.0, note="x")
    with pytest.raises(ConfigError, match="spread_scale must be > 0"):
        ckpt.set_generator_setting(src, "spread_scale", 0.0, note="x")
    assert ckpt.set_generator_setting(src, "spread_scale", 1.2, note="wider")
    assert ckpt.config_of(ckpt.load(src)).model.spread_scale == 1.2


def test_a_settings_variant_names_its_base_weights_instead_of_copying_them(tmp_path, cfg):
    src = tmp_path / "run" / "g.safetensors"
    den = ckpt.denoiser_payload(_denoiser(cfg), cfg, 1.0, {})
    ckpt.save(src, ckpt.generator_payload(_generator(cfg), den, cfg, {"epoch": 2}))
    base = tmp_path / "pub" / "generator.safetensors"
    ckpt.publish(src, base)
    variant = base.parent / "generator-clamp.safetensors"
    ckpt.publish_variant(base, variant, {"max_speed": 1e-3}, note="clamp everyone")
    assert variant.stat().st_size < 20_000 < base.stat().st_size
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    a, b = ckpt.load(base), ckpt.load(variant)
    _assert_same_state(a["state_dict"], b["state_dict"])
    assert ckpt.config_of(b).model.max_speed == 1e-3 and ckpt.config_of(a).model.max_speed == 0
    assert b["meta"]["epoch"] == 2 and b["meta"]["changes"][-1]["note"] == "clamp everyone"
    clamped = ckpt.load_predictor(variant).predict(batch, 4, torch.Generator().manual_seed(5))
    base_pred = ckpt.load_predictor(base)
    base_pred.generator.cfg = ckpt.config_of(b).model  # the same weights, clamped by hand
    torch.testing.assert_close(
        clamped, base_pred.predict(batch, 4, torch.Generator().manual_seed(5))
    )
    # a setting can change again in place; the weights stay by reference
    assert ckpt.set_generator_setting(variant, "max_speed", 2e-3, note="again")
    assert ckpt.config_of(ckpt.load(variant)).model.max_speed == 2e-3
    assert variant.stat().st_size < 20_000

    # the same weights published again are not a conflict (the hash of the rounded weights)
    ckpt.publish(src, base)
    ckpt.load(variant)
    # publishing other weights over the base is refused while a variant names them
    weights = ckpt.load(base)["state_dict"]
    ckpt.save(src, ckpt.generator_payload(_generator(cfg, seed=7), den, cfg, {}))
    with pytest.raises(ckpt.WeightsConflict, match="generator-clamp.safetensors"):
        ckpt.publish(src, base)
    _assert_same_state(ckpt.load(variant)["state_dict"], weights)
    # ... until the weights move to a name of their own, the variants following them
    kept = base.parent / "generator-old.safetensors"
    assert ckpt.move_weights(base, kept) == [variant]
    ckpt.publish(src, base)
    _assert_same_state(ckpt.load(variant)["state_dict"], weights)
    _assert_same_state(ckpt.load(kept)["state_dict"], weights)
    assert ckpt.config_of(ckpt.load(variant)).model.max_speed == 2e-3
    with pytest.raises(TrajprefError, match="exists already"):
        ckpt.move_weights(base, kept)
    with pytest.raises(TrajprefError, match="own weights can move"):
        ckpt.move_weights(variant, base.parent / "v2.safetensors")

    # a base replaced behind the library's back: refused at loading, not silently used
    kept.unlink()
    ckpt.save(kept, ckpt.load(base))
    with pytest.raises(TrajprefError, match="do not match the recorded hash"):
        ckpt.load(variant)


def test_a_variant_changes_only_sampling_settings_and_lives_beside_its_base(tmp_path, cfg):
    base = tmp_path / "generator.safetensors"
    den = ckpt.denoiser_payload(_denoiser(cfg), cfg, 1.0, {})
    ckpt.save(base, ckpt.generator_payload(_generator(cfg), den, cfg, {}))
    with pytest.raises(TrajprefError, match="hidden cannot change after training"):
        ckpt.publish_variant(base, tmp_path / "g-wide.safetensors", {"hidden": 64}, note="x")
    with pytest.raises(TrajprefError, match="beside its base"):
        ckpt.publish_variant(base, tmp_path / "sub" / "g.safetensors", {"max_speed": 1.0}, "x")


def test_a_temporal_generator_is_rebuilt_from_its_checkpoint_alone(tmp_path):
    cfg = load_config(None, [*TINY_OVERRIDES, "model.history_encoder=temporal"])
    gen = _generator(cfg)
    den_payload = ckpt.denoiser_payload(_denoiser(cfg), cfg, 0.7, {})
    ckpt.save(tmp_path / "g.safetensors", ckpt.generator_payload(gen, den_payload, cfg, {}))
    rebuilt, _ = ckpt.build_generator(ckpt.load(tmp_path / "g.safetensors"))
    assert rebuilt.cfg.history_encoder == "temporal"
    _assert_same_state(rebuilt.state_dict(), gen.state_dict())


# ----------------------------------------------------------------------------- model_hash


def test_model_hash_follows_weights_and_settings_not_the_file(tmp_path, cfg):
    run_file = _publish_generator(tmp_path, cfg, 1, name="a")
    pub = tmp_path / "pub" / "a.safetensors"
    ckpt.publish(run_file, pub, half=False)
    # the same weights, embedded denoiser or named one: the same model
    assert ckpt.model_hash(run_file) == ckpt.model_hash(pub)
    assert len(ckpt.model_hash(pub)) == 12
    # other generator weights, same denoiser: another leapfrog model, the same full sampler
    other = tmp_path / "pub" / "b.safetensors"
    ckpt.publish(_publish_generator(tmp_path, cfg, 2, name="b"), other, half=False)
    assert ckpt.model_hash(other) != ckpt.model_hash(pub)
    assert ckpt.model_hash(other, "full") == ckpt.model_hash(pub, "full")
    assert ckpt.model_hash(pub, "full") == ckpt.model_hash(pub.parent / ckpt.DENOISER_NAME, "full")
    # a sampling setting changes what the file predicts, so its digest
    before = ckpt.model_hash(pub)
    ckpt.set_generator_setting(pub, "max_speed", 0.5, note="test")
    assert ckpt.model_hash(pub) != before
    assert ckpt.model_hash(pub, "full") == ckpt.model_hash(other, "full")
    # a settings-only variant of the same weights with the same settings is the same model
    variant = tmp_path / "pub" / "a-v.safetensors"
    ckpt.publish_variant(pub, variant, {"spread_scale": 1.0}, note="no change")
    assert ckpt.model_hash(variant) == ckpt.model_hash(pub)
    ckpt.publish_variant(pub, variant, {"spread_scale": 0.9}, note="narrower")
    assert ckpt.model_hash(variant) != ckpt.model_hash(pub)


def test_model_hash_of_a_header_without_weights_is_a_clear_error():
    with pytest.raises(TrajprefError, match="without"):
        ckpt.header_model_hash({"kind": "generator", "config": {"model": {}}, "scale": 1.0})


def test_a_predictor_built_from_a_payload_predicts_in_eval_mode(tiny_run):
    payload = ckpt.load(tiny_run / "generator.safetensors")
    payload["config"]["model"]["generator_dropout"] = 0.5  # dropout modules to switch off
    predictor = ckpt.predictor_from_payload(payload)
    assert any(isinstance(m, torch.nn.Dropout) for m in predictor.modules())
    assert not any(m.training for m in predictor.modules())


def test_load_predictor_takes_auto_and_says_when_the_gpu_is_missing(tmp_path, cfg, monkeypatch):
    """``device="auto"`` went to ``predictor.to`` as it was: a RuntimeError naming 'auto'."""
    path = tmp_path / "d.safetensors"
    ckpt.save(path, ckpt.denoiser_payload(_denoiser(cfg), cfg, scale=0.7, meta={}))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    pred = ckpt.load_predictor(path, device="auto")
    assert pred.device == torch.device("cpu") and not pred.training
    assert pred.predict(collate([make_scene(2)]), 3).shape == (3, 2, 12, 2)
    with pytest.raises(ConfigError, match="device 'cuda' requested but no CUDA GPU"):
        ckpt.load_predictor(path, device="cuda")


# One table of fine-tuning methods (config.FinetuneMethod, config.USES_RL,
# rl.objective.LOSS_SAMPLES): the CLI offers its names, and a name that reaches a dispatch
# without an entry there is an error, never trained as RLHF-ReS (the walkthrough's finding: a
# new method's name took the k* path of ``RLObjective.selection``).


def test_a_checkpoint_of_a_new_supervised_method_records_no_reward(monkeypatch):
    """A fine-tuned checkpoint's reward came from ``method == "control"``: a new supervised
    method (no RL) recorded the config's reward as if it had trained with it."""
    from trajpref import config
    from trajpref.models import checkpoint

    monkeypatch.setitem(config.USES_RL, "control-ema", False)
    assert checkpoint._run_reward("control-ema", "score") is None
    assert checkpoint._run_reward("control", "score") is None
    assert checkpoint._run_reward("rlhf-res", "set") == "set"
    assert checkpoint._run_reward("rlhf-old-name", "score") == "score"  # an older file's name
