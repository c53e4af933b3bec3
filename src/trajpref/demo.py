"""``make demo``: the whole pipeline on the CPU in a few minutes.

Simulates the Robo scenario (robo-sim), trains the denoiser and the leapfrog generator on it,
fine-tunes the generator with RLHF-ReS, and evaluates constant velocity, the pretrained model
and the RLHF-ReS model on the official Robo test set (or robo-sim's test split when the data is
not on this machine); prints a table and writes figures.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.errors import TrajprefError
from trajpref.evaluation import evaluate
from trajpref.models import checkpoint as ckpt
from trajpref.models.baseline import ConstantVelocity
from trajpref.rl.presets import finetune_config
from trajpref.score import TrajectoryScorer
from trajpref.train.run import finetune, train_stage
from trajpref.types import collate
from trajpref.viz.plot import plot_scene, plot_scene_scored

DEFAULT_CONFIG = Path(__file__).resolve().parent / "resources" / "demo.yaml"
"""The embedded demo config: a small model and short schedules (shipped with the package)."""


def run(out: Path, data_root: str | None, samples: int, seed: int, config: Path,
        overrides: list[str]) -> None:  # fmt: skip
    t0 = time.perf_counter()
    train = load_dataset("robo-sim", "train")
    print(f"[1/5] simulated robo-sim: {len(train)} episodes, {train.num_agents} agents "
          f"in {time.perf_counter() - t0:.1f} s")  # fmt: skip
    try:
        test = load_dataset("robo", "test", data_root)
        where, val = "official Robo test set", "robo"
    except TrajprefError as exc:
        print(f"      ({exc}; using robo-sim's splits instead)")
        test = load_dataset("robo-sim", "test")
        where, val = "robo-sim test split", "robo-sim"
    cfg = load_config(config, [f"data.val_dataset={val}", f"seed={seed}", *overrides])

    run_dir = out / "run"
    t1 = time.perf_counter()
    train_stage("diffusion", cfg, run_dir, data_root, "auto")
    train_stage("generator", cfg, run_dir, data_root, "auto")
    print(f"[2/5] trained the denoiser and the generator in {time.perf_counter() - t1:.0f} s")
    t2 = time.perf_counter()
    generator = run_dir / f"generator{ckpt.SUFFIX}"
    ft_cfg = finetune_config(generator, "rlhf-res", None, config,
                             [f"data.val_dataset={val}", *overrides], seed)  # fmt: skip
    finetune(ft_cfg, generator, run_dir / "rlhf-res", data_root, "auto")
    print(f"[3/5] fine-tuned with RLHF-ReS in {time.perf_counter() - t2:.0f} s")

    scorer = TrajectoryScorer.from_checkpoint(run_dir / f"denoiser{ckpt.SUFFIX}")
    models = {
        f"constant velocity (K={samples})": ConstantVelocity(),
        "pretrained (leapfrog)": ckpt.load_predictor(generator),
        "RLHF-ReS": ckpt.load_predictor(run_dir / "rlhf-res" / f"finetune{ckpt.SUFFIX}"),
    }
    # The demo's models are small and briefly trained: say so wherever their output is shown,
    # so a figure taken out of the demo is not read as the published Robo model's.
    ft = ft_cfg.finetune
    ft_budget = (f"{ft.epochs} RLHF-ReS epochs" if ft.steps_per_epoch is None
                 else f"{ft.epochs * ft.steps_per_epoch} RLHF-ReS steps")  # fmt: skip
    epochs = cfg.generator.epochs
    demo_model = f"demo model ({epochs} generator epoch{'s' * (epochs != 1)}, {ft_budget})"
    print(f"[4/5] {where} ({test.num_agents} agents, {len(test)} scenes), metres, K={samples}; "
          f"the {demo_model}, not the published robo config (--config robo):")  # fmt: skip
    print(f"  {'method':<26} {'minADE':>7} {'minFDE':>7} {'jADE':>7} {'jFDE':>7} "
          f"{'maxATS':>7} {'maxFTS':>7}")  # fmt: skip
    for name, model in models.items():
        r = evaluate(model, test, samples, seed, scorer=scorer, progress=False)
        print(f"  {name:<26} {r['min_ade']:7.3f} {r['min_fde']:7.3f} {r['joint_min_ade']:7.3f} "
              f"{r['joint_min_fde']:7.3f} {r['max_ats']:7.3f} {r['max_fts']:7.3f}")  # fmt: skip

    scene = test[0]
    batch = collate([scene])
    gen = torch.Generator().manual_seed(seed)
    pred = models["RLHF-ReS"].predict(batch, samples, gen)  # [K, P, T_f, 2]
    res = scorer.score(batch, pred)
    agent_ats = res.agent_ats.numpy()  # [K, P]
    figs = [
        plot_scene(scene.history, scene.future, pred.numpy(), out / "robo_scene0_rlhf_res.png",
                   "m", f"{where}, scene 0, RLHF-ReS {demo_model}, K={samples}"),
        plot_scene_scored(scene.history, scene.future, pred.numpy(), agent_ats,
                          out / "robo_scene0_scored.png", "m",
                          f"{where}, scene 0, {demo_model}"),
    ]  # fmt: skip
    total = time.perf_counter() - t0
    print(f"[5/5] wrote {', '.join(str(f) for f in figs)} (total {total:.0f} s)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m trajpref.demo",
        description="make demo: the whole pipeline on the CPU in a few minutes (simulate Robo, "
        "train the denoiser and the generator, fine-tune with RLHF-ReS, evaluate, plot)",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
        allow_abbrev=False,  # as the trajpref command: long options spelled out in full
    )
    parser.add_argument("--out", default="out/demo", help="output folder")
    parser.add_argument("--data-root", default=None, help="data folder; None: $TRAJPREF_DATA")
    parser.add_argument("--samples", type=int, default=20, help="K, futures per agent")
    parser.add_argument("--seed", type=int, default=0, help="seed of training and evaluation")
    parser.add_argument("--config", default=str(DEFAULT_CONFIG), help="pipeline config (YAML)")
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config value (repeatable); default: none",
    )
    args = parser.parse_args(argv)
    try:
        run(Path(args.out), args.data_root, args.samples, args.seed, Path(args.config),
            args.overrides)  # fmt: skip
    except TrajprefError as exc:
        print(f"trajpref demo: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C: one line and 130, as `trajpref train` (cli.main)
        print("trajpref demo: interrupted (run it again to start over)", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
