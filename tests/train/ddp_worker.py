"""Run by ``torchrun`` from test_ddp.py: a few DDP steps of both stages, then each rank saves
its parameters so the test can compare them."""

import dataclasses
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from synthetic import TINY_OVERRIDES  # noqa: E402

from trajpref.config import load_config  # noqa: E402
from trajpref.data import load_dataset  # noqa: E402
from trajpref.models import checkpoint as ckpt  # noqa: E402
from trajpref.train.distributed import barrier, cleanup, init_from_env  # noqa: E402
from trajpref.train.loop import fit  # noqa: E402
from trajpref.train.stages import build_denoiser_stage, build_generator_stage  # noqa: E402


def main(folder: str, out: str) -> None:
    out_dir = Path(out)
    info, device = init_from_env(torch.device("cpu"))
    cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={folder}"])
    train = load_dataset(folder, "train")
    val = load_dataset(folder, "val")
    stage, _ = build_denoiser_stage(cfg, train, val, device)
    fit(stage, train, cfg.data, cfg.denoiser, out_dir, device, cfg.seed, dist_info=info,
        progress=False, max_steps=3)  # fmt: skip
    torch.save(stage.trainable.state_dict(), out_dir / f"denoiser_rank{info.rank}.pt")
    barrier(info)
    gen = build_generator_stage(cfg, ckpt.load(out_dir / "denoiser.safetensors"), val, device)
    # a budget the steps cannot keep pace with: each rank's clock reads a different share, and
    # the ranks must still step with one learning rate (the largest share, all-reduced)
    budget = dataclasses.replace(cfg.generator, max_minutes=0.01, budget_schedule=True)
    fit(gen, train, cfg.data, budget, out_dir, device, cfg.seed, dist_info=info,
        progress=False, max_steps=3)  # fmt: skip
    torch.save(gen.trainable.state_dict(), out_dir / f"generator_rank{info.rank}.pt")
    barrier(info)  # both ranks done before gloo is torn down (distributed.cleanup)
    cleanup(info)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
