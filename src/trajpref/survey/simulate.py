"""``trajpref survey simulate``: synthetic raters, for demos and tests only.

They are not a model of human judgement. A synthetic rater likes a panel as much as its shown
futures are close to what really happened: per panel, with e = ADE (social) or FDE (kinetics)
of the shown futures divided by the median over the method panels of the study,

    rating = clip(round(top - slope * e + b_rater + noise), 1, 5),
    b_rater ~ N(0, bias_sd) once per rater,  noise ~ N(0, noise_sd) per answer,

so that the ground truth (e = 0) gets about ``top`` and a median panel about ``top - slope``.
Their answers are stored with kind ``synthetic`` and submitted, each rater's in the order that
rater is shown the pictures (``Study.rater_order``: the positions recorded, as for a person);
the ratings do not depend on the order (these raters have no position effect), so a seed gives
the same ratings whatever the study's ``order``. ``analyze`` labels any result that uses them.
Agreement between synthetic raters and ATS/FTS measures how ATS/FTS follow the distance to the
ground truth, never how they follow people.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajpref.errors import ConfigError
from trajpref.survey.manifest import GROUND_TRUTH, RATING_MAX, RATING_MIN, Study
from trajpref.survey.store import RATER_RE, AnswerStore, check_rater


@dataclass
class SimulateConfig:
    """How many synthetic raters and how they rate."""

    raters: int = 20
    """Synthetic raters (the paper: 20 judges)."""
    seed: int = 0
    """Seeds the raters' biases and noise."""
    prefix: str = "synthetic"
    """Rater ids are ``{prefix}-01``, ``{prefix}-02``, ... in lower case (rater ids are not
    case-sensitive: ``check_rater``)."""
    top: float = 4.2
    """Expected rating of a panel that shows the ground truth."""
    slope: float = 1.2
    """Points lost per median error."""
    bias_sd: float = 0.4
    """Spread of the raters' personal offsets."""
    noise_sd: float = 0.6
    """Spread of the noise of single answers."""

    def __post_init__(self) -> None:
        if self.raters < 1:
            raise ConfigError("--raters must be >= 1")
        if self.bias_sd < 0 or self.noise_sd < 0:
            raise ConfigError("the spreads must be >= 0")
        if not RATER_RE.fullmatch(f"{self.prefix}-01"):
            raise ConfigError(f"--prefix {self.prefix!r}: letters, digits or '_.@-'")


def simulate(study: Study, store: AnswerStore, cfg: SimulateConfig) -> list[str]:
    """Write ``cfg.raters`` synthetic raters' answers to every panel; returns their ids.
    Refuses ids that exist already (run it again with another ``--prefix``)."""
    width = max(2, len(str(cfg.raters)))
    ids = [check_rater(f"{cfg.prefix}-{i + 1:0{width}d}") for i in range(cfg.raters)]
    taken = sorted(set(ids) & {r.lower() for r in store.raters()})
    if taken:
        raise ConfigError(f"raters {', '.join(taken[:3])}{' ...' if len(taken) > 3 else ''} "
                          "already exist in this database; use another --prefix")  # fmt: skip
    panels = [(s.id, p.id, p.key) for s in study.scenes for p in s.panels]
    methods = [k for _, _, k in panels if k.method != GROUND_TRUTH]
    med_ade = float(np.median([k.ade for k in methods])) if methods else 1.0
    med_fde = float(np.median([k.fde for k in methods])) if methods else 1.0
    err = np.array([[k.ade / max(med_ade, 1e-9), k.fde / max(med_fde, 1e-9)]
                    for _, _, k in panels])  # [Q, 2] (social, kinetics)  # fmt: skip
    rng = np.random.default_rng(cfg.seed)
    for rater in ids:
        bias = rng.normal(0, cfg.bias_sd)
        latent = cfg.top - cfg.slope * err + bias + rng.normal(0, cfg.noise_sd, err.shape)
        ratings = np.clip(np.rint(latent), RATING_MIN, RATING_MAX).astype(int)  # [Q, 2]
        given = {(s, p): {"social": int(r[0]), "kinetics": int(r[1])}
                 for (s, p, _), r in zip(panels, ratings, strict=True)}  # fmt: skip
        store.save_many(rater, [(s.id, p.id, given[(s.id, p.id)])  # in this rater's order
                                for s, shown in study.rater_order(rater) for p in shown],
                        kind="synthetic")  # fmt: skip
        store.submit(rater, kind="synthetic")
    return ids
