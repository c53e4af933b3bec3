"""The trajectory diffusion score on one dataset's test split: maxATS/maxFTS and the top-1 /
top-5 recall of the ground-truth-free ranking for constant velocity, the full-step sampler and
the leapfrog model, all scored by the dataset's published denoiser; the cost of scoring; and
(``--study``) how the score timesteps and shared vs fresh noise change recall and variance.

    python benchmarks/score.py --dataset zara1 --data-root ../shared/data [--study]

Writes benchmarks/results/score_<dataset>.json (rows merge with the accuracy rows of the same
measurement), benchmarks/results/meta/score_<dataset>.json, and with --study
docs/score_study_<dataset>.md.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from datetime import date
from pathlib import Path

import torch

from trajpref.data import load_dataset
from trajpref.data.loader import SceneLoader
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.models.baseline import ConstantVelocity
from trajpref.results import command_line, machine, make_row, sampler_of, write_rows
from trajpref.score.scorer import ScoreAccumulator, TrajectoryScorer, score_timesteps
from trajpref.types import collate

ROOT = Path(__file__).resolve().parent.parent
PAPER = {"top1_recall_ats": 0.219, "top5_recall_ats": 0.674, "top1_recall_fts": 0.184,
         "top5_recall_fts": 0.574}  # fmt: skip


@torch.no_grad()
def predictions(model, dataset, samples: int, seed: int, max_agents: int = 1024):
    """The model's samples for every batch of the split, computed once."""
    gen = torch.Generator().manual_seed(seed)
    out = []
    for batch in SceneLoader(dataset, max_agents=max_agents):
        out.append((batch, model.predict(batch, samples, gen)))
    return out


def score_predictions(scorer, preds) -> dict[str, float]:
    acc = ScoreAccumulator()
    for batch, pred in preds:
        acc.update(scorer, batch, pred)
    return acc.compute()


def study(denoiser_path: Path, preds, seeds: int) -> list[tuple[str, dict]]:
    """Recall and the across-seed std of maxATS for several scorer settings."""
    settings = [
        ("every 3 (paper), shared noise", {"steps": score_timesteps(100, 3)}),
        ("every 3, fresh noise per sample", {"steps": score_timesteps(100, 3),
                                             "shared_noise": False}),
        ("every 6 (17 steps)", {"steps": score_timesteps(100, 6)}),
        ("every 9 (12 steps)", {"steps": score_timesteps(100, 9)}),
        ("every 33 (4 steps)", {"steps": score_timesteps(100, 33)}),
        ("low noise only: 0..30 every 3", {"steps": list(range(0, 31, 3))}),
        ("high noise only: 66..99 every 3", {"steps": list(range(66, 100, 3))}),
    ]  # fmt: skip
    rows = []
    for name, kwargs in settings:
        runs = []
        start = time.perf_counter()
        for seed in range(seeds):
            scorer = TrajectoryScorer.from_checkpoint(denoiser_path, seed=seed, **kwargs)
            runs.append(score_predictions(scorer, preds))
        secs = (time.perf_counter() - start) / seeds
        summary = {}
        for key in runs[0]:
            xs = [r[key] for r in runs]
            summary[key] = (statistics.mean(xs), statistics.stdev(xs) if len(xs) > 1 else 0.0)
        summary["seconds"] = (secs, 0.0)
        rows.append((name, summary))
        print(name, {k: round(v[0], 4) for k, v in summary.items()})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--study", action="store_true")
    parser.add_argument("--study-seeds", type=int, default=3)
    parser.add_argument("--study-only", action="store_true", help="skip the rows, run the study")
    parser.add_argument(
        "--study-scenes",
        type=int,
        default=None,
        help="run the study on this many evenly spread test scenes",
    )
    parser.add_argument("--timing-scenes", type=int, default=100)
    args = parser.parse_args()

    models = ROOT / "models" / args.dataset
    gen_path = models / f"generator{ckpt.SUFFIX}"
    test = load_dataset(args.dataset, "test", args.data_root)
    scorer = TrajectoryScorer.from_checkpoint(gen_path)
    methods = {
        "cv": ConstantVelocity(),
        "full-sampler": ckpt.load_predictor(gen_path, sampler="full"),
        "pretrained": ckpt.load_predictor(gen_path, sampler="leapfrog"),
    }
    if args.study_only:
        args.study = True
    rows, extra = [], {"dataset": args.dataset, "scorer": str(gen_path.relative_to(ROOT)),
                       "paper_recall": PAPER, "methods": {}}  # fmt: skip
    for method, model in methods.items():
        if args.study_only:
            break
        res = evaluate(model, test, args.samples, args.seed, scorer=scorer, progress=False)
        rows.append(make_row(
            dataset=args.dataset, split="test", method=method, seed=args.seed,
            samples=args.samples, **{k: res[k] for k in (
                "min_ade", "min_fde", "joint_min_ade", "joint_min_fde", "max_ats", "max_fts",
                "top1_recall_ats", "top5_recall_ats")},
            uses_score=False,
            checkpoint=None if method == "cv" else str(gen_path.relative_to(ROOT)),
            model_hash=None if method == "cv" else ckpt.model_hash(gen_path, sampler_of(method)),
        ))  # fmt: skip
        extra["methods"][method] = res
        print(f"{method:>12}: minADE {res['min_ade']:.3f} minFDE {res['min_fde']:.3f} "
              f"maxATS {res['max_ats']:.3f} maxFTS {res['max_fts']:.3f} "
              f"recall ATS {res['top1_recall_ats']:.3f}/{res['top5_recall_ats']:.3f} "
              f"FTS {res['top1_recall_fts']:.3f}/{res['top5_recall_fts']:.3f}")  # fmt: skip
    if not args.study_only:
        write_rows(ROOT / "benchmarks" / "results" / f"score_{args.dataset}.json", rows)
        timing(args, test, methods["pretrained"], scorer, extra)
    if args.study:
        study_doc(args, test, methods["pretrained"], models)


def timing(args, test, leap, scorer, extra) -> None:
    """Cost of ranking K samples of one scene; writes the meta file."""
    n = min(args.timing_scenes, len(test))
    elapsed = 0.0
    for i in range(n):
        batch = collate([test[i]])
        pred = leap.predict(batch, args.samples, torch.Generator().manual_seed(i))
        start = time.perf_counter()
        scorer.rank(batch, pred)
        elapsed += time.perf_counter() - start
    extra["ms_to_rank_k_samples_per_scene"] = 1000 * elapsed / n
    extra["timing_threads"] = torch.get_num_threads()
    extra["timing_scenes"] = n
    print(f"ranking K={args.samples} samples: {extra['ms_to_rank_k_samples_per_scene']:.1f} "
          f"ms per scene (mean over {n} scenes, {torch.get_num_threads()} threads)")  # fmt: skip
    meta = ROOT / "benchmarks" / "results" / "meta"
    meta.mkdir(exist_ok=True)
    (meta / f"score_{args.dataset}.json").write_text(json.dumps(extra, indent=2) + "\n")


def study_doc(args, test, leap, models) -> None:
    """The timestep / noise study, written to docs/score_study_<dataset>.md."""
    if args.study_scenes is not None and args.study_scenes < len(test):
        idx = torch.linspace(0, len(test) - 1, args.study_scenes).long().tolist()
        test = type(test)([test.scenes[i] for i in idx], test.info)
    preds = predictions(leap, test, args.samples, args.seed)
    table = study(models / ckpt.DENOISER_NAME, preds, args.study_seeds)
    lines = [
        f"# Score study on {args.dataset} (test split, {len(test)} scenes, leapfrog samples, "
        f"K = {args.samples})", "",
        "Mean over scorer seeds (± std across seeds) of the top-1 / top-5 recall of the "
        "ground-truth-free ranking (chance: 1/K and 5/K), and maxATS20 / maxFTS20. The "
        "predictions are fixed; only the scorer's noise seed and settings change.", "",
        "| setting | top-1 ATS | top-5 ATS | top-1 FTS | top-5 FTS | maxATS | maxFTS "
        "| s per pass |",
        "|---|---|---|---|---|---|---|---|",
    ]  # fmt: skip
    keys = ("top1_recall_ats", "top5_recall_ats", "top1_recall_fts", "top5_recall_fts",
            "max_ats", "max_fts")  # fmt: skip
    for name, s in table:
        cells = " | ".join(f"{s[k][0]:.3f} ± {s[k][1]:.3f}" for k in keys)
        lines.append(f"| {name} | {cells} | {s['seconds'][0]:.1f} |")
    lines += ["", f"_Generated by `{command_line()}` on {date.today().isoformat()}, "
              f"{machine()}; {args.study_seeds} scorer seeds._", ""]  # fmt: skip
    (ROOT / "docs" / f"score_study_{args.dataset}.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
