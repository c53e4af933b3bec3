"""Named settings of the fine-tuning stage. ``paper`` is the equations as written."""

from __future__ import annotations

PAPER_WEIGHTS = {"rlhf": (1.0, 5.0), "rlhf-res": (0.3, 1.5)}
"""(policy, value) weights of Eq. 17 (alpha_p, alpha_v) and Eq. 20 (beta_p, beta_v)."""

PRESETS: dict[str, dict[str, object]] = {
    "paper": {
        "kl_form": "paper",
        "ratio_against": "reference",
        "likelihood": "mean",
        "score_every": 3,
        "gae_lambda": 0.0,
        "value_target": "reward",
        "adv_norm": "none",
        "reward_clip": None,
        "clip": 0.2,
        "value_clip": 0.2,
    },
}
"""Overrides of ``FinetuneConfig`` per preset; the policy/value weights follow the method."""


def preset_overrides(preset: str, method: str) -> list[str]:
    """``key=value`` overrides (for ``config.load_config``) of a preset and method."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; choose {', '.join(PRESETS)}")
    if method not in PAPER_WEIGHTS:
        raise ValueError(f"unknown method {method!r}; choose {', '.join(PAPER_WEIGHTS)}")
    pw, vw = PAPER_WEIGHTS[method]
    values = {**PRESETS[preset], "method": method, "policy_weight": pw, "value_weight": vw}
    return [f"finetune.{k}={'null' if v is None else v}" for k, v in values.items()]
