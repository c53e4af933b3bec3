"""The study folder and its manifest, read and checked before anything is served or analysed.

::

    study/
      manifest.json     public part (title, criteria, scenes -> panels -> image) and the hidden
                        ``key`` (scene -> panel -> method, and the ATS/FTS of what it shows)
      images/*.png      one image per panel (``s01-A.png``), and ``s01-ref.png`` per scene
                        when the ground truth is a reference rather than a rated panel
      answers.sqlite    the raters' answers (``serve`` and ``simulate`` write it)

Scene ids (``s01``) and panel letters (``A``..) carry no information about the method; the
page only ever sees :meth:`Study.public`.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trajpref.errors import ConfigError, ConfigNotFound, DataError

FORMAT = "trajpref-survey/1"
"""The manifest's ``format`` value."""
MANIFEST = "manifest.json"
"""The manifest's file name inside a study folder."""
IMAGES = "images"
"""The folder of panel images inside a study folder."""
DATABASE = "answers.sqlite"
"""The default answers database inside a study folder."""
GROUND_TRUTH = "ground truth"
"""The method name of the panel that shows what really happened."""
CRITERIA = (
    ("social", "Social appropriateness",
     "Do the paths respect the other people: no collisions, plausible passing and groups?"),
    ("kinetics", "Kinetics",
     "Are speeds, accelerations and turns plausible for a walking person?"),
)  # fmt: skip
"""The two questions of the paper's study: (id, label, help). The database has a column each."""
RATING_MIN, RATING_MAX = 1, 5
"""The five-point Likert scale."""

ID_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,31}")
"""Scene ids and panel letters."""
IMAGE_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}\.png")
"""Image file names: a plain name in ``images/``, never a path."""
METHOD_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9 _.+-]{0,39}")
"""Method names given to ``survey build``. These patterns are checked with ``fullmatch``
(``re.match`` with ``$`` would let a trailing newline through)."""
ORDERS = ("rater", "fixed")
"""The manifest's ``order``: ``rater``, each rater sees the scenes, and the panels within each
scene, in an order of their own (``Study.rater_order``); ``fixed``, every rater sees the
manifest's order (``survey build --fixed-order``, and every study built before 2026-12-06,
whose manifest has no ``order``)."""
KEYS = {
    "manifest": ("format", "title", "instructions", "consent", "order", "created",
                 "synthetic", "dataset", "build", "methods", "scenes", "key"),
    "scene": ("id", "reference", "panels"),
    "panel": ("id", "image"),
    "key scene": ("source", "index", "agents", "stratum", "panels"),
    "key panel": ("method", "ats", "fts", "ade", "fde", "max_ats", "max_fts", "shown"),
}  # fmt: skip
"""The keys each object of the manifest may have (what ``manifest_dict`` writes); any other
key is an error naming it, so that a misspelt key a researcher adds by hand (``instruction``
for ``instructions``) is not silently ignored. The records ``dataset`` and ``build`` and the
entries of ``shown`` take any key."""


@dataclass(frozen=True)
class PanelKey:
    """The hidden part of one panel: which method drew it and how the diffusion score rates
    what it shows. The page never sees this."""

    method: str
    """The method's name (``GROUND_TRUTH`` for the real futures)."""
    ats: float
    """ATS of the shown predictions: 1 - sum d(shown) / (R sum d(ground truth)) over the
    scene's agents and steps, R shown futures per agent (0 for the ground truth)."""
    fts: float
    """The same at the final step."""
    ade: float
    """Mean ADE of the shown predictions to the ground truth (0 for the ground truth)."""
    fde: float
    """Mean FDE of the shown predictions."""
    max_ats: float | None = None
    """maxATS_K of the scene: the best of the method's K samples (the paper's tables)."""
    max_fts: float | None = None
    """maxFTS_K of the scene."""
    shown: tuple[dict[str, Any], ...] = ()
    """One entry per drawn future: ``agent``, ``sample``, ``rank``, ``ats``, ``fts``,
    ``ade``, ``fde`` (the agent's own scores)."""


@dataclass(frozen=True)
class Panel:
    """One image to rate."""

    id: str
    """The panel's letter within its scene (``A``, ``B``, ...), in the manifest's order (a
    rater of a study of ``order`` ``rater`` sees the panels in an order of their own)."""
    image: str
    """Its file name under ``images/``."""
    key: PanelKey
    """The hidden key."""


@dataclass(frozen=True)
class StudyScene:
    """One scene of the study and its panels, in the manifest's order."""

    id: str
    """Public id, e.g. ``s01``."""
    panels: tuple[Panel, ...]
    """The panels, methods shuffled."""
    reference: str | None = None
    """An image of the history and the ground truth, shown beside every panel (when the
    ground truth is not a rated panel)."""
    source: str = ""
    """Where the scene comes from (the dataset's scene id); hidden."""
    index: int = -1
    """The scene's index in the split; hidden."""
    agents: int = 0
    """Agents in the scene."""
    stratum: int = 0
    """The scene-size stratum it was drawn from."""


@dataclass(frozen=True)
class Study:
    """A study folder, checked."""

    folder: Path
    """The study folder."""
    title: str
    """Shown on the page."""
    instructions: str
    """Shown on the page before rating."""
    methods: tuple[str, ...]
    """Method names in the order given to ``build`` (the ground truth first when rated)."""
    scenes: tuple[StudyScene, ...]
    """The scenes, in the manifest's order (the order every rater sees with ``order``
    ``fixed``; ``rater_order`` gives a rater's)."""
    dataset: dict[str, Any] = field(default_factory=dict)
    """``name``, ``split``, ``units``, ``frame_interval`` (seconds per step, as read),
    ``t_hist`` and ``t_fut`` (observed and future frames per window; studies built before
    2026-12-07 lack them: 8 and 12) and ``scenes_in_split`` of the data."""
    build: dict[str, Any] = field(default_factory=dict)
    """The build options (for the record), with ``min_gap``, ``t_hist`` and ``t_fut`` as the
    build used them (a default filled in)."""
    synthetic: bool = False
    """True for a study of made-up scenes and scores (demos and tests)."""
    created: str = ""
    """When the study was built (UTC, ISO 8601)."""
    consent: str = ""
    """A consent text shown to every rater before the first picture, with an "I agree" step
    that the answers database records per rater; empty: none (the manifest's optional
    ``consent``)."""
    order: str = "fixed"
    """The presentation order (``ORDERS``): ``rater``, each rater's own (``rater_order``);
    ``fixed``, the manifest's for every rater (a manifest without ``order``: built before
    2026-12-06, when every rater saw that order)."""

    def rater_order(self, rater: str) -> tuple[tuple[StudyScene, tuple[Panel, ...]], ...]:
        """The scenes, each with its panels, in the order ``rater`` sees them. ``order``
        ``fixed``: the manifest's. ``rater``: a permutation of the scenes, and within each
        scene of its panels, that is a function of the study (``study_id``) and the rater id
        in lower case (ids are matched ignoring case): the same at every visit (a reload, a
        resumed session, another machine), another for another rater or study. Each item is
        ranked by a SHA-256 hash of the study id, the rater id and the scene id (and the
        panel letter): a uniformly random order per rater, the same on every platform and
        with every version of numpy."""
        if self.order == "fixed":
            return tuple((s, s.panels) for s in self.scenes)
        seed = f"trajpref-survey-order\0{self.study_id}\0{rater.lower()}"

        def rank(*names: str) -> bytes:
            return hashlib.sha256("\0".join((seed, *names)).encode()).digest()

        scenes = sorted(self.scenes, key=lambda s: rank(s.id))
        return tuple((s, tuple(sorted(s.panels, key=lambda p: rank(s.id, p.id))))
                     for s in scenes)  # fmt: skip

    def positions(self, rater: str | None = None) -> dict[tuple[str, str], tuple[int, int, int]]:
        """(scene id, panel letter) -> (scene position, panel position within the scene,
        position among all the panels), each from 1: where ``rater`` sees each panel
        (``rater_order``); ``None``: the manifest's order."""
        order = (self.rater_order(rater) if rater is not None
                 else tuple((s, s.panels) for s in self.scenes))  # fmt: skip
        out, n = {}, 0
        for i, (s, panels) in enumerate(order, 1):
            for j, p in enumerate(panels, 1):
                n += 1
                out[(s.id, p.id)] = (i, j, n)
        return out

    @property
    def consent_hash(self) -> str:
        """A hash of the consent text: the database records which text a rater agreed to."""
        return hashlib.sha256(self.consent.encode()).hexdigest()[:16]

    @property
    def images_dir(self) -> Path:
        return self.folder / IMAGES

    @property
    def study_id(self) -> str:
        """A hash of what the raters were shown and what the key says about it: the scene /
        panel / method structure, each scene's source, each panel's ATS, FTS, ADE and FDE
        (rounded to 6 decimals), and the dataset record. The answers database records it, so
        that answers are never analysed against another study's key, even one of the same
        structure built from other data or models (their scores differ). A rebuild with the
        same data, models and seed shows the same pictures and gets the same id, so ``created``
        and the build record (device, data folder, how the models were named) are left out."""
        items = {
            "version": 2,
            "dataset": self.dataset,
            "scenes": [
                [s.id, s.source, s.index, [[p.id, p.key.method, *map(_rounded, (
                    p.key.ats, p.key.fts, p.key.ade, p.key.fde))] for p in s.panels]]
                for s in self.scenes
            ],
        }  # fmt: skip
        text = json.dumps(items, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @property
    def legacy_study_id(self) -> str:
        """The id that databases written before 2026-12-05 record: a hash of the scene /
        panel / method structure only. Such a database still opens for the study it
        belongs to (its structure matches); it cannot tell that study apart from another of
        the same structure."""
        items = [(s.id, p.id, p.key.method) for s in self.scenes for p in s.panels]
        return hashlib.sha256(json.dumps(items).encode()).hexdigest()[:16]

    @property
    def num_panels(self) -> int:
        return sum(len(s.panels) for s in self.scenes)

    def panel_ids(self) -> dict[str, tuple[str, ...]]:
        """scene id -> its panel letters."""
        return {s.id: tuple(p.id for p in s.panels) for s in self.scenes}

    def image_files(self) -> dict[str, Path]:
        """Every image the page may load: file name -> path."""
        names = [p.image for s in self.scenes for p in s.panels]
        names += [s.reference for s in self.scenes if s.reference]
        return {n: self.images_dir / n for n in names}

    def public(self) -> dict[str, Any]:
        """What the page sees: no method names, no scores, no data source."""
        return {
            "title": self.title,
            "instructions": self.instructions,
            "consent": self.consent,
            "criteria": [{"id": c, "label": lab, "help": h} for c, lab, h in CRITERIA],
            "scale": [RATING_MIN, RATING_MAX],
            "scenes": [
                {
                    "id": s.id,
                    "reference": f"images/{s.reference}" if s.reference else None,
                    "panels": [{"id": p.id, "image": f"images/{p.image}"} for p in s.panels],
                }
                for s in self.scenes
            ],
        }


def _rounded(x: float) -> float:
    """``x`` to 6 decimals, -0.0 as 0.0: a key value as the study id hashes it, the same
    whatever the digits a JSON writer keeps beyond that."""
    return round(float(x), 6) + 0.0


def manifest_dict(study: Study) -> dict[str, Any]:
    """The JSON form of ``study`` (what ``manifest.json`` holds; ``consent`` only when the study
    has one)."""
    return {
        "format": FORMAT,
        "title": study.title,
        "instructions": study.instructions,
        **({"consent": study.consent} if study.consent else {}),
        "order": study.order,
        "created": study.created,
        "synthetic": study.synthetic,
        "dataset": study.dataset,
        "build": study.build,
        "methods": list(study.methods),
        "scenes": [
            {
                "id": s.id,
                "reference": s.reference,
                "panels": [{"id": p.id, "image": p.image} for p in s.panels],
            }
            for s in study.scenes
        ],
        "key": {
            s.id: {
                "source": s.source,
                "index": s.index,
                "agents": s.agents,
                "stratum": s.stratum,
                "panels": {
                    p.id: {
                        "method": p.key.method,
                        "ats": p.key.ats,
                        "fts": p.key.fts,
                        "ade": p.key.ade,
                        "fde": p.key.fde,
                        "max_ats": p.key.max_ats,
                        "max_fts": p.key.max_fts,
                        "shown": list(p.key.shown),
                    }
                    for p in s.panels
                },
            }
            for s in study.scenes
        },
    }


class _Reader:
    """Typed access to the manifest's JSON with messages that say where a value is wrong."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, where: str, message: str) -> DataError:
        return DataError(f"corrupt manifest: {where}: {message}", self.path)

    def get(self, obj: Any, key: str, kind: type | tuple[type, ...], where: str,
            optional: bool = False) -> Any:  # fmt: skip
        if not isinstance(obj, dict):
            raise self.fail(where, "expected an object")
        if key not in obj or obj[key] is None:
            if optional:
                return None
            raise self.fail(f"{where}.{key}", "missing")
        value = obj[key]
        bad_bool = isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple)
                                                            else (kind,))  # fmt: skip
        if not isinstance(value, kind) or bad_bool:
            raise self.fail(f"{where}.{key}", f"expected {_kind_name(kind)}, got {value!r:.40}")
        return value

    def keys(self, obj: Any, kind: str, where: str) -> None:
        """``obj`` is an object whose keys are all among ``KEYS[kind]``; else an error naming
        each unknown key, the closest allowed one, and the allowed ones."""
        if not isinstance(obj, dict):
            raise self.fail(where, "expected an object")
        allowed = KEYS[kind]
        unknown = sorted(k for k in obj if k not in allowed)
        if not unknown:
            return
        named = []
        for k in unknown:
            close = difflib.get_close_matches(str(k), allowed, n=1, cutoff=0.6)
            named.append(f"{k!r:.40}" + (f" (did you mean {close[0]!r}?)" if close else ""))
        keys = ", ".join(sorted(allowed))
        plural = "s" if len(unknown) > 1 else ""
        raise self.fail(where, f"unknown key{plural} {', '.join(named)}; the keys are: {keys}")

    def number(self, obj: Any, key: str, where: str, optional: bool = False) -> float | None:
        value = self.get(obj, key, (int, float), where, optional)
        if value is None:
            return None
        if not math.isfinite(value):
            raise self.fail(f"{where}.{key}", "not a finite number")
        return float(value)

    def ident(self, value: Any, where: str, pattern: re.Pattern[str] = ID_RE) -> str:
        if not isinstance(value, str) or not pattern.fullmatch(value):
            raise self.fail(where, f"not a valid name: {value!r:.40}")
        return value


def _kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {int: "a number", float: "a number", str: "a string", list: "a list",
             dict: "an object", bool: "true or false"}  # fmt: skip
    return " or ".join(dict.fromkeys(names.get(k, k.__name__) for k in kinds))


def load_study(folder: str | Path) -> Study:
    """Read and check a study folder: the manifest parses, every object has only known keys
    (``KEYS``: a misspelt key is an error naming the closest one), every id is well-formed and
    unique, every panel has a key, every image is a plain file name that exists in
    ``images/``.

    Raises ``ConfigError`` for a missing folder or manifest, ``DataError`` for a corrupt one.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigNotFound(f"{folder}: no such study folder (make one with `trajpref survey "
                             "build`)")  # fmt: skip
    path = folder / MANIFEST
    if not path.is_file():
        raise ConfigError(f"{folder}: not a study folder (no {MANIFEST})")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise DataError(f"corrupt manifest: not valid JSON ({exc})", path) from None
    r = _Reader(path)
    r.keys(raw, "manifest", "top level")
    fmt = r.get(raw, "format", str, "manifest")
    if fmt != FORMAT:
        raise r.fail("format", f"expected {FORMAT!r}, got {fmt!r:.40}")
    methods = tuple(r.get(raw, "methods", list, "manifest"))
    for i, m in enumerate(methods):
        if m != GROUND_TRUTH:
            r.ident(m, f"methods[{i}]", METHOD_RE)
    if len(set(methods)) != len(methods) or not methods:
        raise r.fail("methods", "empty or repeated names")
    key = r.get(raw, "key", dict, "manifest")
    scenes_raw = r.get(raw, "scenes", list, "manifest")
    if not scenes_raw:
        raise r.fail("scenes", "no scenes")
    images = folder / IMAGES
    scenes: list[StudyScene] = []
    seen_images: set[str] = set()

    def image(value: Any, where: str) -> str:
        name = r.ident(value, where, IMAGE_RE)
        if name in seen_images:
            raise r.fail(where, f"image {name} used twice")
        seen_images.add(name)
        file = images / name
        if not file.is_file() or file.is_symlink():
            raise r.fail(where, f"missing image {IMAGES}/{name}")
        return name

    for i, s in enumerate(scenes_raw):
        where = f"scenes[{i}]"
        r.keys(s, "scene", where)
        sid = r.ident(r.get(s, "id", str, where), f"{where}.id")
        if any(x.id == sid for x in scenes):
            raise r.fail(f"{where}.id", f"scene {sid} appears twice")
        ref = r.get(s, "reference", str, where, optional=True)
        ref = image(ref, f"{where}.reference") if ref is not None else None
        skey = r.get(key, sid, dict, "key")
        r.keys(skey, "key scene", f"key.{sid}")
        pkeys = r.get(skey, "panels", dict, f"key.{sid}")
        panels: list[Panel] = []
        for j, p in enumerate(r.get(s, "panels", list, where)):
            pwhere = f"{where}.panels[{j}]"
            r.keys(p, "panel", pwhere)
            pid = r.ident(r.get(p, "id", str, pwhere), f"{pwhere}.id")
            if any(x.id == pid for x in panels):
                raise r.fail(f"{pwhere}.id", f"panel {pid} appears twice in scene {sid}")
            k = r.get(pkeys, pid, dict, f"key.{sid}.panels")
            kw = f"key.{sid}.panels.{pid}"
            r.keys(k, "key panel", kw)
            method = r.get(k, "method", str, kw)
            if method not in methods:
                raise r.fail(f"{kw}.method", f"{method!r:.40} is not one of the methods")
            shown = r.get(k, "shown", list, kw, optional=True) or []
            panels.append(Panel(pid, image(r.get(p, "image", str, pwhere), f"{pwhere}.image"),
                                PanelKey(method, r.number(k, "ats", kw), r.number(k, "fts", kw),
                                         r.number(k, "ade", kw), r.number(k, "fde", kw),
                                         r.number(k, "max_ats", kw, optional=True),
                                         r.number(k, "max_fts", kw, optional=True),
                                         tuple(shown))))  # fmt: skip
        if len(panels) < 1:
            raise r.fail(f"{where}.panels", "no panels")
        if set(pkeys) != {p.id for p in panels}:
            raise r.fail(f"key.{sid}.panels", "does not match the scene's panels")
        if len({p.key.method for p in panels}) != len(panels):
            raise r.fail(f"key.{sid}", "a method appears twice in one scene")
        index = r.get(skey, "index", int, f"key.{sid}", optional=True)
        agents = r.get(skey, "agents", int, f"key.{sid}", optional=True)
        stratum = r.get(skey, "stratum", int, f"key.{sid}", optional=True)
        source = r.get(skey, "source", str, f"key.{sid}", optional=True)
        scenes.append(StudyScene(sid, tuple(panels), ref, source or "",
                                 -1 if index is None else index, agents or 0,
                                 stratum or 0))  # fmt: skip
    if set(key) != {s.id for s in scenes}:
        raise r.fail("key", "does not match the scenes")
    order = r.get(raw, "order", str, "manifest", optional=True) or "fixed"
    if order not in ORDERS:
        raise r.fail("order", f"expected {' or '.join(map(repr, ORDERS))}, got {order!r:.40}")
    dataset = r.get(raw, "dataset", dict, "manifest", optional=True) or {}
    build = r.get(raw, "build", dict, "manifest", optional=True) or {}
    return Study(
        folder=folder,
        title=r.get(raw, "title", str, "manifest"),
        instructions=r.get(raw, "instructions", str, "manifest", optional=True) or "",
        methods=methods,
        scenes=tuple(scenes),
        dataset=dataset,
        build=build,
        synthetic=bool(r.get(raw, "synthetic", bool, "manifest", optional=True)),
        created=r.get(raw, "created", str, "manifest", optional=True) or "",
        consent=r.get(raw, "consent", str, "manifest", optional=True) or "",
        order=order,
    )
