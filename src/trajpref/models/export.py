"""A predictor exported to one file that runs with PyTorch alone (``torch.export``).

A planner that ranks futures in a loop of its own, or a robot's process without trajpref
installed, loads the file with ``torch.export.load(path).module()`` and calls it on one
scene: ``(history [P, T_h, 2] float32, agent_type [P] int64) -> futures [K, P, T_f, 2]``,
absolute positions in the model's units, the very numbers ``predict_scene`` gives for the
same scene without context-only neighbours. The file holds the weights and the graph; loading
it executes no Python code of ours. What trajpref checks before predicting (finite
histories, coordinates float32 can hold, a scene no wider or faster than training, the
steps and units of the data) is the caller's part: the graph does not check values. The
export is for predictors that draw no noise (a leapfrog generator whose denoising steps,
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


class OneScene(nn.Module):
    """One scene's K futures from its histories, without context and without checks:
    ``forward(history [P, T_h, 2], agent_type [P]) -> [K, P, T_f, 2]``, as
    ``DiffusionPredictor.predict`` computes them for a batch of that one scene."""

    def __init__(self, model: DiffusionPredictor, samples: int):
        super().__init__()
        self.model = model
        self.samples = samples

    def forward(self, history: torch.Tensor, agent_type: torch.Tensor) -> torch.Tensor:
        n = history.shape[0]  # P, symbolic in the exported program
        batch = Batch(history=history, future=history.new_zeros(n, self.model.t_fut, 2),
                      scene=torch.zeros(n, dtype=torch.long, device=history.device),
                      agent_type=agent_type, num_scenes=1)  # fmt: skip
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
                          "at every step, which an exported program would fix to one "
                          "draw")  # fmt: skip
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


def _example(model: DiffusionPredictor, agents: int, seed: int) -> tuple[torch.Tensor, ...]:
    """A scene of ``agents`` walkers in the model's units times its scale (random walks at
    a typical step), and their types (all 0): the trace's example and the check's scenes."""
    gen = torch.Generator().manual_seed(seed)
    steps = torch.randn(agents, model.t_hist, 2, generator=gen) * 0.3 + 0.3  # model units
    history = torch.cumsum(steps, 1) * model.scale  # [P, T_h, 2]
    return history.to(model.device), torch.zeros(agents, dtype=torch.long, device=model.device)


def agent_bound(model: DiffusionPredictor, max_agents: int = MAX_AGENTS) -> int:
    """The most agents of one scene an export of ``model`` takes: ``max_agents`` (an integer
    >= 2, else a ``ConfigError``), or fewer for a model with agent roles, whose role embedding
    knows no more slots."""
    if isinstance(max_agents, bool) or not isinstance(max_agents, int) or max_agents < 2:
        raise ConfigError(f"max_agents must be an integer >= 2, got {max_agents!r}")
    return min(max_agents, model.agent_roles) if model.agent_roles else max_agents


def export_predictor(model: DiffusionPredictor, samples: int | None = None,
                     max_agents: int = MAX_AGENTS) -> torch.export.ExportedProgram:  # fmt: skip
    """``model`` (``load_predictor``'s, with its settings as they are: ``neighbour_radius``,
    ``max_speed``, ``spread_scale`` ...) as a ``torch.export.ExportedProgram`` of ``OneScene``,
    for scenes of 1 to ``max_agents`` agents (a model with agent roles: at most as many as
    it knows), keeping ``samples`` of its K (default all). The program is checked against the
    model on two scenes before it is returned: a difference above ``MATCH_TOL`` model units
    is a ``TrajprefError``. ``ConfigError`` for a model that draws noise (``_check_exportable``)
    or a bad count."""
    k = _check_exportable(model, samples)
    max_agents = agent_bound(model, max_agents)
    # a copy without gradients: the program's futures then need no torch.no_grad() to be
    # read as numbers, and the caller's model keeps its own settings
    wrapped = OneScene(copy.deepcopy(model).requires_grad_(False), k).eval()
    example = _example(model, 2 if max_agents >= 2 else 1, seed=0)
    agents = torch.export.Dim("agents", min=1, max=max_agents)
    dims = {"history": {0: agents}, "agent_type": {0: agents}}
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # torch's notes on tracing internals
        program = torch.export.export(wrapped, example, dynamic_shapes=dims, strict=False)
    for agents_in_scene, seed in ((min(3, max_agents), 1), (min(7, max_agents), 2)):
        scene = _example(model, agents_in_scene, seed)
        with torch.no_grad():
            want, got = wrapped(*scene), program.module()(*scene)
        worst = float((want - got).abs().max()) / model.scale
        if not worst <= MATCH_TOL:
            raise TrajprefError(f"the exported program's futures differ from the model's by "
                                f"{worst:.3g} model units on a scene of {agents_in_scene} "
                                "agents: not exported")  # fmt: skip
    return program


def _model_hash(source: str) -> str | None:
    """``checkpoint.model_hash`` of the checkpoint ``source`` names (None where it names none:
    a model built in code)."""
    try:
        return checkpoint.model_hash(source)
    except (TrajprefError, OSError, KeyError, TypeError, ValueError):
        return None


def export_meta(model: DiffusionPredictor, program: torch.export.ExportedProgram, source: str,
                max_agents: int) -> dict[str, Any]:  # fmt: skip
    """What an exported file records of itself (``META_FILE``): its inputs and output, the
    most agents it takes (``agent_bound``), the model's pace and units, where it came from
    (``source``: the checkpoint as named) and the settings baked in."""
    k = program.module()(*_example(model, 1, 0)).shape[0]
    return {
        "format": "trajpref-export/1",
        "source": source,
        "model_hash": _model_hash(source),
        "inputs": {
            "history": f"[P, {model.t_hist}, 2] float32, absolute positions, oldest first",
            "agent_type": "[P] int64 (0 person, 1 ball)",
        },  # fmt: skip
        "output": f"[{k}, P, {model.t_fut}, 2] float32 futures, absolute positions",
        "t_hist": model.t_hist,
        "t_fut": model.t_fut,
        "samples": int(k),
        "max_agents": max_agents,
        "frame_interval": model.frame_interval,
        "units": model.units,
        "scale": model.scale,
        "settings": {
            "tau": model.tau,
            "neighbour_radius": model.neighbour_radius,
            "agent_roles": model.agent_roles,
        },  # fmt: skip
        "trajpref_version": __version__,
        "torch_version": torch.__version__,
    }


def save_exported(program: torch.export.ExportedProgram, path: str | Path,
                  meta: dict[str, Any]) -> Path:  # fmt: skip
    """Write ``program`` to ``path`` (``.pt2``) with ``meta`` as the archive's ``META_FILE``,
    atomically; a write that fails is a one-line ``TrajprefError`` naming the file."""
    path = Path(path)
    if path.suffix != EXPORT_SUFFIX:
        raise ConfigError(f"{path}: an exported predictor is a {EXPORT_SUFFIX} file")
    with atomic_path(path) as tmp:  # an OSError: one line naming the file
        try:
            torch.export.save(program, str(tmp), extra_files={META_FILE: json.dumps(meta)})
        except RuntimeError as exc:  # torch's archive writer (a full disk)
            raise write_failed(path, "the exported predictor", exc) from None
    return path


def load_exported(path: str | Path) -> tuple[nn.Module, dict[str, Any]]:
    """An exported predictor as a callable module and what it records (``export_meta``);
    PyTorch alone does the same: ``torch.export.load(path).module()``."""
    files = {META_FILE: ""}
    program = torch.export.load(str(path), extra_files=files)
    return program.module(), json.loads(files[META_FILE] or "{}")
