"""Benchmark result rows (the schema in docs/design.md) and the README tables made from them."""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from collections.abc import Callable, Sequence
from datetime import date
from pathlib import Path
from typing import Any

import torch

from trajpref.errors import ResultConflict
from trajpref.io import write_json

FIELDS = (
    "dataset", "split", "protocol", "method", "seed", "samples", "min_ade", "min_fde",
    "joint_min_ade", "joint_min_fde", "max_ats", "max_fts", "top1_recall_ats", "top5_recall_ats",
    "train_seconds", "ms_per_scene", "checkpoint", "model_hash", "command", "date", "machine",
    "uses_score",
)  # fmt: skip
"""Every row has exactly these keys (null where not measured). ``protocol``: which test windows
count (``data.PROTOCOLS``; ``make_row`` defaults it to ``all``). ``model_hash``: the digest of
the checkpoint measured (``models.checkpoint.model_hash``: weights, denoiser, scale and model
settings), null for rows without a checkpoint or written before 2026-11-26 and not traced
back to their weights. ``uses_score``: whether the diffusion score took part (in training or
in selecting the samples)."""

METHODS = ("cv", "full-sampler", "pretrained", "pretrained-long", "control", "rlhf", "rlhf-res",
           "rlhf-set", "rlhf-res-smooth")  # fmt: skip
"""Known methods, in the order tables list them."""
FINETUNE_START = "pretrained"
"""The method of the fine-tuning tables' start rows: the published generators as they sample
today (posterior-mean tau steps since 2026-11-24, docs/pretraining.md)."""
ANCESTRAL_SUFFIX = "-ancestral"
"""Rows measured before the published generators switched to posterior-mean steps: the old
``pretrained`` rows, and every fine-tuning row whose run started from those generators (all
fine-tuning runs of 2026-11-22 and 2026-11-23); they stay in the files for the tables of their
time and compare with their own start, ``pretrained-ancestral``."""


RETIRED_STARTS = (
    "-scene",
    "-noclamp",
    "-raw",
    "-h128",
    "-tau5",
    "-noflip",
    "-norev",
    "-nocap",
    "-noscale",
    "-norole",
    "-drop30",
    "-nocontext",
    "-reg0",
)
"""Suffixes of the published default generators that a later default replaced after fine-tuning
runs had started from them, oldest first: the scene-frame generators (replaced 2026-11-25 by
the heading frame), eth's unclamped heading-frame generator of 2026-11-25 (replaced 2026-11-26
by the same weights with a speed clamp, then by the temporal encoder; its fine-tuning rows were
paired with the later default until 2026-11-27), the raw weights (2026-11-26, the moving
average), zara1's 128-wide encoder (2026-11-26), the tau = 5 generators (2026-11-27, no
denoising steps), the zara generators trained without mirrored scenes (2026-11-27), eth's
generator trained without scenes played backwards (2026-11-27) and SDD's generator without
the cap on its samples' sigma (2026-11-29; the same weights, ``model.max_log_sigma``) and
Robo's sim-only generator trained without scale augmentation and with dropout 0.2 (2026-11-29,
replaced by scale augmentation 0.8-1.25 with dropout 0.3), then that generator, which did not
know which robot is which (2026-11-29, replaced by ``model.agent_roles``), then the roles
generator with dropout 0.3 (2026-12-01, replaced by dropout 0.2), then eth's and zara1's
generators that did not read the agents leaving the view (2026-12-02, replaced by
``model.context_agents``), then eth's generator trained without the sample-training term,
one of whose 20 samples was noise (2026-12-06, replaced by ``generator.reg_weight`` 0.02).
Their start row is ``pretrained<suffix>`` and their runs' rows carry the suffix; no run can
begin from them now."""
START_SUFFIXES = (ANCESTRAL_SUFFIX, *RETIRED_STARTS, "-long")
"""Suffixes of fine-tuning rows whose runs began from another start than the published default
generator: ``-ancestral`` (the generators of before 2026-11-24), the ``RETIRED_STARTS`` and
``-long`` (the published ``generator-long``, ``benchmarks/finetune.py --start generator-long
--tag long``)."""
RUNNABLE_STARTS = {"generator": "", "generator-long": "-long"}
"""The published generators a fine-tuning run can start from, and the suffix of their rows
(one of ``START_SUFFIXES`` or "" for the default); ``-ancestral`` names a start that no longer
exists, so no run can begin from it."""


def sampler_of(method: str) -> str:
    """The sampler a row's method ran: ``full`` for ``full-sampler*`` rows (the denoiser alone,
    which is what their ``model_hash`` describes), ``leapfrog`` for every other model row."""
    return "full" if method.startswith("full-sampler") else "leapfrog"


def start_suffix(start: str) -> str:
    """The row suffix of runs from a published generator (``generator-long`` -> ``-long``)."""
    if start not in RUNNABLE_STARTS:
        known = ", ".join(RUNNABLE_STARTS)
        raise ValueError(f"unknown fine-tuning start {start!r}; known: {known}")
    return RUNNABLE_STARTS[start]


def start_record(dataset: str, start: str = "generator") -> str:
    """The file name, under ``benchmarks/results/meta/``, of a start's validation as the
    fine-tuning stage measures it: ``finetune_start_<dataset>.json`` for the default generator,
    ``finetune_start_<dataset>_<start>.json`` for another published one."""
    start_suffix(start)  # a clear error for an unknown start
    name = dataset if start == "generator" else f"{dataset}_{start}"
    return f"finetune_start_{name}.json"


def finetune_start(method: str) -> str:
    """The method of the start row a fine-tuning row compares with: ``pretrained`` plus the
    row's start suffix (``rlhf-res-long`` -> ``pretrained-long``, ``control-ancestral`` ->
    ``pretrained-ancestral``), ``pretrained`` for the runs from the default generator."""
    suffix = next((s for s in START_SUFFIXES if method.endswith(s)), "")
    return FINETUNE_START + suffix


def cpu_name(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The processor's model name where the system says it (Linux: the first ``model name``
    line of ``cpuinfo``), else what ``platform`` knows. Hosts of the same kind can differ in
    their CPU, and a training step's speed with them (docs/pretraining.md, "hotel's budget on a
    slower host"), so a measurement names the model."""
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                return " ".join(value.split())
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> str:
    """A short description of where a number was measured."""
    cpu = cpu_name()
    gpu = f", {torch.cuda.get_device_name(0)}" if torch.cuda.is_available() else ""
    return (
        f"{platform.system()} {platform.machine()} ({cpu}), {os.cpu_count()} CPU cores{gpu}, "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads"
    )


def command_line() -> str:
    """The command that is running, for the ``command`` field."""
    return " ".join(shlex.quote(a) for a in ["python", *sys.argv])


def make_row(**values: Any) -> dict[str, Any]:
    """A full row: unknown keys are an error, missing ones are null; date and machine filled."""
    unknown = set(values) - set(FIELDS)
    if unknown:
        raise KeyError(f"unknown result fields: {sorted(unknown)}")
    row = {k: values.get(k) for k in FIELDS}
    row["protocol"] = row["protocol"] or "all"
    row["date"] = row["date"] or date.today().isoformat()
    row["machine"] = row["machine"] or machine()
    row["command"] = row["command"] or command_line()
    return row


def write_meta(path: str | Path, **fields: Any) -> dict[str, Any]:
    """Write a benchmark's measurement file: where, when and by what command it was measured
    (``machine``, ``threads``, ``date``, ``command``), then ``fields``. Returns what it wrote."""
    meta = {"machine": machine(), "threads": torch.get_num_threads(),
            "date": date.today().isoformat(), "command": command_line(), **fields}  # fmt: skip
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_json(path, meta)
    return meta


def write_rows(path: str | Path, rows: list[dict[str, Any]]) -> None:
    for row in rows:
        if set(row) != set(FIELDS):
            raise KeyError(f"row does not follow the schema: {sorted(set(row) ^ set(FIELDS))}")
    write_json(path, rows)


ROW_KEY = ("dataset", "split", "protocol", "method", "seed", "samples")
"""What identifies one measurement: rows that agree on these measure the same thing."""


def upsert_rows(
    path: str | Path,
    rows: list[dict[str, Any]],
    drop: Callable[[dict[str, Any]], bool] | None = None,
) -> list[dict[str, Any]]:
    """Write ``rows`` into the rows file ``path``, keeping its other rows: a row already there
    with the same ``ROW_KEY`` is replaced, the rest stay in their order (so a run with another
    seed adds to the file instead of overwriting it); old rows for which ``drop(row)`` is true
    are removed (rows that measured something the run replaced). Returns the rows written."""
    path = Path(path)
    new = {tuple(r[k] for k in ROW_KEY): r for r in rows}
    old = json.loads(path.read_text()) if path.is_file() else []
    kept = [r for r in old if tuple(r[k] for k in ROW_KEY) not in new
            and not (drop is not None and drop(r))]  # fmt: skip
    out = kept + list(new.values())
    write_rows(path, out)
    return out


def read_rows(folder: str | Path, protocol: str | None = None) -> list[dict[str, Any]]:
    """Every row of ``folder/*.json``; only those measured under ``protocol`` when given."""
    rows = []
    for path in sorted(Path(folder).glob("*.json")):
        rows.extend(json.loads(path.read_text()))
    return [r for r in rows if protocol is None or r["protocol"] == protocol]


def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return str(x)


def merge_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows of the same measurement (dataset, split, protocol, method, seed, samples) written
    by different scripts (e.g. accuracy by one, scores by another) merged field by field; the
    first non-null value wins. Rows whose ``model_hash`` is known and differs measured
    different weights or settings: merging them is refused (:class:`ResultConflict`)."""
    merged: dict[tuple, dict[str, Any]] = {}
    for r in rows:
        key = tuple(r[k] for k in ROW_KEY)
        if key not in merged:
            merged[key] = dict(r)
            continue
        into = merged[key]
        mine, theirs = into.get("model_hash"), r.get("model_hash")
        if mine is not None and theirs is not None and mine != theirs:
            what = ", ".join(f"{k}={v}" for k, v in zip(ROW_KEY, key, strict=True))
            raise ResultConflict(
                f"rows of one measurement ({what}) measured different checkpoints: "
                f"{mine} ({into.get('date')}: {into.get('command')}) and {theirs} "
                f"({r.get('date')}: {r.get('command')}); re-run the stale one"
            )
        for field, value in r.items():
            if into.get(field) is None:
                into[field] = value
    return list(merged.values())


def base_method(method: str) -> str:
    """A method without its start suffix (``control-long`` -> ``control``)."""
    return next((method.removesuffix(x) for x in START_SUFFIXES if method.endswith(x)), method)


def accuracy_table(rows: list[dict[str, Any]], split: str = "test", protocol: str = "all") -> str:
    """Markdown table: one line per (dataset, method, samples), mean (+- std) over seeds, of
    the rows measured under ``protocol``."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in merge_rows(rows):
        if r["split"] == split and r["protocol"] == protocol:
            groups.setdefault((r["dataset"], r["method"], r["samples"]), []).append(r)
    order = {m: i for i, m in enumerate(METHODS)}
    # a method run from another start (``control-long``, ``control-ancestral``) right after
    # its plain form
    rank = {m: order.get(m, order.get(base_method(m), 98) + 0.5) for _, m, _ in groups}
    keys = sorted(groups, key=lambda k: (k[0], rank[k[1]], k[2]))
    cols = ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "max_ats", "max_fts",
            "top1_recall_ats", "top5_recall_ats")  # fmt: skip
    lines = [
        "| dataset | method | K | seeds | minADE | minFDE | joint minADE | joint minFDE "
        "| maxATS | maxFTS | top-1 / top-5 recall (ATS) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for key in keys:
        g = groups[key]
        vals = []
        for c in cols:
            xs = [r[c] for r in g if r[c] is not None]
            if not xs:
                vals.append("–")
            elif len(xs) == 1:
                vals.append(_fmt(xs[0]))
            else:
                mean = sum(xs) / len(xs)
                std = (sum((x - mean) ** 2 for x in xs) / (len(xs) - 1)) ** 0.5
                vals.append(f"{mean:.3f} ± {std:.3f}")
        recall = f"{vals[6]} / {vals[7]}" if vals[6] != "–" else "–"
        lines.append(f"| {key[0]} | {key[1]} | {key[2]} | {len(g)} | "
                     + " | ".join(vals[:6]) + f" | {recall} |")  # fmt: skip
    return "\n".join(lines)


def _variant(checkpoint: str | None) -> str:
    """``models/eth/generator-speedaug.safetensors`` -> ``speedaug``; the default -> ``""``."""
    return Path(checkpoint).stem.removeprefix("generator").lstrip("-") if checkpoint else ""


SELECTION_FREE = ("first", "random", "kmeans", "fps", "facility", "medoids")
"""The score-free selections, the selection table's columns: ``score.selection``'s methods
whose ``USES_SCORE`` is False, in its order, written out here (``results`` is below ``score``
in the layers; tests/test_results.py compares the two)."""


def selection_table(rows: list[dict[str, Any]], split: str = "test",
                    chosen: dict[str, str | list[str]] | None = None) -> str:  # fmt: skip
    """Markdown table of the ``select-*`` rows: per dataset and K', minFDE_K' of the
    score-free selections, the best of them, the score-using selection and the change (then
    the joint minFDE, the cost, and the per-agent and joint minADE of the same two), each
    the mean over the seeds measured; the change is computed within each seed and shown as
    mean +- std when there are several. ``chosen`` maps a line's label (the dataset, or
    ``"eth (speedaug)"`` for a variant) to its score-using method chosen on validation
    (``benchmarks/selection_chosen.json``), or to a list of them (the chosen setting and, for
    example, its cheaper version), one line each; a line without an entry shows its best
    score-using row, which is the chosen one only when a single setting was read on test."""
    sel = [r for r in merge_rows(rows) if r["split"] == split and r["method"].startswith("select-")]
    groups: dict[tuple, dict[str, list[dict[str, Any]]]] = {}
    for r in sel:
        variant = _variant(r.get("checkpoint"))  # a published variant's rows form their own line
        method = r["method"].removesuffix(f"-{variant}") if variant else r["method"]
        label = f"{r['dataset']} ({variant})" if variant else r["dataset"]
        groups.setdefault((label, r["samples"]), {}).setdefault(method, []).append(r)
    lines = [
        "| dataset | K' | seeds | " + " | ".join(SELECTION_FREE) + " | best without score "
        "| with the score | change | joint minFDE, without / with | ms/scene (score + select) "
        "| minADE, without / with | joint minADE, without / with |",
        "|---|---|---|" + "---|" * len(SELECTION_FREE) + "---|---|---|---|---|---|---|",
    ]
    for (dataset, keep), by_method in sorted(groups.items()):
        free = {m: g for m, g in by_method.items() if not g[0]["uses_score"]}
        every_scored = {m: g for m, g in by_method.items() if g[0]["uses_score"]}
        picks = (chosen or {}).get(dataset)
        picks = [picks] if isinstance(picks, str) else picks
        for pick in picks or [None]:
            if pick is None:
                scored = every_scored
            elif pick in every_scored:  # the rule's choice, never the better of several on test
                scored = {pick: every_scored[pick]}
            else:
                raise ValueError(f"{dataset}: chosen selection {pick!r} has no {split} rows")
            if free and scored:
                lines.append(_selection_line(dataset, keep, by_method, free, scored))
    return "\n".join(lines)


def _selection_line(dataset: str, keep: int, by_method: dict[str, list[dict[str, Any]]],
                    free: dict[str, list[dict[str, Any]]],
                    scored: dict[str, list[dict[str, Any]]]) -> str:  # fmt: skip
    """One line of ``selection_table``: the best of ``free`` against the best of ``scored``."""

    def mean(runs: list[dict[str, Any]], field: str) -> float | None:
        values = [r[field] for r in runs if r[field] is not None]
        return sum(values) / len(values) if values else None

    best_free = min(free, key=lambda m: mean(free[m], "min_fde"))
    best = min(scored, key=lambda m: mean(scored[m], "min_fde"))
    free_by_seed = {r["seed"]: r["min_fde"] for r in free[best_free]}
    changes = torch.tensor([100 * (r["min_fde"] / free_by_seed[r["seed"]] - 1)
                            for r in scored[best] if r["seed"] in free_by_seed])  # fmt: skip
    change = f"{changes.mean():+.1f} %" if len(changes) else "–"
    if len(changes) > 1:
        change = f"{changes.mean():+.1f} ± {changes.std():.1f} %"
    seeds = len({r["seed"] for r in scored[best]})
    cells = [_fmt(mean(by_method[f"select-{c}"], "min_fde")) if f"select-{c}" in by_method
             else "–" for c in SELECTION_FREE]  # fmt: skip
    return (
        f"| {dataset} | {keep} | {seeds} | " + " | ".join(cells)
        + f" | {_fmt(mean(free[best_free], 'min_fde'))} "
        f"| {_fmt(mean(scored[best], 'min_fde'))} "
        f"(`{best.removeprefix('select-')}`) | {change} "
        f"| {_fmt(mean(free[best_free], 'joint_min_fde'))} / "
        f"{_fmt(mean(scored[best], 'joint_min_fde'))} "
        f"| {_fmt(mean(scored[best], 'ms_per_scene'), 1)} "
        f"| {_fmt(mean(free[best_free], 'min_ade'))} / {_fmt(mean(scored[best], 'min_ade'))} "
        f"| {_fmt(mean(free[best_free], 'joint_min_ade'))} / "
        f"{_fmt(mean(scored[best], 'joint_min_ade'))} |"
    )  # fmt: skip


def update_readme(readme: str | Path, marker: str, content: str) -> None:
    """Replace the text between ``<!-- marker:start -->`` and ``<!-- marker:end -->``."""
    path = Path(readme)
    text = path.read_text()
    start, end = f"<!-- {marker}:start -->", f"<!-- {marker}:end -->"
    if start not in text or end not in text:
        raise ValueError(f"{path} has no {start} ... {end} block")
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f"{head}{start}\n{content}\n{end}{tail}")


def row_key(line: str) -> tuple[str, str] | None:
    """The first two cells of a markdown table's data line (``| dataset | method | ...``), or
    None for any other line, the header line and the separator included."""
    cells = [c.strip() for c in line.split("|")[1:3]]
    if not line.startswith("| ") or len(cells) < 2 or cells[0] == "dataset":
        return None
    return cells[0], cells[1]


def table_lines(text: str, heading: str | None = None) -> dict[tuple[str, str], str]:
    """The data lines of the markdown tables in ``text`` (only those under ``heading``, up to
    the next ``## ``, when given) by ``row_key``, the first of each key kept: what a generated
    report falls back to for lines it cannot compute on this machine."""
    out, inside = {}, heading is None
    for line in text.splitlines():
        if heading is not None and line.startswith("## "):
            inside = line == heading
        if inside and (key := row_key(line)) is not None:
            out.setdefault(key, line)
    return out


PEER_COLUMNS = ("eth", "hotel", "univ", "zara1", "zara2", "avg", "sdd", "nba", "nba-rebound",
                "robo")  # fmt: skip
"""Columns of the peers table: the five ETH/UCY folds, their average, SDD, NBA on LED's split
(the peers'), NBA on the rebound split (ours) and Robo."""
PEER_HEADERS = {
    "nba": "nba, LED's 10 + 20",
    "nba-rebound": "nba, rebound 8 + 12 (ball counted)",
}
"""Header of a column whose key alone would mislead: the two NBA splits do not compare."""
OUR_DATASET = {"nba": None, "nba-rebound": "nba"}
"""The dataset whose rows fill our cells of a column (default: the column's own name): our
NBA data is SocialVAE's rebound split (8 observed + 12 predicted steps at 0.12 s: 0.96 s
observed, 1.44 s predicted; 10 players and the ball, every one an agent of the metrics), never
LED's 10 + 20 split at 0.2 s (2 s + 4 s) the peers report, so it has its own column."""
SECONDARY_MARK = "§"
"""Marks a peer's cell whose number is quoted second-hand (``secondary`` in peers.json): as
printed by another paper than the method's own."""


def _pair(values: Any) -> str:
    return "–" if not values else f"{values[0]:.2f} / {values[1]:.2f}"


def peers_table(peers: dict[str, Any], rows: list[dict[str, Any]],
                methods: Sequence[str] = ("pretrained",)) -> str:  # fmt: skip
    """Markdown table: our rows of each of ``methods`` (test split, K = 20, seed-mean) under
    each evaluation protocol beside the published peers (``benchmarks/peers.json``), minADE20
    / minFDE20 per column (``PEER_COLUMNS``; our rows of a dataset go where ``OUR_DATASET``
    says). Our ETH/UCY average is the unweighted mean of the five fold means, there only
    when all five folds are; a method with no row under a protocol gets no line for it. A
    peer's cell listed in its ``secondary`` is marked ``SECONDARY_MARK``."""
    lines = [
        "| method | protocol | " + " | ".join(PEER_HEADERS.get(c, c) for c in PEER_COLUMNS) + " |",
        "|---|---|" + "---|" * len(PEER_COLUMNS),
    ]
    merged = [r for r in merge_rows(rows) if r["split"] == "test" and r["samples"] == 20]
    folds = ("eth", "hotel", "univ", "zara1", "zara2")
    for method in methods:
        for protocol in ("all", "sgan"):
            cells = {}
            for col in PEER_COLUMNS:
                dataset = OUR_DATASET.get(col, col)
                xs = [r for r in merged if r["dataset"] == dataset and r["method"] == method
                      and r["protocol"] == protocol]  # fmt: skip
                if dataset is not None and xs:
                    cells[col] = [sum(r[k] for r in xs) / len(xs) for k in ("min_ade", "min_fde")]
            if all(f in cells for f in folds):
                cells["avg"] = [sum(cells[f][i] for f in folds) / len(folds) for i in (0, 1)]
            if cells:
                lines.append(f"| **trajpref** (`{method}`) | {protocol} | "
                             + " | ".join(f"**{_pair(cells.get(c))}**" if c in cells else "–"
                                          for c in PEER_COLUMNS) + " |")  # fmt: skip
    for name, entry in peers["methods"].items():
        quoted = set(entry.get("secondary", []))
        lines.append(f"| {name} | {entry.get('protocol', 'unknown')} | "
                     + " | ".join(_pair(entry.get(c))
                                  + (f" {SECONDARY_MARK}" if c in quoted and entry.get(c) else "")
                                  for c in PEER_COLUMNS) + " |")  # fmt: skip
    return "\n".join(lines)


def peers_notes(peers: dict[str, Any]) -> str:
    """What the peers table's cells mean beyond its header: how our average is taken, the two
    NBA columns, the second-hand mark, and each protocol read from a peer's public code
    (``protocol_source`` in peers.json: repository, commit, file:line, what the code does)."""
    parts = [
        "The protocol column is about the ETH/UCY cells: on SDD, NBA and Robo every row counts "
        "every agent of its split's windows (`--protocol sgan` is refused there).",
        "Our `avg` is the unweighted mean of the five fold means (each fold counts once, "
        "whatever its number of agent-windows), shown only when all five folds have a row; a "
        "peer's `avg` is as its source printed it.",
        "NBA: the peers' column is LED's 10 + 20 split (10 observed + 20 predicted frames at "
        "0.2 s: 2 s observed, 4 s predicted); ours is SocialVAE's rebound split (8 + 12 steps "
        "at 0.12 s: 0.96 s observed, 1.44 s predicted) in its own column: the two columns do "
        "not compare. Both count the ball as one of 11 agents (LED and MART, whose loader is "
        "LED's, average over all 11 too; SocialVAE, the source of our split, scores the 10 "
        "players only), so the differences are the split (other games and windows), the "
        "history and horizon lengths and their steps, and the feet conversion: LED and MART "
        "divide feet by 94/28 (0.298 m per ft), we multiply by 0.3048, so our distances are "
        "2.3 % larger for the same positions.",
        f"{SECONDARY_MARK} marks a number quoted second-hand, as printed in another paper than "
        f"the method's own (named in the `source` of `benchmarks/peers.json`); check it "
        f"against the method's own paper before citing it.",
    ]
    read = []
    for name, entry in peers["methods"].items():
        src = entry.get("protocol_source")
        if src:
            where = ", ".join(src["lines"])
            read.append(f"{name}: `{entry['protocol']}` ({src['repository']} at "
                        f"{src['commit']}, {where}: {src['reads']})")  # fmt: skip
    if read:
        parts.append("Protocols read from a peer's public code: " + "; ".join(read) + "; "
                     "`unknown`: not checked.")  # fmt: skip
    return " ".join(parts)
