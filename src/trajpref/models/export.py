"""A predictor exported to one file that runs with PyTorch alone (``torch.export``).

A planner that ranks futures in a loop of its own, or a robot's process without trajpref
installed, loads the file with ``torch.export.load(path).module()`` and calls it on one
scene: ``(history [P, T_h, 2] float32, agent_type [P] int64) -> futures [K, P, T_f, 2]``,
absolute positions in the model's units, the very numbers ``predict_scene`` gives for the
same scene without context-only neighbours. The program checks its inputs' dtypes and shapes
(float32 and int64 tensors: ``Tensor dtype mismatch! Expected: Float, Got: double`` asks for
``history.float()``; ``Guard failed: history.size()[0] <= 512`` names the bound on P). The
file holds the graph and the weights (a generator without denoising steps
leaves its denoiser out). ``torch.export.load`` may unpickle what an archive marks so: load
only files you made or trust. What trajpref checks before predicting (finite histories,
coordinates float32 can hold, a scene no wider or faster than training, the steps and units
of the data, agent types 0 or 1) is the caller's part: the graph checks shapes, not values.
The export is for predictors that draw no noise (a leapfrog generator whose denoising steps,
if any, are posterior means: every published generator); a sampler that draws noise would
bake one draw into the graph, and is refused.
"""

from __future__ import annotations

import copy
import json
import warnings
from pathlib import Path
from typing import Any

import torch
from torch import nn

from trajpref import __version__
from trajpref.data.transforms import from_model_frame
from trajpref.errors import ConfigError, TrajprefError
from trajpref.io import atomic_path, write_failed
from trajpref.models import checkpoint
from trajpref.models.predictor import DiffusionPredictor
from trajpref.types import Batch

EXPORT_SUFFIX = ".pt2"
"""The suffix of an exported predictor (``torch.export.save``'s archive)."""

META_FILE = "trajpref.json"
"""The name under which the archive's extra files hold what the export records
(``export_meta``)."""

MAX_AGENTS = 512
"""The most agents of one scene an exported program takes by default (its symbolic P's
bound; ``export_predictor(max_agents=...)``)."""

MATCH_TOL = 1e-4
"""The largest difference, in model units, between the exported program's futures and the
model's own on the check scenes that ``export_predictor`` accepts (it has been exactly 0 for
every published generator on this CPU)."""


def one_scene_batch(history: torch.Tensor, agent_type: torch.Tensor, t_fut: int,
                    future: torch.Tensor | None = None) -> Batch:  # fmt: skip
    """The batch of one scene of ``history`` [P, T_h, 2], built from shapes alone (P stays
    symbolic in an exported program, where ``collate`` reads sizes from the data), its
    ``future`` given or zeros [P, T_f, 2] (unread by the exported programs)."""
    n = history.shape[0]  # P
    future = history.new_zeros(n, t_fut, 2) if future is None else future
    return Batch(history=history, future=future, agent_type=agent_type, num_scenes=1,
                 scene=torch.zeros(n, dtype=torch.long, device=history.device))  # fmt: skip


class _NoDenoiser(nn.Module):
    """Stands in the exported copy for the denoiser of a generator that takes no denoising
    step (``tau`` 0), which never runs it: its config alone (the window lengths the
    predictor reads from it), no weights, so the file does not carry them."""

    def __init__(self, cfg: Any):
        super().__init__()
        self.cfg = cfg

    def context(self, features: Any) -> torch.Tensor:
        raise TrajprefError("an exported generator without denoising steps has no denoiser")


class OneScene(nn.Module):
    """One scene's K futures from its histories, without context and without checks:
    ``forward(history [P, T_h, 2], agent_type [P]) -> [K, P, T_f, 2]``, as
    ``DiffusionPredictor.predict`` computes them for a batch of that one scene. The batch is
    built here from shapes alone (``predict_scene``'s builder reads sizes from the data,
    which would fix P in the graph)."""

    def __init__(self, model: DiffusionPredictor, samples: int):
        super().__init__()
        self.model = model
        self.samples = samples

    def forward(self, history: torch.Tensor, agent_type: torch.Tensor) -> torch.Tensor:
        # traced at float32 / int64 the casts vanish from the graph, which instead checks the
        # dtypes first ("Tensor dtype mismatch! Expected: Float, Got: double"), a clearer
        # message than the matrix product's that would come without them
        history, agent_type = history.to(torch.float32), agent_type.to(torch.long)
        batch = one_scene_batch(history, agent_type, self.model.t_fut)
        y = self.model.sample_normalised(batch, self.samples)  # [K, P, T_f, 2], no noise drawn
        return from_model_frame(y, batch, self.model.scale)  # [K, P, T_f, 2]


def _check_exportable(model: object, samples: int | None) -> int:
    """K for ``model`` (``samples``, or its generator's K), or a ``ConfigError`` saying why
    it cannot be exported."""
    if not isinstance(model, DiffusionPredictor):
        raise ConfigError(f"export takes a diffusion checkpoint's predictor "
                          f"(load_predictor(path)), got {type(model).__name__}: the "
                          "constant-velocity baseline is three lines of arithmetic, nothing to "
                          "export")  # fmt: skip
    if model.sampler != "leapfrog" or model.generator is None:
        raise ConfigError("export takes a leapfrog generator: the full sampler draws noise "
                          "at every step, which an exported program would fix to one draw "
                          "(to export a denoiser's diffusion score: trajpref export --scorer, "
                          "trajpref.score.export.export_scorer)")  # fmt: skip
    if model.tau > 0 and model.stochastic:
        raise ConfigError(f"this predictor takes {model.tau} denoising steps with ancestral "
                          "noise (stochastic): an exported program would fix it to one draw; "
                          "export it with model.stochastic = False (posterior-mean steps, the "
                          "published models' way)")  # fmt: skip
    own = model.generator.samples
    k = own if samples is None else samples
    if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= own:
        raise ConfigError(f"samples must be an integer in 1..{own} (the generator's K), "
                          f"got {samples!r}")  # fmt: skip
    return k


def _example(model: DiffusionPredictor, agents: int, seed: int,
             ball: bool = False) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """A scene of ``agents`` walkers in the model's units times its scale (random walks at
    a typical step), and their types (0; with ``ball``, the last agent 1): the trace's example
    and the check's scenes."""
    gen = torch.Generator().manual_seed(seed)
    steps = torch.randn(agents, model.t_hist, 2, generator=gen) * 0.3 + 0.3  # model units
    history = torch.cumsum(steps, 1) * model.scale  # [P, T_h, 2]
    types = torch.zeros(agents, dtype=torch.long)
    types[-1] = int(ball)
    return history.to(model.device), types.to(model.device)


def agent_bound(model: DiffusionPredictor, max_agents: int = MAX_AGENTS) -> int:
    """The most agents of one scene an export of ``model`` takes (``bounded_agents`` by its
    generator's roles)."""
    return bounded_agents(max_agents, model.agent_roles)


def bounded_agents(max_agents: int, roles: int) -> int:
    """``max_agents`` (an integer >= 1, else a ``ConfigError``), or ``roles`` where a network
    knows that many agent roles (0: none), whose role embedding knows no more slots."""
    if isinstance(max_agents, bool) or not isinstance(max_agents, int) or max_agents < 1:
        raise ConfigError(f"max_agents must be an integer >= 1, got {max_agents!r}")
    return min(max_agents, roles) if roles else max_agents


def export_predictor(model: DiffusionPredictor, samples: int | None = None,
                     max_agents: int = MAX_AGENTS) -> torch.export.ExportedProgram:  # fmt: skip
    """``model`` (``load_predictor``'s, with its settings as they are: ``neighbour_radius``,
    ``max_speed``, ``spread_scale`` ...) as a ``torch.export.ExportedProgram`` of ``OneScene``,
    for scenes of 1 to ``max_agents`` agents (a model with agent roles: at most as many as
    it knows), keeping ``samples`` of its K (default all). The program is checked against the
    model on scenes of 1, 3 and up to 64 agents (the last with a ball) before it is returned: a
    difference above ``MATCH_TOL`` model units is a ``TrajprefError``. ``ConfigError`` for a
    model that draws noise (``_check_exportable``) or a bad count."""
    k = _check_exportable(model, samples)
    max_agents = agent_bound(model, max_agents)
    # a copy without gradients: the program's futures then need no torch.no_grad() to be
    # read as numbers, and the caller's model keeps its own settings
    own = copy.deepcopy(model).requires_grad_(False)
    if own.tau == 0:  # never run: the file need not carry it
        own.denoiser = _NoDenoiser(own.denoiser.cfg)
    wrapped = OneScene(own, k).eval()
    example = _example(model, min(2, max_agents), seed=0)
    dims = program_dims(max_agents, {"history": 0, "agent_type": 0})
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # torch's notes on tracing internals
        program = torch.export.export(wrapped, example, dynamic_shapes=dims, strict=False)
    checks = sorted({1, min(3, max_agents), min(max_agents, 64)})  # the last with a ball
    for seed, agents_in_scene in enumerate(checks, 1):
        scene = _example(model, agents_in_scene, seed, ball=agents_in_scene == checks[-1])
        with torch.no_grad():
            want, got = wrapped(*scene), program.module()(*scene)
        worst = float((want - got).abs().max()) / model.scale
        if not worst <= MATCH_TOL:
            raise TrajprefError(f"the exported program's futures differ from the model's by "
                                f"{worst:.3g} model units on a scene of {agents_in_scene} "
                                "agents: not exported")  # fmt: skip
    return program


def source_fields(source: str) -> dict[str, Any]:
    """What an exported file records of the checkpoint ``source`` names: ``source`` (a file's
    path resolved, a published name as it is) and ``checkpoint_hash``, its
    ``checkpoint.model_hash`` (None where it names none: a model built in code; the settings
    changed before the export are not in it)."""
    try:
        digest = checkpoint.model_hash(source)
    except (TrajprefError, OSError, KeyError, TypeError, ValueError):
        digest = None
    path = Path(source)
    return {"source": str(path.resolve()) if path.is_file() else source,
            "checkpoint_hash": digest}  # fmt: skip


def program_dims(max_agents: int, inputs: dict[str, int]) -> dict[str, dict[int, Any]]:
    """``torch.export``'s ``dynamic_shapes`` for a one-scene program: each input's agent
    dimension (``inputs``: name -> that dimension's index) symbolic from 1 to ``max_agents``;
    left fixed (an empty entry) where ``max_agents`` is 1 (a one-role model)."""
    if max_agents <= 1:
        return {name: {} for name in inputs}
    agents = torch.export.Dim("agents", min=1, max=max_agents)
    return {name: {dim: agents} for name, dim in inputs.items()}


def program_agents(program: torch.export.ExportedProgram) -> int:
    """The most agents P an exported one-scene program takes: the bound on its first input's
    first dimension (that dimension itself where it is fixed)."""
    first = next(n for n in program.graph.nodes if n.op == "placeholder"
                 and n.name == program.graph_signature.user_inputs[0])  # fmt: skip
    agents = first.meta["val"].shape[0]
    if isinstance(agents, int):  # a fixed P
        return agents
    return int(program.range_constraints[agents.node.expr].upper)


def program_shape(program: torch.export.ExportedProgram) -> tuple[int, int]:
    """(K, the most agents P) of an exported ``OneScene`` program, read from its graph: the
    futures' first dimension and ``program_agents``."""
    output = next(n for n in program.graph.nodes if n.op == "output").args[0][0]
    return int(output.meta["val"].shape[0]), program_agents(program)


def export_meta(model: DiffusionPredictor, program: torch.export.ExportedProgram,
                source: str) -> dict[str, Any]:  # fmt: skip
    """What an exported file records of itself (``META_FILE``): its inputs and output, the
    most agents it takes, the model's pace and units, where it came from (``source``: the
    checkpoint as named, and its file's ``checkpoint_hash``) and the settings fixed in it."""
    k, max_agents = program_shape(program)
    units = model.units or "the training data's units"
    return {
        "format": "trajpref-export/1",
        **source_fields(source),
        "inputs": {
            "history": f"[P, {model.t_hist}, 2] float32, absolute positions in {units}, oldest "
            "first, every one finite (a NaN makes every agent's futures NaN)",
            "agent_type": "[P] int64: 0 for a person; 1 only for the ball of a model trained "
            "with one (nba's: one per scene)",
        },
        "context": (
            "not read: the neighbours seen for part of the history, which this model "
            "reads in trajpref (predict_scene's context=), are left out"
            if model.reads_context
            else None
        ),  # fmt: skip
        "output": f"[{k}, P, {model.t_fut}, 2] float32 futures, absolute positions",
        "roles": (
            "agents are read in order as roles (their training data's order)"
            if model.agent_roles
            else None
        ),  # fmt: skip
        "t_hist": model.t_hist,
        "t_fut": model.t_fut,
        "samples": k,
        "max_agents": max_agents,
        "frame_interval": model.frame_interval,
        "units": model.units,
        "scale": model.scale,
        "settings": {  # as exported: the checkpoint's, or as set on the model before
            "tau": model.tau,
            "neighbour_radius": model.neighbour_radius,
            "max_speed": model.generator.cfg.max_speed,
            "spread_scale": model.generator.cfg.spread_scale,
            "max_log_sigma": model.generator.cfg.max_log_sigma,
            "agent_roles": model.agent_roles,
        },
        "trajpref_version": __version__,
        "torch_version": torch.__version__,
    }


def save_exported(program: torch.export.ExportedProgram, path: str | Path,
                  meta: dict[str, Any]) -> Path:  # fmt: skip
    """Write ``program`` to ``path`` (``.pt2``) with ``meta`` as the archive's ``META_FILE``,
    atomically; a write that fails is a one-line ``TrajprefError`` naming the file."""
    path = Path(path)
    if path.suffix.lower() != EXPORT_SUFFIX:
        raise ConfigError(f"{path}: an exported predictor is a {EXPORT_SUFFIX} file")
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:  # an OSError: one line, the file
        try:  # through a handle: the archive's inner folder is not named after tmp's name
            torch.export.save(program, fh, extra_files={META_FILE: json.dumps(meta)})
        except RuntimeError as exc:  # torch's archive writer (a full disk)
            raise write_failed(path, "the exported predictor", exc) from None
    return path


def load_exported(path: str | Path) -> tuple[nn.Module, dict[str, Any]]:
    """An exported predictor as a callable module and what it records (``export_meta``);
    PyTorch alone does the same: ``torch.export.load(path).module()``. Loading may unpickle
    what the archive marks so (``torch.export.load``): load only files you made or trust."""
    files = {META_FILE: ""}
    program = torch.export.load(str(path), extra_files=files)
    return program.module(), json.loads(files[META_FILE] or "{}")
