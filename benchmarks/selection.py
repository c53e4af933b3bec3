"""Keeping K' of the K = 20 samples, with and without the diffusion score (no training).

    # choose the settings on a validation split (prints a table; no results rows: its record
    # goes to results/meta/select_<D>_val[_<tag>].json, which a rerun with the same --tag
    # replaces, so give a new study its own --tag)
    python benchmarks/selection.py --dataset zara1 --split val --data-root ../shared/data
    # then the chosen settings, once, on the test split (rows: results/select_<D>.json)
    python benchmarks/selection.py --dataset zara1 --split test --drop 0.5 \
        --data-root ../shared/data

One pass predicts the 20 samples of every scene once (seed 0) and scores them once; every
selection method then works on the same samples, so the comparison is paired. Methods (see
``trajpref.score.selection``): ``first``, ``random``, ``kmeans``, ``fps`` (no score), ``top``,
``score-kmeans``, ``score-fps`` (score), and the coverage methods ``facility`` and ``medoids``
with their score-weighted ``score-`` forms. Per-agent metrics come from per-agent selection, joint
metrics from per-scene selection. The time of each selection (its share of the scoring
included) is reported in ms per scene, beside the prediction's own.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import time
from pathlib import Path

import numpy as np
import torch
from speed_clamp import observed_step  # the clamp rule's measure of an agent's pace

from trajpref.data import hold_out_scene, load_dataset, run_splits
from trajpref.data.loader import SceneLoader
from trajpref.data.transforms import scene_speeds
from trajpref.evaluation import sampled_batches
from trajpref.io import read_checkpoint_header
from trajpref.metrics import MetricAccumulator, min_ade_fde
from trajpref.models import checkpoint as ckpt
from trajpref.results import command_line, machine, make_row, upsert_rows
from trajpref.score.scorer import PRECISIONS, TrajectoryScorer, score_timesteps
from trajpref.score.selection import (
    DROPPING,
    METHODS,
    WEIGHTED,
    SelectionConfig,
    batch_observed_pace,
    gather,
    select_samples,
    within_pace,
)
from trajpref.types import TrajectoryDataset

ROOT = Path(__file__).resolve().parent.parent


def settings(args) -> list[SelectionConfig]:
    """Every (method, K', drop, per) this run measures."""
    out = []
    methods = args.methods or METHODS
    for method, keep, per in itertools.product(methods, args.keep, ("agent", "scene")):
        drops = args.drop if method in DROPPING else [0.0]
        temps = args.temperature if method in WEIGHTED else [1.0]
        for drop, temp in itertools.product(drops, temps):
            bandwidth = args.free_bandwidth if method == "facility" else args.bandwidth
            out.append(SelectionConfig(keep=keep, method=method, drop=drop, per=per,
                                       final=args.final, temperature=temp,
                                       bandwidth=bandwidth or args.bandwidth))  # fmt: skip
    return out


PAPER_SCORE_EVERY = 3
"""The paper's spacing of the score steps (34 of 100); other spacings name their rows."""
FACILITY_BANDWIDTH = 0.5
"""score-facility's bandwidth in the rows before 2026-11-27; others name their rows."""


def name_of(cfg: SelectionConfig) -> str:
    drop = f"-d{round(cfg.drop * 100):02d}" if cfg.method in DROPPING else ""
    temp = f"-t{cfg.temperature:g}" if cfg.method in WEIGHTED else ""
    if cfg.method == "score-facility" and cfg.bandwidth != FACILITY_BANDWIDTH:
        temp += f"-b{cfg.bandwidth:g}"
    return f"select-{cfg.method}{drop}{temp}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--split", default="val", choices=["val", "test"])
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--model", default=None, help="default models/<D>/generator.safetensors")
    parser.add_argument(
        "--variant", default=None,
        help="a published variant (models/<D>/generator-NAME.safetensors): its methods carry "
        "the suffix -NAME, its rows go to select_<D>_NAME.json")  # fmt: skip
    parser.add_argument(
        "--scorer", default=None,
        help="a denoiser checkpoint (path or DATASET/NAME) that scores the samples instead of "
        "the generator's own; the pace gate then reads its training windows, with any paced "
        "copy it trained on (data.extra_time_step); rows carry -scorer-<its stem>")  # fmt: skip
    parser.add_argument("--samples", type=int, default=20, help="K, the candidates")
    parser.add_argument("--keep", type=int, nargs="+", default=[1, 3, 5])
    parser.add_argument("--drop", type=float, nargs="+", default=[0.25, 0.3, 0.4, 0.5, 0.6])
    parser.add_argument("--methods", nargs="+", default=None, choices=METHODS)
    parser.add_argument("--temperature", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    parser.add_argument(
        "--bandwidth",
        type=float,
        default=FACILITY_BANDWIDTH,
        help="score-facility's (other values name the rows, -b<value>)",
    )
    parser.add_argument("--free-bandwidth", type=float, default=None,
                        help="facility's (default: --bandwidth)")  # fmt: skip
    parser.add_argument("--final", action="store_true", help="score by the final step (FTS)")
    parser.add_argument("--score-every", type=int, default=9, help="score steps' spacing")
    parser.add_argument("--score-from", type=int, default=0,
                        help="the first score step (0, the lowest noise level; a later one "
                        "keeps only the noisier steps, whose rows carry f<step>)")  # fmt: skip
    parser.add_argument("--max-scenes", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--speed-norm",
        type=float,
        default=None,
        metavar="Q",
        help="score with speed normalisation: speed_ref = the Q-quantile of the training "
        "split's scene speeds (docs/selection.md)",
    )
    parser.add_argument(
        "--pace-bins",
        type=float,
        nargs="+",
        default=None,
        metavar="Q",
        help="diagnosis: also report per-agent minFDE_K' within bins of observed pace cut at "
        "these quantiles of the training split's observed step (meta file only; no rows)",
    )
    parser.add_argument(
        "--score-precision",
        default="fp32",
        choices=PRECISIONS,
        help="arithmetic of the score passes; bf16 rows of score methods carry the suffix -bf16",
    )
    parser.add_argument(
        "--trust-quantile",
        type=float,
        default=None,
        metavar="Q",
        help="score methods fall back to their score-free counterpart for agents observed "
        "faster than the Q-quantile of the training split's observed step (model units; "
        "SelectionConfig.trust_speed); their rows carry the suffix -gate",
    )
    parser.add_argument(
        "--stretch",
        type=float,
        default=1.0,
        help="validation only: multiply every coordinate by this (a scene moving this much "
        "faster, as eth's test split does against its training folds)",
    )
    parser.add_argument(
        "--holdout-scene",
        default=None,
        metavar="PREFIX",
        help="validation on a training location the model did not see: that scene's windows "
        "of the train and val splits (trajpref.data.hold_out_scene); use a generator and "
        "denoiser trained with data.holdout_scene=PREFIX (runs/holdout/<D>/)",
    )
    parser.add_argument("--tag", default="", help="suffix of the meta file (validation runs)")
    parser.add_argument(
        "--draws",
        type=int,
        default=1,
        help="oversampling: D passes with seeds seed..seed+D-1 (the same generator samples, "
        "other tau-step noise) give D*K candidates; `first` then keeps the first pass's own K",
    )
    args = parser.parse_args()
    torch.manual_seed(args.seed)
    if args.stretch != 1.0 and args.split == "test":
        parser.error("--stretch simulates a shift on validation data; not on a test split")
    if args.holdout_scene is not None and (args.split != "val" or not args.holdout_scene):
        parser.error("--holdout-scene needs a file-name prefix and --split val")

    stem = f"generator-{args.variant}" if args.variant else "generator"
    path = Path(args.model or ROOT / "models" / args.dataset / f"{stem}.safetensors")
    model = ckpt.load_predictor(path, sampler="leapfrog")
    steps = score_timesteps(model.schedule.num_steps, args.score_every, args.score_from)
    # rows and test records of other steps than the paper's name their number of steps, and
    # their first step when it is not the chain's first
    steps_tag = ""
    if args.score_every != PAPER_SCORE_EVERY or args.score_from:
        steps_tag = f"s{len(steps)}" + (f"f{args.score_from}" if args.score_from else "")
    trained_on = training_dataset(path)  # robo's models train on robo-sim: robo has no train split
    speed_ref = None
    if args.speed_norm is not None:
        speed_ref = training_speed(trained_on, args.data_root, args.speed_norm)
        print(f"speed_ref = {speed_ref:.4f} units/step (the {args.speed_norm:g}-quantile of the "
              "training split's scene speeds)")  # fmt: skip
    if args.scorer:
        scorer = TrajectoryScorer.from_checkpoint(args.scorer, steps=steps, speed_ref=speed_ref,
                                                  precision=args.score_precision)  # fmt: skip
    else:
        scorer = TrajectoryScorer(model.denoiser, model.schedule, model.scale, steps,
                                  speed_ref=speed_ref, precision=args.score_precision)  # fmt: skip
    trust_speed, cuts = 0.0, []
    if args.trust_quantile is not None or args.pace_bins:
        gate_data = (scorer_training_split(args.scorer, args.data_root) if args.scorer
                     else load_dataset(trained_on, "train", args.data_root))  # fmt: skip
        train_pace = observed_step(gate_data, model.scale)
        cuts = [float(np.quantile(train_pace, q)) for q in sorted(args.pace_bins or [])]
    if args.trust_quantile is not None:
        trust_speed = float(np.quantile(train_pace, args.trust_quantile))
        print(f"trust_speed = {trust_speed:.4f} model units/step (the {args.trust_quantile:g}"
              "-quantile of the training split's observed step)")  # fmt: skip
    data = load_dataset(args.dataset, args.split, args.data_root)
    if args.holdout_scene:  # the held-out location's windows of both splits
        train = load_dataset(args.dataset, "train", args.data_root)
        data = hold_out_scene(train, data, args.holdout_scene)[1]
    data = data.evenly_spaced(args.max_scenes)
    if args.stretch != 1.0:
        data = stretched(data, args.stretch)

    configs = settings(args)
    accs = {i: MetricAccumulator() for i in range(len(configs))}
    bins = len(cuts) + 1
    bin_fde = {i: torch.zeros(bins, dtype=torch.float64) for i in range(len(configs))}
    bin_agents = torch.zeros(bins, dtype=torch.float64)
    seconds = {"predict": 0.0, "score": 0.0} | {i: 0.0 for i in range(len(configs))}
    scenes = 0
    rng = torch.Generator().manual_seed(args.seed)
    t0 = time.perf_counter()
    passes = [sampled_batches(model, data, args.samples, args.seed + d, "cpu", 1024,
                              d == 0, f"select {args.dataset}/{args.split}")
              for d in range(args.draws)]  # fmt: skip
    for drawn in zip(*passes, strict=True):
        batch = drawn[0][0]
        pred = torch.cat([p for _, p in drawn])  # [D*K, N, T_f, 2]
        seconds["predict"] += time.perf_counter() - t0
        t1 = time.perf_counter()
        d = scorer.residual(batch, pred)  # [K, N, T_f]; the ground truth is not read
        residual = d[..., -1] if args.final else d.sum(-1)  # [K, N]
        seconds["score"] += time.perf_counter() - t1
        trusted = within_pace(batch, model.scale, trust_speed)  # [N] or None
        if cuts:
            pace_bin = torch.bucketize(batch_observed_pace(batch, model.scale), torch.tensor(cuts))
            bin_agents += torch.bincount(pace_bin, minlength=bins).double()  # [bins]
        for i, cfg in enumerate(configs):
            t2 = time.perf_counter()
            idx = select_samples(pred, cfg, residual if cfg.uses_score else None, batch, rng,
                                 trusted if cfg.uses_score else None)  # fmt: skip
            seconds[i] += time.perf_counter() - t2
            kept = gather(pred, idx)  # [K', N, T_f, 2]
            accs[i].update(kept, batch.future, batch.scene, batch.num_scenes)
            if cuts and cfg.per == "agent":
                fde = min_ade_fde(kept, batch.future)[1]  # [N]
                bin_fde[i].index_add_(0, pace_bin, fde.double())  # [bins]
        scenes += batch.num_scenes
        t0 = time.perf_counter()

    rows, lines = [], []
    ms_predict = 1000 * seconds["predict"] / scenes
    ms_score = 1000 * seconds["score"] / scenes
    header = (f"{args.dataset}/{args.split}: {scenes} scenes, K = {args.samples} x {args.draws} "
              f"draws, score every "
              f"{args.score_every} from step {args.score_from} "
              f"({'final step' if args.final else 'whole future'}); "
              f"predict {ms_predict:.1f} ms/scene, score {ms_score:.1f} ms/scene")  # fmt: skip
    print(header)
    print(f"{'method':<26} {'per':<6} {'K':>2} {'minADE':>7} {'minFDE':>7} {'ms/scene':>8}")
    merged: dict[tuple, dict] = {}
    for i, cfg in enumerate(configs):
        res = accs[i].compute()
        ms = 1000 * seconds[i] / scenes + (ms_score if cfg.uses_score else 0.0)
        key = (name_of(cfg), cfg.keep)
        if cfg.per == "agent":
            ade, fde = res["min_ade"], res["min_fde"]
            merged.setdefault(key, {}).update(min_ade=ade, min_fde=fde, ms=ms,
                                              uses_score=cfg.uses_score)  # fmt: skip
        else:
            ade, fde = res["joint_min_ade"], res["joint_min_fde"]
            merged.setdefault(key, {}).update(joint_min_ade=ade, joint_min_fde=fde)
        lines.append(f"{key[0]:<26} {cfg.per:<6} {cfg.keep:>2} {ade:7.4f} {fde:7.4f} {ms:8.2f}")
        print(lines[-1])

    def row_method(method: str, uses_score: bool) -> str:
        """A row's method: the setting's name with the suffixes of this run's options."""
        method = method if args.draws == 1 else f"{method}-x{args.draws}"
        method += f"-{args.variant}" if args.variant else ""
        if args.scorer and uses_score:
            method += f"-scorer-{scorer_label(args.scorer)}"
        if steps_tag and uses_score:
            method += f"-{steps_tag}"
        if args.speed_norm is not None and uses_score:  # the score-free rows are as before
            method += f"-sn{round(args.speed_norm * 100)}"
        if trust_speed and uses_score:
            method += "-gate"
        if args.score_precision != "fp32" and uses_score:
            method += f"-{args.score_precision}"
        return method

    pace = None
    if cuts:
        edges = [0.0, *cuts, float("inf")]
        names = [f"{lo:.3f}-{hi:.3f}" for lo, hi in zip(edges, edges[1:], strict=False)]
        pace = {"quantiles": sorted(args.pace_bins), "cuts_model_units": cuts, "bins": names,
                "agents": bin_agents.tolist(), "min_fde": {}}  # fmt: skip
        print(f"per-agent minFDE by observed pace (model units/step; agents {bin_agents.tolist()})")
        for i, cfg in enumerate(configs):
            if cfg.per != "agent":
                continue
            per_bin = (bin_fde[i] / bin_agents.clamp(min=1)).tolist()
            pace["min_fde"][f"{row_method(name_of(cfg), cfg.uses_score)}@{cfg.keep}"] = per_bin
            cells = "  ".join(f"{n}: {v:.4f}" for n, v in zip(names, per_bin, strict=True))
            print(f"{name_of(cfg):<30} K'={cfg.keep}  {cells}")
    for (method, keep), v in merged.items():
        method = row_method(method, v["uses_score"])
        rows.append(make_row(
            dataset=args.dataset, split=args.split, method=method, seed=args.seed, samples=keep,
            min_ade=v["min_ade"], min_fde=v["min_fde"], joint_min_ade=v["joint_min_ade"],
            joint_min_fde=v["joint_min_fde"], ms_per_scene=round(v["ms"], 3),
            checkpoint=str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path),
            model_hash=ckpt.model_hash(path),
            uses_score=v["uses_score"],
        ))  # fmt: skip
    meta = {"header": header, "ms_predict_per_scene": ms_predict, "ms_score_per_scene": ms_score,
            "score_every": args.score_every, "score_from": args.score_from,
            "final": args.final, "scenes": scenes,
            "speed_ref": speed_ref, "stretch": args.stretch, "draws": args.draws,
            "trust_speed": trust_speed, "trust_quantile": args.trust_quantile,
            "score_precision": args.score_precision, "pace_bins": pace,
            "holdout_scene": args.holdout_scene, "scorer": args.scorer,
            "command": command_line(), "machine": machine()}  # fmt: skip
    out_dir = ROOT / "benchmarks" / "results"
    variant = f"_{args.variant}" if args.variant else ""
    suffix = (
        variant + ("" if args.split == "test" else "_val") + (f"_{args.tag}" if args.tag else "")
    )
    if steps_tag and args.split == "test":
        suffix += f"_{steps_tag}"  # beside the paper's spacing's record, not over it
    suffix += f"_seed{args.seed}" if args.seed else ""  # seed 0 keeps the files' old names
    (out_dir / "meta").mkdir(exist_ok=True)
    label = Path(args.dataset).name  # a user folder's name, not its whole path
    (out_dir / "meta" / f"select_{label}{suffix}.json").write_text(
        json.dumps(meta | {"rows": rows}, indent=2) + "\n"
    )
    if args.split == "test" and not cuts:  # a --pace-bins diagnosis writes its meta file only
        draws = "" if args.draws == 1 else f"_x{args.draws}"
        # rows of other seeds stay: each seed adds its own (results.upsert_rows)
        upsert_rows(out_dir / f"select_{label}{variant}{draws}.json", rows)


def training_dataset(path: Path) -> str:
    """The dataset whose training split trained the model at ``path`` (its recorded config):
    the split the pace gate and the speed normalisation read (``robo``'s models train on
    ``robo-sim``; the ETH/UCY folds on their own leave-one-out training split)."""
    return read_checkpoint_header(path)["config"]["data"]["dataset"]


def scorer_label(scorer: str) -> str:
    """A scorer's name in row methods: its run folder for a file path (``runs/pace/eth-den/
    denoiser.safetensors`` -> ``eth-den``), the name itself for a published ``DATASET/NAME``."""
    path = Path(scorer)
    if path.suffix:
        return path.parent.name or path.stem
    return scorer.replace("/", "-")


def scorer_training_split(scorer: str, data_root: str | None) -> TrajectoryDataset:
    """The windows a denoiser checkpoint trained on, built from its recorded data config as
    its run built them (``data.run_splits``: reading options, held-out scene, validation cut,
    and the copy at ``data.extra_time_step`` when it had one)."""
    header = read_checkpoint_header(ckpt.resolve_path(scorer))
    cfg = ckpt.config_of(header)
    return run_splits(cfg.data, data_root, cfg.model.windows)[0]


def training_speed(dataset: str, data_root: str | None, quantile: float) -> float:
    """The ``quantile`` of the training split's scene speeds (data units per step)."""
    train = load_dataset(dataset, "train", data_root)
    speeds = [scene_speeds(b) for b in SceneLoader(train, max_agents=4096, shuffle=False)]
    return float(np.quantile(torch.cat(speeds).numpy(), quantile))


def stretched(data: TrajectoryDataset, factor: float) -> TrajectoryDataset:
    """Every coordinate multiplied by ``factor`` (about the origin: the models are
    translation-invariant, so this is a pure change of speed and scene size)."""
    scenes = [dataclasses.replace(s, history=s.history * factor, future=s.future * factor)
              for s in data.scenes]  # fmt: skip
    return TrajectoryDataset(scenes, data.info)


if __name__ == "__main__":
    main()
