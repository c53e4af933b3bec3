"""Regenerate the README's generated tables (results, selection, peers, cost, planner) from
benchmarks/results/*.json and the records beside them.

python benchmarks/update_readme.py            # rewrite README.md's generated blocks
python benchmarks/update_readme.py --check    # exit 1 if README.md would change (writes nothing)
"""

from __future__ import annotations

import argparse
import difflib
import json
import sys
import tempfile
from pathlib import Path

from planner_latency import CALLS
from row_hashes import timed_weights, untraceable
from zoo_index import portable_command

from trajpref.results import (
    ANCESTRAL_SUFFIX,
    METHODS,
    RETIRED_STARTS,
    ROW_KEY,
    accuracy_table,
    base_method,
    peers_notes,
    peers_table,
    read_rows,
    selection_table,
    update_readme,
)

ROOT = Path(__file__).resolve().parent.parent
ZOO = ROOT / "src" / "trajpref" / "zoo"
"""The published files (``models/`` links here), by the path git tracks them under."""


EQUAL_BUDGET = ("pretrained", "control", "rlhf", "rlhf-res", "rlhf-set")
"""The equal-budget table's start and methods, as the README shows them."""


def _latest_equal_budget(row: dict, current: set[tuple[str, str]]) -> bool:
    """Whether an ``-ancestral`` row belongs to the latest equal-budget table of its dataset:
    one of the table's methods (or its start), on a dataset where no run of those methods from
    a later generator (today's default or a retired one, ``RETIRED_STARTS``) has rows yet."""
    base = base_method(row["method"])
    newer = any((row["dataset"], m + s) in current
                for m in EQUAL_BUDGET[1:] for s in ("", *RETIRED_STARTS))  # fmt: skip
    had = any((row["dataset"], m + ANCESTRAL_SUFFIX) in current for m in EQUAL_BUDGET[1:])
    return base in EQUAL_BUDGET and had and not newer


def without_superseded(rows: list[dict]) -> list[dict]:
    """``rows`` less those that a re-measurement supersedes: a row without a ``model_hash``
    whose checkpoint file is gone (``row_hashes.untraceable``: ``models/eth/generator.pt`` of
    2026-11-22, replaced by the ``.safetensors`` files on 2026-11-23) beside a row of the same
    measurement (``ROW_KEY``) that names a hash. ``merge_rows`` fills each field from the
    first row that has it, so the undigested row's numbers would stand beside the
    re-measurement's (eth's full-sampler line showed the minADE of 2026-11-22 and the maxATS
    of 2026-12-06)."""
    hashed = {tuple(r[k] for k in ROW_KEY) for r in rows if r.get("model_hash")}
    return [r for r in rows
            if not (untraceable(r) and tuple(r[k] for k in ROW_KEY) in hashed)]  # fmt: skip


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Regenerate the README's generated tables (between its <!-- name:start --> "
        "and <!-- name:end --> markers) from benchmarks/results/*.json, benchmarks/peers.json, "
        "benchmarks/selection_chosen.json and benchmarks/results/meta/; prints each table. "
        "Without options it rewrites README.md.",
    )
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 (printing the difference) when the README "
                        "would change, 0 when it is up to date")  # fmt: skip
    parser.add_argument("--readme", type=Path, default=ROOT / "README.md",
                        help="the README to update or check (default: the repository's "
                        "README.md)")  # fmt: skip
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Rewrite the README's generated blocks (0), or with ``--check`` compare them with what
    the records give, writing nothing: 0 when they match, 1 otherwise."""
    args = parse_args(argv)
    readme = args.readme
    if not args.check:
        regenerate(readme)
        return 0
    before = readme.read_text()
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / readme.name
        copy.write_text(before)
        regenerate(copy, show=False)
        after = copy.read_text()
    if after == before:
        print(f"{readme} is up to date")
        return 0
    diff = difflib.unified_diff(before.splitlines(), after.splitlines(), f"{readme} (now)",
                                f"{readme} (regenerated)", lineterm="", n=0)  # fmt: skip
    sys.stdout.writelines(line + "\n" for line in diff)
    print(f"{readme} would change: run python benchmarks/update_readme.py to rewrite it")
    return 1


def regenerate(readme: Path, show: bool = True) -> None:
    """Replace the generated blocks of ``readme``; ``show``: print each table."""
    out = print if show else (lambda *_: None)
    every = without_superseded(read_rows(ROOT / "benchmarks" / "results"))
    # the README keeps the methods users run (also from the longer published generators,
    # ``control-long``); fine-tuning ablations (tagged runs) are listed in docs/rlhf_results*.md.
    # Rows of the generators of before 2026-11-24 (``-ancestral``) stay only where they are
    # the latest equal-budget table: its methods and their start, on the datasets where the
    # table has no rows from a newer start yet
    current = {(r["dataset"], r["method"]) for r in every}
    # The fine-tuning runs from a replaced default (``RETIRED_STARTS``) are in the reports
    # only; the replaced defaults' own rows (``pretrained-tau5``) stay beside today's
    rows = [r for r in every if (base_method(r["method"]) in METHODS
                                 or r["method"].startswith("pretrained-"))
            and (not r["method"].endswith(ANCESTRAL_SUFFIX)
                 or _latest_equal_budget(r, current))
            and (not r["method"].endswith(RETIRED_STARTS)
                 or r["method"].startswith("pretrained-"))]  # fmt: skip
    selected = [r for r in every if r["method"].startswith("select-")]
    dates = sorted({r["date"] for r in rows})
    machines = sorted({r["machine"] for r in rows})
    table = accuracy_table(rows, protocol="all")
    note = (
        f"\n\n_Generated by `python benchmarks/update_readme.py` from "
        f"`benchmarks/results/*.json` ({sum(r['protocol'] == 'all' for r in rows)} rows; "
        f"{len(every) - len(rows) - len(selected)} more rows, fine-tuning ablations and the "
        f"runs from the generators of before 2026-11-24 (suffix `-ancestral`), are in "
        f"[docs/rlhf_results.md](docs/rlhf_results.md), its frozen predecessor "
        f"[docs/rlhf_results_2026-11-23.md](docs/rlhf_results_2026-11-23.md) and "
        f"[docs/rlhf.md](docs/rlhf.md); measured "
        f"{', '.join(dates)} on {'; '.join(machines)}). Units: metres, except SDD in pixels._"
    )
    update_readme(readme, "results", table + note)
    out(table)
    if selected:
        chosen_file = ROOT / "benchmarks" / "selection_chosen.json"
        chosen = json.loads(chosen_file.read_text()) if chosen_file.exists() else None
        table = selection_table(selected, chosen=chosen)
        note = (
            "\n\n_Generated by `python benchmarks/update_readme.py` from "
            "`benchmarks/results/select_*.json` (test splits, K = 20 candidates of the default "
            "generator, or of the published variant in brackets, scored by its own denoiser; "
            "settings chosen on the validation splits, "
            "[docs/selection.md](docs/selection.md)). minFDE per agent, mean over the seeds; "
            "the change is taken within each seed, mean ± std. The published samplers are "
            "deterministic (posterior-mean steps), so every seed selects from the same 20 "
            "samples and only `random` differs: the ± is 0 by construction, not a measured "
            "spread. The joint column selects one set of indices per scene: `trajpref "
            "evaluate` gives it with `--select-per scene` beside the row's options (without "
            "it, the joint numbers it prints are of the per-agent selections). ms/scene is "
            "the mean over the seeds' runs, some of which shared the machine with training; "
            "the cost bar is measured alone by `benchmarks/selection_cost.py`._"
        )
        update_readme(readme, "selection", table + note)
        out(table)
    peers = json.loads((ROOT / "benchmarks" / "peers.json").read_text())
    table = peers_table(peers, every, methods=("pretrained", "pretrained-long"))
    note = (
        "\n\n_Generated by `python benchmarks/update_readme.py` from `benchmarks/peers.json` "
        "and the `pretrained` rows of `benchmarks/results/*.json` (the CPU default config of "
        "each fold on 2 CPU cores; the configs now cap the two stages at 45 minutes in all "
        "(`max_minutes`), but the published weights were trained without that guard (their "
        "cards' commands lift it), often beside other jobs: the cost table gives their minutes "
        "as run and as estimated alone) and the `pretrained-long` rows (longer generator "
        "schedules trained on a borrowed GPU, published beside the defaults until they were "
        "superseded on validation; their weights are in the git history; robo's is 60 epochs, "
        f"the ETH/UCY folds' 160). {peers_notes(peers)}_"
    )
    update_readme(readme, "peers", table + note)
    out(table)
    table = accuracy_table(rows, protocol="sgan")
    update_readme(readme, "results-sgan", table)
    out(table)
    speed = speed_table(ROOT / "benchmarks" / "results" / "meta", zoo_dir=ZOO)
    update_readme(readme, "speed", speed)
    out(speed)
    planner = planner_table(ROOT / "benchmarks" / "results" / "meta" / "planner_latency_zara1.json")
    if planner is not None:
        update_readme(readme, "planner", planner)
        out(planner)


PLANNER_HEADERS = (
    "`predict_scene`",
    "`rank_samples`, 34 steps",
    "rank, `with_steps([0])`",
    "`select_for_scene`, default (12 steps)",
    "`chosen_selection` (34)",
    "`chosen_selection(cheap=True)` (1)",
    '`method="facility"` (no score)',
)
"""The README's header of each planner call, in ``planner_latency.CALLS`` order."""
PLANNER_COLUMNS = tuple(zip(CALLS, PLANNER_HEADERS, strict=True))
"""The planner calls' columns: the record's key (``planner_latency.CALLS``) and the README's
header."""


def planner_table(path: Path) -> str | None:
    """The README's table of what each planning call costs, from
    ``benchmarks/planner_latency.py``'s record (None when there is none)."""
    if not path.is_file():
        return None
    rec = json.loads(path.read_text())
    lines = ["| P | " + " | ".join(head for _, head in PLANNER_COLUMNS) + " |",
             "|---|" + "---|" * len(PLANNER_COLUMNS)]  # fmt: skip
    for row in rec["rows"]:
        cells = " | ".join(f"{row[key]:.1f}" for key, _ in PLANNER_COLUMNS)
        lines.append(f"| {row['agents']} | {cells} |")
    ratio = [row["rank_34"] / row["predict_scene"] for row in rec["rows"]]
    cheap = [row["chosen_cheap"] / row["predict_scene"] for row in rec["rows"]]
    lines += ["", (
        f"_Generated by `python benchmarks/update_readme.py` from `{path.name}`: "
        f"`{portable_command(rec['command'])}`, {rec['date']}, {rec['machine']}; "
        f"{rec['dataset']}/generator and "
        f"{rec['dataset']}/denoiser, K = {rec['samples']}, `select` keeps {rec['keep']}, "
        f"median of {rec['calls']} interleaved calls per size after a warm-up call, on the "
        f"first agents of a {rec['split']} scene. The 34-step score costs "
        f"{min(ratio):.0f}-{max(ratio):.0f}x the prediction; the cheap chosen setting "
        f"{min(cheap):.1f}-{max(cheap):.1f}x._")]  # fmt: skip
    return "\n".join(lines)


def speed_table(meta_dir: Path, zoo_dir: Path | None = None) -> str:
    """Training cost and parameters from meta/pretrained_*.json (default configs); sampler
    latency and the full / leapfrog ratio from meta/speed.json (every published generator,
    timed side by side in one run by benchmarks/speed.py) where it has the model, else from
    the training run's own timing (marked *). With ``zoo_dir`` (the published files), each
    timed row is checked against its file (``timed_weights``): latencies of weights the file
    no longer holds are marked †, and the rows nothing can check are named as unknown."""
    speed_path = meta_dir / "speed.json"
    speed = json.loads(speed_path.read_text()) if speed_path.is_file() else {"models": {}}
    timed = speed["models"]
    checked = ({name: timed_weights(name, t, speed_path, zoo_dir) for name, t in timed.items()}
               if zoo_dir is not None else {})  # fmt: skip
    cost_path = meta_dir / "train_cost.json"
    cost_run = json.loads(cost_path.read_text()) if cost_path.is_file() else {"datasets": {}}
    estimates = cost_run["datasets"]
    repeat_path = meta_dir / "train_cost_repeat.json"  # a longer probe of some configs
    repeat = json.loads(repeat_path.read_text()) if repeat_path.is_file() else {"datasets": {}}
    lines = [
        "| model | params D / G | train D / G (min), as run | train D + G (min), estimated "
        "alone | samples/s D / G | leapfrog ms/scene | full ms/scene | full / leapfrog "
        "| score K=20 ms/scene |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    defaults = {}
    used_repeat = False  # whether any row shows the repeat probe in brackets
    for path in sorted(meta_dir.glob("pretrained_*.json")):
        m = json.loads(path.read_text())
        # only the default's own record: variants (trained elsewhere or off the default
        # config) and the records of replaced defaults (``pretrained_<D>_raw.json``, ...)
        # carry a suffix after the dataset's name
        if not m.get("variant") and path.stem == f"pretrained_{m['dataset']}":
            defaults[f"{m['dataset']}/generator"] = m
    for name in sorted(set(defaults) | set(timed)):
        m, t = defaults.get(name), timed.get(name)
        score_path = meta_dir / f"score_{name.split('/')[0]}.json"
        score_ms = (json.loads(score_path.read_text())["ms_to_rank_k_samples_per_scene"]
                    if score_path.is_file() and m is not None else None)  # fmt: skip
        est = estimates.get(name.split("/")[0]) if m is not None else None
        guess = "–" if est is None else f"{est['minutes']:.1f}"
        again = repeat["datasets"].get(name.split("/")[0]) if est is not None else None
        if again is not None and est.get("date", cost_run["date"]) > repeat["date"]:
            again = None  # the repeat probed an older config than the estimate
        used_repeat = used_repeat or again is not None
        guess += "" if again is None else f" ({again['minutes']:.1f})"
        if m is not None:
            p, secs, r = m["params"], m["stage_seconds"], m["samples_per_second"]
            cost = (f"{p['denoiser'] / 1e6:.2f} M / {p['generator'] / 1e6:.2f} M "
                    f"| {secs['denoiser'] / 60:.1f} / {secs['generator'] / 60:.1f} | {guess} "
                    f"| {r['denoiser']:.0f} / {r['generator']:.0f}")  # fmt: skip
        else:
            cost = "– | – | – | –"
        if t is not None:
            mark = "†" if checked.get(name, ("",))[0] == "other" else ""
            ms = (f"{t['leapfrog_ms_per_scene']:.1f}{mark} | {t['full_ms_per_scene']:.1f}{mark} "
                  f"| {t['full_over_leapfrog']:.1f}x{mark}")  # fmt: skip
        else:
            ms = (f"{m['ms_per_scene']['leapfrog']:.1f}* | {m['ms_per_scene']['full']:.1f}* "
                  f"| {m['speedup_full_over_leapfrog']:.1f}x*")  # fmt: skip
        score = "–" if score_ms is None else f"{score_ms:.1f}"
        lines.append(f"| {name} | {cost} | {ms} | {score} |")
    if estimates:
        lines.append("")
        lines.append(
            f"_Estimated minutes: `{portable_command(cost_run['command'])}`, {cost_run['date']}, "
            f"{cost_run['machine']}: each stage's throughput and one validation pass, measured "
            f"alone {_probe(cost_run['datasets'], cost_run)}, times the config's epochs and "
            "evaluations." + _older(estimates, cost_run) + "_"
        )
    if used_repeat:
        lines.append("")
        lines.append(
            f"_In brackets: a longer probe right after, `{portable_command(repeat['command'])}`, "
            f"{repeat['date']}: the same estimate from more timed steps. The two differ by up to "
            "20 % on this machine, whose speed drifts from hour to hour (and by 2x from day to "
            "day), so a config estimated within a few minutes of 45 sits at the budget's edge._"
        )
    if timed:
        lines.append("")
        lines.append(
            f"_Latencies: `{portable_command(speed['command'])}`, {speed['date']}, "
            f"{speed['machine']}; "
            f"{speed['samples']} samples, the same test scenes for both samplers."
            + _weights_note(checked, timed)
            + "_"
        )
    scored = sorted(name.split("/")[0] for name in defaults
                    if (meta_dir / f"score_{name.split('/')[0]}.json").is_file())  # fmt: skip
    if scored:
        lines.append("")
        lines.append(_score_note(meta_dir, scored))
    return "\n".join(lines)


def _weights_note(checked: dict[str, tuple[str, str]], timed: dict) -> str:
    """The latency note's sentences on which weights were timed (``timed_weights``)."""
    if not checked:
        return ""
    other = sorted(n for n, (s, _) in checked.items() if s == "other")
    unknown = sorted(n for n, (s, _) in checked.items() if s == "unknown")
    if all(t.get("model_hash") for t in timed.values()):
        out = " The record names each model's weights hash: each is its file's today"
    else:
        some = "any" if not any(t.get("model_hash") for t in timed.values()) else "some"
        out = (f" The record names no weights hash for {some} model (`benchmarks/speed.py` "
               "records it since 2026-12-06); traced through git, the files committed with it "
               "are today's")  # fmt: skip
    if other:
        out += (f", except † {' and '.join(f'`{n}` ({checked[n][1]})' for n in other)}: those "
                "latencies timed the weights that file held before, and the record must be "
                "measured again (as a whole, so that its rows compare)")  # fmt: skip
    if unknown:
        out += (f"; unknown for {' and '.join(f'`{n}` ({checked[n][1]})' for n in unknown)}, "
                "not checked against its file")  # fmt: skip
    return out + "."


def _score_note(meta_dir: Path, datasets: list[str]) -> str:
    """Where the score column comes from: ``benchmarks/score.py``'s timing of one ranking of
    K = 20 samples per scene (``meta/score_<D>.json``), with the date, machine and command of
    the same run's rows (``score_<D>.json`` beside ``meta/``), one group per run setting."""
    groups: dict[tuple, list[str]] = {}
    for d in datasets:
        meta = json.loads((meta_dir / f"score_{d}.json").read_text())
        rows_path = meta_dir.parent / f"score_{d}.json"
        rows = json.loads(rows_path.read_text()) if rows_path.is_file() else []
        row = next((r for r in rows if r.get("method") == "pretrained"), None) or {}
        command = (row.get("command") or "").replace(f"--dataset {d}", "--dataset <D>")
        key = (command, row.get("date"), row.get("machine"), meta.get("timing_scenes"),
               meta.get("timing_threads"))  # fmt: skip
        groups.setdefault(key, []).append(d)
    parts = []
    for (command, day, machine, scenes, threads), names in groups.items():
        where = (f"`{command}`, {day}, {machine}" if command else
                 "date, machine and command not recorded")  # fmt: skip
        parts.append(f"{', '.join(names)}: {where} ({scenes} test scenes, {threads} threads)")
    return (
        "_Score K=20: the time to rank the K = 20 samples of one scene with the dataset's "
        "denoiser at the paper's 34 score steps, timed by `benchmarks/score.py` in its own run "
        "(`benchmarks/results/meta/score_<D>.json`; the date and machine are those of the same "
        "run's rows in `benchmarks/results/score_<D>.json`), not beside the latencies: "
        + "; ".join(parts)
        + "._"
    )


def _probe_label(entry: dict) -> str:
    """How an estimate was probed: warm (after N untimed short epochs) or cold (entries
    written before the probe was recorded were cold)."""
    warm = entry.get("probe", {}).get("warm", 0)
    return f"after {warm} untimed warm-up epochs" if warm else "in a cold probe"


def _probe(estimates: dict, run: dict) -> str:
    """The probe of the entries that ``run`` itself measured."""
    own = [e for e in estimates.values() if e.get("date", run["date"]) == run["date"]]
    labels = sorted({_probe_label(e) for e in own}) or [_probe_label({})]
    return " / ".join(labels)


def _older(estimates: dict, run: dict) -> str:
    """A note naming the datasets whose estimate comes from an earlier run than ``run``, with
    the machine and probe of each where they differ from ``run``'s."""
    by_date: dict[tuple[str, str], list[str]] = {}
    probe = _probe(estimates, run)
    for name, entry in estimates.items():
        if entry.get("date", run["date"]) != run["date"]:
            how = [] if entry.get("machine", run["machine"]) == run["machine"] else [
                f"on {entry['machine']}"]  # fmt: skip
            if _probe_label(entry) != probe:
                how.append(_probe_label(entry))
            key = (entry["date"], f" ({', '.join(how)})" if how else "")
            by_date.setdefault(key, []).append(name)
    parts = [f"{', '.join(sorted(names))} from {day}{how}"
             for (day, how), names in sorted(by_date.items())]  # fmt: skip
    return f" Kept from earlier runs of the same script: {'; '.join(parts)}." if parts else ""


if __name__ == "__main__":
    sys.exit(main())
