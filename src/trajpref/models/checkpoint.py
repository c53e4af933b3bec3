"""Checkpoint files: safetensors weights plus a plain-JSON header; loading never unpickles.

A file holds the network's tensors under ``model/``, an embedded denoiser's under
``denoiser/`` and a fine-tuning critic's under ``critic/``; the safetensors metadata entry
``trajpref`` is a JSON header with the format, kind, resolved config, data scale, content hash
and run metadata (and, for a generator, its embedded denoiser's header or a reference
``denoiser_ref`` = relative path + hash). Published files store float weights in half
precision; they load as float32.

In memory a checkpoint is a *payload* dict: ``format, kind, config, scale, state_dict, hash,
meta`` (+ ``denoiser`` payload, ``denoiser_ref``, ``critic`` state). The legacy format
(``trajpref-checkpoint/1``, a ``.pt`` file read with ``torch.load(weights_only=True)``) still
loads, with a deprecation warning.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import re
import shutil
import warnings
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from trajpref.config import USES_RL, ExperimentConfig, experiment_from_dict, to_dict
from trajpref.device import resolve_device
from trajpref.diffusion.schedule import DDPMSchedule
from trajpref.errors import (
    ConfigError,
    DenoiserConflict,
    ModelNotFound,
    TrajprefDeprecationWarning,
    TrajprefError,
    WeightsConflict,
)
from trajpref.io import (
    atomic_path,
    load_tensors,
    read_checkpoint_header,
    resume_state_message,
    write_failed,
)
from trajpref.models import zoo
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator
from trajpref.models.predictor import DiffusionPredictor, Sampler
from trajpref.types import WINDOW

FORMAT = "trajpref-checkpoint/2"
LEGACY_FORMAT = "trajpref-checkpoint/1"
KINDS = ("denoiser", "generator")
SUFFIX = ".safetensors"
LEGACY_SUFFIX = ".pt"
DENOISER_NAME = "denoiser" + SUFFIX
"""File name of a published dataset's default denoiser, beside its generators."""
_GROUPS = {"state_dict": "model", "critic": "critic"}
"""Payload entries holding tensors -> their prefix in the file."""


def state_hash(state: dict[str, torch.Tensor]) -> str:
    """A content hash of a state dict, over its float32 values (to tie a generator to its
    denoiser; half-precision files hash their weights as loaded)."""
    h = hashlib.sha256()
    for key in sorted(state):
        h.update(key.encode())
        value = state[key].detach().cpu()
        value = value.float() if value.is_floating_point() else value
        h.update(value.contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def header_model_hash(header: dict[str, Any], sampler: Sampler = "leapfrog") -> str:
    """What a checkpoint predicts with, as a 12-digit digest: its weights' hash, its
    denoiser's (named or embedded), its data scale and its model settings (the sampling
    settings such as ``max_speed`` included). Two checkpoints with the same digest predict the
    same; a results row records it (``model_hash``) so that rows of different weights are
    never merged. ``sampler="full"``: the digest of what the full sampler runs, the denoiser
    and the data scale alone (a generator file and its denoiser's file give the same one),
    and the file's ``neighbour_radius`` where one is set (the full sampler's denoiser applies
    it too). ``header`` is a checkpoint's metadata or payload (tensors are not read)."""
    den = header.get("denoiser_ref") or header.get("denoiser") or {}
    try:
        if sampler == "full":
            weights = header["hash"] if header["kind"] == "denoiser" else den.get("hash")
            parts = {"sampler": "full", "denoiser": weights, "scale": float(header["scale"])}
            radius = (header["config"].get("model") or {}).get("neighbour_radius")
            if radius is not None:  # a file without one keeps the digest it always had
                parts["neighbour_radius"] = float(radius)
        else:
            parts = {"kind": header["kind"], "weights": header["hash"],
                     "denoiser": den.get("hash"), "scale": float(header["scale"]),
                     "model": header["config"]["model"]}  # fmt: skip
    except (KeyError, TypeError) as exc:
        raise TrajprefError(f"a checkpoint header without {exc}") from None
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def model_hash(path: str | Path, sampler: Sampler = "leapfrog") -> str:
    """:func:`header_model_hash` of a checkpoint file or published name (header only for
    ``.safetensors``; a legacy ``.pt`` file is loaded)."""
    path = resolve_path(path)
    if path.suffix == LEGACY_SUFFIX:
        return header_model_hash(_read_legacy(path), sampler)
    return header_model_hash(read_checkpoint_header(path), sampler)


def _cpu_state(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().cpu().clone() for k, v in module.state_dict().items()}


def denoiser_payload(denoiser: Denoiser, cfg: ExperimentConfig, scale: float,
                     meta: dict[str, Any]) -> dict[str, Any]:  # fmt: skip
    state = _cpu_state(denoiser)
    return {"format": FORMAT, "kind": "denoiser", "config": to_dict(cfg), "scale": float(scale),
            "state_dict": state, "hash": state_hash(state), "meta": meta}  # fmt: skip


def generator_payload(generator: Generator, denoiser: dict[str, Any], cfg: ExperimentConfig,
                      meta: dict[str, Any],
                      critic: torch.nn.Module | None = None) -> dict[str, Any]:  # fmt: skip
    """A generator's payload. A fine-tuned one (``meta`` names its ``method``) also records
    its ``reward`` in ``meta`` (``cfg.finetune.reward``; None for the control, which has
    none), unless ``meta`` gives it: the file alone says how it was made."""
    if "method" in meta and "reward" not in meta:
        meta = {**meta, "reward": _run_reward(meta["method"], cfg.finetune.reward)}
    state = _cpu_state(generator)
    out = {"format": FORMAT, "kind": "generator", "config": to_dict(cfg),
           "scale": denoiser["scale"], "state_dict": state, "hash": state_hash(state),
           "denoiser": denoiser, "meta": meta}  # fmt: skip
    if critic is not None:
        out["critic"] = _cpu_state(critic)
    return out


def _run_reward(method: str, reward: str | None) -> str | None:
    """The reward a fine-tuning run of ``method`` trained with: None for a method that is no
    RL (``config.USES_RL``: the control). A name that table lacks (read from a file that an
    older or newer trajpref wrote) is taken for RL unless it is ``control``."""
    return reward if USES_RL.get(method, method != "control") else None


def finetune_reward(header: dict[str, Any]) -> str | None:
    """The reward a fine-tuned checkpoint was trained with (``score``, ``set``, ``sda``, or
    the name of a reward registered with ``trajpref.rl.register_reward``), from
    its header or payload: ``meta.reward``, or for a file written before it was recorded,
    its config's ``finetune.reward`` (``score`` where that predates the option too). None
    for the control and for a checkpoint that is no fine-tune (no ``meta.method``)."""
    meta = header.get("meta") or {}
    if meta.get("method") is None:
        return None
    if "reward" in meta:
        return meta["reward"]
    section = (header.get("config") or {}).get("finetune") or {}
    return _run_reward(meta["method"], section.get("reward", "score"))


# ----------------------------------------------------------------------------- files


def _flatten(payload: dict[str, Any], half: bool, prefix: str = ""):
    """-> (tensors {name: tensor}, header without tensors)."""
    tensors: dict[str, torch.Tensor] = {}
    header = {k: v for k, v in payload.items() if k not in (*_GROUPS, "denoiser")}
    for key, group in _GROUPS.items():
        for name, value in payload.get(key, {}).items():
            value = value.detach().cpu()
            if half and value.is_floating_point():
                value = value.half()
            tensors[f"{prefix}{group}/{name}"] = value.contiguous()
    if "denoiser" in payload:
        inner, header["denoiser"] = _flatten(payload["denoiser"], half, prefix + "denoiser/")
        tensors.update(inner)
    return tensors, header


def _unflatten(tensors: dict[str, torch.Tensor], header: dict[str, Any], prefix: str = ""):
    payload = {k: v for k, v in header.items() if k != "denoiser"}
    for key, group in _GROUPS.items():
        head = f"{prefix}{group}/"
        state = {name[len(head):]: value.float() if value.is_floating_point() else value
                 for name, value in tensors.items() if name.startswith(head)}  # fmt: skip
        if state or key == "state_dict":
            payload[key] = state
    if isinstance(header.get("denoiser"), dict):
        payload["denoiser"] = _unflatten(tensors, header["denoiser"], prefix + "denoiser/")
    return payload


def save(path: str | Path, payload: dict[str, Any], half: bool = False) -> None:
    """Write a payload as ``.safetensors`` (float weights in half precision with ``half``;
    the recorded hashes are then those of the rounded weights)."""
    path = Path(path)
    if path.suffix != SUFFIX:
        raise TrajprefError(f"{path}: checkpoints are written as {SUFFIX} files")
    if half:  # round first, so that the hashes describe what the file holds
        payload = _rounded(payload)
    tensors, header = _flatten(payload, half)
    header["format"] = FORMAT
    with atomic_path(path) as tmp:
        try:
            save_file(tensors, str(tmp), metadata={"trajpref": json.dumps(header)})
        except SafetensorError as exc:  # a full disk: not an OSError, and it names no file
            raise write_failed(path, "the checkpoint", exc) from None


def _rounded(payload: dict[str, Any]) -> dict[str, Any]:
    """A copy whose float weights are rounded to half precision (held as float32), with the
    hashes of the rounded weights."""
    out = _unflatten(*_flatten(payload, half=True))
    _rehash(out)
    return out


def _rehash(payload: dict[str, Any]) -> None:
    payload["hash"] = state_hash(payload["state_dict"])
    if "denoiser" in payload:
        _rehash(payload["denoiser"])


MODEL_SPECS = (
    "a published model such as 'zara1/generator' (`trajpref models` lists them) or a "
    "checkpoint file"
)
"""What names a checkpoint, as ``check_spec``'s message says it."""


def check_spec(spec: object, call: str, accepted: str = MODEL_SPECS) -> None:
    """``ConfigError`` unless ``spec`` is a ``str`` or an ``os.PathLike`` (a ``Path``), saying
    what ``call`` takes (``accepted``); None or a number would otherwise fail inside
    ``pathlib`` with a bare ``TypeError``."""
    if not isinstance(spec, (str, os.PathLike)):
        shown = "None" if spec is None else type(spec).__name__
        if isinstance(spec, (int, float, bytes)):
            shown += f" {spec!r}"[:60]
        name = getattr(spec, "checkpoint", None)  # a loaded model records what it was loaded by
        if isinstance(name, str):
            shown += f", a loaded model: pass its name, {name!r}"
        raise ConfigError(f"{call}: expected a str or a path (os.PathLike) naming {accepted}; "
                          f"got {shown}")  # fmt: skip


def resolve_path(path: str | Path) -> Path:
    """``path``, the published model it names (``DATASET/NAME``, e.g. ``zara1/generator``:
    see ``trajpref models``), or the ``.safetensors`` file that replaced a legacy ``.pt``
    path. An existing file wins over a published name. ``ConfigError`` for a ``path`` that is
    no str or path (``check_spec``)."""
    check_spec(path, "checkpoint")
    spec = path
    path = Path(path)
    if not path.is_file() and zoo.is_name(spec):
        return zoo.resolve(str(spec))
    if not path.is_file() and path.suffix == LEGACY_SUFFIX:
        new = path.with_suffix(SUFFIX)
        if new.is_file():
            warnings.warn(f"{path} is now {new}", TrajprefDeprecationWarning, stacklevel=3)
            return new
    if not path.is_file():  # a published model's repository path names it, as the CLI does
        raise ModelNotFound(zoo.not_here_message(spec) or f"{path}: no such checkpoint")
    return path


def _read_file(path: Path) -> dict[str, Any]:
    if path.suffix == LEGACY_SUFFIX:
        return _read_legacy(path)
    header = read_checkpoint_header(path)
    try:
        tensors = load_file(str(path))
    except (SafetensorError, OSError) as exc:
        raise TrajprefError(
            f"{path}: not a trajpref checkpoint ({exc.__class__.__name__})"
        ) from None
    if header.get("format") != FORMAT:
        raise TrajprefError(f"{path}: not a trajpref checkpoint (format {FORMAT} expected)")
    return _unflatten(tensors, header)


def _read_legacy(path: Path) -> dict[str, Any]:
    try:
        payload = load_tensors(path)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for bad files
        raise TrajprefError(
            f"{path}: not a loadable checkpoint ({exc.__class__.__name__})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != LEGACY_FORMAT:
        if path.name.endswith("_last.pt"):
            raise TrajprefError(resume_state_message(path))
        raise TrajprefError(f"{path}: not a trajpref checkpoint")
    missing = {"kind", "config", "scale", "state_dict", "hash"} - set(payload)
    if missing:
        raise TrajprefError(f"{path}: a checkpoint without {', '.join(sorted(missing))}")
    _upgrade_config(payload)
    # warned only once the file has proved to be a checkpoint: a broken file gets one error
    warnings.warn(
        f"{path}: a legacy .pt checkpoint; it still loads, but new files are {SUFFIX} "
        "(benchmarks/convert_models.py converts)",
        TrajprefDeprecationWarning,
        stacklevel=4,
    )
    return payload


def _upgrade_config(payload: dict[str, Any]) -> None:
    """Rewrite a legacy payload's config dicts in today's layout (the file's own warning
    already said it is old)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        payload["config"] = to_dict(config_of(payload))
    if isinstance(payload.get("denoiser"), dict):
        _upgrade_config(payload["denoiser"])


def _load_file(path: str | Path) -> dict[str, Any]:
    payload = _read_file(resolve_path(path))
    if payload.get("kind") not in KINDS:
        raise TrajprefError(f"{path}: unknown checkpoint kind {payload.get('kind')!r}")
    return payload


def load(path: str | Path) -> dict[str, Any]:
    """Load a checkpoint file (never executing code) into a payload dict.

    A generator checkpoint that names its denoiser (``denoiser_ref``: a path relative to the
    checkpoint's folder and a content hash) gets that denoiser loaded in; a mismatch is
    refused."""
    path = resolve_path(path)
    payload = _load_file(path)
    _attach_weights(payload, path)
    ref = payload.get("denoiser_ref")
    if payload["kind"] == "generator" and "denoiser" not in payload and ref is not None:
        try:  # an older file may name denoiser.pt, now converted to .safetensors
            den_path = resolve_path(path.parent / ref["path"])
        except TrajprefError:
            raise ModelNotFound(
                f"{path}: this generator names its denoiser instead of embedding it (a "
                f"published file): it needs {ref['path']} (hash {ref['hash']}) beside it, in "
                f"{path.parent}; copy the denoiser it was published with there (`trajpref "
                "models` lists them) or load it by its published name"
            ) from None
        den = _load_file(den_path)
        found = state_hash(den["state_dict"]) if den.get("kind") == "denoiser" else None
        if found != ref["hash"]:
            raise TrajprefError(
                f"{path}: its denoiser {den_path} does not match the recorded hash "
                f"{ref['hash']} (found {found})"
            )
        payload["denoiser"] = den
    return payload


def _attach_weights(payload: dict[str, Any], path: Path) -> None:
    """A settings-only variant (``weights_ref``: the file of its weights, relative to its own
    folder, and their hash) gets those weights loaded in; a mismatch is refused."""
    ref = payload.get("weights_ref")
    if ref is None:
        return
    base_path = resolve_path(path.parent / ref["path"])
    base = _load_file(base_path)
    if base.get("kind") != payload["kind"] or base.get("hash") != ref["hash"]:
        raise TrajprefError(
            f"{path}: its weights {base_path} do not match the recorded hash {ref['hash']} "
            f"(found {base.get('hash')})"
        )
    payload["state_dict"] = base["state_dict"]


def publish_variant(base: str | Path, dst: str | Path, changes: dict[str, Any], note: str) -> None:
    """A published generator with other ``POST_HOC_SETTINGS`` and the same weights, written as
    a few kilobytes that name the base file by path (relative, same folder) and hash instead of
    copying its weights. ``changes`` maps ``model`` fields to values; each is logged in
    ``meta["changes"]`` with ``note``."""
    base, dst = Path(base), Path(dst)
    if base.parent.resolve() != dst.parent.resolve():
        raise TrajprefError(f"{dst}: a variant lives beside its base {base}")
    payload = _read_file(base)
    if payload["kind"] != "generator" or "weights_ref" in payload:
        raise TrajprefError(f"{base}: a variant is made from a generator file with its weights")
    bad = sorted(set(changes) - set(POST_HOC_SETTINGS))
    if bad:
        raise TrajprefError(
            f"model.{bad[0]} cannot change after training; only {', '.join(POST_HOC_SETTINGS)} can"
        )
    before = config_of(payload).model
    payload.pop("state_dict")
    payload.pop("critic", None)  # a fine-tuning value head is not a sampling setting
    payload["weights_ref"] = {"path": base.name, "hash": payload["hash"]}
    payload["config"]["model"].update(changes)
    config_of(payload)  # the edited config must still be valid
    logged = [{k: v, "previous": getattr(before, k), "note": note} for k, v in changes.items()]
    payload["meta"] = {**payload["meta"], "changes": [*payload["meta"].get("changes", []), *logged]}
    save(dst, payload)


def publish(
    src: str | Path, dst: str | Path, denoiser_name: str = DENOISER_NAME,
    replace_denoiser: bool = False, half: bool = True,
) -> None:  # fmt: skip
    """Copy a checkpoint to ``dst`` (half precision by default). A generator's denoiser is
    written once as ``dst.parent / denoiser_name`` and referenced by path and hash.

    A different denoiser already at that path is replaced only with ``replace_denoiser``:
    other published generators (variants, fine-tuned models) may point to it."""
    payload = load(src)
    payload.pop("denoiser_ref", None)
    dst = Path(dst)
    if payload["kind"] == "generator" and dst.is_file():
        _check_no_variant_loses_its_weights(dst, payload, half)
    if payload["kind"] != "generator":
        save(dst, payload, half)
        return
    den = payload.pop("denoiser")
    if half:
        den = _rounded(den)
    den_path = dst.parent / denoiser_name
    current = state_hash(_load_file(den_path)["state_dict"]) if den_path.is_file() else None
    if current != den["hash"]:
        if current is not None and not replace_denoiser:
            raise DenoiserConflict(
                f"{den_path} holds a different denoiser, which other checkpoints may name; "
                "publish under another denoiser_name or pass replace_denoiser=True"
            )
        save(den_path, den, half)
    payload["denoiser_ref"] = {"path": denoiser_name, "hash": den["hash"]}
    save(dst, payload, half)


def variants_of(path: str | Path) -> list[Path]:
    """The settings-only variants (``publish_variant``) beside ``path`` that take their weights
    from it."""
    path = Path(path)
    found = []
    for other in sorted(path.parent.glob(f"*{SUFFIX}")):
        if other.name == path.name:
            continue
        ref = read_checkpoint_header(other).get("weights_ref")  # headers only: no weights read
        if ref is not None and ref["path"] == path.name:
            found.append(other)
    return found


def _check_no_variant_loses_its_weights(dst: Path, payload: dict[str, Any], half: bool) -> None:
    """Refuse to publish ``payload`` over ``dst`` when variants name ``dst``'s weights and the
    new file would hold other weights (compared by the hash the file would record)."""
    names = [v.name for v in variants_of(dst)]
    if not names:
        return
    new_hash = state_hash(_rounded(payload)["state_dict"]) if half else payload["hash"]
    if read_checkpoint_header(dst).get("hash") != new_hash:
        raise WeightsConflict(
            f"{dst} holds the weights of {', '.join(names)}: move them first "
            "(checkpoint.move_weights) or remove those variants"
        )


def move_weights(src: str | Path, dst: str | Path) -> list[Path]:
    """Copy a published generator file to a new name in the same folder and point every
    settings-only variant that takes its weights from ``src`` at the copy (the way to keep a
    default's weights as a named variant before another generator is published over it).
    Returns the re-pointed variants; ``src`` itself is left in place."""
    src, dst = Path(src), Path(dst)
    if src.parent.resolve() != dst.parent.resolve():
        raise TrajprefError(f"{dst}: weights move within their folder ({src.parent})")
    if dst.exists():
        raise TrajprefError(f"{dst} exists already")
    payload = _read_file(src)
    if payload.get("kind") != "generator" or "weights_ref" in payload:
        raise TrajprefError(f"{src}: only a generator file with its own weights can move")
    moved = variants_of(src)
    shutil.copyfile(src, dst)
    for variant in moved:
        record = _read_file(variant)
        record["weights_ref"] = {**record["weights_ref"], "path": dst.name}
        save(variant, record)
    return moved


POST_HOC_SETTINGS = ("stochastic_steps", "max_speed", "spread_scale", "max_log_sigma",
                     "neighbour_radius")  # fmt: skip
"""``model`` fields of a generator file that may change after training without retraining:
how its tau steps sample, its input speed clamp, its samples' spread, the cap on their
sigma and the neighbour radius of its attention across agents (the weights are not
touched). Each is part of the file's config, so of ``header_model_hash``."""


def set_generator_setting(
    path: str | Path, name: str, value: Any, note: str, date: str | None = None
) -> bool:
    """Rewrite one of a generator file's ``POST_HOC_SETTINGS`` in place (the weights, their
    precision and hashes stay as they are). The change is logged in ``meta["changes"]`` with
    the previous value, ``note`` and ``date`` (ISO, today's when not given). Returns False
    when the file already has the value (it is then left untouched)."""
    if date is None:
        date = datetime.date.today().isoformat()
    elif not re.fullmatch(r"\d{4}-\d{2}-\d{2}", date):
        raise TrajprefError(f"date must be YYYY-MM-DD, got {date!r}")
    if name not in POST_HOC_SETTINGS:
        raise TrajprefError(
            f"model.{name} cannot change after training; only {', '.join(POST_HOC_SETTINGS)} can"
        )
    path = Path(path)
    payload = _read_file(path)
    if payload["kind"] != "generator":
        raise TrajprefError(f"{path}: {name} is a generator setting, not a denoiser's")
    previous = getattr(config_of(payload).model, name)
    if previous == value:
        return False
    half = any(t.dtype == torch.float16 for t in load_file(str(path)).values())
    payload["config"]["model"][name] = value
    config_of(payload)  # the edited config must still be valid
    change = {name: value, "previous": previous, "date": date, "note": note}
    payload["meta"] = {**payload["meta"], "changes": [*payload["meta"].get("changes", []), change]}
    save(path, payload, half)
    return True


def set_stochastic_steps(
    path: str | Path, stochastic: bool, note: str, date: str | None = None
) -> bool:
    """Whether a generator file's tau denoising steps add ancestral noise
    (``set_generator_setting`` for ``model.stochastic_steps``)."""
    return set_generator_setting(path, "stochastic_steps", stochastic, note, date)


# ----------------------------------------------------------------------------- models


LEGACY_DEFAULTS = {("model", "stochastic_steps"): True}
"""Settings whose default changed after checkpoints were written without them: such a file
keeps the value it was trained and evaluated with (ancestral tau steps before 2026-11-24)."""


def config_of(payload: dict[str, Any]) -> ExperimentConfig:
    """The ``ExperimentConfig`` a payload was trained with: a key its header lacks takes its
    default (or its ``LEGACY_DEFAULTS`` value); a key this version does not know is said to
    come from a newer trajpref."""
    config = payload["config"]
    missing = {k: v for k, v in LEGACY_DEFAULTS.items() if k[1] not in config.get(k[0], {})}
    if missing:
        config = {section: dict(values) if isinstance(values, dict) else values
                  for section, values in config.items()}  # fmt: skip
        for (section, name), value in missing.items():
            config.setdefault(section, {})[name] = value
    return experiment_from_dict(config, stored="a checkpoint's config")


def header_of(spec: str | Path) -> dict[str, Any]:
    """Checkpoint ``spec``'s header (``spec`` as ``resolve_path`` takes it), its weights left
    unread; a legacy ``.pt`` file is loaded whole, without its state dict, and without its
    deprecation warning (loading the model warns of the format once)."""
    path = resolve_path(spec)
    if path.suffix != LEGACY_SUFFIX:
        return read_checkpoint_header(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TrajprefDeprecationWarning)
        return {k: v for k, v in _read_legacy(path).items() if k != "state_dict"}


def windows_of(spec: str | Path) -> tuple[int, int]:
    """(T_h, T_f), the observed and future frames of the windows a checkpoint reads (its
    ``model.t_hist`` and ``model.t_fut``), from its header (``header_of``). Data for it are cut
    alike: ``trajpref.data.ReadOptions(t_hist=..., t_fut=...)``."""
    model = header_of(spec).get("config", {}).get("model", {})
    return (int(model.get("t_hist", WINDOW[0])), int(model.get("t_fut", WINDOW[1])))


def agreed_windows(
    readers: dict[str, tuple[int, int] | None],
    given: tuple[int | None, int | None] = (None, None),
) -> tuple[int, int]:
    """(T_h, T_f) to cut data into for ``readers`` (a label such as ``--model run/g`` -> the
    lengths that model or scorer reads, ``windows_of``; None: any, the constant-velocity
    baseline) and ``given`` (``--history``, ``--future``; None: not given): the readers' one
    pair, else ``given``, else 8 + 12. ``ConfigError`` where two readers disagree, or a given
    length differs from theirs."""
    found = {label: w for label, w in readers.items() if w is not None}
    if len(set(found.values())) > 1:
        (first, own), *rest = found.items()
        others = ", ".join(f"{label} of {h} + {f}" for label, (h, f) in rest)
        raise ConfigError(f"{first} reads windows of {own[0]} observed + {own[1]} future "
                          f"frames, {others}: they must read the same lengths (one cut of the "
                          "data serves them all), so give ones trained on the same window "
                          "lengths")  # fmt: skip
    if not found:
        return tuple(w if g is None else g for g, w in zip(given, WINDOW, strict=True))
    label, own = next(iter(found.items()))
    for flag, want, need in zip(("--history", "--future"), given, own, strict=True):
        if want is not None and want != need:
            raise ConfigError(f"{flag} {want}: {label} reads windows of {own[0]} observed + "
                              f"{own[1]} future frames (its model.t_hist and model.t_fut); "
                              f"leave {flag} out, and the data are cut as it needs")  # fmt: skip
    return own


def build_denoiser(payload: dict[str, Any], *,
                   loading: bool = False) -> tuple[Denoiser, ExperimentConfig]:  # fmt: skip
    """The denoiser of a denoiser payload and its config. Training (the default) builds it
    with its random initialisation, which draws from torch's global stream (a seeded stage
    relies on those draws), then copies the weights in; ``loading=True`` builds it without
    any (``built_for_loading``): nothing is drawn, so it is safe beside other threads."""
    if payload["kind"] != "denoiser":
        raise TrajprefError(f"expected a denoiser checkpoint, got a {payload['kind']}")
    if state_hash(payload["state_dict"]) != payload["hash"]:
        raise TrajprefError("denoiser weights do not match their recorded hash")
    cfg = config_of(payload)
    if loading:
        return built_for_loading(Denoiser, cfg.model, payload["state_dict"]), cfg
    model = Denoiser(cfg.model)
    model.load_state_dict(payload["state_dict"])
    return model, cfg


def build_generator(payload: dict[str, Any], *,
                    loading: bool = False) -> tuple[Generator, ExperimentConfig]:  # fmt: skip
    """The generator of a generator payload and its config; ``loading`` as
    ``build_denoiser``'s."""
    if payload["kind"] != "generator":
        raise TrajprefError(f"expected a generator checkpoint, got a {payload['kind']}")
    cfg = config_of(payload)
    if loading:
        return built_for_loading(Generator, cfg.model, payload["state_dict"]), cfg
    model = Generator(cfg.model)
    model.load_state_dict(payload["state_dict"])
    return model, cfg


def built_for_loading(cls: type[torch.nn.Module], cfg: Any,
                      state: dict[str, torch.Tensor]) -> torch.nn.Module:  # fmt: skip
    """``cls(cfg)`` holding the weights ``state``, built without random initialisation.

    The module is built on the meta device (shapes only: its initialisers run on no data and
    draw nothing from torch's global generator; ``torch.device("meta")`` holds in this thread
    alone), then takes a float32 copy of each weight (``load_state_dict(assign=True)``, the
    same strict check of names and shapes). Shared parameters are shared again, and buffers
    that are no part of the state dict are rebuilt on the CPU by the module's
    ``config_buffers()``; a tensor left on the meta device is a ``TrajprefError``."""
    with torch.device("meta"):
        model = cls(cfg)
    shared = _shared_parameters(model)
    model.load_state_dict({name: _owned(value) for name, value in state.items()}, assign=True)
    for first, *others in shared:
        tied = model.get_parameter(first)
        for name in others:
            owner, _, attr = name.rpartition(".")
            setattr(model.get_submodule(owner), attr, tied)
    for module in model.modules():
        rebuild = getattr(module, "config_buffers", None)
        for name, value in (rebuild() if callable(rebuild) else {}).items():
            setattr(module, name, value)
    left = [name for name, t in [*model.named_parameters(), *model.named_buffers()] if t.is_meta]
    if left:
        raise TrajprefError(f"{cls.__name__}: {', '.join(left)} not loaded (no weights in the "
                            "checkpoint, and not rebuilt by config_buffers())")  # fmt: skip
    return model


def _owned(value: torch.Tensor) -> torch.Tensor:
    """A contiguous copy of a weight (float32 if floating), as ``load_state_dict`` copies into
    a float32 parameter: the module shares no memory with the payload (or a mapped file)."""
    dtype = torch.float32 if value.is_floating_point() else value.dtype
    out = torch.empty(value.shape, dtype=dtype, device=value.device)
    return out.copy_(value.detach())


def _shared_parameters(model: torch.nn.Module) -> list[list[str]]:
    """The names of each parameter that a module holds under several names."""
    names: dict[int, list[str]] = {}
    for name, param in model.named_parameters(remove_duplicate=False):
        names.setdefault(id(param), []).append(name)
    return [group for group in names.values() if len(group) > 1]


def denoiser_of(payload: dict[str, Any]) -> dict[str, Any]:
    """The denoiser payload of a denoiser or generator payload."""
    return payload if payload["kind"] == "denoiser" else payload["denoiser"]


def predictor_from_payload(payload: dict[str, Any], sampler: Sampler | None = None, *,
                           loading: bool = False) -> DiffusionPredictor:  # fmt: skip
    """A ``DiffusionPredictor`` from a denoiser (full sampler only) or generator payload, in
    eval mode (a generator trained with dropout predicts without it; training code sets its
    own mode). ``loading`` as ``build_denoiser``'s: training builds with the random
    initialisation it seeded (the default), the loading calls with none."""
    denoiser, cfg = build_denoiser(denoiser_of(payload), loading=loading)
    generator = None
    if payload["kind"] == "generator":
        generator, cfg = build_generator(payload, loading=loading)
    sampler = sampler or ("leapfrog" if generator is not None else "full")
    schedule = DDPMSchedule.from_config(cfg.diffusion)
    predictor = DiffusionPredictor(denoiser, schedule, payload["scale"], generator,
                                   cfg.model.tau, sampler, cfg.model.stochastic_steps)  # fmt: skip
    return predictor.eval()


def as_float32(module: torch.nn.Module) -> torch.nn.Module:
    """``module`` with its floating-point parameters and buffers in float32, the precision the
    weights are stored and computed in: a host that has set
    ``torch.set_default_dtype(torch.float64)`` builds modules in float64, which then refuse
    float32 inputs. The loaded weights are float32 values, so nothing is rounded; the host's
    default dtype is left as it is (nothing global is changed)."""
    return module.float()


def load_predictor(path: str | Path, *, sampler: Sampler | None = None, device: Any = "cpu"):
    """A ``DiffusionPredictor`` from a checkpoint file, on ``device``, in eval mode.

    ``device`` as ``trajpref.device.resolve_device`` takes it (``auto``: CUDA when available,
    else the CPU; a device this machine lacks is a ``ConfigError`` before the file is read).
    ``sampler`` and ``device`` are keyword-only, as in ``registry.load_predictor``, so that the
    two functions cannot be called with their arguments in different orders. The predictor
    carries its training data's step, units and scene width (``models.timing.attach_timing``:
    ``frame_interval``, ``units``, ``training_width``, ``timing``; the full sampler's width is
    its denoiser's) and the file's ``model.neighbour_radius`` (a
    generator file's own, or a bare denoiser's; training code, which builds its predictors
    from payloads, never applies it). Loading draws nothing from torch's global random stream,
    nor saves and restores it: the modules are built without random initialisation
    (``built_for_loading``), so ``torch.manual_seed(s)`` gives the same draws after it as
    before, and another thread drawing from that stream meanwhile is not disturbed. Its
    weights are float32 whatever ``torch.get_default_dtype()`` is (``as_float32``).
    """
    from trajpref.models.timing import attach_timing

    device = resolve_device(device)  # "auto" as the CLI reads it; a missing GPU in one line
    payload = load(path)
    predictor = predictor_from_payload(payload, sampler, loading=True)  # no random init
    predictor = as_float32(predictor).to(device).eval()  # float32 under any default dtype
    predictor.neighbour_radius = config_of(payload).model.neighbour_radius
    # the training width of the network that reads the scene: the full sampler runs the denoiser
    runs_denoiser = predictor.sampler != "leapfrog"
    return attach_timing(predictor, payload, denoiser_of(payload) if runs_denoiser else None)
