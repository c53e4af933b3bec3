"""Run by ``torchrun`` (2 processes) from test_ddp.py, each part writing what it found
into ``out`` (a part that fails leaves the others' files for their tests):

- ``budget``: the denoiser stage with a 0.02 min CPU-time budget, rank 1's clock made to run
  fast (0.5 s a reading), so that rank 1 alone spends the budget: each rank writes the
  seconds and steps ``fit`` returns (``budget_rank<R>.json``);
- ``same``, ``data``, ``seed``: the ranks' run facts compared (``train.run.check_same_run``)
  when they agree, when rank 1 reads another dataset (``other``) and when each rank takes its
  rank as its seed: each rank writes the error it got, or null (``check_<case>_rank<R>.json``).
"""

import dataclasses
import itertools
import json
import sys
import time
import types
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from synthetic import TINY_OVERRIDES  # noqa: E402

from trajpref.config import load_config  # noqa: E402
from trajpref.data import load_dataset  # noqa: E402
from trajpref.train import loop  # noqa: E402
from trajpref.train.distributed import barrier, cleanup, init_from_env  # noqa: E402
from trajpref.train.stages import build_denoiser_stage  # noqa: E402


def budget(info, device, cfg, folder: str, out: Path) -> None:
    train, val = load_dataset(folder, "train"), load_dataset(folder, "val")
    if info.rank == 1:  # rank 1's CPU clock reads 0.5 s more at each reading
        fast = itertools.count(step=0.5)
        loop.time = types.SimpleNamespace(perf_counter=time.perf_counter,
                                          process_time=lambda: float(next(fast)))  # fmt: skip
    section = dataclasses.replace(cfg.denoiser, epochs=3, max_minutes=0.02, budget_clock="cpu")
    stage, _ = build_denoiser_stage(cfg, train, val, device)
    try:
        summary = loop.fit(stage, train, cfg.data, section, out / "budget", device, cfg.seed,
                           dist_info=info, progress=False)  # fmt: skip
    finally:
        loop.time = time
    (out / f"budget_rank{info.rank}.json").write_text(json.dumps({
        "spent": summary["budget_seconds"], "steps": summary["steps"],
        "reached": summary["budget_reached"]}))  # fmt: skip


def same_run(info, cfg, folder: str, other: str, out: Path) -> None:
    from trajpref.errors import ConfigError
    from trajpref.train.run import check_same_run, data_fingerprint, run_facts

    for case in ("same", "data", "seed"):
        where = other if case == "data" and info.rank == 1 else folder
        seed = info.rank if case == "seed" else cfg.seed
        run_cfg = dataclasses.replace(cfg, seed=seed)
        train, val = load_dataset(where, "train"), load_dataset(where, "val")
        facts = run_facts(run_cfg, "denoiser", None, data_fingerprint(train, val), train, None)
        try:
            check_same_run(info, facts)
            found = None
        except ConfigError as exc:
            found = {"type": type(exc).__name__, "message": str(exc)}
        (out / f"check_{case}_rank{info.rank}.json").write_text(json.dumps(found))


def main(folder: str, other: str, out: str) -> None:
    out_dir = Path(out)
    info, device = init_from_env(torch.device("cpu"))
    cfg = load_config(None, [*TINY_OVERRIDES, f"data.dataset={folder}"])
    try:
        budget(info, device, cfg, folder, out_dir)
    finally:  # the other parts' files even when this one failed
        barrier(info)
        same_run(info, cfg, folder, other, out_dir)
        barrier(info)
        cleanup(info)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3])
