"""Checkpoints: plain tensors and primitives only, loaded with ``weights_only=True``.

A denoiser checkpoint holds its config, data scale and weights. A generator checkpoint embeds
the whole denoiser checkpoint it was trained with, so it alone rebuilds the predictor.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import torch

from trajpref.config import ExperimentConfig, from_dict, to_dict
from trajpref.errors import TrajprefError
from trajpref.io import atomic_path
from trajpref.models.denoiser import Denoiser
from trajpref.models.generator import Generator

FORMAT = "trajpref-checkpoint/1"
KINDS = ("denoiser", "generator")


def save(path: str | Path, payload: dict[str, Any]) -> None:
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)


def load(path: str | Path) -> dict[str, Any]:
    """Load a checkpoint file without executing code; check its format.

    A generator checkpoint that names its denoiser (``denoiser_ref``: a path relative to the
    checkpoint's folder and a content hash) gets that denoiser loaded in, and a mismatch is
    refused."""
    payload = _load_file(path)
    ref = payload.get("denoiser_ref")
    if payload["kind"] == "generator" and "denoiser" not in payload and ref is not None:
        den_path = Path(path).parent / ref["path"]
        den = _load_file(den_path)
        if den.get("kind") != "denoiser" or den.get("hash") != ref["hash"]:
            raise TrajprefError(
                f"{path}: its denoiser {den_path} does not match the recorded hash "
                f"{ref['hash']} (found {den.get('hash')})"
            )
        payload["denoiser"] = den
    return payload


def publish(
    src: str | Path, dst: str | Path, denoiser_name: str = "denoiser.pt",
    replace_denoiser: bool = False,
) -> None:  # fmt: skip
    """Copy a generator checkpoint to ``dst`` with its embedded denoiser written once as
    ``dst.parent / denoiser_name`` and referenced by path and hash (smaller files).

    A different denoiser already at that path is replaced only with ``replace_denoiser``:
    other published generators (variants, fine-tuned models) may point to it."""
    payload = load(src)
    dst = Path(dst)
    if payload["kind"] != "generator":
        save(dst, payload)
        return
    den = payload.pop("denoiser")
    den_path = dst.parent / denoiser_name
    current = _load_file(den_path).get("hash") if den_path.is_file() else None
    if current != den["hash"]:
        if current is not None and not replace_denoiser:
            raise TrajprefError(
                f"{den_path} holds a different denoiser, which other checkpoints may name; "
                "publish under another denoiser_name or pass replace_denoiser=True"
            )
        save(den_path, den)
    payload["denoiser_ref"] = {"path": denoiser_name, "hash": den["hash"]}
    save(dst, payload)


def _load_file(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    if not path.is_file():
        raise TrajprefError(f"{path}: no such checkpoint")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for bad files
        raise TrajprefError(
            f"{path}: not a loadable checkpoint ({exc.__class__.__name__})"
        ) from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise TrajprefError(f"{path}: not a trajpref checkpoint (format {FORMAT} expected)")
    if payload.get("kind") not in KINDS:
        raise TrajprefError(f"{path}: unknown checkpoint kind {payload.get('kind')!r}")
    return payload


def state_hash(state: dict[str, torch.Tensor]) -> str:
    """A content hash of a state dict (to tie a generator to its denoiser)."""
    h = hashlib.sha256()
    for key in sorted(state):
        h.update(key.encode())
        h.update(state[key].detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def denoiser_payload(denoiser: Denoiser, cfg: ExperimentConfig, scale: float,
                     meta: dict[str, Any]) -> dict[str, Any]:  # fmt: skip
    state = {k: v.detach().cpu().clone() for k, v in denoiser.state_dict().items()}
    return {"format": FORMAT, "kind": "denoiser", "config": to_dict(cfg), "scale": float(scale),
            "state_dict": state, "hash": state_hash(state), "meta": meta}  # fmt: skip


def generator_payload(generator: Generator, denoiser: dict[str, Any], cfg: ExperimentConfig,
                      meta: dict[str, Any]) -> dict[str, Any]:  # fmt: skip
    state = {k: v.detach().cpu().clone() for k, v in generator.state_dict().items()}
    return {"format": FORMAT, "kind": "generator", "config": to_dict(cfg),
            "scale": denoiser["scale"], "state_dict": state, "hash": state_hash(state),
            "denoiser": denoiser, "meta": meta}  # fmt: skip


def config_of(payload: dict[str, Any]) -> ExperimentConfig:
    return from_dict(ExperimentConfig, payload["config"])


def build_denoiser(payload: dict[str, Any]) -> tuple[Denoiser, ExperimentConfig]:
    if payload["kind"] != "denoiser":
        raise TrajprefError(f"expected a denoiser checkpoint, got a {payload['kind']}")
    cfg = config_of(payload)
    model = Denoiser(cfg.model)
    model.load_state_dict(payload["state_dict"])
    if state_hash(payload["state_dict"]) != payload["hash"]:
        raise TrajprefError("denoiser weights do not match their recorded hash")
    return model, cfg


def build_generator(payload: dict[str, Any]) -> tuple[Generator, ExperimentConfig]:
    if payload["kind"] != "generator":
        raise TrajprefError(f"expected a generator checkpoint, got a {payload['kind']}")
    cfg = config_of(payload)
    model = Generator(cfg.model, cfg.generator.samples)
    model.load_state_dict(payload["state_dict"])
    return model, cfg


def load_predictor(path: str | Path, sampler: str | None = None, device: Any = "cpu"):
    """A ``DiffusionPredictor`` from a denoiser (full sampler only) or generator checkpoint."""
    from trajpref.models.predictor import DiffusionPredictor

    payload = load(path)
    if payload["kind"] == "generator":
        generator, cfg = build_generator(payload)
        denoiser, _ = build_denoiser(payload["denoiser"])
        sampler = sampler or "leapfrog"
    else:
        denoiser, cfg = build_denoiser(payload)
        generator = None
        sampler = sampler or "full"
    predictor = DiffusionPredictor(cfg.model, cfg.diffusion, payload["scale"], denoiser,
                                   generator, cfg.generator.tau, sampler)  # fmt: skip
    return predictor.to(device).eval()
