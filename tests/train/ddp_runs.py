"""Run by ``torchrun`` (2 processes) from test_ddp.py: the runs whose results the tests compare
with one process's, each a few steps on the tiny synthetic walks, in ``out``:

- ``full``: the denoiser stage, uninterrupted (2 epochs);
- ``stop``: the same run stopped after its first epoch, then resumed to its end;
- ``mix12``: a state that one process wrote after the first epoch (made by the test before
  this launch), resumed here on two; ``stop21``: the first epoch, for the test to resume on
  one;
- ``shape``: one epoch of a stage whose loss is a statistic of the batch alone (no random
  draw, no weight moves it), so that the logged training loss can be compared exactly;
- ``control``: two fine-tuning steps of the control (its critic gets no gradient), from the
  generator ``start``; each rank saves its weights;
- ``gen_full`` and ``gen_stop``: the generator stage with dropout (on ``start``'s denoiser),
  uninterrupted, and stopped after its first epoch then resumed.
"""

import dataclasses
import sys
from pathlib import Path

import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from synthetic import TINY_OVERRIDES  # noqa: E402

from trajpref.config import ExperimentConfig, load_config  # noqa: E402
from trajpref.data import load_dataset  # noqa: E402
from trajpref.models import checkpoint as ckpt  # noqa: E402
from trajpref.rl.presets import finetune_config  # noqa: E402
from trajpref.train.distributed import barrier, cleanup, init_from_env  # noqa: E402
from trajpref.train.loop import fit  # noqa: E402
from trajpref.train.stages import (  # noqa: E402
    Stage,
    build_denoiser_stage,
    build_finetune_stage,
    build_generator_stage,
)
from trajpref.types import Batch, TrajectoryDataset  # noqa: E402


def config(folder: str) -> ExperimentConfig:
    """The tiny config on ``folder``, as the tests' one-process runs use it."""
    return load_config(None, [*TINY_OVERRIDES, f"data.dataset={folder}"])


class ShapeObjective(nn.Module):
    """A loss that is a statistic of the batch alone: each agent's squared distance from the
    first to the last future step (unchanged by the rotation that augments it), averaged
    over the agents; the denoiser's weights enter it only times 0, so that DDP has their
    gradients."""

    def __init__(self, denoiser: nn.Module):
        super().__init__()
        self.denoiser = denoiser

    def forward(self, batch: Batch, generator: torch.Generator | None = None):
        span = (batch.future[:, -1] - batch.future[:, 0]).pow(2).sum(-1)  # [N]
        zero = sum(p.sum() for p in self.denoiser.parameters()) * 0.0
        return span.mean() + zero, {}


def shape_stage(cfg: ExperimentConfig, train: TrajectoryDataset, val: TrajectoryDataset,
                device: torch.device) -> Stage:  # fmt: skip
    """The denoiser stage with ``ShapeObjective`` as its loss."""
    stage, _ = build_denoiser_stage(cfg, train, val, device)
    return dataclasses.replace(stage, objective=ShapeObjective(stage.trainable))


def main(folder: str, out: str, start: str, steps_per_epoch: int) -> None:
    out_dir = Path(out)
    info, device = init_from_env(torch.device("cpu"))
    cfg = config(folder)
    train = load_dataset(folder, "train")
    val = load_dataset(folder, "val")

    def denoiser(where: str, **kw) -> nn.Module:
        stage, _ = build_denoiser_stage(cfg, train, val, device)
        fit(stage, train, cfg.data, cfg.denoiser, out_dir / where, device, cfg.seed,
            dist_info=info, progress=False, **kw)  # fmt: skip
        barrier(info)  # rank 0's files written before any rank reads them
        return stage.trainable

    denoiser("full")
    denoiser("stop", max_steps=steps_per_epoch)
    denoiser("stop", resume=str(out_dir / "stop" / "denoiser_last.pt"))
    denoiser("mix12", resume=str(out_dir / "mix12" / "denoiser_last.pt"))
    denoiser("stop21", max_steps=steps_per_epoch)  # the test resumes it on one process

    stage = shape_stage(cfg, train, val, device)
    fit(stage, train, cfg.data, cfg.denoiser, out_dir / "shape", device, cfg.seed,
        dist_info=info, progress=False, max_steps=steps_per_epoch)  # fmt: skip

    ft = finetune_config(start, "control", overrides=[f"data.dataset={folder}",
                                                      "finetune.eval_max_scenes=4"])  # fmt: skip
    control = build_finetune_stage(ft, ckpt.load(start), val, device)
    fit(control, train, ft.data, ft.finetune, out_dir / "control", device, ft.seed,
        dist_info=info, progress=False, max_steps=2)  # fmt: skip
    torch.save(control.trainable.state_dict(), out_dir / "control" / f"rank{info.rank}.pt")
    barrier(info)

    # dropout draws from torch's own generator, each rank's own (their batches differ)
    gen_cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={folder}",
                                 "model.generator_dropout=0.2"])  # fmt: skip
    denoiser_payload = ckpt.load(start)["denoiser"]

    def generator(where: str, first_masks: bool = False, **kw) -> None:
        stage = build_generator_stage(gen_cfg, denoiser_payload, val, device)
        states = []  # torch's generator when the first dropout of a training step draws
        if first_masks:
            drop = next(m for m in stage.objective.modules() if isinstance(m, torch.nn.Dropout))
            drop.register_forward_pre_hook(
                lambda module, _: states.append(torch.get_rng_state()) if module.training else None
            )
        fit(stage, train, gen_cfg.data, gen_cfg.generator, out_dir / where, device,
            gen_cfg.seed, dist_info=info, progress=False, **kw)  # fmt: skip
        if first_masks:
            torch.save(states[0], out_dir / where / f"first_mask_rng_rank{info.rank}.pt")
        barrier(info)

    generator("gen_full", first_masks=True)
    generator("gen_stop", max_steps=steps_per_epoch)
    generator("gen_stop", resume=str(out_dir / "gen_stop" / "generator_last.pt"))
    barrier(info)  # both ranks done before gloo is torn down (distributed.cleanup)
    cleanup(info)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]))
