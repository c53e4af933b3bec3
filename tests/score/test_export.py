"""The diffusion score exported (``trajpref.score.export``, ``trajpref export --scorer``): the
scorer's residuals for any scene and sample count up to its bounds, the very ranking of
``rank_samples``, what the file records, and what it refuses."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import _run

from trajpref.errors import ConfigError
from trajpref.models.export import load_exported, save_exported
from trajpref.models.registry import load_predictor
from trajpref.score.export import export_scorer, scorer_meta
from trajpref.score.scorer import TrajectoryScorer, predict_scene, rank_samples, score_timesteps
from trajpref.types import Batch


def _scene(agents: int, samples: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """history [P, 8, 2] and samples [K, P, 12, 2] continuing it, float32 metres."""
    rng = np.random.default_rng(seed)
    track = np.cumsum(rng.normal(0.3, 0.2, (agents, 20, 2)), 1)
    futures = track[None, :, 8:] + rng.normal(0, 0.1, (samples, agents, 12, 2)).cumsum(2)
    return track[:, :8].astype(np.float32), futures.astype(np.float32)


@pytest.fixture(scope="module")
def tiny_scorer(tiny_run):
    return TrajectoryScorer.from_checkpoint(str(tiny_run / "denoiser.safetensors"))


@pytest.fixture(scope="module")
def tiny_program(tiny_scorer):
    return export_scorer(tiny_scorer, max_agents=16)


@pytest.mark.parametrize(("agents", "samples"), [(1, 1), (3, 7), (16, 20)])
def test_the_program_gives_the_scorers_residuals_at_every_size(tiny_scorer, tiny_program,
                                                               agents, samples):  # fmt: skip
    history, futures = _scene(agents, samples)
    batch = Batch(history=torch.from_numpy(history), future=torch.from_numpy(futures[0]),
                  scene=torch.zeros(agents, dtype=torch.long),
                  agent_type=torch.zeros(agents, dtype=torch.long), num_scenes=1)  # fmt: skip
    want = tiny_scorer.residual(batch, torch.from_numpy(futures))  # [K, P, T_f]
    got = tiny_program.module()(torch.from_numpy(history), torch.from_numpy(futures),
                                torch.zeros(agents, dtype=torch.long))  # fmt: skip
    assert got.shape == want.shape == (samples, agents, 12)
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-6)


def test_a_published_scorer_ranks_as_rank_samples_and_records_itself(tmp_path):
    scorer = TrajectoryScorer.from_checkpoint("zara1/denoiser")
    scorer = scorer.with_steps(score_timesteps(scorer.schedule.num_steps, 50))  # 2 steps
    program = export_scorer(scorer, max_agents=32)
    model = load_predictor("zara1/generator")
    history, _ = _scene(6, 1, seed=5)
    samples = predict_scene(model, history, 20)
    order, total = rank_samples(scorer, history, samples)
    got = program.module()(torch.from_numpy(history), torch.from_numpy(samples),
                           torch.zeros(6, dtype=torch.long)).sum(-1).sum(-1)  # fmt: skip
    np.testing.assert_array_equal(got.argsort().numpy(), order)
    np.testing.assert_array_equal(got.numpy(), total)  # steps, then agents: the same bits
    meta = scorer_meta(scorer, program, "zara1/denoiser")
    path = save_exported(program, tmp_path / "score.pt2", meta)
    _, recorded = load_exported(path)
    assert recorded["settings"]["steps"] == [0, 50] and recorded["max_agents"] == 32
    assert recorded["max_samples"] == 1024 and recorded["checkpoint_hash"] is not None
    assert recorded["format"] == "trajpref-export-scorer/1"


def test_scorers_that_would_fix_k_or_change_the_frame_are_refused(tiny_scorer):
    with pytest.raises(ConfigError, match="takes a TrajectoryScorer"):
        export_scorer(load_predictor("cv"))
    own = TrajectoryScorer(tiny_scorer.denoiser, tiny_scorer.schedule, tiny_scorer.scale,
                           shared_noise=False)  # fmt: skip
    with pytest.raises(ConfigError, match="draws its noise per sample"):
        export_scorer(own)
    with pytest.raises(ConfigError, match="max_agents must be an integer >= 1"):
        export_scorer(tiny_scorer, max_agents=0)


def test_the_command_exports_a_score_and_keeps_generator_flags_to_generators(capsys, tmp_path,
                                                                            tiny_run):  # fmt: skip
    out = tmp_path / "score.pt2"
    code, said, err = _run(capsys, "export", tiny_run / "denoiser.safetensors", "--scorer",
                           "--score-every", "5", "--max-agents", "4", "--out", out)  # fmt: skip
    assert code == 0, err
    assert "-> residuals [K, P, 12] at 2 score steps, P from 1 to 4, K from 1 to 1024" in said
    assert load_exported(out)[1]["settings"]["steps"] == [0, 5]
    code, _, err = _run(capsys, "export", tiny_run / "denoiser.safetensors", "--scorer",
                        "--samples", "3", "--out", tmp_path / "x.pt2")  # fmt: skip
    assert code == 2 and "--samples: a generator's settings" in err
    for flag, value in (("--score-every", "3"), ("--score-from", "0")):  # the defaults too
        code, _, err = _run(capsys, "export", tiny_run / "generator.safetensors", flag, value,
                            "--out", tmp_path / "y.pt2")  # fmt: skip
        assert code == 2 and "--score-every and --score-from go with --scorer" in err
    for flag, value, said in (("--score-every", "0", "--score-every must be >= 1, got 0"),
                              ("--score-from", "10", "--score-from 10: the scorer's steps "
                               "are 0..9")):  # fmt: skip
        code, _, err = _run(capsys, "export", tiny_run / "denoiser.safetensors", "--scorer",
                            flag, value, "--out", tmp_path / "z.pt2")  # fmt: skip
        assert code == 2 and said in err
