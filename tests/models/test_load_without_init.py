"""Loading a model builds its modules without random initialisation (walkthrough 69): it
used to build them with it, inside ``torch.random.fork_rng``, which saved torch's global
generator and restored it after, so another thread drawing from that generator meanwhile got
its draws repeated. Now the modules are built on the meta device and take the file's weights
(``checkpoint.built_for_loading``): nothing is drawn, saved or restored, and the loaded
models are the ones the old build gave, bit for bit (checked below against that build, kept
here as the reference). Training still builds with its seeded random initialisation."""

from __future__ import annotations

import dataclasses
import json
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from models.rng_guard import refuse_global_randomness, tensors_of
from safetensors import safe_open
from synthetic import TINY_OVERRIDES, make_scene
from torch import nn

import trajpref
from trajpref.config import load_config, to_dict
from trajpref.errors import TrajprefError
from trajpref.models import checkpoint as ckpt
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.models.generator import Generator
from trajpref.models.registry import load_predictor
from trajpref.models.timing import attach_timing
from trajpref.score.scorer import TrajectoryScorer, predict_scene
from trajpref.types import collate

INDEX = Path(trajpref.__file__).parent / "zoo" / "index.json"
PUBLISHED = [(r["name"], r["kind"]) for r in json.loads(INDEX.read_text())["models"]]
LOADS = [(name, sampler) for name, kind in PUBLISHED
         for sampler in (("leapfrog", "full") if kind == "generator" else ("full",))]  # fmt: skip
"""Every published model as the predictor(s) it loads as: a generator with either sampler,
a denoiser with the full sampler."""
CHECKED = ["zara1/generator", "robo/generator", "sdd/generator", "eth/generator-pace",
           "zara1/denoiser"]  # fmt: skip
"""The models whose numbers are compared with the old build's (eth's runs a GRU)."""


def old_build(spec: str, sampler: str | None = None):
    """The predictor as loading built it before 2026-12 (random initialisation, then the
    weights copied in; the fork of the generator aside): the reference."""
    payload = ckpt.load(spec)
    with torch.random.fork_rng(devices=[]):
        predictor = ckpt.predictor_from_payload(payload, sampler)  # training's build
    predictor = ckpt.as_float32(predictor).eval()
    predictor.neighbour_radius = ckpt.config_of(payload).model.neighbour_radius
    return attach_timing(predictor, payload)


def _history(model, seed: int = 0) -> np.ndarray:
    """Three agents walking at about a third of the model's scale per step: [3, T_h, 2]."""
    rng = np.random.default_rng(seed)
    step = 0.06 * float(model.scale)
    walk = np.cumsum(rng.normal(0.0, step, (3, model.t_hist, 2)), 1) + 3 * step
    return walk.astype(np.float32)


# ----------------------------------------------------------------------------- published


@pytest.mark.parametrize(("name", "sampler"), LOADS, ids=[f"{n}-{s}" for n, s in LOADS])
def test_loading_draws_saves_and_restores_nothing(monkeypatch, name, sampler):
    state = torch.get_rng_state()
    seen = refuse_global_randomness(monkeypatch)
    model = load_predictor(name, sampler=sampler)
    monkeypatch.undo()
    assert torch.equal(torch.get_rng_state(), state)
    assert seen, "the modules' initialisers ran on the meta device (the check saw them)"
    left = [n for n, t in tensors_of(model) if t.is_meta or t.device.type != "cpu"]
    assert not left, left


@pytest.mark.parametrize("name", CHECKED)
def test_loaded_models_equal_the_old_build(name):
    for sampler in [s for n, s in LOADS if n == name]:
        new, old = load_predictor(name, sampler=sampler), old_build(name, sampler)
        new_tensors, old_tensors = tensors_of(new), tensors_of(old)
        assert [n for n, _ in new_tensors] == [n for n, _ in old_tensors]
        for (key, a), (_, b) in zip(new_tensors, old_tensors, strict=True):
            assert a.dtype == b.dtype == torch.float32, key
            assert a.requires_grad == b.requires_grad and a.stride() == b.stride(), key
            assert torch.equal(a, b), key
        assert not new.training and new.sampler == old.sampler
        history = _history(new)
        np.testing.assert_array_equal(predict_scene(new, history, 20, seed=3),
                                      predict_scene(old, history, 20, seed=3))  # fmt: skip


def test_published_half_weights_load_as_float32_copies():
    path = ckpt.resolve_path("zara1/generator")
    with safe_open(str(path), "pt") as fh:
        stored = {k: fh.get_tensor(k) for k in fh.keys()}
    assert {t.dtype for t in stored.values()} == {torch.float16}  # published in half
    model = load_predictor("zara1/generator")
    for name, value in model.generator.state_dict().items():
        assert value.dtype == torch.float32
        assert torch.equal(value, stored[f"model/{name}"].float()), name
    payload = ckpt.load(path)
    generator, _ = ckpt.build_generator(payload, loading=True)
    weight = generator.mean_head[0].weight
    assert weight.data_ptr() != payload["state_dict"]["mean_head.0.weight"].data_ptr()


def test_a_thread_drawing_meanwhile_gets_its_own_sequence():
    """A thread draws from torch's global generator while this one loads models 20 times: its
    draws are those it makes alone (the fork of the old loading repeated them)."""
    load_predictor("zara1/generator")  # imports and first-use costs outside the loop
    torch.manual_seed(1234)
    draws: list[torch.Tensor] = []
    started, stop = threading.Event(), threading.Event()

    def draw():
        while not stop.is_set():
            draws.append(torch.randn(4))
            started.set()
            time.sleep(1e-4)  # a few thousand draws, between which the loads run

    thread = threading.Thread(target=draw)
    try:
        thread.start()
        started.wait(10)
        during = []
        for i in range(20):
            before = len(draws)
            if i % 2:
                TrajectoryScorer.from_checkpoint("zara1/denoiser")
            else:
                load_predictor("zara1/generator" if i % 4 == 0 else "eth/generator-pace")
            during.append(len(draws) - before)
    finally:
        stop.set()
        thread.join(30)
    assert sum(during) > 0, "the thread drew while models loaded"
    torch.manual_seed(1234)
    alone = [torch.randn(4) for _ in draws]
    assert torch.equal(torch.stack(draws), torch.stack(alone))


# ----------------------------------------------------------------------------- modules


@pytest.fixture(scope="module")
def cfg():
    return load_config(None, TINY_OVERRIDES)


EVERY_PART = {"query_layers": 2, "query_width": 16, "future_rank": 3, "history_encoder": "temporal",
              "agent_roles": 6, "denoiser_roles": 6, "pair_distance": True,
              "generator_dropout": 0.1, "encoder_dropout": 0.1, "agent_frame": "heading",
              "mean_prior": "velocity"}  # fmt: skip
"""Every optional part of the networks at once: the learnt queries (drawn with torch.randn),
the time projection (a buffer outside the state dict), a GRU, role embeddings, dropout."""


@pytest.mark.parametrize("parts", [{}, EVERY_PART], ids=["plain", "every-part"])
@pytest.mark.parametrize("cls", [Denoiser, Generator])
def test_built_for_loading_equals_the_randomly_initialised_build(monkeypatch, cfg, cls, parts):
    model_cfg = dataclasses.replace(cfg.model, **parts)
    torch.manual_seed(5)
    trained = cls(model_cfg)  # stands for a trained network
    state = {k: v.clone() for k, v in trained.state_dict().items()}
    torch.manual_seed(6)
    reference = cls(model_cfg)
    reference.load_state_dict(state)
    refuse_global_randomness(monkeypatch)
    loaded = ckpt.built_for_loading(cls, model_cfg, state)
    monkeypatch.undo()
    names = [n for n, _ in tensors_of(reference)]
    assert [n for n, _ in tensors_of(loaded)] == names
    if cls is Generator:
        assert "0.time_projection" in names and ("0.queries" in names) == bool(parts)
    for (key, a), (_, b) in zip(tensors_of(loaded), tensors_of(reference), strict=True):
        assert not a.is_meta and a.dtype == b.dtype and a.requires_grad == b.requires_grad, key
        assert torch.equal(a, b), key
    batch = collate([make_scene(3), make_scene(2, seed=1)])
    features = scene_features(batch, 0.7)
    loaded.eval(), reference.eval()
    with torch.no_grad():
        if cls is Generator:
            got, want = loaded(features), reference(features)
            for field in ("mean", "log_sigma", "shifts"):
                assert torch.equal(getattr(got, field), getattr(want, field)), field
        else:
            y = torch.randn(2, 5, 12, 2, generator=torch.Generator().manual_seed(0))
            assert torch.equal(loaded(y, 3, loaded.context(features)),
                               reference(y, 3, reference.context(features)))  # fmt: skip


def test_built_for_loading_under_a_float64_default(cfg):
    model_cfg = dataclasses.replace(cfg.model, future_rank=0)  # its projection: torch.eye
    torch.manual_seed(5)
    state = Generator(model_cfg).state_dict()
    previous = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        loaded = ckpt.as_float32(ckpt.built_for_loading(Generator, model_cfg, state))
        reference = Generator(model_cfg)
        reference.load_state_dict(state)
        reference = ckpt.as_float32(reference)
    finally:
        torch.set_default_dtype(previous)
    for (key, a), (_, b) in zip(tensors_of(loaded), tensors_of(reference), strict=True):
        assert a.dtype == b.dtype == torch.float32 and torch.equal(a, b), key


def test_weights_of_another_dtype_load_as_float32(cfg):
    torch.manual_seed(5)
    state = Denoiser(cfg.model).state_dict()
    for dtype in (torch.float16, torch.float64, torch.bfloat16):
        other = {k: v.to(dtype) for k, v in state.items()}
        reference = Denoiser(cfg.model)
        reference.load_state_dict(other)
        loaded = ckpt.built_for_loading(Denoiser, cfg.model, other)
        for (key, a), (_, b) in zip(tensors_of(loaded), tensors_of(reference), strict=True):
            assert a.dtype == torch.float32 and torch.equal(a, b), (dtype, key)


def test_a_legacy_pt_file_loads_without_random_initialisation(monkeypatch, tmp_path, cfg):
    torch.manual_seed(0)
    model = Denoiser(cfg.model)
    state = {k: v.clone() for k, v in model.state_dict().items()}
    legacy = {"format": ckpt.LEGACY_FORMAT, "kind": "denoiser", "config": to_dict(cfg),
              "scale": 0.7, "state_dict": state, "hash": ckpt.state_hash(state),
              "meta": {}}  # fmt: skip
    torch.save(legacy, tmp_path / "old.pt")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # the legacy file's own warning
        refuse_global_randomness(monkeypatch)
        loaded = ckpt.load_predictor(tmp_path / "old.pt")
        scorer = TrajectoryScorer.from_checkpoint(tmp_path / "old.pt")
        monkeypatch.undo()
    for denoiser in (loaded.denoiser, scorer.denoiser):
        for name, value in model.state_dict().items():
            assert torch.equal(denoiser.state_dict()[name], value), name
        assert not any(t.is_meta for _, t in tensors_of(denoiser))


class _Tied(nn.Module):
    def __init__(self, width: int):
        super().__init__()
        self.a = nn.Linear(width, width)
        self.b = nn.Linear(width, width)
        self.b.weight = self.a.weight  # one parameter under two names
        self.register_buffer("count", torch.zeros(()))  # persistent: in the state dict


class _Derived(nn.Module):
    def __init__(self, width: int):
        super().__init__()
        self.a = nn.Linear(width, width)
        self.register_buffer("eye", torch.eye(width), persistent=False)


def test_shared_parameters_stay_shared_and_persistent_buffers_load():
    torch.manual_seed(0)
    source = _Tied(3)
    source.count += 7
    loaded = ckpt.built_for_loading(_Tied, 3, source.state_dict())
    assert loaded.a.weight is loaded.b.weight and isinstance(loaded.a.weight, nn.Parameter)
    assert torch.equal(loaded.b.weight, source.a.weight) and loaded.count.item() == 7
    assert len(list(loaded.parameters())) == len(list(source.parameters())) == 3


def test_a_buffer_outside_the_state_dict_needs_config_buffers():
    with pytest.raises(TrajprefError, match="eye not loaded"):
        ckpt.built_for_loading(_Derived, 3, _Derived(3).state_dict())
    _Derived.config_buffers = lambda self: {"eye": torch.eye(3)}
    try:
        loaded = ckpt.built_for_loading(_Derived, 3, _Derived(3).state_dict())
    finally:
        del _Derived.config_buffers
    assert torch.equal(loaded.eye, torch.eye(3)) and "eye" not in loaded.state_dict()


def test_wrong_weights_are_refused_as_before(cfg):
    state = Denoiser(cfg.model).state_dict()
    with pytest.raises(RuntimeError, match="Missing key"):
        ckpt.built_for_loading(Denoiser, cfg.model, {k: v for k, v in state.items()
                                                     if k != "inp.weight"})  # fmt: skip
    bigger = dataclasses.replace(cfg.model, denoiser_width=64)
    with pytest.raises(RuntimeError, match="size mismatch"):
        ckpt.built_for_loading(Denoiser, bigger, state)


# ----------------------------------------------------------------------------- training


def test_training_builds_draw_as_before(cfg):
    """Training's builds (the default, ``loading=False``) still draw their random
    initialisation from the global stream: a seeded stage's draws after the build are those
    after building the networks by hand."""
    torch.manual_seed(0)
    denoiser = ckpt.denoiser_payload(Denoiser(cfg.model), cfg, 0.7, {})
    payload = ckpt.generator_payload(Generator(cfg.model), denoiser, cfg, {})
    model_cfg = cfg.model
    torch.manual_seed(3)
    ckpt.predictor_from_payload(payload)
    after = torch.rand(5)
    torch.manual_seed(3)
    Denoiser(model_cfg)
    Generator(model_cfg)
    assert torch.equal(torch.rand(5), after)
    torch.manual_seed(3)
    plain = torch.rand(5)
    torch.manual_seed(3)
    ckpt.predictor_from_payload(payload, loading=True)  # the loading calls' build draws nothing
    assert torch.equal(torch.rand(5), plain)
