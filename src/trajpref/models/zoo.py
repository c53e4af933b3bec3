"""The model zoo: published checkpoints that ship inside the package, named ``DATASET/NAME``.

The files live in ``trajpref/zoo/<dataset>/<name>.safetensors`` (the repository's ``models/``
folder links there), each beside a model card ``<name>.md``; ``zoo/index.json`` describes them
(method, training machine and minutes, the test row). ``benchmarks/zoo_index.py`` writes the
index and the cards from ``benchmarks/results/`` and the checkpoints' own headers, so an
installed wheel can list its models without the benchmark results.

A name resolves to a file wherever a checkpoint path is accepted (``--model``, ``--from``,
``--scorer``, ``--denoiser``, ``TrajectoryScorer.from_checkpoint``): see
``checkpoint.resolve_path``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from trajpref.errors import ModelNotFound, TrajprefError
from trajpref.io import read_checkpoint_header
from trajpref.models.timing import UNKNOWN_UNITS, model_timing
from trajpref.types import WINDOW

ZOO_DIR = Path(__file__).resolve().parent.parent / "zoo"
"""Where the published checkpoints live: inside the installed package."""
INDEX = "index.json"
"""The zoo's index file, in ``ZOO_DIR``."""
INDEX_FORMAT = "trajpref-zoo/1"
SUFFIX = ".safetensors"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")


def is_name(spec: str | Path) -> bool:
    """Whether ``spec`` has the form of a zoo name (``DATASET/NAME``, no file suffix)."""
    text = str(spec)
    return bool(_NAME.match(text)) and not text.endswith((SUFFIX, ".pt"))


def named_by_path(spec: str | Path) -> str | None:
    """The published model that ``spec``, a checkpoint path that is no file here, names by its
    place: ``models/zara1/generator.safetensors`` (the repository's path, given outside the
    repository) or ``zara1/generator.safetensors`` (a name with a suffix) name
    ``zara1/generator``; None for a file that exists, a name, a legacy ``.pt`` path whose
    ``.safetensors`` file exists, a path that names no published model, and one in another
    folder (``runs/zara1/generator.safetensors``: a run's own output, not the zoo's)."""
    path = Path(spec)
    if path.exists() or is_name(spec) or path.with_suffix(SUFFIX).is_file():
        return None
    if len(path.parts) != 2 and path.parent.parent.name not in ("models", "zoo"):
        return None
    name = f"{path.parent.name}/{path.stem}"
    return name if path.suffix in (SUFFIX, ".pt") and name in published() else None


def not_here_message(spec: str | Path, flag: str | None = None) -> str | None:
    """The one-line error for a checkpoint path that is no file here but names a published
    model (``named_by_path``): it names the published name, which works in any folder; None
    when ``spec`` names none. ``flag``: the command-line option it was given to
    (``--model``), which the message repeats."""
    name = named_by_path(spec)
    if name is None:
        return None
    given, use = (f"{flag} {spec}", f"{flag} {name}") if flag else (str(spec), name)
    return (f"{given}: no such checkpoint here; the published model is named {name} ({use} "
            "works in any folder)")  # fmt: skip


def published(root: Path | None = None) -> dict[str, Path]:
    """Every published checkpoint, ``{"DATASET/NAME": file}``, sorted by name."""
    root = ZOO_DIR if root is None else root
    files = root.glob(f"*/*{SUFFIX}") if root.is_dir() else []
    return dict(sorted((f"{f.parent.name}/{f.stem}", f) for f in files))


def generators(datasets: list[str] | None = None, root: Path | None = None) -> dict[str, Path]:
    """The published generators (``DATASET/generator``, ``DATASET/generator-VARIANT``), sorted
    by name; only those of ``datasets`` when given."""
    return {name: path for name, path in published(root).items()
            if name.split("/")[1].startswith("generator")
            and (datasets is None or name.split("/")[0] in datasets)}  # fmt: skip


def header(path: Path) -> dict[str, Any]:
    """The ``trajpref`` JSON header of a checkpoint file, without reading its weights."""
    return read_checkpoint_header(path)


def resolve(name: str, root: Path | None = None) -> Path:
    """The file of a published model, or ``name`` itself when it is a file (a run's own
    checkpoint: ``trajpref models res/finetune.safetensors`` shows its header,
    ``file_card``); an unknown name is an error that lists the known ones."""
    models = published(root)
    if name in models:
        return models[name]
    if Path(name).is_file():
        return Path(name)
    known = ", ".join(models) or "none (the package was built without its models)"
    folder = " (a folder: name a checkpoint file in it)" if Path(name).is_dir() else ""
    raise ModelNotFound(
        f"{name}: neither a checkpoint file nor a published model{folder}; published: {known} "
        "(`trajpref models` describes them)"
    )


def _published_name(path: Path, root: Path | None = None) -> str | None:
    """The published name of a file of the zoo given by its path, or None."""
    return next((n for n, f in published(root).items() if f.resolve() == path.resolve()), None)


def load_index(root: Path | None = None) -> dict[str, dict[str, Any]]:
    """The index's entries by name (empty when the zoo has no index)."""
    path = (ZOO_DIR if root is None else root) / INDEX
    if not path.is_file():
        return {}
    try:
        index = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise TrajprefError(f"{path}: unreadable zoo index ({exc.__class__.__name__})") from None
    if not isinstance(index, dict) or index.get("format") != INDEX_FORMAT:
        raise TrajprefError(f"{path}: not a zoo index (format {INDEX_FORMAT} expected)")
    return {entry["name"]: entry for entry in index.get("models", [])}


def entries(root: Path | None = None) -> list[dict[str, Any]]:
    """One entry per published file: its index entry (``indexed: True``), or what the file's
    own header says (name, dataset, kind, training minutes) when the index does not describe
    it yet (``benchmarks/zoo_index.py`` adds it)."""
    index = load_index(root)
    out = []
    for name, path in published(root).items():
        entry = dict(index.get(name) or _from_header(name, path))
        entry["indexed"] = name in index
        entry["path"] = str(path)
        out.append(entry)
    return out


def _from_header(name: str, path: Path) -> dict[str, Any]:
    head = header(path)
    meta = head.get("meta") or {}
    seconds = meta.get("train_seconds")
    train = {"minutes": {head.get("kind", "?"): round(seconds / 60, 1)}} if seconds else {}
    return {"name": name, "dataset": path.parent.name, "kind": head.get("kind", "?"),
            "method": meta.get("method", "(not indexed)"), "train": train}  # fmt: skip


def card(name: str, root: Path | None = None) -> str:
    """The model card (Markdown) of a published model; for a checkpoint file that is not one
    (a run's own, given by its path), what its header says (``file_card``)."""
    path = resolve(name, root)
    if name not in published(root):  # a file, by its path
        name = _published_name(path, root) or ""
        if not name:
            return file_card(path)
        path = published(root)[name]
    path = path.with_suffix(".md")
    if not path.is_file():
        raise TrajprefError(f"{name}: published without a model card ({path.name})")
    return path.read_text()


def entry(name: str, root: Path | None = None) -> dict[str, Any]:
    """What ``trajpref models NAME --json`` prints: a published model's entry (``entries``),
    or for a checkpoint file given by its path, what its header says (``_from_header``, with
    its ``path`` and ``indexed: False``)."""
    path = resolve(name, root)
    found = next((e for e in entries(root) if e["name"] == name), None)
    if found is None and _published_name(path, root) is not None:
        found = next(e for e in entries(root) if e["name"] == _published_name(path, root))
    if found is not None:
        return found
    head = header(path)
    out = _from_header(str(path), path)
    out.update(dataset=(head.get("meta") or {}).get("dataset", out["dataset"]), indexed=False,
               path=str(path), hash=head.get("hash"))  # fmt: skip
    return out


def _val(values: dict[str, Any]) -> str:
    """``min_ade 0.2990, min_fde 0.5380, score 1.23``: a validation's numbers."""
    keys = [k for k in ("min_ade", "min_fde", "score") if isinstance(values.get(k), (int, float))]
    return ", ".join(f"{k} {values[k]:.4g}" for k in keys) or "-"


DEFAULT_SAMPLES = 20
"""``trajpref evaluate``'s ``--samples`` default: a generator of another K needs its own."""
INTERVAL_FROM = {"given": "given", "timestamps": "its files' time column",
                 "declared": "declared by its TrajNet++ scenes",
                 "default": "0.4 s between frames assumed, none given",
                 "dataset": "the dataset's own"}  # fmt: skip
"""How a card says where a run's frame interval came from (``DatasetInfo.interval_from``)."""


def reading_flags(timing: dict[str, Any]) -> tuple[list[str], str]:
    """The data flags that read data as a checkpoint's run read its own (``timing``:
    ``timing.model_timing``'s record: ``--frame-interval`` where it was given, ``--time-step``
    other than 1, ``--units`` where known, for a folder), and its seconds per step with where
    its interval came from (``0.4 s per step (its files' time column)``; empty when
    unknown)."""
    flags = []
    step, every, units = timing.get("step"), timing.get("time_step", 1.0), timing.get("units")
    builtin = timing.get("interval_from") == "dataset"
    if timing.get("interval_from") == "given" and step is not None:
        flags.append(f"--frame-interval {step / every:g}")
    if every != 1:
        flags.append(f"--time-step {every:g}")
    if units not in UNKNOWN_UNITS and units is not None and not builtin:
        flags.append(f"--units {units}")
    pace = ""
    if step is not None:
        origin = INTERVAL_FROM.get(str(timing.get("interval_from")))
        pace = f"{step:g} s per step" + (f" ({origin})" if origin else "")
    return flags, pace


def _lineage_text(lineage: list[dict[str, Any]]) -> str:
    """``denoiser on `D`, then generator on `D` (its epoch chosen on `V`'s val split)``."""
    parts = []
    for e in lineage:
        text = f"{e.get('stage')} on `{e.get('dataset')}`"
        if e.get("holdout_scene"):
            text += f" (scene `{e['holdout_scene']}*` held out, its epoch chosen on it)"
        elif e.get("val_dataset"):
            text += f" (its epoch chosen on `{e['val_dataset']}`'s val split)"
        parts.append(text)
    return ", then ".join(parts)


def file_card(path: Path) -> str:
    """A short card (Markdown) of a checkpoint file that is not published (a run's own,
    ``<stage>.safetensors``, ``_raw``, ``_epoch<E>``), from its header alone (its weights
    are not read): what it is, what it was trained on, the epoch it kept with its validation,
    where and how long it trained."""
    head = header(path)
    meta = head.get("meta") or {}
    kind = head.get("kind", "?")
    config = head.get("config") or {}
    lines = [f"# {path}", ""]
    what = f"A **{kind}** checkpoint"
    if meta.get("method"):
        reward = f" (reward `{meta['reward']}`)" if meta.get("reward") else ""
        what += f" fine-tuned with `{meta['method']}`{reward}"
        if meta.get("from"):
            what += f" from the generator with weights hash `{meta['from']}`"
    lines += [f"{what}: a training run's own file, not a published model (`trajpref models` "
              f"lists those). Weights hash `{head.get('hash', '?')}`.", ""]  # fmt: skip
    data = config.get("data") or {}
    dataset = meta.get("dataset") or data.get("dataset")
    try:
        timing = model_timing(head)
    except (KeyError, TypeError, ValueError, AttributeError):
        timing = None  # a header without its data section
    flags, pace = reading_flags(timing) if timing else ([], "")
    if dataset:
        digest = f" (data hash `{meta['data_hash']}`)" if meta.get("data_hash") else ""
        read = f", read with `{' '.join(flags)}`" if flags else ""
        lines.append(f"- Data: `{dataset}`{digest}{read}" + (f": {pace}." if pace else "."))
    model = config.get("model") or {}
    windows = (model.get("t_hist", WINDOW[0]), model.get("t_fut", WINDOW[1]))
    if windows != WINDOW:  # the published models' lengths go without saying
        lines.append(f"- Windows: {windows[0]} observed + {windows[1]} future frames "
                     "(`model.t_hist`, `model.t_fut`): evaluate, predict and plot cut the data "
                     f"so; `trajpref data stats` takes `--history {windows[0]} --future "
                     f"{windows[1]}`.")  # fmt: skip
    if timing and timing.get("lineage"):
        lines.append(f"- Lineage: {_lineage_text(timing['lineage'])}.")
    denoiser = head.get("denoiser")
    if isinstance(denoiser, dict) and denoiser.get("hash"):
        lines.append(f"- Denoiser: weights hash `{denoiser['hash']}` (inside this file).")
    if meta.get("method"):
        lines.append(f"- Preset: `{meta['preset']}`." if meta.get("preset")
                     else "- Preset: none (its own fine-tuning settings).")  # fmt: skip
    if "epoch" in meta:
        kept = f"- Kept: epoch {meta['epoch']}, step {meta.get('step', '?')}"
        if isinstance(meta.get("val"), dict):
            kept += f"; its validation: {_val(meta['val'])}"
        lines.append(kept + ".")
    if meta.get("weights"):
        lines.append(f"- Weights: {meta['weights']}.")
    elif meta.get("ema_epochs"):
        lines.append(f"- Weights: a moving average of the training iterates (ema_epochs "
                     f"{meta['ema_epochs']:g}).")  # fmt: skip
    if meta.get("machine") or meta.get("train_seconds") is not None:
        processes = meta.get("processes", 1)
        on = f" on {meta['machine']}" if meta.get("machine") else ""
        spent = meta.get("train_seconds")
        took = f"{spent / 60:.1f} min of training steps" if spent is not None else "trained"
        lines.append(f"- Trained{on}, {processes} process(es): {took} to the kept epoch.")
    model = config.get("model") or {}
    if kind == "generator" and "samples" in model:
        lines.append(f"- Samples K = {model['samples']}, tau = {model.get('tau', '?')}.")
    stage = path.name.partition(".")[0].partition("_")[0]  # finetune_raw -> finetune
    command = f"trajpref evaluate --model {path}"
    test_on = data.get("val_dataset") or dataset  # robo.yaml: trained on robo-sim, tested on robo
    if test_on:
        command += f" --dataset {test_on} --split test" + "".join(f" {f}" for f in flags)
    samples = model.get("samples")
    if kind == "generator" and isinstance(samples, int) and samples != DEFAULT_SAMPLES:
        command += f" --samples {samples}"
    lines += ["", f"The run folder it came from holds the run's config (`{stage}_config.yaml`), "
              "metrics log and run record; the file alone rebuilds its model. "
              f"`{command}` tests it.", ""]  # fmt: skip
    return "\n".join(lines)


def _minutes(train: dict[str, Any]) -> str:
    parts = [f"{v:.1f}" for v in (train.get("minutes") or {}).values() if v is not None]
    return " + ".join(parts) or "-"


def _test(entry: dict[str, Any]) -> str:
    test = entry.get("test")
    if not test:
        return "-"
    return f"{test['min_ade']:.3f} / {test['min_fde']:.3f}"


def table(rows: list[dict[str, Any]]) -> str:
    """The listing printed by ``trajpref models``: one line per model."""
    head = ("name", "kind", "method", "test minADE/minFDE", "trained on", "train min")
    lines = [head]
    for e in rows:
        train = e.get("train") or {}
        lines.append((
            e["name"],
            e.get("kind", "?"),
            e.get("method", "(not indexed)"),
            _test(e),
            train.get("machine_short", "-"),
            _minutes(train),
        ))  # fmt: skip
    widths = [max(len(str(row[i])) for row in lines) for i in range(len(head))]
    return "\n".join(
        "  ".join(str(v).ljust(w) for v, w in zip(row, widths, strict=True)).rstrip()
        for row in lines
    )
