"""``trajpref survey analyze``: the paper's Table 3 from a study's answers.

- Human score of an answer: the mean of its two ratings (social appropriateness, kinetics).
  Per method: mean and standard deviation over all its answers (raters x scenes); the two
  criteria are also reported apart.
- ATS / FTS of a panel: the diffusion score of the futures it shows (``PanelKey``); per
  method: mean and standard deviation over scenes. The ground truth's are 0 by definition.
- Significance (the stars): the best method by human score against every other row, with
  the Wilcoxon signed-rank test (two-sided; zero differences dropped; exact null
  distribution when n <= 50 and no ties, else the normal approximation with tie
  correction). Human score: paired over raters (each rater's mean over the scenes; raters who
  answered every panel only). ATS/FTS: paired over scenes. p-values are Holm-adjusted within
  each column; stars: *** p < 0.001, ** p < 0.01, * p < 0.05, ns otherwise.
- Agreement of human scores with ATS/FTS (methods only, the ground truth left out): Spearman
  rho and Kendall tau-b between the methods' means (n = methods), between panels (each
  panel's mean human score against its ATS, n = scenes x methods), and Kendall tau within
  each scene, averaged over scenes. p-values: exact for few pairs (Spearman by enumeration
  up to 8, Kendall by scipy's exact method without ties), else the usual approximations.
- The best method is named (bold, "Best method") only when at least one rater answered every
  panel and every method has at least ``MIN_ANSWERS`` answers: an unfinished pilot names none,
  and no tests are run. A mark of a row that scores above the best method (the ground truth,
  typically) carries ``ABOVE``: its stars then mean significantly *higher*.
- Position effect (``PositionCheck``): the mean human score by the picture's place within its
  scene as the rater was shown it (1 = first), and a Friedman test whose blocks are the raters
  (a Wilcoxon signed-rank test for two pictures per scene): each rater's mean score at each
  place, over the scenes in which they answered every picture. A rater's scenes are not
  independent of each other (one rater's habits run through all of them), raters are: a test
  over (rater, scene) pairs would count one rater's many scenes as many independent blocks.
  With per-rater orders (``Study.order`` ``rater``) position and method are unrelated; with a
  fixed order they are confounded, and the report says so.
- Raters left out by request (``--exclude-rater``: a failed attention check, a test run) are
  dropped before anything is computed and named in the report; rater ids that differ only by
  case (an older or imported database) are counted apart, with a warning.
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from scipy import stats

from trajpref import __version__
from trajpref.errors import ConfigError, DataWarning
from trajpref.io import atomic_path, check_output_dir, check_output_file, dumps_json
from trajpref.survey.manifest import DATABASE, GROUND_TRUTH, Study, load_study
from trajpref.survey.store import AnswerStore, case_variants, private_output
from trajpref.viz.plot import plot_survey_summary

RaterKind = Literal["auto", "human", "synthetic", "all"]
LEVELS = ((0.001, "***"), (0.01, "**"), (0.05, "*"))
"""Significance marks: the first level a p-value falls below; ``ns`` otherwise."""
EXACT_MAX_N = 50
"""The Wilcoxon test uses the exact null distribution up to this many pairs (without ties)."""
EXACT_SPEARMAN_MAX_N = 8
"""Spearman's p-value is exact (by enumeration) up to this many pairs."""
NOTHING_IGNORED = {"answers": 0, "unknown_panels": 0, "unknown_raters": 0}
"""``Analysis.ignored`` when every answer was used."""
MIN_ANSWERS = 2
"""A best method is named only when every method has at least this many answers (and at least
one rater answered every panel)."""
ABOVE = "↑"
"""Follows the mark of a row that scores above the best method in that column."""


def stars(p: float) -> str:
    if not math.isfinite(p):
        return "n/a"
    for level, mark in LEVELS:
        if p < level:
            return mark
    return "ns"


def holm(pvalues: list[float]) -> list[float]:
    """Holm's step-down adjustment (NaN entries are left out and stay NaN)."""
    idx = [i for i, p in enumerate(pvalues) if math.isfinite(p)]
    order = sorted(idx, key=lambda i: pvalues[i])
    out = [math.nan] * len(pvalues)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(order) - rank) * pvalues[i]))
        out[i] = running
    return out


@dataclass
class Comparison:
    """One paired comparison of the best method against another row."""

    other: str
    """The row compared with the best method."""
    column: str
    """``human``, ``ats`` or ``fts``."""
    n: int
    """Pairs (raters for ``human``, scenes for ATS/FTS), zero differences included."""
    statistic: float
    """Wilcoxon's W: the smaller of the two signed-rank sums."""
    p: float
    """Two-sided p-value."""
    p_holm: float = math.nan
    """Holm-adjusted within the column."""
    method: str = ""
    """``exact`` or ``normal approximation``."""
    mark: str = ""
    """Stars of ``p_holm``."""
    higher: bool = False
    """The row's mean over the pairs is above the best method's (its stars then mean
    significantly *higher*)."""


def wilcoxon(x: np.ndarray, y: np.ndarray) -> tuple[float, float, str]:
    """Paired two-sided Wilcoxon signed-rank test: (W, p, method). Zero differences are
    dropped (Wilcoxon's convention); all zero -> p = 1."""
    d = np.asarray(x, float) - np.asarray(y, float)  # [n]
    nz = d[d != 0]
    if len(d) < 2:
        return math.nan, math.nan, "too few pairs"
    if len(nz) == 0:
        return 0.0, 1.0, "no differences"
    ties = len(np.unique(np.abs(nz))) < len(nz)
    exact = len(nz) <= EXACT_MAX_N and not ties and len(nz) == len(d)
    method = "exact" if exact else "asymptotic"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = stats.wilcoxon(x, y, zero_method="wilcox", alternative="two-sided",
                             method=method)  # fmt: skip
    return float(res.statistic), float(res.pvalue), ("exact" if exact
                                                      else "normal approximation")  # fmt: skip


def _compare(other: str, column: str, x: list[float], y: list[float]) -> Comparison:
    """The best method's values ``x`` against the row's ``y``, paired."""
    w, p, method = wilcoxon(np.asarray(x, float), np.asarray(y, float))
    higher = bool(len(x)) and float(np.mean(y)) > float(np.mean(x))
    return Comparison(other, column, len(x), w, p, method=method, higher=higher)


def _corr(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Spearman rho and Kendall tau-b with their p-values (NaN when undefined)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    out = {"n": int(len(a)), "spearman": math.nan, "spearman_p": math.nan,
           "kendall": math.nan, "kendall_p": math.nan}  # fmt: skip
    if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rho, p = spearman(a, b)
        k = stats.kendalltau(a, b)  # exact p for small n without ties
    out.update(spearman=rho, spearman_p=p, kendall=float(k.statistic),
               kendall_p=float(k.pvalue))  # fmt: skip
    return out


def spearman(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Spearman's rho and its two-sided p-value: exact (all n! orderings) for n <= 8, where
    scipy's t approximation is far off (it gives p = 0 for a perfect rank match of 3),
    scipy's otherwise."""
    n = len(a)
    if n > EXACT_SPEARMAN_MAX_N:
        res = stats.spearmanr(a, b)
        return float(res.statistic), float(res.pvalue)
    ra, rb = stats.rankdata(a), stats.rankdata(b)  # [n]
    perms = np.array(list(itertools.permutations(range(n))))  # [n!, n]
    za = (ra - ra.mean()) / np.linalg.norm(ra - ra.mean())
    zb = (rb - rb.mean()) / np.linalg.norm(rb - rb.mean())
    null = zb[perms] @ za  # [n!] rho of every ordering
    rho = float(zb @ za)
    return rho, float(np.mean(np.abs(null) >= abs(rho) - 1e-12))


@dataclass
class PositionCheck:
    """Is a picture rated differently for where it is shown within its scene?"""

    order: str
    """The study's presentation order (``Study.order``): ``rater`` or ``fixed``."""
    positions: list[dict[str, float]]
    """Per place within the scene (1 = shown first): ``position``, ``answers``, ``mean`` and
    ``sd`` of the human score."""
    test: str = ""
    """``Friedman`` (three or more pictures per scene), ``Wilcoxon signed-rank`` (two), or
    empty (no test: fewer than two raters with a complete scene, or one picture per scene)."""
    blocks: int = 0
    """Raters with at least one scene in which they answered every picture: the test's
    blocks (each rater's mean score per place over those scenes; raters are independent of
    each other, a rater's scenes are not)."""
    scenes: int = 0
    """(rater, scene) pairs in which every picture was answered: what the raters' means are
    taken over."""
    statistic: float = math.nan
    """Friedman's chi-squared (Wilcoxon's W)."""
    p: float = math.nan
    """Its p-value (chi-squared approximation with tie correction; Wilcoxon: see
    ``wilcoxon``)."""
    note: str = ""
    """How to read it (with a fixed order, position and method are the same thing)."""


def position_check(study: Study, rows: list[tuple],
                   positions: dict[tuple[str, str, str], tuple] | None = None
                   ) -> PositionCheck:  # fmt: skip
    """The position-effect check of ``rows`` (``AnswerStore.rows()``). ``positions``
    (``AnswerStore.positions()``: (rater, scene, panel) -> (scene position, panel position,
    position)): where each answer's picture was shown; without it (or for an answer it
    lacks), where ``Study.positions`` shows it to that rater now."""
    own: dict[str, dict[tuple[str, str], tuple[int, int, int]]] = {}
    size = {s.id: len(s.panels) for s in study.scenes}
    k = max(size.values())
    by_pos: dict[int, list[float]] = {j: [] for j in range(1, k + 1)}
    blocks: dict[tuple[str, str], dict[int, float]] = {}
    for rater, _, scene, panel, social, kinetics, _ in rows:
        where = (positions or {}).get((rater, scene, panel))
        if where is None:
            if rater not in own:
                own[rater] = study.positions(rater)
            where = own[rater][(scene, panel)]
        h = (social + kinetics) / 2
        by_pos.setdefault(where[1], []).append(h)
        if size[scene] == k:
            blocks.setdefault((rater, scene), {})[where[1]] = h
    table = []
    for j, v in sorted(by_pos.items()):
        mean, sd = _mean_sd(v)
        table.append({"position": j, "answers": len(v), "mean": mean, "sd": sd})
    complete: dict[str, list[dict[int, float]]] = {}  # rater -> their complete scenes
    for (rater, _), b in blocks.items():
        if sorted(b) == list(range(1, k + 1)):
            complete.setdefault(rater, []).append(b)
    # one block per rater: their mean score at each place over their complete scenes; k x [R]
    columns = [np.array([np.mean([b[j] for b in scenes]) for scenes in complete.values()])
               for j in range(1, k + 1)]  # fmt: skip
    if study.order == "fixed":
        note = ("every rater saw the same order (a fixed-order study): each place within a scene "
                "always showed the same method, so a difference between places cannot be told "
                "from a difference between methods")  # fmt: skip
    else:
        note = ("each rater saw an order of their own, so the places within a scene are not "
                "tied to the methods: a significant difference is a position effect")  # fmt: skip
    check = PositionCheck(study.order, table, blocks=len(complete),
                          scenes=sum(len(v) for v in complete.values()), note=note)  # fmt: skip
    if len(complete) < 2 or k < 2:
        return check
    if k == 2:
        w, p, _ = wilcoxon(columns[0], columns[1])
        check.test, check.statistic, check.p = "Wilcoxon signed-rank", w, p
        return check
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # every block all ties: NaN
        res = stats.friedmanchisquare(*columns)
    check.test, check.statistic, check.p = "Friedman", float(res.statistic), float(res.pvalue)
    return check


@dataclass
class MethodRow:
    """One row of the table."""

    method: str
    """The method (or ``ground truth``)."""
    answers: int
    """Answers to its panels."""
    human: float
    """Mean human score (mean of the two ratings)."""
    human_sd: float
    """Its standard deviation over answers."""
    social: float
    """Mean social-appropriateness rating."""
    social_sd: float
    """Its standard deviation."""
    kinetics: float
    """Mean kinetics rating."""
    kinetics_sd: float
    """Its standard deviation."""
    ats: float
    """Mean ATS of the shown futures over scenes."""
    ats_sd: float
    """Its standard deviation over scenes."""
    fts: float
    """Mean FTS of the shown futures."""
    fts_sd: float
    """Its standard deviation over scenes."""
    max_ats: float = math.nan
    """Mean maxATS_K of the method's samples (the paper's Table 1 measure)."""
    max_fts: float = math.nan
    """Mean maxFTS_K."""
    ade: float = math.nan
    """Mean ADE of the shown futures over scenes, in the data's units (0 for the ground
    truth)."""
    ade_sd: float = math.nan
    """Its standard deviation over scenes."""
    fde: float = math.nan
    """Mean FDE of the shown futures over scenes, in the data's units."""
    fde_sd: float = math.nan
    """Its standard deviation over scenes."""
    marks: dict[str, str] = field(default_factory=dict)
    """column -> stars against the best method."""


@dataclass
class Analysis:
    """Everything ``analyze`` reports."""

    title: str
    """The study's title."""
    dataset: dict[str, Any]
    """The study's data."""
    rater_kind: str
    """Which raters were used: human, synthetic or all."""
    synthetic: bool
    """True when any answer or the study itself is synthetic."""
    raters: int
    """Raters with at least one answer."""
    complete_raters: int
    """Raters who answered every panel (the paired test uses these)."""
    scenes: int
    """Scenes in the study."""
    panels: int
    """Panels in the study."""
    best: str | None
    """The method with the highest mean human score (ground truth excluded); None when no
    rater answered every panel or a method has fewer than ``MIN_ANSWERS`` answers
    (``no_best``)."""
    rows: list[MethodRow]
    """Methods by mean human score, best first; the ground truth last."""
    tests: list[Comparison]
    """Paired tests of the best method against the others."""
    agreement: dict[str, dict[str, dict[str, float]]]
    """level (methods, panels, within_scene) -> score (ats, fts) -> correlations."""
    ignored: dict[str, int] = field(default_factory=lambda: dict(NOTHING_IGNORED))
    """Answers in the database that match no panel of the study or no rater
    (``AnswerStore.ignored``): ``answers``, ``unknown_panels``, ``unknown_raters``."""
    excluded: list[str] = field(default_factory=list)
    """Raters left out on request (``--exclude-rater``), as stored."""
    excluded_answers: int = 0
    """Their answers to this study's panels."""
    case_variants: list[list[str]] = field(default_factory=list)
    """Groups of the raters used whose ids differ only by case (an older or imported
    database): counted as different raters."""
    units: str = "unknown"
    """The data's coordinate units (of ADE and FDE)."""
    no_best: str = ""
    """Why no best method is named (``best`` None); empty otherwise."""
    unused_synthetic: int = 0
    """Synthetic raters left out because ``--raters auto`` chose the human raters."""
    study_id: str = ""
    """The study's id (``Study.study_id``, as the answers database records it)."""
    provenance: dict[str, Any] = field(default_factory=dict)
    """``trajpref`` (the version that analysed) and ``build``: what the manifest's build
    record says of the versions and models that built the study (``trajpref_version``,
    ``torch_version``, ``hashes``; empty for a study built before they were recorded)."""
    position_effect: PositionCheck | None = None
    """The position-effect check (``position_check``)."""

    def to_dict(self) -> dict[str, Any]:
        return _finite(asdict(self))

    def table(self) -> str:
        """The Table-3 layout as Markdown."""
        lines = ["| Method | Human score (↑) | ATS (↑) | FTS (↑) |", "|---|---|---|---|"]
        for r in self.rows:
            name = f"**{r.method}**" if self.best and r.method == self.best else r.method
            gt = r.method == GROUND_TRUTH
            lines.append(
                f"| {name} | {_pm(r.human, r.human_sd)}{_mark(r.marks.get('human'))} | "
                f"{'0 (by definition)' if gt else _pm(r.ats, r.ats_sd)}"
                f"{_mark(r.marks.get('ats'))} | "
                f"{'0 (by definition)' if gt else _pm(r.fts, r.fts_sd)}"
                f"{_mark(r.marks.get('fts'))} |"
            )
        return "\n".join(lines)

    def legend(self) -> str:
        n_h = self.complete_raters
        units = (" Human score = mean of the two ratings (1-5); ATS/FTS = the diffusion score "
                 "of the futures each panel shows (a ratio, no unit); ADE/FDE = their distance "
                 f"to the real futures, {unit_text(self.units)}.")  # fmt: skip
        gt = any(r.method == GROUND_TRUTH for r in self.rows)
        unranked = " (the ground truth is not ranked: it is listed last)" if gt else ""
        if not self.best:
            return (f"Mean ± sd (n/a for one value). Rows by human score{unranked}; no best "
                    f"method is named and no tests are run: {self.no_best}.{units}")  # fmt: skip
        top = next(r.human for r in self.rows if r.method == self.best)
        tied = [r.method for r in self.rows
                if r.method not in (self.best, GROUND_TRUTH) and r.human == top]  # fmt: skip
        tie = (f" (tied with {', '.join(tied)}: of equal methods the first given to `survey "
               "build` is named)" if tied else "")  # fmt: skip
        highest = "has the highest of the methods" if gt else "has the highest"
        return (
            f"Mean ± sd (n/a for one value). Rows by human score{unranked}; **{self.best}** "
            f"{highest}{tie}. Marks: two-sided Wilcoxon signed-rank test of {self.best} against "
            f"the row, human score paired over raters (each rater's mean over the scenes, "
            f"n = {n_h} raters who answered every panel), ATS/FTS paired over scenes "
            f"(n = {self.scenes}); p-values Holm-adjusted within each column; *** p < 0.001, "
            f"** p < 0.01, * p < 0.05, ns not significant. A {ABOVE} after a mark: the row "
            f"scores *higher* than {self.best} in that column (e.g. the ground truth), so its "
            f"stars mean significantly higher; without {ABOVE}, lower or equal.{units}"
        )

    def markdown(self) -> str:
        out = [f"# Human evaluation: {self.title}", ""]
        if self.synthetic:
            out += ["> **SYNTHETIC RATERS (or a synthetic study): not human data.** These "
                    "answers come from `trajpref survey simulate`, whose raters prefer futures "
                    "close to the ground truth; the table shows the analysis working, not what "
                    "people think.", ""]  # fmt: skip
        ds = self.dataset
        where = f"{ds.get('name', '?')}/{ds.get('split', '?')}" if ds else "?"
        out += [f"Data: {where}; {self.scenes} scenes, {self.panels} panels; raters: "
                f"{self.raters} {self.rater_kind} ({self.complete_raters} answered every "
                "panel)."]  # fmt: skip
        if self.unused_synthetic:
            out += ["", f"Not used: {unused_text(self.unused_synthetic)}."]
        if self.ignored["answers"]:
            text = ignored_text(self.ignored)
            out += ["", f"{text[0].upper()}{text[1:]}: they are not in the tables below."]
        if self.excluded:
            out += ["", f"Excluded raters (--exclude-rater): {', '.join(self.excluded)} "
                    f"({self.excluded_answers} answer{'' if self.excluded_answers == 1 else 's'}"
                    "): they are not in the tables below."]  # fmt: skip
        if self.case_variants:
            text = case_variants_text(self.case_variants)
            out += ["", f"{text[0].upper()}{text[1:]}."]
        out += ["", self.table(), "", self.legend(), "",
                "## Per criterion", "",
                "| Method | Social appropriateness | Kinetics | answers | "
                f"{with_unit('ADE', self.units)} | {with_unit('FDE', self.units)} | maxATS_K | "
                "maxFTS_K |",
                "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for r in self.rows:
            out.append(f"| {r.method} | {_pm(r.social, r.social_sd)} | "
                       f"{_pm(r.kinetics, r.kinetics_sd)} | {r.answers} | "
                       f"{_pm(r.ade, r.ade_sd)} | {_pm(r.fde, r.fde_sd)} | {_num(r.max_ats)} | "
                       f"{_num(r.max_fts)} |")  # fmt: skip
        named = (
            f"Best method: {self.best}."
            if self.best
            else f"No best method is named and no tests are run: {self.no_best}."
        )
        out += ["", "## Tests", "", named, "",
                "| Against | Column | n | W | p | p (Holm) | | Null distribution |",
                "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for t in self.tests:
            out.append(f"| {t.other} | {t.column} | {t.n} | {_num(t.statistic, 1)} | "
                       f"{_p(t.p)} | {_p(t.p_holm)} | {t.mark} | {t.method} |")  # fmt: skip
        out += ["", "## Agreement of human scores with ATS / FTS", "",
                "Ground truth left out. *methods*: the methods' mean scores; *panels*: each "
                "panel's mean human score against its ATS/FTS; *within scene*: Kendall tau "
                "between the methods' ranks in each scene, averaged over the scenes where neither "
                "ranking is all ties (its p: Wilcoxon signed-rank test of the scenes' tau "
                "against 0).", "",
                "| Level | Score | n | Spearman rho | p | Kendall tau | p |",
                "|---|---|---|---|---|---|---|"]  # fmt: skip
        for level, scores in self.agreement.items():
            for score, c in scores.items():
                out.append(f"| {level.replace('_', ' ')} | {score.upper()} | {c['n']} | "
                           f"{_num(c['spearman'])} | {_p(c['spearman_p'])} | "
                           f"{_num(c['kendall'])} | {_p(c['kendall_p'])} |")  # fmt: skip
        if self.position_effect is not None:
            out += ["", *self.position_markdown()]
        return "\n".join(out) + "\n"

    def position_markdown(self) -> list[str]:
        """The report's section on the position effect."""
        c = self.position_effect
        out = ["## Position effect", "",
               "Human score by the picture's place within its scene, as each rater was shown "
               "it (1 = first).", "",
               "| Place in scene | answers | Human score |", "|---|---|---|"]  # fmt: skip
        out += [f"| {r['position']} | {r['answers']} | {_pm(r['mean'], r['sd'])} |"
                for r in c.positions]  # fmt: skip
        name = "chi²" if c.test == "Friedman" else "W"
        blocks = (f"{c.blocks} rater{'' if c.blocks == 1 else 's'} (each one block: their "
                  f"mean score at each place over the scenes in which they answered every "
                  f"picture, {c.scenes} (rater, scene) pairs in all; raters are independent "
                  f"of each other, one rater's scenes are not)")  # fmt: skip
        test = (f"{c.test} test over {blocks}: {name} = {_num(c.statistic)}, p = {_p(c.p)}"
                if c.test else f"no test: {blocks}; at least 2 raters are needed")  # fmt: skip
        return [*out, "", f"{test}; {c.note}."]


def ignored_text(ignored: dict[str, int]) -> str:
    """``ignored: N answers (M to ..., K from ...)``: what the warning and the report say."""
    n = ignored["answers"]
    return (f"ignored: {n} answer{'' if n == 1 else 's'} ({ignored['unknown_panels']} to "
            f"scenes or panels this study does not have, {ignored['unknown_raters']} from "
            "raters not in the raters table)")  # fmt: skip


def case_variants_text(groups: list[list[str]]) -> str:
    """What the warning and the report say about rater ids that differ only by case."""
    names = "; ".join(" = ".join(g) for g in groups)
    return (f"rater ids that differ only by case, counted as different raters: {names} (a "
            "database written before ids were made case-insensitive, or imported; if they are "
            "one person, leave all but one out with --exclude-rater)")  # fmt: skip


def unused_text(n: int) -> str:
    """What the report says of the synthetic raters ``--raters auto`` left out."""
    return (
        f"{n} synthetic rater{'' if n == 1 else 's'} (`--raters auto` uses the human raters "
        "when there are any; `--raters synthetic` or `--raters all` includes them)"
    )


def with_unit(name: str, units: str | None) -> str:
    """``ADE [m]``; ``ADE (units unknown)`` when the data did not say."""
    return f"{name} [{units}]" if units and units != "unknown" else f"{name} (units unknown)"


def unit_text(units: str | None) -> str:
    return f"in {units}" if units and units != "unknown" else "in the data's units (unknown)"


def _finite(obj: Any) -> Any:
    """NaN -> None, so that the JSON is valid."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj


def _num(x: float, digits: int = 2) -> str:
    return "–" if not math.isfinite(x) else f"{x:.{digits}f}"


def _pm(mean: float, sd: float) -> str:
    """``mean ± sd``; ``± n/a`` where the sd is undefined (one value)."""
    if not math.isfinite(mean):
        return "–"
    return f"{mean:.2f} ± {_num(sd) if math.isfinite(sd) else 'n/a'}"


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return "< 0.0001" if p < 1e-4 else f"{p:.4f}"


def _mark(mark: str | None) -> str:
    return f" {mark}" if mark else ""


def _mean_sd(values: list[float] | np.ndarray) -> tuple[float, float]:
    """Mean and sample sd; the sd is NaN (n/a) for one value, both NaN for none."""
    v = np.asarray(values, float)
    if v.size == 0:
        return math.nan, math.nan
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else math.nan


def select_rows(rows: list[tuple], rater_kind: RaterKind = "auto",
                exclude: list[str] | tuple[str, ...] = ()) -> tuple[list[tuple], str]:  # fmt: skip
    """The rows (``AnswerStore.rows()`` or ``records()`` as tuples: rater first, kind second)
    of the chosen raters, and the kind chosen. ``auto`` picks human raters when there are
    any, else synthetic ones, and decides before ``exclude`` (stored ids) is applied: leaving
    out every human rater is an error, never a silent switch to synthetic raters."""
    if rater_kind == "auto":
        rater_kind = "human" if any(r[1] == "human" for r in rows) else "synthetic"
    left = set(exclude)
    everyone = rows
    rows = [r for r in rows if r[0] not in left and rater_kind in ("all", r[1])]
    if not rows:
        after = f" left after --exclude-rater {', '.join(exclude)}" if exclude else " yet"
        others = sorted({r[0] for r in everyone if r[0] not in left and r[1] != rater_kind})
        hint = ""
        if rater_kind != "all" and others:
            kind = "synthetic" if rater_kind == "human" else "human"
            hint = (f"; there {'is' if len(others) == 1 else 'are'} {len(others)} {kind} "
                    f"rater{'' if len(others) == 1 else 's'}: use --raters {kind} (or --raters "
                    "all)")  # fmt: skip
        raise ConfigError(f"no answers from {rater_kind} raters{after}{hint}")
    return rows, rater_kind


def analyze(study: Study, rows: list[tuple], rater_kind: RaterKind = "auto",
            ignored: dict[str, int] | None = None,
            exclude: list[str] | tuple[str, ...] = (),
            positions: dict[tuple[str, str, str], tuple] | None = None) -> Analysis:  # fmt: skip
    """The analysis of ``rows`` (``AnswerStore.rows()``: rater, kind, scene, panel, social,
    kinetics, submitted). ``rater_kind``: ``auto`` uses the human raters when there are any,
    else the synthetic ones. ``ignored`` (``AnswerStore.ignored()``) is reported as given.
    ``exclude``: rater ids (as stored, ``AnswerStore.find_raters``) whose answers are left
    out and named in the report. ``positions`` (``AnswerStore.positions()``): where each
    answer's picture was shown, for the position-effect check (``position_check``)."""
    ignored = dict(ignored or NOTHING_IGNORED)
    if not rows:
        note = f"; {ignored_text(ignored)}" if ignored["answers"] else ""
        raise ConfigError(f"no answers to this study's panels yet{note}")
    excluded = list(dict.fromkeys(exclude))
    left_out = set(excluded)
    excluded_answers = sum(1 for r in rows if r[0] in left_out)
    unused = 0
    if rater_kind == "auto" and any(r[1] == "human" for r in rows):
        unused = len({r[0] for r in rows if r[1] == "synthetic" and r[0] not in left_out})
    rows, rater_kind = select_rows(rows, rater_kind, excluded)
    synthetic = study.synthetic or any(r[1] == "synthetic" for r in rows)
    method_of = {(s.id, p.id): p.key.method for s in study.scenes for p in s.panels}
    keys = {(s.id, p.id): p.key for s in study.scenes for p in s.panels}
    methods = list(study.methods)
    raters = sorted({r[0] for r in rows})
    # per method: every answer; per rater and method: the ratings, to average over scenes
    answers: dict[str, list[tuple[int, int]]] = {m: [] for m in methods}
    per_rater: dict[str, dict[str, list[float]]] = {r: {m: [] for m in methods} for r in raters}
    per_panel: dict[tuple[str, str], list[float]] = {k: [] for k in keys}
    count: dict[str, int] = dict.fromkeys(raters, 0)
    for rater, _, scene, panel, social, kinetics, _ in rows:
        m = method_of[(scene, panel)]
        answers[m].append((social, kinetics))
        per_rater[rater][m].append((social + kinetics) / 2)
        per_panel[(scene, panel)].append((social + kinetics) / 2)
        count[rater] += 1
    complete = [r for r in raters if count[r] == study.num_panels]
    table: dict[str, MethodRow] = {}
    for m in methods:
        a = np.asarray(answers[m], float).reshape(-1, 2)  # [A, 2]
        ks = [k for k in keys.values() if k.method == m]
        table[m] = MethodRow(
            m, len(a), *_mean_sd(a.mean(1)), *_mean_sd(a[:, 0]), *_mean_sd(a[:, 1]),
            *_mean_sd([k.ats for k in ks]), *_mean_sd([k.fts for k in ks]),
            float(np.mean([k.max_ats for k in ks if k.max_ats is not None] or [math.nan])),
            float(np.mean([k.max_fts for k in ks if k.max_fts is not None] or [math.nan])),
            *_mean_sd([k.ade for k in ks]), *_mean_sd([k.fde for k in ks]),
        )  # fmt: skip
    candidates = [m for m in methods if m != GROUND_TRUTH and math.isfinite(table[m].human)]
    if not candidates:
        raise ConfigError("no answers to any method's panels yet")
    best: str | None = max(candidates, key=lambda m: (table[m].human, -methods.index(m)))
    unanswered_last = lambda m: (not math.isfinite(table[m].human), -table[m].human)  # noqa: E731
    ordered = sorted((m for m in methods if m != GROUND_TRUTH), key=unanswered_last)
    ordered += [GROUND_TRUTH] if GROUND_TRUTH in methods else []
    few = [m for m in methods if table[m].answers < MIN_ANSWERS]
    no_best = ""
    if not complete:
        no_best = "no rater answered every panel"
    elif few:
        no_best = (f"{', '.join(few)} {'has' if len(few) == 1 else 'have'} fewer than "
                   f"{MIN_ANSWERS} answers")  # fmt: skip
    if no_best:
        best = None
    # tests: human over complete raters, ATS/FTS over scenes
    tests: list[Comparison] = []
    rater_means = {r: {m: float(np.mean(per_rater[r][m])) for m in methods} for r in complete}
    for m in ordered if best else ():
        if m == best:
            continue
        x = [rater_means[r][best] for r in complete]
        y = [rater_means[r][m] for r in complete]
        tests.append(_compare(m, "human", x, y))
        if m == GROUND_TRUTH:
            continue
        for col in ("ats", "fts"):
            by_scene = {s.id: {p.key.method: getattr(p.key, col) for p in s.panels}
                        for s in study.scenes}  # fmt: skip
            x = [v[best] for v in by_scene.values()]
            y = [v[m] for v in by_scene.values()]
            tests.append(_compare(m, col, x, y))
    for col in ("human", "ats", "fts"):
        group = [t for t in tests if t.column == col]
        for t, p in zip(group, holm([t.p for t in group]), strict=True):
            t.p_holm = p
            t.mark = stars(p)
            table[t.other].marks[col] = f"{t.mark} {ABOVE}" if t.higher else t.mark
    # agreement (methods only)
    ms = [m for m in methods if m != GROUND_TRUTH]
    agreement: dict[str, dict[str, dict[str, float]]] = {"methods": {}, "panels": {},
                                                         "within_scene": {}}  # fmt: skip
    panel_keys = [k for k in keys if method_of[k] != GROUND_TRUTH and per_panel[k]]
    for col in ("ats", "fts"):
        agreement["methods"][col] = _corr([table[m].human for m in ms],
                                          [getattr(table[m], col) for m in ms])  # fmt: skip
        agreement["panels"][col] = _corr([np.mean(per_panel[k]) for k in panel_keys],
                                         [getattr(keys[k], col) for k in panel_keys])  # fmt: skip
        taus = []
        for s in study.scenes:
            ks = [(s.id, p.id) for p in s.panels if p.key.method != GROUND_TRUTH]
            if len(ks) < 2 or not all(per_panel[k] for k in ks):
                continue
            h = [np.mean(per_panel[k]) for k in ks]
            v = [getattr(keys[k], col) for k in ks]
            if np.ptp(h) > 0 and np.ptp(v) > 0:
                taus.append(float(stats.kendalltau(h, v).statistic))
        agreement["within_scene"][col] = {
            "n": len(taus), "spearman": math.nan, "spearman_p": math.nan,
            "kendall": float(np.mean(taus)) if taus else math.nan,
            "kendall_p": (float(stats.wilcoxon(taus).pvalue)
                          if len(taus) >= 2 and any(taus) else math.nan),
        }  # fmt: skip
    return Analysis(
        title=study.title, dataset=study.dataset, rater_kind=rater_kind, synthetic=synthetic,
        raters=len(raters), complete_raters=len(complete), scenes=len(study.scenes),
        panels=study.num_panels, best=best, rows=[table[m] for m in ordered], tests=tests,
        agreement=agreement, ignored=ignored, excluded=excluded,
        excluded_answers=excluded_answers, case_variants=case_variants(raters),
        units=str(study.dataset.get("units") or "unknown"), no_best=no_best,
        unused_synthetic=unused, study_id=study.study_id, provenance=provenance(study),
        position_effect=position_check(study, rows, positions),
    )  # fmt: skip


def provenance(study: Study) -> dict[str, Any]:
    """What made the study and its analysis: this trajpref's version, and the manifest build
    record's ``trajpref_version``, ``torch_version`` and checkpoint ``hashes`` (None where a
    study built before they were recorded has none)."""
    build = study.build or {}
    return {
        "trajpref": __version__,
        "build": {k: build.get(k) for k in ("trajpref_version", "torch_version", "hashes")},
    }


Columns = dict[str, tuple[np.ndarray, np.ndarray]]
"""Axis title -> (mean [M], sd [M]), as ``plot_survey_summary`` takes them."""


def figure_data(
    result: Analysis,
) -> tuple[list[str], Columns, dict[str, list[str]], dict[str, tuple[float, float]]]:
    """What ``plot_survey_summary`` draws: the methods, and per axis (its title names the
    quantity and its unit) the means and sds, the marks and fixed x ranges. The ground truth
    draws no ATS, FTS or ADE bar (0 by definition)."""
    names = [r.method for r in result.rows]
    gt = np.array([math.nan if r.method == GROUND_TRUTH else 0.0 for r in result.rows])  # [M]
    human = "human score (rating 1-5)"
    labels = {human: "human", "ATS (ratio, no unit)": "ats", "FTS (ratio, no unit)": "fts",
              with_unit("ADE of the shown futures", result.units): "ade"}  # fmt: skip
    columns = {}
    for label, col in labels.items():
        mean = np.array([getattr(r, col) for r in result.rows])  # [M]
        sd = np.array([getattr(r, f"{col}_sd") for r in result.rows])  # [M]
        columns[label] = (mean if col == "human" else mean + gt, sd)
    marks = {label: [r.marks.get(col, "") for r in result.rows]
             for label, col in labels.items() if col != "ade"}  # fmt: skip
    return names, columns, marks, {human: (0.0, 5.4)}


def run_analysis(
    folder: str | Path,
    db: str | Path | None = None,
    out: str | Path | None = None,
    rater_kind: RaterKind = "auto",
    exclude: list[str] | tuple[str, ...] = (),
) -> tuple[Analysis, dict[str, Path]]:
    """Read a study and its answers, analyse, write ``analysis.md``, ``analysis.json`` and
    ``analysis.png`` into ``out`` (default: the study folder). ``exclude``: rater ids to
    leave out (``--exclude-rater``; any case; an id that names no rater is an error).
    ``analysis.md`` and ``.json`` name the excluded raters: they are written owner-only.

    The database is opened read-only (nothing is ever written into it). The output paths are
    checked before the answers are read, and the three files are renamed into place together
    at the end: nothing is written on error. Answers that match no panel of the study or no
    rater are left out, counted in a warning and in the report (``Analysis.ignored``)."""
    study = load_study(folder)
    given = out is not None
    out = Path(out) if given else study.folder
    check_output_dir(out, "--out" if given else "the study folder")
    paths = {"markdown": out / "analysis.md", "json": out / "analysis.json",
             "figure": out / "analysis.png"}  # fmt: skip
    for path in paths.values():
        check_output_file(path, what="cannot write")
    store = AnswerStore(db or study.folder / DATABASE, study, readonly=True)
    try:
        rows, ignored, positions = store.rows(), store.ignored(), store.positions()
        excluded = store.find_raters(list(exclude))
    finally:
        store.close()
    result = analyze(study, rows, rater_kind, ignored, excluded, positions)
    if ignored["answers"]:
        warnings.warn(f"{store.path}: {ignored_text(ignored)}", DataWarning, stacklevel=2)
    if result.case_variants:
        warnings.warn(f"{store.path}: {case_variants_text(result.case_variants)}", DataWarning,
                      stacklevel=2)  # fmt: skip
    names, columns, marks, xlims = figure_data(result)
    label = "SYNTHETIC raters - not human data. " if result.synthetic else ""
    reference = (f"; marks: Wilcoxon test against {result.best} ({ABOVE}: the row is higher)"
                 if result.best else "; no best method named, no tests")  # fmt: skip
    # all three written to temporary files first, renamed only when every one is complete;
    # the figure's first: it creates a new --out folder (and removes it again on failure)
    with (atomic_path(paths["figure"]) as figure, private_output(paths["markdown"]) as markdown,
          private_output(paths["json"]) as js):  # fmt: skip
        plot_survey_summary(names, columns, marks, figure,
                            f"{label}{result.title} ({result.raters} raters, "
                            f"{result.scenes} scenes{reference})", xlims=xlims)  # fmt: skip
        markdown.write_text(result.markdown(), encoding="utf-8")
        js.write_text(dumps_json(result.to_dict(), indent=2) + "\n")
    return result, paths
