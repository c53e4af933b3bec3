"""RLHF / RLHF-ReS fine-tuning from a dataset's published generator, evaluated on the test
split (chosen on validation), one row per method and seed.

    python benchmarks/finetune.py --dataset zara1 --methods rlhf rlhf-res --seeds 0 1 2 \
        --data-root ../shared/data [--preset paper] [--set finetune.epochs=3 ...]

Runs go to runs/<dataset>-<method>-s<seed>[-<tag>] (resumed when their _last.pt exists; a
folder started from another start or with other settings is refused).
Writes benchmarks/results/finetune_<dataset>[_<tag>].json and, with ``--publish``, seed 0's
model of the untagged run as models/<dataset>/<method>.safetensors. Every invocation also writes
benchmarks/results/meta/finetune_start_<dataset>.json: the start's validation exactly as the
fine-tuning stage computes it each epoch (the "epoch 0" the run logs start from);
``--start-only`` writes just that. ``--start generator-long --tag long`` starts from another
published generator (its rows are named <method>-long, its start's validation is
meta/finetune_start_<dataset>_generator-long.json).

``--runs DIR`` and ``--results DIR`` put the run folders and the rows (with their ``meta/``)
elsewhere (``benchmarks/reproduce.py --out`` uses them, so that its training leaves the
repository as it is); ``--models DIR`` reads the start from, and ``--publish`` writes into,
``DIR/<dataset>/`` instead of models/. The three go together, all or none (benchmarks/paths.py):
a run kept out of the repository neither publishes into its models nor adds rows of an
unpublished start to its results (name the repository's own folder to mean it). A row's
``checkpoint`` is relative to the repository when the run folder lies inside it, otherwise
absolute (readers join it to the repository's root, which keeps an absolute path as it is).
"""

from __future__ import annotations

import argparse
import fcntl
import json
from contextlib import contextmanager
from pathlib import Path

from equal_budget import budget_of, row_budget
from paths import add_elsewhere_options, require_all_or_none, shown

from trajpref import io
from trajpref.config import load_config, to_dict, uses_rl
from trajpref.data import load_dataset
from trajpref.device import resolve_device
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.results import RUNNABLE_STARTS, make_row, start_record, start_suffix, write_rows
from trajpref.rl.presets import finetune_config
from trajpref.score.scorer import TrajectoryScorer
from trajpref.train.loop import load_resume_state
from trajpref.train.run import finetune, finetune_run_config, finished
from trajpref.train.stages import build_finetune_stage

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--methods", nargs="+", default=["rlhf", "rlhf-res"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--preset", default=None)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    parser.add_argument("--tag", default="", help="names an ablation: its own runs and rows")
    parser.add_argument(
        "--start",
        default="generator",
        choices=list(RUNNABLE_STARTS),
        help="the published generator to start from, <models>/<dataset>/<START>.safetensors "
        "(another than the default needs a --tag ending in its name, e.g. --start "
        "generator-long --tag long, so that its rows compare with their own start)",
    )
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--samples", type=int, default=20)
    add_elsewhere_options(
        parser,
        runs="the folder of the run folders (default: the repository's runs/)",
        results="where the rows (finetune_<dataset>[_<tag>].json) and meta/ go (default: the "
        "repository's benchmarks/results/)",
        models="the published models: the start is read from, and --publish writes into, "
        "DIR/<dataset>/ (default: the repository's models/)",
    )
    parser.add_argument(
        "--publish",
        action="store_true",
        help="publish seed 0's model as <models>/<dataset>/<method>.safetensors (only for the "
        "dataset's best method: docs/architecture.md, published models)",
    )
    parser.add_argument(
        "--skip-done",
        action="store_true",
        help="skip (method, seed) pairs that already have a row in the results file measured "
        "under this invocation's budget (the --set keys of equal_budget.py's budget: "
        "finetune.max_minutes, warmup_steps, eval_every_minutes, eval_every; a row's are read "
        "from its command); a row of another budget is run again and replaced, once its run "
        "folder (started with other settings, so refused) is moved away or the runs take a "
        "new --tag",
    )
    parser.add_argument(
        "--no-start-validation",
        action="store_true",
        help="do not re-validate the start (meta/finetune_start_<dataset>.json is kept)",
    )
    parser.add_argument(
        "--start-only",
        action="store_true",
        help="only validate the start (meta/finetune_start_<dataset>.json)",
    )
    args = parser.parse_args()
    require_all_or_none(parser, args)
    args.runs = (args.runs or ROOT / "runs").absolute()
    args.results = (args.results or ROOT / "benchmarks" / "results").absolute()
    args.models = (args.models or ROOT / "models").absolute()

    start = args.models / args.dataset / f"{args.start}{ckpt.SUFFIX}"
    if not start.is_file():
        parser.error(f"no published {args.start} for {args.dataset}: {start} does not exist")
    variant = start_suffix(args.start).lstrip("-")
    if variant and not args.tag.endswith(variant):
        parser.error(f"--start {args.start} needs a --tag ending in '{variant}' (e.g. --tag "
                     f"{variant}): its rows are named <method>-<tag>")  # fmt: skip
    if not args.no_start_validation:
        start_validation(args, start)
    if args.start_only:
        return
    suffix = f"_{args.tag}" if args.tag else ""
    out = args.results / f"finetune_{args.dataset}{suffix}.json"
    jobs = [(m, s) for m in args.methods for s in args.seeds]
    if args.skip_done and out.is_file():
        budget = budget_of(args.overrides)  # as row_budget reads it back from the command
        done = {(r["method"], r["seed"]) for r in json.loads(out.read_text())
                if row_budget(r) == budget}  # fmt: skip
        jobs = [(m, s) for m, s in jobs if (_method_name(m, args.tag), s) not in done]
    if not jobs:
        print(f"{args.dataset}: every requested row is already in {out.name}")
        return
    test = load_dataset(args.dataset, "test", args.data_root)
    scorer = TrajectoryScorer.from_checkpoint(start, args.device)
    for method, seed in jobs:
        run = args.runs / f"{args.dataset}-{method}-s{seed}{'-' + args.tag if args.tag else ''}"
        cfg = finetune_config(str(start), method, args.preset, None, args.overrides, seed)
        last = run / "finetune_last.pt"
        check_start(run, start)
        check_settings(run, cfg)
        if finished(last, cfg.finetune):  # epochs or budget spent: a resume would be refused
            state = load_resume_state(last)
            summary = {"train_seconds": state["elapsed"], "steps": state["step"]}
        else:
            summary = finetune(cfg, start, run, args.data_root, args.device,
                               str(last) if last.is_file() else None, progress=True)  # fmt: skip
        best = run / f"finetune{ckpt.SUFFIX}"
        model = ckpt.load_predictor(best, sampler="leapfrog", device=args.device)
        res = evaluate(model, test, args.samples, 0, args.device, scorer=scorer,
                       progress=False)  # fmt: skip
        if args.publish and seed == 0 and not args.tag:
            ckpt.publish(best, args.models / args.dataset / f"{method}{ckpt.SUFFIX}")
        method_name = _method_name(method, args.tag)
        row = make_row(
            dataset=args.dataset, split="test", method=method_name, seed=seed,
            samples=args.samples, **{k: res[k] for k in (
                "min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "max_ats",
                "max_fts", "top1_recall_ats", "top5_recall_ats")},
            train_seconds=round(summary["train_seconds"], 1),
            checkpoint=shown(best, ROOT), model_hash=ckpt.model_hash(best),
            uses_score=uses_rl(cfg.finetune.method)
            and (cfg.finetune.policy_weight > 0 or cfg.finetune.value_weight > 0),
        )  # fmt: skip
        print(f"{args.dataset} {method_name} seed {seed}: minADE {res['min_ade']:.3f} "
              f"minFDE {res['min_fde']:.3f} maxATS {res['max_ats']:.3f} maxFTS "
              f"{res['max_fts']:.3f} ({summary['train_seconds']:.0f} s, "
              f"{summary['steps']} steps)")  # fmt: skip
        out.parent.mkdir(parents=True, exist_ok=True)
        with _locked(out):
            # re-read: keeps rows of other methods/seeds, also those written meanwhile by
            # a concurrent invocation for another method or seed
            rows = json.loads(out.read_text()) if out.is_file() else []
            rows = [r for r in rows if (r["method"], r["seed"]) != (method_name, seed)]
            write_rows(out, [*rows, row])


def _method_name(method: str, tag: str) -> str:
    return f"{method}-{tag}" if tag else method


@contextmanager
def _locked(path: Path):
    """Hold an exclusive lock beside ``path`` (concurrent invocations write one file)."""
    with open(path.with_suffix(".lock"), "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def check_start(run: Path, start: Path) -> None:
    """Refuse to resume or reuse a run folder begun from another start: the first run records
    the start's weights hash in ``<run>/start.json``; a folder with fine-tuning files but no
    record, or with another hash, is an error (it would silently supply an old run's model)."""
    record = run / "start.json"
    want = {"start": shown(start, ROOT), "hash": ckpt.load(start)["hash"]}
    if record.is_file():
        have = json.loads(record.read_text())
        if have.get("hash") != want["hash"]:
            raise SystemExit(f"{run} was started from {have.get('start')} (weights "
                             f"{have.get('hash')}), not from {want['start']} ({want['hash']}): "
                             "move the folder away or name the new runs with --tag")  # fmt: skip
        return
    if any(run.glob("finetune*")):
        raise SystemExit(
            f"{run} holds a fine-tuning run with no record of its start: move it "
            "away (it may come from another generator) or name the new runs with --tag"
        )
    run.mkdir(parents=True, exist_ok=True)
    record.write_text(json.dumps(want, indent=2) + "\n")


SETTINGS_FREE = ("finetune.keep_checkpoints",)
"""The settings in which a run folder may differ from the invocation that reuses it: what the
run keeps on disk, nothing that shapes its model or its budget."""


def check_settings(run: Path, cfg) -> None:
    """Refuse a run folder whose fine-tuning was started with other settings than this
    invocation's ``cfg`` (its ``finetune_config.yaml``, the config the stage trains with and
    writes, ``train.run.finetune_run_config``; ``sda`` and registered rewards without scaling):
    another budget, preset, learning rate or seed. Unchecked, finetune.py would resume such a
    run under the new settings (a resume may change the budget) or, when its budget is spent,
    take its finished model as this invocation's row. A folder without the file has not
    started a run (``check_start`` has dealt with older folders)."""
    saved = run / "finetune_config.yaml"
    if not saved.is_file():
        return
    want = io.dotted(to_dict(finetune_run_config(cfg)[0]))  # as the stage writes it
    have = io.dotted(to_dict(load_config(saved)))
    changed = [f"{k}: {have.get(k)!r} -> {want.get(k)!r}"
               for k in sorted(set(have) | set(want))
               if k not in SETTINGS_FREE and have.get(k) != want.get(k)]  # fmt: skip
    if changed:
        more = f" (and {len(changed) - 3} more)" if len(changed) > 3 else ""
        raise SystemExit(f"{run} was fine-tuned with other settings than these ("
                         f"{'; '.join(changed[:3])}{more}): move the folder away, or name the "
                         "new runs with --tag")  # fmt: skip


def start_meta(dataset: str, start: str = "generator", results: Path | None = None) -> Path:
    """Where the start's validation is kept: meta/finetune_start_<dataset>.json for the default
    generator, meta/finetune_start_<dataset>_<start>.json for another published one, under
    ``results`` (default: the repository's benchmarks/results/)."""
    return (results or ROOT / "benchmarks" / "results") / "meta" / start_record(dataset, start)


def start_validation(args, start: Path) -> dict[str, float]:
    """The fine-tuning stage's validation of the untouched start (its "epoch 0")."""
    cfg = finetune_config(str(start), args.methods[0], args.preset, None, args.overrides, 0)
    val = load_dataset(cfg.data.val_dataset or cfg.data.dataset, "val", args.data_root)
    stage = build_finetune_stage(cfg, ckpt.load(start), val, resolve_device(args.device))
    res = stage.validate()
    meta = {"dataset": args.dataset, "start": shown(start, ROOT),
            "eval_max_scenes": cfg.finetune.eval_max_scenes, "val": res}  # fmt: skip
    path = start_meta(args.dataset, args.start, args.results)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(meta, indent=2) + "\n")
    print(f"{args.dataset} start (validation): " + " ".join(f"{k} {v:.4f}" for k, v in res.items()))
    return res


if __name__ == "__main__":
    main()
