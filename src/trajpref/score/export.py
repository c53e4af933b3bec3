"""The diffusion score exported to one file that PyTorch alone runs (``torch.export``).

A planner that draws futures (from an exported generator, ``models.export``, or any other
predictor) ranks them without ground truth by the residual of the denoiser, as
``rank_samples`` does: ``(history [P, T_h, 2] float32, samples [K, P, T_f, 2] float32,
agent_type [P] int64) -> residual [K, P, T_f] float32``, lower is more human-like, the very
numbers of ``TrajectoryScorer.residual``. ``d.sum(-1).sum(-1)`` (steps, then agents, as
``rank_samples`` adds them) orders the samples exactly as ``rank_samples`` does (ATS order;
``.sum((1, 2))`` adds in another order and may differ by float rounding); ``d[..., -1].sum(-1)``
as its ``final=True`` (FTS order). The scorer's noise, drawn per agent slot from
its seed (``scorer.slot_noise``), is a table in the file for the first ``max_agents`` slots,
so the program draws nothing and gives the very residuals of the scorer. The scorer's checks
(finite inputs, samples that continue the history, the pace and units, the ball's flag) are
the caller's part, as for an exported generator. Load only files you made or trust
(``torch.export.load`` may unpickle).
"""

from __future__ import annotations

import copy
import warnings
from typing import Any

import torch
from torch import nn

from trajpref import __version__
from trajpref.data.transforms import to_model_frame
from trajpref.errors import ConfigError, TrajprefError
from trajpref.models.encoder import scene_features
from trajpref.models.export import (
    MAX_AGENTS,
    bounded_agents,
    one_scene_batch,
    program_agents,
    program_dims,
    source_fields,
)
from trajpref.score.scorer import TrajectoryScorer, slot_noise

MAX_SAMPLES = 1024
"""The most samples K one call of an exported scorer takes (its symbolic K's bound)."""

MATCH_TOL = 1e-5
"""The largest relative difference between the exported residuals and the scorer's on the
check scenes that ``export_scorer`` accepts (they have been equal for every published
denoiser; a margin for float rounding on other builds)."""


class SceneResidual(nn.Module):
    """One scene's residuals from its histories and sampled futures, without checks:
    ``forward(history [P, T_h, 2], samples [K, P, T_f, 2], agent_type [P]) -> d [K, P, T_f]``,
    as ``TrajectoryScorer.residual`` computes them for a batch of that one scene, with the
    noise of its first ``max_agents`` slots held as a buffer."""

    def __init__(self, scorer: TrajectoryScorer, max_agents: int):
        super().__init__()
        self.denoiser = scorer.denoiser
        self.schedule = scorer.schedule
        self.steps = list(scorer.steps)
        self.scale = scorer.scale
        self.radius = scorer.neighbour_radius
        gen = torch.Generator().manual_seed(scorer.seed)
        shape = (len(self.steps), 1, scorer.t_fut, 2)  # one slot's draw, shared by the K
        noise = slot_noise(max_agents, shape, gen)  # [P_max, S, 1, T_f, 2]
        self.register_buffer("noise", noise.to(scorer.device))

    def forward(self, history: torch.Tensor, samples: torch.Tensor,
                agent_type: torch.Tensor) -> torch.Tensor:  # fmt: skip
        n = history.shape[0]  # P, symbolic in the exported program
        batch = one_scene_batch(history, agent_type, samples.shape[2])
        features = scene_features(batch, self.scale, radius=self.radius)
        context = self.denoiser.context(features)  # [P, H]
        y = to_model_frame(samples, batch, self.scale)  # [K, P, T_f, 2]
        z = self.noise[:n].permute(1, 2, 0, 3, 4)  # [S, 1, P, T_f, 2]
        d = y.new_zeros(y.shape[0], n, y.shape[2])  # [K, P, T_f]
        for i, s in enumerate(self.steps):  # unrolled in the program
            y_s = self.schedule.add_noise(y, z[i], torch.tensor(s))  # [K, P, T_f, 2]
            eps = self.denoiser(y_s, s, context)  # [K, P, T_f, 2]
            d = d + (eps - z[i]).pow(2).sum(-1)
        return d / len(self.steps)  # [K, P, T_f]


def _check_exportable(scorer: object) -> TrajectoryScorer:
    if not isinstance(scorer, TrajectoryScorer):
        raise ConfigError(f"export_scorer takes a TrajectoryScorer "
                          f"(TrajectoryScorer.from_checkpoint(path)), got "
                          f"{type(scorer).__name__}")  # fmt: skip
    if not scorer.shared_noise:
        raise ConfigError("this scorer draws its noise per sample: an exported one would fix "
                          "K; export a scorer with shared_noise (every published one)")  # fmt: skip
    if scorer.speed_ref is not None or scorer.precision != "fp32":
        raise ConfigError("export_scorer takes a scorer at its checkpoint's settings (no "
                          "speed_ref, fp32 steps)")  # fmt: skip
    return scorer


def _example(scorer: TrajectoryScorer, agents: int, samples: int, seed: int,
             ball: bool = False) -> tuple[torch.Tensor, ...]:  # fmt: skip
    """A scene of ``agents`` walkers and ``samples`` futures continuing each one (random
    walks in model units times the scale), their types 0 (with ``ball``, the last agent 1):
    the trace's example and the check's scenes."""
    gen = torch.Generator().manual_seed(seed)
    t_h, t_f = scorer.t_hist, scorer.t_fut
    steps = torch.randn(agents, t_h + t_f, 2, generator=gen) * 0.3 + 0.3  # [P, T, 2]
    track = torch.cumsum(steps, 1) * scorer.scale
    spread = torch.randn(samples, agents, t_f, 2, generator=gen).cumsum(2) * 0.1 * scorer.scale
    futures = track[None, :, t_h:] + spread  # [K, P, T_f, 2]
    device = scorer.device
    types = torch.zeros(agents, dtype=torch.long)
    types[-1] = int(ball)
    return track[:, :t_h].to(device), futures.to(device), types.to(device)


def export_scorer(scorer: TrajectoryScorer,
                  max_agents: int = MAX_AGENTS) -> torch.export.ExportedProgram:  # fmt: skip
    """``scorer`` (with its steps, seed and ``neighbour_radius`` as they are) as a
    ``torch.export.ExportedProgram`` of ``SceneResidual`` for scenes of 1 to ``max_agents``
    agents and 1 to ``MAX_SAMPLES`` samples, checked against the scorer on scenes of 1, 3 and
    up to 64 agents (the last with a ball) before it is returned (a relative difference of the
    residuals above ``MATCH_TOL`` is a ``TrajprefError``)."""
    scorer = _check_exportable(scorer)
    max_agents = bounded_agents(max_agents, scorer.denoiser.cfg.denoiser_roles)
    own = copy.deepcopy(scorer)
    own.denoiser.requires_grad_(False)
    wrapped = SceneResidual(own, max_agents).eval()
    example = _example(scorer, min(2, max_agents), 3, seed=0)
    dims = program_dims(max_agents, {"history": 0, "samples": 1, "agent_type": 0})
    dims["samples"][0] = torch.export.Dim("samples", min=1, max=MAX_SAMPLES)
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # torch's notes on tracing internals
        program = torch.export.export(wrapped, example, dynamic_shapes=dims, strict=False)
    checks = sorted({1, min(3, max_agents), min(64, max_agents)})  # the last with a ball
    for seed, agents in enumerate(checks, 1):
        scene = _example(scorer, agents, 5, seed, ball=agents == checks[-1])
        with torch.no_grad():
            history, samples, types = scene
            batch = one_scene_batch(history, types, scorer.t_fut, future=samples[0])  # unread
            want = scorer.residual(batch, samples)  # [K, P, T_f]
            got = program.module()(*scene)  # [K, P, T_f]
        worst = float(((want - got).abs() / want.abs().clamp_min(1e-12)).max())
        if not worst <= MATCH_TOL:
            raise TrajprefError(f"the exported scorer's residuals differ from the scorer's by "
                                f"{worst:.3g} (relative) on a scene of {agents} agents: not "
                                "exported")  # fmt: skip
    return program


def scorer_meta(scorer: TrajectoryScorer, program: torch.export.ExportedProgram,
                source: str) -> dict[str, Any]:  # fmt: skip
    """What an exported scorer's file records of itself (``models.export.META_FILE``)."""
    bound = program_agents(program)
    units = scorer.units or "the training data's units"
    return {
        "format": "trajpref-export-scorer/1",
        **source_fields(source),
        "inputs": {
            "history": f"[P, {scorer.t_hist}, 2] float32, absolute positions in {units}, "
            "oldest first, every one finite",
            "samples": f"[K, P, {scorer.t_fut}, 2] float32 futures continuing the history, "
            "absolute positions",
            "agent_type": "[P] int64: 0 for a person; 1 only for the ball of a scorer "
            "trained with one (nba's)",
        },
        "output": f"[K, P, {scorer.t_fut}] float32 residuals, lower is more human-like: "
        "d.sum(-1).sum(-1).argsort() ranks the K as rank_samples does (ATS order), "
        "d[..., -1].sum(-1).argsort() as its final=True (FTS order)",
        "roles": (
            "agents are read in order as roles (their training data's order)"
            if scorer.denoiser.cfg.denoiser_roles
            else None
        ),  # fmt: skip
        "t_hist": scorer.t_hist,
        "t_fut": scorer.t_fut,
        "max_agents": bound,
        "max_samples": MAX_SAMPLES,
        "frame_interval": scorer.frame_interval,
        "units": scorer.units,
        "scale": scorer.scale,
        "settings": {
            "steps": list(scorer.steps),
            "seed": scorer.seed,
            "neighbour_radius": scorer.neighbour_radius,
            "denoiser_roles": scorer.denoiser.cfg.denoiser_roles,
        },
        "trajpref_version": __version__,
        "torch_version": torch.__version__,
    }
