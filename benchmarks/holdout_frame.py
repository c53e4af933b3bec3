"""The agent frame of each ETH/UCY fold, chosen on a held-out training location.

    python benchmarks/holdout_frame.py --folds univ zara1 eth zara2 hotel --workers 2 \
        --data-root ../shared/data
    python benchmarks/holdout_frame.py --report      # the table only, from the record
    python benchmarks/holdout_frame.py --temporal --folds univ zara1 --data-root ../shared/data

The rule (fixed before the runs) is in docs/pretraining.md, "The agent frame re-decided on a
held-out training location". Per fold, one location of its training split is held out
(``data.holdout_scene``): hotel (``biwi_hotel``) on every fold but hotel's, Zara
(``crowds_zara``) on hotel's. Three jobs per fold, each one ``trajpref train`` process on one
thread, seed 0, the fold's config otherwise:

- ``denoiser``: the diffusion stage without the held-out location;
- ``scene`` and ``heading``: the generator stage from that denoiser with
  ``model.agent_frame=scene`` / ``heading``, its checkpoint chosen on the held-out location.

A finished job (its metrics reached the config's last epoch) is skipped when the script runs
again, and an interrupted one resumes from its ``<stage>_last.pt``. When both generators of a
fold exist, each is measured by ``trajpref evaluate --split val --holdout-scene H`` (K = 20,
seed 0) and the fold's row is written to ``benchmarks/results/meta/holdout_frame_val.json``:
the frame with the lower held-out minFDE20 wins, with no margin. No test split is read.

``--temporal`` runs the next study on the folds whose frame is decided: one more generator
per fold (``<frame>-temporal``: the chosen frame with ``model.history_encoder=temporal``, from
the same held-out denoiser), adopted where its held-out minFDE20 is at least 1 % below the
chosen frame's run (docs/pretraining.md, "a temporal history encoder").
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import subprocess
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

from trajpref.config import load_config
from trajpref.io import write_json
from trajpref.results import command_line, machine, update_readme
from trajpref.train import read_metrics
from trajpref.train.run import STAGE_NAMES, last_state_path

ROOT = Path(__file__).resolve().parent.parent
FOLDS = ("univ", "zara1", "eth", "zara2", "hotel")
"""The ETH/UCY folds, in the order the rule runs them."""
HELD_OUT = {"eth": "biwi_hotel", "univ": "biwi_hotel", "zara1": "biwi_hotel",
            "zara2": "biwi_hotel", "hotel": "crowds_zara"}  # fmt: skip
"""The training location each fold holds out (a file-name prefix of its training split)."""
FRAMES = ("scene", "heading")
RECORD = ROOT / "benchmarks" / "results" / "meta" / "holdout_frame_val.json"
DOC = ROOT / "docs" / "pretraining.md"
"""Its tables' block (``holdout-frame``) is rewritten from the record on every run."""
KNOWN = ROOT / "benchmarks" / "results" / "meta" / "frame_known.json"
"""The models trained on every scene: file-level validation and test (context for --plot)."""


def run_dir(fold: str, job: str, runs: Path) -> Path:
    return runs / fold / job


def stage_of(job: str) -> str:
    """The ``trajpref train`` stage of a job: ``diffusion`` for the denoiser, else ``generator``."""
    return "diffusion" if job == "denoiser" else "generator"


def job_command(fold: str, job: str, runs: Path, data_root: str | None) -> list[str]:
    """The ``trajpref train`` command of one job (``--resume`` when a state is there)."""
    stage = stage_of(job)
    out = run_dir(fold, job, runs)
    cmd = [sys.executable, "-m", "trajpref.cli", "train", stage, "--config",
           str(ROOT / "configs" / f"{fold}.yaml"), "--out", str(out),
           "--set", f"data.holdout_scene={HELD_OUT[fold]}", "--no-progress"]  # fmt: skip
    if job != "denoiser":
        frame, _, extra = job.partition("-")  # "heading" or "heading-temporal"
        den = run_dir(fold, "denoiser", runs) / "denoiser.safetensors"
        cmd += ["--denoiser", str(den), "--set", f"model.agent_frame={frame}"]
        if extra == "temporal":
            cmd += ["--set", "model.history_encoder=temporal"]
    state = last_state_path(out, stage)
    if state.is_file():
        cmd += ["--resume", str(state)]
    if data_root:
        cmd += ["--data-root", data_root]
    return cmd


@functools.cache
def last_epoch(fold: str, stage: str) -> int:
    """The epochs of a stage in the fold's config (read once: the scheduler asks every poll)."""
    cfg = load_config(ROOT / "configs" / f"{fold}.yaml", [])
    return (cfg.denoiser if stage == "diffusion" else cfg.generator).epochs


def finished(fold: str, job: str, runs: Path) -> bool:
    """Whether a job's metrics reached its config's last epoch."""
    stage = stage_of(job)
    out = run_dir(fold, job, runs)
    if not (out / f"{STAGE_NAMES[stage]}_metrics.jsonl").is_file():
        return False
    records = read_metrics(out, STAGE_NAMES[stage])
    return bool(records) and records[-1]["epoch"] >= last_epoch(fold, stage)


def train(
    folds: list[str], runs: Path, workers: int, data_root: str | None,
    jobs: dict[str, tuple[str, ...]] | None = None,
) -> None:  # fmt: skip
    """Run every unfinished job, ``workers`` at a time, each generator after its denoiser.
    ``jobs``: each fold's jobs (default: the denoiser and both frames)."""
    jobs = jobs or {f: ("denoiser", *FRAMES) for f in folds}
    every = [(f, j) for f in folds for j in jobs[f]]
    pending = [k for k in every if not finished(*k, runs)]
    print(f"{len(every) - len(pending)} of {len(every)} jobs finished; {len(pending)} to run")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    logs = ROOT / "runs" / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    running: dict[tuple[str, str], tuple[subprocess.Popen, float]] = {}
    failed = []
    while pending or running:
        for key, (proc, t0) in list(running.items()):
            if proc.poll() is None:
                continue
            del running[key]
            status = "ok" if proc.returncode == 0 else f"FAILED (exit {proc.returncode})"
            print(f"{key[0]} {key[1]}: {status} in {(time.time() - t0) / 60:.1f} min", flush=True)
            if proc.returncode != 0:
                failed.append(key)
        blocked = {f for f, _ in failed}
        ready = [(f, j) for f, j in pending if f not in blocked
                 and (j == "denoiser" or finished(f, "denoiser", runs))]  # fmt: skip
        pending = [k for k in pending if k[0] not in blocked]
        if pending and not ready and not running:  # a denoiser exited before its last epoch
            sys.exit(f"jobs waiting on an unfinished denoiser: {pending}")
        while ready and len(running) < workers:
            key = ready.pop(0)
            pending.remove(key)
            cmd = job_command(*key, runs, data_root)
            with open(logs / f"holdout-{key[0]}-{key[1]}.log", "a") as log:  # the child keeps it
                running[key] = (subprocess.Popen(cmd, env=env, stdout=log, stderr=log), time.time())
            print(f"{key[0]} {key[1]}: started", flush=True)
        time.sleep(5)
    if failed:
        sys.exit(f"{len(failed)} jobs failed (logs in runs/logs/holdout-*.log): {failed}")


def held_out_metrics(fold: str, job: str, runs: Path, data_root: str | None) -> dict:
    """One generator run on its held-out location (``trajpref evaluate``, cached in the run
    folder as ``holdout_val.json``), with its best epoch and training minutes."""
    out = run_dir(fold, job, runs)
    result = out / "holdout_val.json"
    if not result.is_file():
        cmd = [sys.executable, "-m", "trajpref.cli", "evaluate", "--dataset", fold, "--split",
               "val", "--holdout-scene", HELD_OUT[fold], "--model",
               str(out / "generator.safetensors"), "--samples", "20", "--seed", "0",
               "--json", "--no-progress", "--out", str(result)]  # fmt: skip
        if data_root:
            cmd += ["--data-root", data_root]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    res = json.loads(result.read_text())
    records = read_metrics(out, "generator")
    best = min((r for r in records if "val_score" in r), key=lambda r: r["val_score"])
    return {
        **{
            k: res[k]
            for k in ("min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "agents", "scenes")
        },  # fmt: skip
        "best_epoch": best["epoch"],
        "epochs": records[-1]["epoch"],
        "train_minutes": round(records[-1]["train_seconds"] / 60, 1),
    }


def measure(fold: str, runs: Path, data_root: str | None) -> dict | None:
    """Both generators of a fold on its held-out location; None until both are trained."""
    if not all(finished(fold, j, runs) for j in FRAMES):
        return None
    row = {"holdout_scene": HELD_OUT[fold]}
    for frame in FRAMES:
        row[frame] = held_out_metrics(fold, frame, runs, data_root)
    scene, heading = row["scene"]["min_fde"], row["heading"]["min_fde"]
    row["heading_vs_scene_pct"] = round(100 * (heading / scene - 1), 2)
    row["chosen"] = "heading" if heading < scene else "scene"
    return row


TEMPORAL_BAR_PCT = -1.0
"""The temporal encoder is adopted for a fold at this change of held-out minFDE20 or below."""


def measure_temporal(fold: str, row: dict, runs: Path, data_root: str | None) -> dict | None:
    """The chosen frame with ``history_encoder=temporal`` against that frame's own run (the
    rule of docs/pretraining.md); None until it is trained."""
    job = f"{row['chosen']}-temporal"
    if not finished(fold, job, runs):
        return None
    metrics = held_out_metrics(fold, job, runs, data_root)
    change = round(100 * (metrics["min_fde"] / row[row["chosen"]]["min_fde"] - 1), 2)
    return {**metrics, "frame": row["chosen"], "vs_frame_pct": change,
            "adopted": change <= TEMPORAL_BAR_PCT}  # fmt: skip


def temporal_report(record: dict) -> str:
    lines = [
        "| fold | frame | its held-out minADE20 / minFDE20 | + temporal encoder (best epoch) "
        "| change | training min (frame -> temporal) | adopted (<= -1 %) |",
        "|---|---|---|---|---|---|---|",
    ]
    for fold in FOLDS:
        row = record["folds"].get(fold, {})
        tmp = row.get("temporal")
        if tmp is None:
            continue
        base = row[tmp["frame"]]
        lines.append(
            f"| {fold} | {tmp['frame']} | {base['min_ade']:.4f} / {base['min_fde']:.4f} "
            f"| {tmp['min_ade']:.4f} / {tmp['min_fde']:.4f} ({tmp['best_epoch']} of "
            f"{tmp['epochs']}) | {tmp['vs_frame_pct']:+.1f} % "
            f"| {base['train_minutes']} -> {tmp['train_minutes']} "
            f"| {'yes' if tmp['adopted'] else 'no'} |"
        )
    return "\n".join(lines)


LOCATIONS = {"biwi_eth": "eth", "biwi_hotel": "hotel", "crowds_zara": "zara",
             "students": "univ", "uni_examples": "univ"}  # fmt: skip
"""Recording location of each ETH/UCY file-name prefix."""


def direction_shares(fold: str, data_root: str | None, min_speed: float = 0.1) -> dict:
    """Per location of a fold's training split, and for its test split: the agents moving
    faster than ``min_speed`` (m per step, first to last observed position) and the share of
    them whose direction lies within 45 degrees of the x axis (either way). Held-out
    locations differ from the rest in more than their people: hotel's walkers move along y.
    """
    from trajpref.data import load_dataset
    from trajpref.data.registry import scene_file

    def share(scenes) -> dict:
        d = np.concatenate([s.history[:, -1] - s.history[:, 0] for s in scenes])  # [N, 2]
        moving = d[np.linalg.norm(d, axis=-1) / 7 > min_speed]  # 7 observed steps
        along_x = np.abs(moving[:, 0]) >= np.abs(moving[:, 1])  # within 45 degrees of x
        return {"agents": int(len(moving)), "along_x": round(float(along_x.mean()), 3)}

    train = load_dataset(fold, "train", data_root)
    by_loc: dict[str, list] = {}
    for s in train.scenes:
        prefix = next(p for p in LOCATIONS if scene_file(s).startswith(p))
        by_loc.setdefault(LOCATIONS[prefix], []).append(s)
    out = {loc: share(scenes) for loc, scenes in sorted(by_loc.items())}
    out[f"{fold} (test)"] = share(load_dataset(fold, "test", data_root).scenes)
    return out


def known_change(known: dict, which: str, fold: str) -> float | None:
    """Heading vs scene minFDE20 change (%) of the models trained on every scene, from
    ``meta/frame_known.json``: ``which`` is ``file_val`` (the fold's usual validation split)
    or ``test``; None when not recorded."""
    pair = known.get(which, {}).get(fold)
    return None if pair is None else 100 * (pair["heading"] / pair["scene"] - 1)


def report(record: dict, known: dict | None = None) -> str:
    """The table of the held-out-location rows; with ``known``, the same change as the
    file-level validation and the test split measured it (context only, not the rule's)."""
    known = known or {}
    lines = [
        "| fold | held out | windows (agents) | scene frame minADE20 / minFDE20 (best epoch) "
        "| heading frame | heading vs scene: held out | file-level val | test "
        "| joint minFDE scene -> heading | chosen |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]

    def pct(x: float | None) -> str:
        return "–" if x is None else f"{x:+.1f} %"

    for fold in FOLDS:
        row = record["folds"].get(fold)
        if row is None:
            continue
        s, h = row["scene"], row["heading"]
        lines.append(
            f"| {fold} | {row['holdout_scene']} | {s['scenes']} ({s['agents']}) "
            f"| {s['min_ade']:.4f} / {s['min_fde']:.4f} ({s['best_epoch']} of {s['epochs']}) "
            f"| {h['min_ade']:.4f} / {h['min_fde']:.4f} ({h['best_epoch']} of {h['epochs']}) "
            f"| {pct(row['heading_vs_scene_pct'])} | {pct(known_change(known, 'file_val', fold))} "
            f"| {pct(known_change(known, 'test', fold))} "
            f"| {s['joint_min_fde']:.3f} -> {h['joint_min_fde']:.3f} | {row['chosen']} |"
        )
    return "\n".join(lines)


def plot(record: dict, known: dict, path: Path) -> None:
    """Bars per fold: heading vs scene (% minFDE20) by file-level validation, by the held-out
    location and on the test split; a validator that ranks like the test has bars of the
    test's sign."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folds = [f for f in FOLDS if f in record["folds"]]
    series = [
        ("file-level validation", [known_change(known, "file_val", f) for f in folds]),
        ("held-out location", [record["folds"][f]["heading_vs_scene_pct"] for f in folds]),
        ("test (read once per model)", [known_change(known, "test", f) for f in folds]),
    ]
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(folds), 3.6))
    width = 0.27
    for i, (name, values) in enumerate(series):
        xs = [j + (i - 1) * width for j, v in enumerate(values) if v is not None]
        ax.bar(xs, [v for v in values if v is not None], width, label=name)
    ax.axhline(0, color="black", lw=0.8)
    ax.set_xticks(range(len(folds)), folds)
    ax.set_ylabel("heading vs scene frame,\nminFDE20 change (%)")
    ax.set_title("heading vs scene frame: three validators", fontsize=10)
    ax.legend(fontsize=8, frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--folds", nargs="+", default=list(FOLDS), choices=FOLDS)
    parser.add_argument("--workers", type=int, default=2, help="jobs at once (one thread each)")
    parser.add_argument("--runs", default=str(ROOT / "runs" / "holdout"), help="run folders")
    parser.add_argument("--data-root", default=None, help="data folder ($TRAJPREF_DATA)")
    parser.add_argument("--report", action="store_true", help="print the recorded table only")
    parser.add_argument(
        "--directions",
        action="store_true",
        help="print, per location of each fold's training split and for its test split, the "
        "share of moving agents that walk along x (no training)",
    )
    parser.add_argument(
        "--temporal",
        action="store_true",
        help="the next study: each fold's chosen frame with model.history_encoder=temporal "
        "(folds whose frame is decided only)",
    )
    parser.add_argument(
        "--plot", default=None, metavar="PNG", help="also draw each fold's three validators"
    )
    args = parser.parse_args(argv)
    if args.workers < 1:
        parser.error("--workers must be >= 1")
    if args.directions:
        for fold in args.folds:
            shares = direction_shares(fold, args.data_root)
            cells = [f"{loc} {v['along_x']:.2f} of {v['agents']}" for loc, v in shares.items()]
            print(f"{fold} fold: " + ", ".join(cells))
        return 0
    record = json.loads(RECORD.read_text()) if RECORD.is_file() else {"folds": {}}
    if not args.report:
        runs = Path(args.runs)
        if args.temporal:
            decided = [f for f in args.folds if f in record["folds"]]
            if not decided:
                parser.error("--temporal needs folds whose frame is decided: run without it first")
            jobs = {f: (f"{record['folds'][f]['chosen']}-temporal",) for f in decided}
            train(decided, runs, args.workers, args.data_root, jobs)
            for fold in decided:
                tmp = measure_temporal(fold, record["folds"][fold], runs, args.data_root)
                if tmp is not None:
                    record["folds"][fold]["temporal"] = tmp
        else:
            train(args.folds, runs, args.workers, args.data_root)
            for fold in args.folds:
                row = measure(fold, runs, args.data_root)
                if row is not None:
                    record["folds"][fold] = {**record["folds"].get(fold, {}), **row}
        record.update(machine=machine(), date=date.today().isoformat(), command=command_line())
        write_json(RECORD, record)
    known = json.loads(KNOWN.read_text()) if KNOWN.is_file() else {}
    table = report(record, known)
    if any("temporal" in row for row in record["folds"].values()):
        table += "\n\n" + temporal_report(record)
    print(table)
    if record["folds"]:
        update_readme(DOC, "holdout-frame", table)
    if args.plot:
        plot(record, known, Path(args.plot))
    return 0


if __name__ == "__main__":
    sys.exit(main())
