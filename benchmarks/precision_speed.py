"""How much faster a training step runs under bfloat16 autocast than in float32, side by side.

    python benchmarks/precision_speed.py --datasets zara1 sdd --data-root ../shared/data

For each dataset's default config and each pretraining stage (the denoiser by Eq. 2, the
generator through the published denoiser), the same training batches are stepped in turn with
``precision=fp32`` and ``precision=bf16`` (``train.loop.precision_autocast``, as the loop),
round after round, so both see the same machine load; the first round is warm-up and not
timed. Prints agent-windows per second of each and their ratio, and writes
benchmarks/results/meta/precision_speed.json. A speed ratio only: whether bf16 steps train as
well is a validation question (docs/pretraining.md, "bfloat16 training steps").
"""

from __future__ import annotations

import argparse
import itertools
import platform
import time
from pathlib import Path

import torch

from trajpref.config import load_config
from trajpref.data import load_dataset
from trajpref.data.loader import SceneLoader
from trajpref.models import checkpoint as ckpt
from trajpref.results import write_meta
from trajpref.train.loop import precision_autocast
from trajpref.train.stages import build_denoiser_stage, build_generator_stage

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results" / "meta" / "precision_speed.json"


def cpu_flags() -> list[str]:
    """The bfloat16-related instruction sets this CPU reports (Linux only; [] elsewhere)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return []
    words = set(text.split())
    return sorted(w for w in ("avx512_bf16", "amx_bf16", "amx_tile", "avx512f") if w in words)


def time_stage(stage, batches, rounds: int, device: torch.device) -> dict[str, float]:
    """Seconds per precision over ``rounds`` timed rounds (one warm-up round first), stepping
    an AdamW optimiser on the stage's trainable parameters as the loop does."""
    params = [p for p in stage.trainable.parameters() if p.requires_grad]
    opt = torch.optim.AdamW(params, lr=1e-5)  # small: the weights barely move between rounds
    stage.objective.train()
    seconds = {"fp32": 0.0, "bf16": 0.0}
    for r in range(rounds + 1):
        for batch in batches:
            for name in seconds:
                gen = torch.Generator().manual_seed(r)
                t0 = time.perf_counter()
                with precision_autocast(device, name):
                    loss, _ = stage.objective(batch, gen)
                opt.zero_grad(set_to_none=True)
                loss.float().backward()
                opt.step()
                if r > 0:
                    seconds[name] += time.perf_counter() - t0
    return seconds


def step_timing_args(description: str, dataset: str, out: Path) -> argparse.Namespace:
    """The options of the benchmarks that time training steps side by side (this one and
    ``optimizer_speed.py``), parsed and checked; torch then runs on ``--threads`` threads."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--datasets", nargs="+", default=[dataset])
    parser.add_argument("--data-root", default=None, help="default: $TRAJPREF_DATA")
    parser.add_argument("--batches", type=int, default=4, help="training batches per round")
    parser.add_argument("--rounds", type=int, default=3, help="timed rounds (after one warm-up)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--out", default=str(out))
    args = parser.parse_args()
    if args.batches < 1 or args.rounds < 1 or args.threads < 1:
        parser.error("--batches, --rounds and --threads must be >= 1")
    torch.set_num_threads(args.threads)
    return args


def timing_batches(dataset: str, args: argparse.Namespace, device: torch.device):
    """A default config, its training split and the first ``--batches`` batches of it (the
    same for every arm), and the agent-windows the timed rounds step over."""
    cfg = load_config(ROOT / "configs" / f"{dataset}.yaml")
    train = load_dataset(cfg.data.dataset, "train", args.data_root)
    loader = SceneLoader(train, max_agents=cfg.data.max_agents, shuffle=True, seed=0)
    batches = [b.to(device) for b in itertools.islice(loader, args.batches)]
    return cfg, train, batches, sum(b.num_agents for b in batches) * args.rounds


def timing_stages(cfg, train, dataset: str, device: torch.device) -> dict:
    """The stages to time: the denoiser by Eq. 2 and, when the dataset has a published
    denoiser, the generator through it."""
    stages = {"denoiser": build_denoiser_stage(cfg, train, train, device)[0]}
    published = ROOT / "models" / dataset / f"denoiser{ckpt.SUFFIX}"
    if published.is_file():
        stages["generator"] = build_generator_stage(cfg, ckpt.load(published), train, device)
    return stages


def main() -> None:
    args = step_timing_args(__doc__.splitlines()[0], "zara1", OUT)
    device = torch.device("cpu")

    entries = {}
    for dataset in args.datasets:
        cfg, train, batches, agents = timing_batches(dataset, args, device)
        stages = timing_stages(cfg, train, dataset, device)
        entry = {}
        for name, stage in stages.items():
            sec = time_stage(stage, batches, args.rounds, device)
            entry[name] = {
                "agent_windows": agents,
                "fp32_per_second": round(agents / sec["fp32"], 1),
                "bf16_per_second": round(agents / sec["bf16"], 1),
                "speedup": round(sec["fp32"] / sec["bf16"], 2),
            }
            print(f"{dataset:<9} {name:<9} fp32 {agents / sec['fp32']:7.1f}  bf16 "
                  f"{agents / sec['bf16']:7.1f} agent-windows/s  bf16 is "
                  f"{sec['fp32'] / sec['bf16']:.2f}x", flush=True)  # fmt: skip
        entries[dataset] = entry
    write_meta(args.out, datasets=entries, cpu_flags=cpu_flags(),
               processor=platform.processor() or platform.machine())  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
