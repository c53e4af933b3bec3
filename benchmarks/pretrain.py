"""Pretrained predictor (denoiser + leapfrog generator) on one dataset: train (optional),
publish the checkpoints, evaluate on the test split, and time the two samplers side by side.

    # train both stages (background-friendly: each stage resumes from <run>/<stage>_last.pt)
    python benchmarks/pretrain.py --dataset zara1 --train --data-root ../shared/data
    # or evaluate an existing run folder
    python benchmarks/pretrain.py --dataset zara1 --run-dir runs/zara1 --data-root ../shared/data
    # or re-measure a published generator as it is, after a change of its sampling setting
    # (benchmarks/deterministic_steps.py): its training records are kept from the meta file
    python benchmarks/pretrain.py --dataset zara1 --published --data-root ../shared/data
    # univ's test split is large: skip the full sampler's accuracy (its speed is still timed)
    python benchmarks/pretrain.py --dataset univ --train --no-full-eval --data-root ../shared/data
    # a retrained default that replaces the published one: keep the old test row beside it
    python benchmarks/pretrain.py --dataset zara1 --run-dir runs/new --keep-replaced tau5 \
        --no-full-eval --data-root ../shared/data
    # a variant trained elsewhere (e.g. a longer schedule on a GPU), published beside the default
    python benchmarks/pretrain.py --dataset zara1 --run-dir runs/zara1-g100 --variant long \
        --train-machine "1x H100" --no-full-eval --data-root ../shared/data

Writes models/<dataset>/{denoiser,generator}.safetensors,
benchmarks/results/pretrained_<dataset>.json (methods ``pretrained`` and ``full-sampler``) and
prints the numbers for docs/pretraining.md. With ``--variant NAME``:
models/<dataset>/generator-NAME.safetensors, method ``pretrained-NAME`` in
pretrained_<dataset>_NAME.json; the README's cost table (this machine, default configs) skips it.
With ``--keep-replaced NAME`` the default's ``pretrained`` row (and its meta file) is first
kept as ``pretrained-NAME``, its checkpoint named by the commit that holds its weights.

``--runs DIR``, ``--results DIR`` and ``--models DIR`` put the run folder (``DIR/<dataset>``),
the rows and meta file, and the published checkpoints elsewhere (``benchmarks/reproduce.py
--out`` uses all three, so that its training leaves the repository as it is). The three go
together, all or none (benchmarks/paths.py): a run kept out of the repository never publishes
into its models, and a generator published elsewhere never replaces its rows (name the
repository's own folder to mean it).
``--keep-replaced`` names the repository's commits, so it takes none of the three. A row's
``checkpoint`` is relative to the repository when the file lies inside it, otherwise absolute.
"""

from __future__ import annotations

import argparse
import json
import subprocess
from pathlib import Path

from paths import add_elsewhere_options, require_all_or_none, shown

from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.evaluation import evaluate, time_predictors
from trajpref.models import checkpoint as ckpt
from trajpref.results import make_row, sampler_of, upsert_rows, write_rows
from trajpref.train import read_metrics, train_stage
from trajpref.train.run import finished

ROOT = Path(__file__).resolve().parent.parent


def _train(args, run_dir: Path) -> None:
    cfg = load_config(ROOT / "configs" / f"{args.dataset}.yaml")
    for stage in ("diffusion", "generator"):
        name = "denoiser" if stage == "diffusion" else "generator"
        last = run_dir / f"{name}_last.pt"
        optim = cfg.denoiser if stage == "diffusion" else cfg.generator
        if finished(last, optim):  # trained already: a resume would be refused
            print(f"{run_dir}: the {name} stage has finished (its {optim.epochs} epochs, or "
                  "its time budget)")  # fmt: skip
            continue
        resume = str(last) if last.is_file() else None
        train_stage(stage, cfg, run_dir, args.data_root, args.device, resume)


def stage_records(logs: dict[str, list[dict]]) -> tuple[dict, dict, dict, dict]:
    """From each stage's metric records: its training seconds, its mean agent-windows per
    second, the epochs it trained, and the share of its time budget it used at the end (None
    without ``budget_schedule``; a config's ``max_minutes`` with it ends a stage early,
    annealed, on a host too slow for the schedule). A stage without records gets None."""
    seconds = {s: (log[-1]["train_seconds"] if log else None) for s, log in logs.items()}
    rates = {s: (sum(r["samples_per_second"] for r in log) / len(log) if log else None)
             for s, log in logs.items()}  # fmt: skip
    epochs = {s: (log[-1]["epoch"] if log else None) for s, log in logs.items()}
    share = {s: (log[-1].get("budget_share") if log else None) for s, log in logs.items()}
    return seconds, rates, epochs, share


def _git(root: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True)


def keep_replaced(root: Path, dataset: str, name: str) -> Path:
    """Keep the published default's test row before a retrained generator replaces it: the
    ``pretrained`` row of ``pretrained_<dataset>.json`` is written as ``pretrained-<name>`` to
    ``pretrained_<dataset>_<name>.json`` (its checkpoint named as ``git show <commit>:<path>``,
    the commit that holds the weights it measured) and its meta file is copied beside, so
    docs and tables can still compare with it. Refuses when the published generator differs
    from its last commit (the row would name other weights) or the name holds another row;
    calling it again for the same row is a no-op."""
    results = root / "benchmarks" / "results"
    rows_path = results / f"pretrained_{dataset}.json"
    kept_rows = results / f"pretrained_{dataset}_{name}.json"
    kept_meta = results / "meta" / kept_rows.name
    rows = json.loads(rows_path.read_text()) if rows_path.is_file() else []
    row = next((r for r in rows if r["method"] == "pretrained"), None)
    if row is None:
        raise SystemExit(f"--keep-replaced: no 'pretrained' row in {rows_path} to keep")
    weights = (root / "models" / dataset / f"generator{ckpt.SUFFIX}").resolve()
    rel = weights.relative_to(root.resolve()).as_posix()
    commit = _git(root, "log", "-1", "--format=%h", "--", rel).stdout.strip()
    if not commit:
        raise SystemExit(f"--keep-replaced: {rel} has no commit to name the kept row's weights")
    kept = {**row, "method": f"pretrained-{name}", "checkpoint": f"git show {commit}:{rel}"}
    if kept_rows.exists():  # a second call for the same replacement (a rerun) is fine
        if json.loads(kept_rows.read_text()) == [kept]:
            return kept_rows
        raise SystemExit(f"--keep-replaced {name}: {kept_rows.name} exists already with "
                         "another row; pick another name")  # fmt: skip
    if _git(root, "diff", "--quiet", "HEAD", "--", rel).returncode != 0:
        raise SystemExit(f"--keep-replaced: {rel} differs from its last commit; commit or "
                         "restore it first (the kept row must name the weights it "
                         "measured)")  # fmt: skip
    write_rows(kept_rows, [kept])
    meta = results / "meta" / rows_path.name
    if meta.is_file():
        kept_meta.write_text(meta.read_text())
    return kept_rows


def _is_full_sampler_row(row: dict) -> bool:
    return row["method"].startswith("full")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True, help="config name under configs/")
    parser.add_argument("--run-dir", default=None, help="default <runs>/<dataset>")
    add_elsewhere_options(
        parser,
        runs="the folder of the default run folder (default: the repository's runs/)",
        results="where the rows (pretrained_<dataset>[_VARIANT].json) and meta/ go (default: "
        "the repository's benchmarks/results/)",
        models="publish into (and with --published, re-measure from) DIR/<dataset>/ "
        "(default: the repository's models/)",
    )
    parser.add_argument("--train", action="store_true", help="train (or resume) both stages")
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timing-scenes", type=int, default=100)
    parser.add_argument(
        "--no-full-eval",
        action="store_true",
        help="time the full sampler but skip its whole-test-split accuracy "
        "(about 15x the leapfrog cost: ~30 min on univ's test split)",
    )
    parser.add_argument(
        "--variant",
        default=None,
        help="publish as generator-VARIANT.safetensors, rows as pretrained-VARIANT",
    )
    parser.add_argument(
        "--train-machine",
        default=None,
        help="where the run was trained, when not on this machine (recorded "
        "in the meta file; the row's train_seconds is then left empty)",
    )
    parser.add_argument(
        "--published",
        action="store_true",
        help="re-measure the published generator (and its leapfrog row) as it is: no "
        "training or publishing; the training records come from the previous meta file",
    )
    parser.add_argument(
        "--keep-replaced",
        default=None,
        metavar="NAME",
        help="first keep the published default's test row (and meta file) as "
        "pretrained-NAME in pretrained_<dataset>_NAME.json",
    )
    args = parser.parse_args()
    if args.keep_replaced is not None and (args.variant or args.published):
        parser.error("--keep-replaced keeps the default a retrained one replaces: no "
                     "--variant or --published")  # fmt: skip
    if args.keep_replaced is not None and not args.keep_replaced.replace("-", "").isalnum():
        parser.error("--keep-replaced takes letters, digits and '-'")
    if args.published and (args.train or args.run_dir or args.train_machine):
        parser.error("--published re-measures a published file: no --train, --run-dir or "
                     "--train-machine")  # fmt: skip
    if args.variant is not None and not args.variant.replace("-", "").isalnum():
        parser.error("--variant takes letters, digits and '-'")
    require_all_or_none(parser, args)
    elsewhere = args.runs or args.results or args.models
    if args.keep_replaced is not None and elsewhere:
        parser.error("--keep-replaced keeps a row of the repository's published default: no "
                     "--runs, --results or --models")  # fmt: skip
    runs = (args.runs or ROOT / "runs").absolute()
    results = (args.results or ROOT / "benchmarks" / "results").absolute()
    suffix = f"-{args.variant}" if args.variant else ""
    file_suffix = f"_{args.variant}" if args.variant else ""

    run_dir = Path(args.run_dir or runs / args.dataset)
    if args.train:
        _train(args, run_dir)
    models = (args.models or ROOT / "models").absolute() / args.dataset
    models.mkdir(parents=True, exist_ok=True)
    # the generator names models/<dataset>/denoiser.safetensors by path and hash instead of
    # embedding it; published weights are half precision
    published = models / f"generator{suffix}{ckpt.SUFFIX}"
    run_generator = run_dir / f"generator{ckpt.SUFFIX}"
    # a retrained default replaces its own denoiser; a variant trained with a denoiser of its
    # own gets its own file: it never overwrites the one the default generator points to
    meta_path = results / "meta" / f"pretrained_{args.dataset}{file_suffix}.json"
    previous = json.loads(meta_path.read_text()) if meta_path.is_file() else None
    if args.published:
        if previous is None or not published.is_file():
            parser.error(f"--published: no {published.name} or {meta_path.name} to re-measure")
        args.train_machine = previous.get("train_machine")
        args.no_full_eval = True  # the full sampler does not depend on the generator
    else:
        if args.keep_replaced is not None:
            print(f"kept the replaced row: {keep_replaced(ROOT, args.dataset, args.keep_replaced)}")
        try:
            ckpt.publish(run_generator, published, replace_denoiser=not args.variant)
        except ckpt.DenoiserConflict:
            ckpt.publish(run_generator, published, denoiser_name=f"denoiser{suffix}{ckpt.SUFFIX}")
    gen_ckpt = ckpt.load(published)
    den_ckpt = gen_ckpt["denoiser"]
    train_seconds = den_ckpt["meta"]["train_seconds"] + gen_ckpt["meta"]["train_seconds"]
    # total time of each whole stage (the best checkpoint may come before the last epoch)
    logs = {s: read_metrics(run_dir, s) for s in ("denoiser", "generator")}
    if args.published:
        logs = {s: [] for s in logs}  # the training records are the previous meta file's
    stage_seconds, rates, epochs_done, budget_share = stage_records(logs)
    denoiser_note = None
    if args.published:
        stage_seconds, rates = previous["stage_seconds"], previous["samples_per_second"]
        epochs_done = previous.get("epochs_done", epochs_done)
        budget_share = previous.get("budget_share", budget_share)
        denoiser_note = previous.get("denoiser_note")
    elif not logs["denoiser"] and previous is not None:
        # a generator-only run from the published denoiser: that denoiser's training cost is
        # the one its own run recorded, kept from the previous meta file
        stage_seconds["denoiser"] = previous["stage_seconds"]["denoiser"]
        rates["denoiser"] = previous["samples_per_second"]["denoiser"]
        epochs_done["denoiser"] = previous.get("epochs_done", {}).get("denoiser")
        budget_share["denoiser"] = previous.get("budget_share", {}).get("denoiser")
        denoiser_note = "reused the published denoiser; its cost is from its own training run"

    test = load_dataset(args.dataset, "test", args.data_root)
    leap = ckpt.load_predictor(published, sampler="leapfrog", device=args.device)
    full = ckpt.load_predictor(published, sampler="full", device=args.device)
    speed = time_predictors({"leapfrog": leap, "full": full}, test, args.samples,
                            args.timing_scenes)  # fmt: skip
    params = {"denoiser": sum(p.numel() for p in leap.denoiser.parameters()),
              "generator": sum(p.numel() for p in leap.generator.parameters())}  # fmt: skip

    rows = []
    if args.train_machine is not None:
        train_seconds = None  # trained elsewhere: not a cost on this machine
    for method, model, ms, secs in (
        (f"pretrained{suffix}", leap, speed["leapfrog"], train_seconds),
        (f"full-sampler{suffix}", full, speed["full"], None),
    ):
        if method.startswith("full-sampler") and args.no_full_eval:
            continue
        res = evaluate(model, test, args.samples, args.seed, args.device)
        rows.append(make_row(
            dataset=args.dataset, split="test", method=method, seed=args.seed,
            samples=args.samples, min_ade=res["min_ade"], min_fde=res["min_fde"],
            joint_min_ade=res["joint_min_ade"], joint_min_fde=res["joint_min_fde"],
            train_seconds=round(secs, 1) if secs is not None else None,
            ms_per_scene=round(ms, 3),
            uses_score=False,
            checkpoint=shown(published, ROOT),
            model_hash=ckpt.model_hash(published, sampler_of(method)),
        ))  # fmt: skip
        print(f"{args.dataset} {method:>12}: minADE {res['min_ade']:.3f} minFDE "
              f"{res['min_fde']:.3f}  joint {res['joint_min_ade']:.3f}/"
              f"{res['joint_min_fde']:.3f}  {ms:.1f} ms/scene")  # fmt: skip
    out = results / f"pretrained_{args.dataset}{file_suffix}.json"
    # a generator-only run keeps the full sampler's row (same denoiser); a new denoiser
    # published without --full-eval drops it (it measured the old one)
    new_denoiser = args.no_full_eval and logs["denoiser"]
    upsert_rows(out, rows, drop=_is_full_sampler_row if new_denoiser else None)
    extra = {
        "dataset": args.dataset,
        "variant": args.variant,
        "train_machine": args.train_machine,
        # the training process's own machine and threads (checkpoints since 2026-11-27)
        "trained_on": gen_ckpt["meta"].get("machine"),
        "stochastic_steps": ckpt.config_of(gen_ckpt).model.stochastic_steps,
        "params": params,
        "stage_seconds": stage_seconds,
        "denoiser_note": denoiser_note,
        "seconds_to_best": {"denoiser": den_ckpt["meta"]["train_seconds"],
                            "generator": gen_ckpt["meta"]["train_seconds"]},
        "best_epoch": {"denoiser": den_ckpt["meta"]["epoch"],
                       "generator": gen_ckpt["meta"]["epoch"]},
        "samples_per_second": rates,
        "epochs_done": epochs_done,
        "budget_share": budget_share,
        "val": gen_ckpt["meta"]["val"],
        "ms_per_scene": speed,
        "speedup_full_over_leapfrog": speed["full"] / speed["leapfrog"],
        "checkpoint_mb": {"denoiser": (models / gen_ckpt["denoiser_ref"]["path"]).stat().st_size
                                      / 2**20,
                          "generator": published.stat().st_size / 2**20},
    }  # fmt: skip
    meta_path.parent.mkdir(parents=True, exist_ok=True)
    meta_path.write_text(json.dumps(extra, indent=2) + "\n")
    print(json.dumps(extra, indent=2))


if __name__ == "__main__":
    main()
