"""The RLHF report: test accuracy of every fine-tuning method against its own pretrained start
(mean +- std over seeds, relative change), the training diagnostics of the runs behind them,
and the reward-alignment study. Reads benchmarks/results/{pretrained,finetune}_*.json, the
run folders runs/<dataset>-<method>-s<seed>[-<tag>]/finetune_metrics.jsonl and
benchmarks/results/meta/reward_alignment_*.json; writes docs/rlhf_results.md.

    python benchmarks/finetune_report.py --datasets zara1 eth robo
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from trajpref.results import (
    ANCESTRAL_SUFFIX,
    FINETUNE_START,
    RETIRED_STARTS,
    finetune_start,
    merge_rows,
    read_rows,
    table_lines,
)
from trajpref.train import read_metrics

ROOT = Path(__file__).resolve().parent.parent
START_ORDER = tuple(FINETUNE_START + s for s in (ANCESTRAL_SUFFIX, *RETIRED_STARTS, "", "-long"))
"""The accuracy table's groups, oldest start first: the generators of before 2026-11-24, the
later defaults that were replaced, today's default, then its longer sibling."""
RUN_SUFFIX = {"rlhf": "rlhf", "rlhf-res": "rlhf-res", "rlhf-res-reg-only": "rlhf-res"}


def _ms(xs: list[float], digits: int = 3) -> str:
    """mean +- std (sample std) of xs, or the single value."""
    if not xs:
        return "–"
    if len(xs) == 1:
        return f"{xs[0]:.{digits}f}"
    return f"{statistics.mean(xs):.{digits}f} ± {statistics.stdev(xs):.{digits}f}"


def _col(rows: list[dict], key: str) -> list[float]:
    return [r[key] for r in rows if r[key] is not None]


def _at(logs: list[list[dict]], i: int, key: str) -> list[float]:
    """``key`` of the i-th logged epoch of every run that logged it."""
    return [lg[i][key] for lg in logs if key in lg[i]]


def _pct(new: float, old: float) -> str:
    return f"{100 * (new - old) / old:+.1f} %"


def _start(rows: list[dict], dataset: str, method: str) -> dict | None:
    """The test row of the start a fine-tuning method's runs began from (as they sampled it:
    ``pretrained-ancestral`` for the rows of before 2026-11-24, ``pretrained`` since)."""
    key = (dataset, finetune_start(method), "test")
    return next((r for r in rows if (r["dataset"], r["method"], r["split"]) == key), None)


def _log(run: Path) -> list[dict]:
    """A run's finetune_metrics.jsonl, one dict per epoch ([] when missing)."""
    return read_metrics(run, "finetune")


def _best_epochs(logs: list[list[dict]]) -> str:
    return ", ".join(
        str(max((e["epoch"] for e in lg if e.get("best")), default=None)) for lg in logs
    )


def accuracy_section(rows: list[dict], datasets: list[str]) -> tuple[str, dict]:
    lines = [
        "| dataset | method | seeds | minADE | minFDE | ADE vs start | FDE vs start "
        "| joint minADE / minFDE | maxATS / maxFTS | fine-tune s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    fde_change: dict[str, dict[str, float]] = {}
    for d in datasets:
        tuned = {r["method"] for r in rows if r["dataset"] == d
                 and r["method"].startswith("rlhf") and r["split"] == "test"}  # fmt: skip
        for start in sorted({finetune_start(m) for m in tuned}, key=START_ORDER.index):
            methods = sorted(m for m in tuned if finetune_start(m) == start)
            s = _start(rows, d, methods[0])
            if s is None:
                continue
            lines.append(
                f"| {d} | {s['method']} (start) | 1 | {s['min_ade']:.3f} | {s['min_fde']:.3f} "
                f"| – | – | {s['joint_min_ade']:.3f} / {s['joint_min_fde']:.3f} "
                f"| {_ms(_col([s], 'max_ats'))} / {_ms(_col([s], 'max_fts'))} | – |"
            )
            for m in methods:
                g = [r for r in rows if (r["dataset"], r["method"], r["split"]) == (d, m, "test")]
                ade, fde = [r["min_ade"] for r in g], [r["min_fde"] for r in g]
                fde_change.setdefault(m, {})[d] = statistics.mean(fde) / s["min_fde"] - 1
                lines.append(
                    f"| {d} | {m} | {len(g)} | {_ms(ade)} | {_ms(fde)} "
                    f"| {_pct(statistics.mean(ade), s['min_ade'])} "
                    f"| {_pct(statistics.mean(fde), s['min_fde'])} "
                    f"| {_ms(_col(g, 'joint_min_ade'))} / {_ms(_col(g, 'joint_min_fde'))} "
                    f"| {_ms(_col(g, 'max_ats'))} / {_ms(_col(g, 'max_fts'))} "
                    f"| {_ms(_col(g, 'train_seconds'), 0)} |"
                )
    return "\n".join(lines), fde_change


DIAGNOSTICS = "## Training diagnostics of the same runs (mean ± std over seeds)"
REWARD = "## Can fine-tuning raise the reward, and what does that cost? (validation)"


def still_current(
    before: dict[tuple[str, str], str], rows: list[dict]
) -> dict[tuple[str, str], str]:
    """The reward-section lines of ``before`` whose test minFDE cell is still what today's
    test rows of that (dataset, method) give: a line of runs that a new default retired (whose
    rows were renamed, and whose method name today's runs reuse) is not carried over."""
    out = {}
    for (d, method), line in before.items():
        fde = [r["min_fde"] for r in rows if r["dataset"] == d and r["split"] == "test"
               and r["method"] == method]  # fmt: skip
        if fde and f"| {_ms(fde)} (" in line:
            out[d, method] = line
    return out


def _run_dirs(dataset: str, method: str) -> list[Path]:
    tag = "-reg-only" if method.endswith("-reg-only") else ""
    return sorted((ROOT / "runs").glob(f"{dataset}-{RUN_SUFFIX[method]}-s[0-9]{tag}"))


def diagnostics_section(datasets: list[str], before: dict[tuple[str, str], str]) -> str:
    """One line per (dataset, method) whose run folders are here; ``before``'s line where
    none is (``table_lines`` of the last report: a new checkout has no
    ``runs/``, and regenerating the report must not drop its lines)."""
    lines = [
        "| dataset | method | runs | reward, epoch 1 -> last | KL to G_0 (last) "
        "| critic explained variance (last) | val minFDE, epoch 1 -> last | best epoch |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for d in datasets:
        for m in RUN_SUFFIX:
            logs = [lg for lg in map(_log, _run_dirs(d, m)) if lg]
            if not logs:
                lines.extend([before[d, m]] if (d, m) in before else [])
                continue
            lines.append(
                f"| {d} | {m} | {len(logs)} | {_ms(_at(logs, 0, 'train_reward'))} -> "
                f"{_ms(_at(logs, -1, 'train_reward'))} "
                f"| {_ms(_at(logs, -1, 'train_kl_to_reference'), 2)} "
                f"| {_ms(_at(logs, -1, 'train_explained_variance'))} "
                f"| {_ms(_at(logs, 0, 'val_min_fde'))} -> {_ms(_at(logs, -1, 'val_min_fde'))} "
                f"| {_best_epochs(logs)} |"
            )
    return "\n".join(lines)


def _settings(command: str) -> str:
    """The --preset / --set part of a benchmark command, short."""
    words, out = command.split(), []
    for flag, value in zip(words, words[1:], strict=False):
        if flag == "--preset":
            out.append(f"preset {value}")
        elif flag == "--set":
            out.append(value.removeprefix("finetune."))
    return ", ".join(out) or "defaults"


def reward_section(
    rows: list[dict], datasets: list[str], before: dict[tuple[str, str], str] | None = None
) -> str:
    """Runs that logged meanATS on validation: does fine-tuning raise the reward, and what
    does that do to accuracy? meanATS is the average sample's ATS, the quantity the policy
    gradient pushes up. A method whose run folders are not here keeps ``before``'s line."""
    before = before or {}
    meta = ROOT / "benchmarks" / "results" / "meta"
    lines = [
        "| dataset | run | settings | seeds | steps | val meanATS: start -> epoch 1 -> last (max) "
        "| val maxATS start -> last | val minFDE start -> last | best epoch | test minFDE "
        "(vs start) | machine |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for d in datasets:
        start_path, start = meta / f"finetune_start_{d}.json", _start(rows, d, "rlhf")
        if not start_path.is_file() or start is None:
            continue
        v0, t0 = json.loads(start_path.read_text())["val"], start["min_fde"]
        # the run folders hold today's runs only: the older rows' folders are gone (and their
        # names are today's), so those rows are left to docs/rlhf_results_2026-11-23.md
        tuned = [r for r in rows if r["dataset"] == d and r["split"] == "test"
                 and r["method"].startswith("rlhf")
                 and not r["method"].endswith(ANCESTRAL_SUFFIX)]  # fmt: skip
        for method in sorted({r["method"] for r in tuned}):
            base = "rlhf-res" if method.startswith("rlhf-res") else "rlhf"
            tag = method.removeprefix(base).lstrip("-")
            runs, steps = [], []
            for r in sorted((r for r in tuned if r["method"] == method), key=lambda r: r["seed"]):
                log = _log(ROOT / "runs" / f"{d}-{base}-s{r['seed']}{'-' + tag if tag else ''}")
                # the validated epochs (validation by the budget clock skips some epochs)
                validated = [e for e in log or [] if "val_mean_ats" in e]
                if validated:
                    runs.append((r, validated))
                    steps.append(log[-1]["step"])
            if not runs:
                lines.extend([before[d, method]] if (d, method) in before else [])
                continue
            logs = [lg for _, lg in runs]
            r0 = runs[0][0]
            peak = [max(e["val_mean_ats"] for e in lg) for lg in logs]
            fde = [r["min_fde"] for r, _ in runs]
            gpu = "GPU" if "NVIDIA" in r0["machine"] else "CPU"
            lines.append(
                f"| {d} | {method} | {_settings(r0['command'] or '')} | {len(runs)} "
                f"| {steps[0]} | {v0['mean_ats']:.3f} -> "
                f"{_ms(_at(logs, 0, 'val_mean_ats'))} -> {_ms(_at(logs, -1, 'val_mean_ats'))} "
                f"({_ms(peak)}) | {v0['max_ats']:.3f} -> {_ms(_at(logs, -1, 'val_max_ats'))} "
                f"| {v0['min_fde']:.3f} -> {_ms(_at(logs, -1, 'val_min_fde'))} "
                f"| {_best_epochs(logs)} "
                f"| {_ms(fde)} ({_pct(statistics.mean(fde), t0)}) | {gpu} |"
            )
    return "\n".join(lines)


def alignment_section(datasets: list[str]) -> str:
    meta = ROOT / "benchmarks" / "results" / "meta"
    lines = [
        "| dataset | model | agents | Spearman(reward, -ADE) / (-FDE) | Spearman(reward, "
        "distance travelled) | FDE: reward's top / mean / best sample | minFDE top-5 by "
        "reward / 5 random | minFDE top-10 / 10 random | mean reward | endpoint spread "
        "| minADE / minFDE (K=20) | reward variance: share of the action / of the denoising "
        "noise |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for d in datasets:
        for path in sorted(meta.glob(f"reward_alignment_{d}*.json")):
            a = json.loads(path.read_text())
            name = path.stem.removeprefix(f"reward_alignment_{d}").lstrip("_") or "pretrained"
            lines.append(
                f"| {d} | {name} | {a['agents']} | {a['rho_reward_neg_ade']:.2f} / "
                f"{a['rho_reward_neg_fde']:.2f} | {a['rho_reward_travelled']:.2f} "
                f"| {a['fde_top_reward']:.3f} / {a['fde_mean_sample']:.3f} / "
                f"{a['fde_best_sample']:.3f} | {a['min_fde_top5_by_reward']:.3f} / "
                f"{a['min_fde_random5']:.3f} | {a['min_fde_top10_by_reward']:.3f} / "
                f"{a['min_fde_random10']:.3f} | {a['reward_mean']:.2f} "
                f"| {a['endpoint_spread']:.3f} | {a['min_ade']:.3f} / {a['min_fde']:.3f} "
                f"| {100 * a['share_action']:.1f} % / {100 * a['share_denoising_noise']:.1f} % |"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["zara1", "eth", "robo"])
    args = parser.parse_args()
    rows = merge_rows(read_rows(ROOT / "benchmarks" / "results", protocol="all"))
    out = ROOT / "docs" / "rlhf_results.md"
    old = out.read_text() if out.is_file() else ""
    current = still_current(table_lines(old, REWARD), rows)  # runs not retired since
    acc, change = accuracy_section(rows, args.datasets)
    avg = {
        m: statistics.mean(v.values()) for m, v in change.items() if len(v) == len(args.datasets)
    }
    summary = ", ".join(f"{m} {100 * v:+.1f} %" for m, v in sorted(avg.items()))
    text = "\n\n".join([
        "# RLHF results (generated)",
        "_Generated by `python benchmarks/finetune_report.py` from `benchmarks/results/` and "
        "the run folders of `benchmarks/finetune.py`; the commands and their reading are in "
        "[rlhf.md](rlhf.md). The two diagnostic tables keep, as they were, the lines of runs "
        "whose folders were not on the machine that regenerated this page._",
        "## Test accuracy against the pretrained start (K = 20, per agent unless joint)",
        acc,
        f"Mean relative change of minFDE20 over {', '.join(args.datasets)} (methods run on all "
        f"of them): {summary or '–'}.",
        DIAGNOSTICS,
        "`reward` is the mean clipped per-step score r over the epoch's rollouts; `KL to G_0` "
        "the k3 estimate per sample; explained variance of the critic against its target.",
        diagnostics_section(args.datasets, {k: v for k, v in table_lines(old, DIAGNOSTICS)
                                            .items() if k in current}),
        REWARD,
        "Runs that log meanATS (the average sample's ATS on the validation scenes, the "
        "quantity the policy gradient pushes up; `start` is the pretrained generator, "
        "`benchmarks/results/meta/finetune_start_<dataset>.json`). The model kept is the best "
        "epoch by validation minADE + minFDE; `settings` are the run's `--set` overrides of "
        "the defaults.",
        reward_section(rows, args.datasets, current),
        "## Is the reward worth maximising? (`benchmarks/reward_alignment.py`, validation)",
        "Per agent over its 20 samples, averaged over agents; reward = the summed clipped "
        "score that fine-tuning maximises.",
        alignment_section(args.datasets),
    ])  # fmt: skip
    out.write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
