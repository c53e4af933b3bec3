"""Writing a study folder: what each panel shows, its scores, the images, the manifest.

``build`` fills :class:`SceneData` from a dataset and real models; :func:`make_synthetic_study`
fills it with made-up scenes and scores (for demos, tests and the load benchmark). Both end in
:func:`write_study`, which shuffles the methods of every scene behind panel letters, renders one
image per panel, rewrites the images uncompressed so that a scene's are of one byte size
(:func:`store_uncompressed`) and writes the manifest, all into a temporary folder renamed onto
``out`` at the end: a failed build leaves nothing behind.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import zlib
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Literal

import numpy as np

from trajpref.errors import ConfigError
from trajpref.io import write_json
from trajpref.survey.manifest import (
    GROUND_TRUTH,
    IMAGES,
    MANIFEST,
    METHOD_RE,
    ORDERS,
    Panel,
    PanelKey,
    Study,
    StudyScene,
    load_study,
    manifest_dict,
)
from trajpref.viz.plot import NO_UNITS, plot_panel

GroundTruthMode = Literal["rated", "reference"]

INSTRUCTIONS = {
    "rated": (
        "Each picture shows people's past paths (lines with dots) and, for every person, the "
        "continuations a prediction gives them (darker lines are the ones it finds more "
        "likely). Rate each picture from 1 (not plausible at all) to 5 (fully plausible) on "
        "both questions. Keys 1-5 rate, the left and right arrows move between pictures."
    ),
    "reference": (
        "Each picture shows people's past paths (lines with dots) and, for every person, the "
        "continuations a prediction gives them (darker lines are the ones it finds more "
        "likely); the small picture beside it shows what really happened (dashed). Rate each "
        "picture from 1 (not plausible at all) to 5 (fully plausible) on both questions. "
        "Keys 1-5 rate, the left and right arrows move between pictures."
    ),
}
"""The default instructions, per ground-truth mode."""


@dataclass
class ShownSet:
    """What one panel draws and how the diffusion score rates it."""

    paths: np.ndarray
    """[R, P, T_f, 2] the shown futures, best first per agent."""
    weights: np.ndarray
    """[R, P] shading in [0, 1] (darker = higher score), as the paper's Fig. 2."""
    ats: float
    """ATS of the shown futures (see ``PanelKey.ats``)."""
    fts: float
    """FTS of the shown futures."""
    ade: float
    """Mean ADE of the shown futures."""
    fde: float
    """Mean FDE of the shown futures."""
    max_ats: float | None = None
    """maxATS_K of the method's K samples for this scene."""
    max_fts: float | None = None
    """maxFTS_K of the method's K samples for this scene."""
    shown: list[dict[str, Any]] = field(default_factory=list)
    """Per drawn future: ``agent``, ``sample``, ``rank``, ``ats``, ``fts``, ``ade``, ``fde``."""


@dataclass
class SceneData:
    """One picked scene with every method's panel, before shuffling."""

    history: np.ndarray
    """[P, T_h, 2] absolute positions."""
    future: np.ndarray
    """[P, T_f, 2] the ground truth."""
    panels: dict[str, ShownSet]
    """method name -> what its panel shows (the ground truth included when rated)."""
    source: str = ""
    """The dataset's scene id."""
    index: int = -1
    """The scene's index in the split."""
    stratum: int = 0
    """The size stratum it was drawn from."""


def shown_predictions(pred: np.ndarray, d_pred: np.ndarray, d_gt: np.ndarray,
                      future: np.ndarray, top: int = 2) -> ShownSet:  # fmt: skip
    """Each agent's ``top`` samples by its own ATS, as the paper's Fig. 2, with the scores of
    what is shown.

    pred [K, P, T_f, 2], d_pred [K, P, T_f] (diffusion residuals of the samples), d_gt [P, T_f]
    (of the ground truth, same noise), future [P, T_f, 2]. The panel's ATS is the ratio of sums
    over everything drawn: 1 - sum_{r,p,t} d_pred[k_rp, p, t] / (R sum_{p,t} d_gt[p, t]); FTS
    the same at the final step; ``max_ats``/``max_fts`` are the scene's best of K.
    """
    k, p = pred.shape[:2]
    r = min(top, k)
    agent_ats = 1 - d_pred.sum(-1) / d_gt.sum(-1)  # [K, P]
    agent_fts = 1 - d_pred[..., -1] / d_gt[..., -1]  # [K, P]
    err = np.linalg.norm(pred - future[None], axis=-1)  # [K, P, T_f]
    pick = np.argsort(-agent_ats, axis=0, kind="stable")[:r]  # [R, P]
    cols = np.arange(p)[None].repeat(r, 0)  # [R, P]
    lo, hi = agent_ats.min(0), agent_ats.max(0)  # [P]
    weights = np.where(hi > lo, (agent_ats[pick, cols] - lo) / np.maximum(hi - lo, 1e-12), 1.0)
    shown = [
        {
            "agent": int(i),
            "sample": int(pick[j, i]),
            "rank": int(j),
            "ats": float(agent_ats[pick[j, i], i]),
            "fts": float(agent_fts[pick[j, i], i]),
            "ade": float(err[pick[j, i], i].mean()),
            "fde": float(err[pick[j, i], i, -1]),
        }
        for i in range(p)
        for j in range(r)
    ]
    d_shown = d_pred[pick, cols]  # [R, P, T_f]
    scene_ats = 1 - d_pred.sum((1, 2)) / d_gt.sum()  # [K]
    scene_fts = 1 - d_pred[..., -1].sum(1) / d_gt[..., -1].sum()  # [K]
    return ShownSet(
        paths=pred[pick, cols],  # [R, P, T_f, 2]
        weights=np.clip(weights, 0.0, 1.0),
        ats=float(1 - d_shown.sum() / (r * d_gt.sum())),
        fts=float(1 - d_shown[..., -1].sum() / (r * d_gt[..., -1].sum())),
        ade=float(err[pick, cols].mean()),
        fde=float(err[pick, cols, -1].mean()),
        max_ats=float(scene_ats.max()),
        max_fts=float(scene_fts.max()),
        shown=shown,
    )


def ground_truth_panel(future: np.ndarray) -> ShownSet:
    """The real futures as a rated panel: one path per agent, ATS = FTS = 0 by definition."""
    p = future.shape[0]
    shown = [{"agent": i, "sample": -1, "rank": 0, "ats": 0.0, "fts": 0.0, "ade": 0.0,
              "fde": 0.0} for i in range(p)]  # fmt: skip
    return ShownSet(future[None], np.ones((1, p)), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, shown)


def scene_limits(history: np.ndarray, future: np.ndarray, panels: list[ShownSet],
                 margin: float = 0.08) -> tuple[float, float, float, float]:  # fmt: skip
    """(x0, x1, y0, y1) covering the history, the ground truth and every shown path."""
    pts = [history.reshape(-1, 2), future.reshape(-1, 2)]
    pts += [s.paths.reshape(-1, 2) for s in panels]
    pts = np.concatenate(pts)  # [M, 2]
    lo, hi = pts.min(0), pts.max(0)  # [2]
    pad = margin * max(float((hi - lo).max()), 1e-3)
    return (float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad))


def _panel_image(history: np.ndarray, paths: np.ndarray, weights: np.ndarray, out: Path,
                 limits: tuple[float, float, float, float], units: str,
                 dashed: bool = False) -> None:  # fmt: skip
    """``plot_panel``; for data of unknown units without the axis titles, so that no rater
    reads "x [unknown]" (the tick values stay)."""
    known = units not in NO_UNITS  # the figures' own (models.timing.UNKNOWN_UNITS, None besides)
    plot_panel(history, paths, weights, out, limits, units if known else "", dashed=dashed,
               axis_titles=known)  # fmt: skip


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
"""The first eight bytes of every PNG file."""
PNG_CHUNK_OVERHEAD = 12
"""Bytes of a chunk besides its data: length, type, CRC."""


def png_chunks(data: bytes) -> list[tuple[bytes, bytes, int]]:
    """The chunks of PNG ``data``: ``(type, data, crc)`` each, in file order; ``ValueError``
    for data that is not a well-formed PNG (a bad signature, a chunk past the end, a wrong
    CRC, bytes after ``IEND``)."""
    if data[:8] != PNG_SIGNATURE:
        raise ValueError("not a PNG file")
    out, pos = [], 8
    while pos < len(data):
        if pos + PNG_CHUNK_OVERHEAD > len(data):
            raise ValueError("a PNG chunk runs past the end of the file")
        length = int.from_bytes(data[pos : pos + 4], "big")
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        end = pos + 8 + length
        if len(body) != length or end + 4 > len(data):
            raise ValueError(f"PNG chunk {kind!r} runs past the end of the file")
        crc = int.from_bytes(data[end : end + 4], "big")
        if crc != zlib.crc32(kind + body):
            raise ValueError(f"PNG chunk {kind!r}: wrong CRC")
        out.append((kind, body, crc))
        pos = end + 4
        if kind == b"IEND" and pos != len(data):
            raise ValueError("bytes after the PNG's IEND chunk")
    return out


def _chunk(kind: bytes, body: bytes) -> bytes:
    return (len(body).to_bytes(4, "big") + kind + body
            + zlib.crc32(kind + body).to_bytes(4, "big"))  # fmt: skip


def stored_png(rgb: np.ndarray) -> bytes:
    """An 8-bit RGB PNG of ``rgb`` [H, W, 3] (uint8) whose pixel data are not compressed:
    the signature, ``IHDR``, one ``IDAT`` (a zlib stream of deflate *stored* blocks, level 0:
    its length is a function of the byte count alone, whatever the pixels) and ``IEND``; no
    text or other chunk. Two pictures of one pixel size are therefore of one byte size, with
    the same chunks of the same lengths: only their pixels differ."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or 0 in rgb.shape:
        raise ValueError(f"expected pixels [H, W, 3], got {list(rgb.shape)}")
    h, w = rgb.shape[:2]
    rows = np.concatenate([np.zeros((h, 1), np.uint8), rgb.reshape(h, 3 * w)], axis=1)
    header = w.to_bytes(4, "big") + h.to_bytes(4, "big") + bytes([8, 2, 0, 0, 0])
    return (PNG_SIGNATURE + _chunk(b"IHDR", header)  # 8-bit, RGB, no interlacing
            + _chunk(b"IDAT", zlib.compress(rows.tobytes(), 0))  # filter 0 on every row
            + _chunk(b"IEND", b""))  # fmt: skip


def png_rgb(path: Path) -> np.ndarray:
    """A PNG file's pixels as 8-bit RGB [H, W, 3], transparent parts laid on white (the
    page's background; matplotlib's panels are opaque). Read with Pillow, which matplotlib
    requires."""
    from PIL import Image  # what matplotlib reads and writes PNG files with

    with Image.open(path) as image:
        rgba = np.asarray(image.convert("RGBA"), dtype=np.float64)  # [H, W, 4]
    alpha = rgba[..., 3:] / 255.0
    return np.rint(rgba[..., :3] * alpha + 255.0 * (1.0 - alpha)).astype(np.uint8)


def store_uncompressed(paths: list[Path]) -> int:
    """Rewrite the PNG files ``paths`` (one scene's panels and reference) with the same
    pixels as ``stored_png``: uncompressed, so that their byte sizes and chunk lengths say
    nothing of what is drawn (compressed, the ground truth's picture, with fewer lines, was
    the smallest of its scene). Pictures of different pixel sizes (never seen: a scene's
    panels share their axes) are first grown to the largest with white on the right and at
    the bottom. Returns the files' one byte size."""
    pixels = {p: png_rgb(p) for p in paths}
    h = max(a.shape[0] for a in pixels.values())
    w = max(a.shape[1] for a in pixels.values())
    sizes = set()
    for p, a in pixels.items():
        if a.shape[:2] != (h, w):
            a = np.pad(a, ((0, h - a.shape[0]), (0, w - a.shape[1]), (0, 0)),
                       constant_values=255)  # fmt: skip
        data = stored_png(a)
        p.write_bytes(data)
        sizes.add(len(data))
    (size,) = sizes
    return size


def _check_out(out: Path) -> None:
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ConfigError(f"{out}: already exists; a study folder is never overwritten "
                          "(its answers would no longer match): choose a new --out")  # fmt: skip


def _letters(n: int) -> list[str]:
    if n > 26:
        raise ConfigError(f"a scene can have at most 26 panels, got {n}")
    return [chr(ord("A") + i) for i in range(n)]


def write_study(
    out: str | Path,
    scenes: list[SceneData],
    methods: list[str],
    *,
    seed: int = 0,
    title: str = "Which predicted paths look human?",
    instructions: str | None = None,
    ground_truth: GroundTruthMode = "rated",
    units: str = "m",
    dataset: dict[str, Any] | None = None,
    build: dict[str, Any] | None = None,
    synthetic: bool = False,
    consent: str = "",
    order: str = "rater",
) -> Study:
    """Shuffle, render and write a study folder; returns it as read back by ``load_study``.

    ``methods`` lists the panels of every scene (``GROUND_TRUTH`` among them when it is rated);
    each scene's panels are put in a random order (seeded) and named A, B, ...; the images are
    written uncompressed, so that a scene's are of one byte size (``store_uncompressed``).
    ``order``: ``rater``, each rater sees the scenes and panels in an order of their own
    (``Study.rater_order``); ``fixed``, every rater sees the manifest's. The folder appears
    only once complete, owner-only (0700): the raters' answers go into it. The
    build record gets the study's id (``Study.study_id``, which it does not enter). ``units``
    unknown (``""``, ``unknown``): the pictures' axes name no unit. ``consent``: a consent
    text every rater agrees to first (``Study.consent``).
    """
    out = Path(out)
    _check_out(out)
    if not scenes:
        raise ConfigError("a study needs at least one scene")
    for m in methods:
        if m != GROUND_TRUTH and not METHOD_RE.fullmatch(m):
            raise ConfigError(f"method name {m!r}: use letters, digits, ' _.+-' (at most 40)")
    if len(set(methods)) != len(methods):
        raise ConfigError("method names must be unique")
    if order not in ORDERS:
        raise ConfigError(f"order must be one of {', '.join(ORDERS)}, got {order!r}")
    rng = np.random.default_rng(seed)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.building-", dir=out.parent))
    try:
        os.chmod(tmp, 0o700)  # owner-only: the answers (personal data) will be kept in it
        (tmp / IMAGES).mkdir()
        entries = []
        width = max(2, len(str(len(scenes))))
        for i, sc in enumerate(scenes):
            sid = f"s{i + 1:0{width}d}"
            if set(sc.panels) != set(methods):
                raise ConfigError(f"scene {sid}: panels {sorted(sc.panels)} != {sorted(methods)}")
            shuffled = [methods[j] for j in rng.permutation(len(methods))]
            limits = scene_limits(sc.history, sc.future, list(sc.panels.values()))
            panels = []
            for letter, method in zip(_letters(len(shuffled)), shuffled, strict=True):
                s = sc.panels[method]
                name = f"{sid}-{letter}.png"
                _panel_image(sc.history, s.paths, s.weights, tmp / IMAGES / name, limits, units)
                key = PanelKey(method, s.ats, s.fts, s.ade, s.fde, s.max_ats, s.max_fts,
                               tuple(s.shown))  # fmt: skip
                panels.append(Panel(letter, name, key))
            reference = None
            if ground_truth == "reference":
                reference = f"{sid}-ref.png"
                _panel_image(sc.history, sc.future[None], np.ones((1, sc.future.shape[0])),
                             tmp / IMAGES / reference, limits, units, dashed=True)  # fmt: skip
            store_uncompressed([tmp / IMAGES / p.image for p in panels]
                               + ([tmp / IMAGES / reference] if reference else []))  # fmt: skip
            entries.append(StudyScene(sid, tuple(panels), reference, sc.source, sc.index,
                                      int(sc.history.shape[0]), sc.stratum))  # fmt: skip
        study = Study(
            folder=tmp,
            title=title,
            instructions=instructions if instructions is not None else INSTRUCTIONS[ground_truth],
            methods=tuple(methods),
            scenes=tuple(entries),
            dataset=dataset or {},
            build=build or {},
            synthetic=synthetic,
            created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
            consent=consent.strip(),
            order=order,
        )
        study = replace(study, build={**study.build, "study_id": study.study_id})
        write_json(tmp / MANIFEST, manifest_dict(study))
        load_study(tmp)  # what was written must read back
        if out.exists():
            out.rmdir()  # empty (checked above)
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return load_study(out)


def make_synthetic_study(
    out: str | Path,
    scenes: int = 3,
    methods: tuple[str, ...] = ("alpha", "beta"),
    seed: int = 0,
    agents: tuple[int, int] = (2, 4),
    samples: int = 6,
    top: int = 2,
    ground_truth: GroundTruthMode = "rated",
    order: str = "rater",
) -> Study:
    """A study of made-up walks and made-up predictions (for demos, tests and the load
    benchmark; marked ``synthetic`` in the manifest). Method i adds noise of scale
    0.15 (i + 1) m per step to the real futures, and its residuals are made up as
    d = 1 + squared error, so that ATS falls as the error grows."""
    rng = np.random.default_rng(seed)
    data = []
    for i in range(scenes):
        p = int(rng.integers(agents[0], agents[1] + 1))
        start = rng.uniform(-4, 4, (p, 1, 2))  # [P, 1, 2]
        vel = rng.normal(0, 0.4, (p, 1, 2))  # [P, 1, 2]
        track = start + vel * np.arange(20)[None, :, None]  # [P, 20, 2]
        history, future = track[:, :8], track[:, 8:]  # [P, 8, 2], [P, 12, 2]
        panels: dict[str, ShownSet] = {}
        for j, m in enumerate(methods):
            noise = rng.normal(0, 0.15 * (j + 1), (samples, p, 12, 2)).cumsum(2)
            pred = future[None] + noise  # [K, P, 12, 2]
            d_pred = 1 + (noise**2).sum(-1)  # [K, P, 12]
            panels[m] = shown_predictions(pred, d_pred, np.ones((p, 12)), future, top)
        if ground_truth == "rated":
            panels[GROUND_TRUTH] = ground_truth_panel(future)
        data.append(SceneData(history, future, panels, f"synthetic#{i}", i, 0))
    names = ([GROUND_TRUTH] if ground_truth == "rated" else []) + list(methods)
    return write_study(out, data, names, seed=seed, ground_truth=ground_truth,
                       title="SYNTHETIC study (made-up scenes and scores)",
                       dataset={"name": "synthetic", "split": "test", "units": "m"},
                       build={"synthetic": True, "seed": seed}, synthetic=True,
                       order=order)  # fmt: skip
