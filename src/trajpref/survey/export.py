"""``trajpref survey export``: the answers as one CSV table for R, pandas or SPSS.

One row per answer (long format), unblinded: the rater, the scene and panel, where that rater
was shown the picture, the method behind the panel and what the key says about it (ATS, FTS,
ADE, FDE in the data's units; the ground truth's ATS and FTS empty: defined as 0, not
measured), the two ratings and their mean, when the answer was given, and the record of what
built the study (study id, versions, the method's checkpoint hashes). The same raters as
``analyze`` (``--raters``, ``--exclude-rater``). Rater ids are personal data: the file is
written owner-only (0600), atomically.
"""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

from trajpref.errors import ConfigError, DataWarning
from trajpref.io import check_output_file
from trajpref.survey.analyze import RaterKind, case_variants_text, select_rows
from trajpref.survey.manifest import DATABASE, GROUND_TRUTH, load_study
from trajpref.survey.store import AnswerStore, case_variants, private_output

COLUMNS = (
    "rater", "kind", "submitted_at", "scene", "panel", "position", "scene_position",
    "panel_position", "method", "social", "kinetics", "human_score", "ats", "fts", "ade", "fde",
    "units", "source", "agents", "stratum", "revision", "created_at", "updated_at",
    "consented_at", "study_id", "weights_hash", "model_hash", "trajpref_version",
    "torch_version",
)  # fmt: skip
"""The CSV's columns. ``position``: the picture's place in the order this row's rater was
shown the pictures (1 = first; raters of a study built with per-rater orders see different
orders); ``scene_position``: its scene's place in that order (1 = first scene);
``panel_position``: the picture's place within its scene (1 = first shown of the scene); for
an answer saved before positions were recorded (2026-12-06), when every rater saw the
manifest's order, that order's (``AnswerStore.shown_at``); ``human_score``: the mean of the
two ratings; ``ade``/``fde`` in ``units``; ``created_at``/``updated_at``: the answer's first
and last save (UTC); ``submitted_at``: when the rater submitted (empty if not);
``ats``/``fts`` empty (NA) for the ground truth (0 by definition, not a measurement: an
average over the column must not mix it in);
``consented_at``: when the rater agreed to the study's consent text (empty if the study has
none or for synthetic raters); ``study_id``: ``Study.study_id``; ``weights_hash``/``model_hash``:
the method's checkpoint (empty for cv and the ground truth, or a study built before they were
recorded); ``trajpref_version``/``torch_version``: what built the study."""


def export_csv(folder: str | Path, path: str | Path, db: str | Path | None = None,
               rater_kind: RaterKind = "auto",
               exclude: list[str] | tuple[str, ...] = ()) -> dict[str, object]:  # fmt: skip
    """Write the answers of ``folder``'s study to the CSV file ``path``; returns ``{"path",
    "answers", "raters", "kind", "synthetic"}``. The output path is checked before the answers
    are read; nothing is written on error."""
    study = load_study(folder)
    path = check_output_file(path, what="--csv")
    store = AnswerStore(db or study.folder / DATABASE, study, readonly=True)
    try:
        records = store.records()
        excluded = store.find_raters(list(exclude))
    finally:
        store.close()
    if not records:
        raise ConfigError(f"{store.path}: no answers to this study's panels yet")
    keyed = [(r["rater"], r["kind"], r) for r in records]
    chosen, kind = select_rows(keyed, rater_kind, excluded)
    raters = sorted({r[0] for r in chosen})
    if case_variants(raters):
        warnings.warn(f"{store.path}: {case_variants_text(case_variants(raters))}", DataWarning,
                      stacklevel=2)  # fmt: skip
    units = str(study.dataset.get("units") or "unknown")
    build = study.build or {}
    hashes = (build.get("hashes") or {}).get("methods") or {}
    versions = [build.get("trajpref_version") or "", build.get("torch_version") or ""]
    where = {(s.id, p.id): (s, p.key) for s in study.scenes for p in s.panels}
    with private_output(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        out = csv.writer(fh)
        out.writerow(COLUMNS)
        for _, _, r in chosen:
            scene, key = where[(r["scene"], r["panel"])]
            gt = key.method == GROUND_TRUTH
            h = hashes.get(key.method) or {}
            out.writerow([
                r["rater"], r["kind"], r["submitted_at"] or "", r["scene"], r["panel"],
                r["position"], r["scene_position"], r["panel_position"], key.method,
                r["social"], r["kinetics"], (r["social"] + r["kinetics"]) / 2,
                "" if gt else key.ats, "" if gt else key.fts, key.ade, key.fde, units,
                scene.source, scene.agents, scene.stratum, r["revision"], r["created_at"],
                r["updated_at"], r.get("consented_at") or "", study.study_id,
                h.get("weights_hash") or "", h.get("model_hash") or "", *versions,
            ])  # fmt: skip
    synthetic = study.synthetic or any(r[1] == "synthetic" for r in chosen)
    return {"path": path, "answers": len(chosen), "raters": len(raters), "kind": kind,
            "synthetic": synthetic}  # fmt: skip
