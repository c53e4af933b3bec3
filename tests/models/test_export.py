"""An exported predictor (``trajpref.models.export``, ``trajpref export``): the very futures of
the model for scenes of any size up to its bound, a file PyTorch alone loads, what it
records, and the models it refuses (those that draw noise)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from helpers import _run

from trajpref.errors import ConfigError
from trajpref.models.export import (
    META_FILE,
    agent_bound,
    export_meta,
    export_predictor,
    load_exported,
    program_shape,
    save_exported,
)
from trajpref.models.registry import load_predictor
from trajpref.score.scorer import predict_scene


def _scene(agents: int, t_hist: int = 8, seed: int = 3) -> np.ndarray:
    """[P, T_h, 2] random walks in metres, float32."""
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(0.3, 0.2, (agents, t_hist, 2)), 1).astype(np.float32)


@pytest.fixture(scope="module")
def tiny(tiny_run):
    return load_predictor(str(tiny_run / "generator.safetensors"))


@pytest.fixture(scope="module")
def tiny_program(tiny):
    return export_predictor(tiny, max_agents=16)


@pytest.mark.parametrize("agents", [1, 2, 5, 16])
def test_the_program_gives_the_models_own_futures_at_every_scene_size(tiny, tiny_program,
                                                                      agents):  # fmt: skip
    history = _scene(agents)
    want = predict_scene(tiny, history, tiny.generator.samples)  # [K, P, T_f, 2]
    got = tiny_program.module()(torch.from_numpy(history), torch.zeros(agents, dtype=torch.long))
    assert got.shape == want.shape == (4, agents, 12, 2)
    np.testing.assert_allclose(got.numpy(), want, atol=1e-6)  # no torch.no_grad() needed


def test_a_scene_larger_than_the_bound_is_refused_by_the_program(tiny_program):
    with pytest.raises(AssertionError, match="<= 16"):  # torch's own guard, naming the bound
        tiny_program.module()(torch.from_numpy(_scene(17)), torch.zeros(17, dtype=torch.long))


def test_the_program_checks_its_inputs_dtypes_before_any_arithmetic(tiny_program):
    """The README names this message and its remedy (history.float())."""
    history = torch.from_numpy(_scene(3).astype(np.float64))
    with pytest.raises(RuntimeError, match="Tensor dtype mismatch! Expected: Float, Got: double"):
        tiny_program.module()(history, torch.zeros(3, dtype=torch.long))


def test_the_file_loads_with_pytorch_alone_and_records_itself(tiny, tiny_program, tmp_path,
                                                              tiny_run):  # fmt: skip
    source = str(tiny_run / "generator.safetensors")
    meta = export_meta(tiny, tiny_program, source)
    path = save_exported(tiny_program, tmp_path / "tiny.pt2", meta)
    again = save_exported(tiny_program, tmp_path / "again.PT2", meta)  # any case of .pt2
    assert path.read_bytes() == again.read_bytes()  # no temporary name inside the archive
    plain = torch.export.load(str(path)).module()  # no trajpref call
    history = torch.from_numpy(_scene(3))
    types = torch.zeros(3, dtype=torch.long)
    np.testing.assert_array_equal(plain(history, types).numpy(),
                                  tiny_program.module()(history, types).numpy())  # fmt: skip
    module, recorded = load_exported(path)
    assert recorded == json.loads(json.dumps(meta))
    assert (recorded["t_hist"], recorded["t_fut"], recorded["samples"]) == (8, 12, 4)
    assert recorded["max_agents"] == 16 and recorded["source"] == source
    assert recorded["checkpoint_hash"] is not None and META_FILE == "trajpref.json"
    assert recorded["settings"]["tau"] == 2 and recorded["roles"] is None
    assert module(history, types).shape == (4, 3, 12, 2)


def test_the_first_samples_and_a_neighbour_radius_are_fixed_in_the_program(tiny):
    tiny.neighbour_radius = 1.0
    try:
        program = export_predictor(tiny, samples=2, max_agents=4)
        history = _scene(4)
        want = predict_scene(tiny, history, 2)  # the radius applies to both
    finally:
        tiny.neighbour_radius = None
    got = program.module()(torch.from_numpy(history), torch.zeros(4, dtype=torch.long))
    np.testing.assert_allclose(got.numpy(), want, atol=1e-6)
    far = predict_scene(tiny, history, 2)  # without the radius: other futures
    assert not np.allclose(far, want)


def test_models_that_draw_noise_and_bad_counts_are_refused(tiny_run, tiny):
    with pytest.raises(ConfigError, match="constant-velocity baseline"):
        export_predictor(load_predictor("cv"))
    full = load_predictor(str(tiny_run / "denoiser.safetensors"))
    with pytest.raises(ConfigError, match="the full sampler draws noise"):
        export_predictor(full)
    stochastic = load_predictor(str(tiny_run / "generator.safetensors"))
    stochastic.stochastic = True  # tau = 2 ancestral steps
    with pytest.raises(ConfigError, match="2 denoising steps with ancestral noise"):
        export_predictor(stochastic)
    for samples in (0, 5, 2.0):
        with pytest.raises(ConfigError, match=r"samples must be an integer in 1\.\.4"):
            export_predictor(tiny, samples=samples)
    with pytest.raises(ConfigError, match="max_agents must be an integer >= 1"):
        export_predictor(tiny, max_agents=0)


def test_a_published_generator_exports_exactly_and_roles_bound_the_agents(zara1, robo):
    history = _scene(6)
    program = export_predictor(zara1)
    got = program.module()(torch.from_numpy(history), torch.zeros(6, dtype=torch.long))
    np.testing.assert_array_equal(got.numpy(), predict_scene(zara1, history, 20))
    assert agent_bound(robo) == 3  # leader, follower, approacher
    robo_program = export_predictor(robo)
    assert program_shape(robo_program) == (20, 3)
    meta = export_meta(robo, robo_program, "robo/generator")
    assert meta["roles"].startswith("agents are read in order as roles")
    three = _scene(3) * 0.3
    got = robo_program.module()(torch.from_numpy(three), torch.zeros(3, dtype=torch.long))
    np.testing.assert_array_equal(got.numpy(), predict_scene(robo, three, 20))


def test_the_command_writes_a_checked_file_and_refuses_what_it_cannot(capsys, tiny_run,
                                                                      tmp_path):  # fmt: skip
    out = tmp_path / "tiny.pt2"
    code, said, err = _run(capsys, "export", tiny_run / "generator.safetensors", "--out", out,
                           "--max-agents", "8")  # fmt: skip
    assert code == 0, err
    assert said.startswith(f"wrote {out}: history [P, 8, 2]")
    assert "-> futures [4, P, 12, 2], P from 1 to 8; checked against the model" in said
    assert load_exported(out)[1]["max_agents"] == 8
    code, _, err = _run(capsys, "export", "cv", "--out", tmp_path / "cv.pt2")
    assert code == 2 and "constant-velocity baseline" in err
    code, _, err = _run(capsys, "export", "zara1/generator", "--out", tmp_path / "z.onnx")
    assert code == 2 and "the output must be a .pt2 file" in err
    code, _, err = _run(capsys, "export", "zara1/generator", "--out", tmp_path / "z.pt2",
                        "--samples", "21")  # fmt: skip
    assert code == 2 and "--samples 21: zara1/generator emits K = 20 samples" in err
    assert not (tmp_path / "cv.pt2").exists() and not (tmp_path / "z.onnx").exists()
