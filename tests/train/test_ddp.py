"""Two CPU processes under torchrun (gloo): after a few DDP steps both ranks hold identical
parameters (the generator's with a time budget that sets its learning rate), and rank 0 alone
writes the run files."""

import importlib.util
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from synthetic import write_dataset

from trajpref.models import checkpoint as ckpt


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_process_ddp_ranks_agree(tmp_path):
    folder = write_dataset(tmp_path / "walks")
    out = tmp_path / "run"
    out.mkdir()
    worker = Path(__file__).with_name("ddp_worker.py")
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2",
           "--master_addr=127.0.0.1", f"--master_port={_free_port()}",
           str(worker), str(folder), str(out)]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for stage in ("denoiser", "generator"):
        r0 = torch.load(out / f"{stage}_rank0.pt", weights_only=True)
        r1 = torch.load(out / f"{stage}_rank1.pt", weights_only=True)
        assert r0.keys() == r1.keys()
        for key in r0:
            assert torch.equal(r0[key], r1[key]), f"{stage}.{key} differs between ranks"
    # rank 0 alone wrote the run files, after the 3 steps it was given
    assert torch.load(out / "denoiser_last.pt", weights_only=True)["step"] == 3
    assert (out / "denoiser_metrics.jsonl").read_text().count("\n") == 1


def test_the_readme_torchrun_command_trains_both_stages(tmp_path):
    """The README's launch, ``torchrun -m trajpref.cli train ...``, through the CLI and
    ``train.run`` (which waits for every rank before leaving the process group). An explicit
    ``OMP_NUM_THREADS`` is each process's (it was divided again by the process count); the
    run record keeps the launcher's command line for the resume advice, and the config says
    that the run trained on two processes."""
    import json
    import os
    import shlex

    from synthetic import TINY_OVERRIDES

    folder = write_dataset(tmp_path / "walks")
    out = tmp_path / "run"
    sets = [arg for o in [*TINY_OVERRIDES, f"data.dataset={folder}"] for arg in ("--set", o)]
    launchers = {}
    for stage in ("diffusion", "generator"):
        cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2",
               "--master_addr=127.0.0.1", f"--master_port={_free_port()}", "-m",
               "trajpref.cli", "train", stage, "--out", str(out), "--device", "cpu",
               "--no-progress", *sets]  # fmt: skip
        launchers[stage] = shlex.join(cmd[: cmd.index("train")])  # with its own port
        env = {**os.environ, "OMP_NUM_THREADS": "2"}
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert "terminate called" not in proc.stderr
    for stage, name in (("diffusion", "denoiser"), ("generator", "generator")):
        assert (out / f"{name}.safetensors").is_file()
        assert (out / f"{name}_metrics.jsonl").read_text().count("\n") == 2  # 2 epochs, rank 0
        session = json.loads((out / f"{name}_run.json").read_text())[-1]
        assert session["threads"] == 2 and session["world_size"] == 2
        assert session["launcher"] == launchers[stage]
        assert (out / f"{name}_config.yaml").read_text().startswith("# trained on 2 processes")


# --- two processes against one: the same schedule, the whole batches' log, resumes, the
# fine-tuning control (one torchrun launch, tests/train/ddp_runs.py, for all of them)


def _ddp_runs():
    spec = importlib.util.spec_from_file_location(
        "ddp_runs", Path(__file__).with_name("ddp_runs.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def runs(tmp_path_factory, walks, tiny_run):
    """``two``: ddp_runs.py's folders (2 processes); ``one``: the same runs on one process."""
    from trajpref.data import load_dataset
    from trajpref.data.loader import SceneLoader
    from trajpref.train.loop import fit
    from trajpref.train.stages import build_denoiser_stage

    worker = _ddp_runs()
    one, two = tmp_path_factory.mktemp("one"), tmp_path_factory.mktemp("two")
    cfg = worker.config(str(walks))
    train, val = load_dataset(str(walks), "train"), load_dataset(str(walks), "val")
    steps = len(SceneLoader(train, max_agents=cfg.data.max_agents))
    cpu = torch.device("cpu")

    def one_process(folder, stage=None, **kw):
        stage = stage or build_denoiser_stage(cfg, train, val, cpu)[0]
        fit(stage, train, cfg.data, cfg.denoiser, folder, cpu, cfg.seed, progress=False, **kw)

    one_process(one / "full")
    one_process(one / "shape", worker.shape_stage(cfg, train, val, cpu), max_steps=steps)
    one_process(two / "mix12", max_steps=steps)  # resumed on two processes by the worker
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2",
           "--master_addr=127.0.0.1", f"--master_port={_free_port()}",
           str(Path(__file__).with_name("ddp_runs.py")), str(walks), str(two),
           str(tiny_run / "generator.safetensors"), str(steps)]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return {"one": one, "two": two, "cfg": cfg, "steps": steps, "start": tiny_run}


def _last(folder, name="denoiser"):
    return torch.load(folder / f"{name}_last.pt", weights_only=True)


def test_two_processes_train_the_one_process_schedule(runs):
    """The same optimiser steps and learning rates epoch by epoch (each step's batch is one
    process's, shared between the ranks), and a validation loss close to one process's
    (the random draws differ)."""
    from trajpref.train import read_metrics

    one = read_metrics(runs["one"] / "full", "denoiser")
    two = read_metrics(runs["two"] / "full", "denoiser")
    assert (
        [r["step"] for r in two] == [r["step"] for r in one] == [runs["steps"], 2 * runs["steps"]]
    )
    assert [r["lr"] for r in two] == [r["lr"] for r in one]
    assert [r["processes"] for r in two] == [2, 2] and one[0]["processes"] == 1
    assert two[-1]["val_score"] == pytest.approx(one[-1]["val_score"], rel=0.05)
    meta = ckpt.read_checkpoint_header(runs["two"] / "full" / "denoiser.safetensors")["meta"]
    assert meta["processes"] == 2


def test_the_log_reports_the_whole_batches_not_rank_0s(runs):
    """A loss that depends on the batch alone logs the same epoch mean on two processes as on
    one: the ranks' agent-weighted sums are added before the log is written."""
    from trajpref.train import read_metrics

    one = read_metrics(runs["one"] / "shape", "denoiser")[0]
    two = read_metrics(runs["two"] / "shape", "denoiser")[0]
    assert two["step"] == one["step"] == runs["steps"]
    assert two["train_loss"] == pytest.approx(one["train_loss"], rel=1e-5)


def test_a_two_process_resume_ends_where_the_uninterrupted_run_does(runs):
    """Each rank's random generators are saved and restored: stopped after its first epoch
    and resumed, the run ends bit for bit where the uninterrupted one does."""
    full, stop = _last(runs["two"] / "full"), _last(runs["two"] / "stop")
    assert stop["step"] == full["step"] and stop["world_size"] == 2
    assert len(stop["rank_generators"]) == 2
    assert not torch.equal(stop["rank_generators"][0]["noise_gen"],
                           stop["rank_generators"][1]["noise_gen"])  # fmt: skip
    for key, value in full["trainable"].items():
        assert torch.equal(stop["trainable"][key], value), key


def test_a_two_process_generator_with_dropout_resumes_where_the_uninterrupted_run_ends(runs):
    """Dropout draws from torch's own generator: each rank's is saved and restored (how far
    one has run may differ between the ranks: on a GPU it counts the elements drawn), so that
    the resumed run ends bit for bit where the uninterrupted one does."""
    full = _last(runs["two"] / "gen_full", "generator")
    stop = _last(runs["two"] / "gen_stop", "generator")
    assert stop["step"] == full["step"] == 2 * runs["steps"]
    for key, value in full["trainable"].items():
        assert torch.equal(stop["trainable"][key], value), key
    assert [sorted(own) for own in stop["rank_generators"]] == [
        ["aug_gen", "noise_gen", "torch_rng"]
    ] * 2


def test_each_rank_draws_its_own_dropout_masks(runs):
    """The stage builder seeds every rank alike (the same starting weights); the loop then
    seeds torch's generator of each rank after the first by its rank, so that the ranks'
    first dropout masks are not drawn from one stream (they were, before 2026-12-06)."""
    folder = runs["two"] / "gen_full"
    r0 = torch.load(folder / "first_mask_rng_rank0.pt", weights_only=True)
    r1 = torch.load(folder / "first_mask_rng_rank1.pt", weights_only=True)
    assert not torch.equal(r0, r1)


def test_a_resume_on_another_process_count_continues_the_same_schedule(runs, capsys):
    """A state written on one process resumed on two, and one written on two resumed on one,
    end at the uninterrupted run's step and learning rate (the schedule does not depend on
    the count); the second says that its random draws differ from an uninterrupted run's."""
    from trajpref.train import read_metrics
    from trajpref.train.run import train_stage

    one = read_metrics(runs["one"] / "full", "denoiser")
    mix12 = read_metrics(runs["two"] / "mix12", "denoiser")
    assert [(r["step"], r["lr"]) for r in mix12] == [(r["step"], r["lr"]) for r in one]
    assert [r["processes"] for r in mix12] == [1, 2]
    folder = runs["two"] / "stop21"
    train_stage("diffusion", runs["cfg"], folder, device="cpu", progress=False,
                resume=str(folder / "denoiser_last.pt"))  # fmt: skip
    assert "resumed on 1 process(es) from a state written on 2" in capsys.readouterr().err
    mix21 = read_metrics(folder, "denoiser")
    assert [(r["step"], r["lr"]) for r in mix21] == [(r["step"], r["lr"]) for r in one]


def test_the_fine_tuning_control_trains_on_two_processes(runs):
    """The control never calls its critic: DDP is told so, the ranks agree, and the critic
    keeps its initial weights (no gradient, as on one process)."""
    from trajpref.data import load_dataset
    from trajpref.rl.presets import finetune_config
    from trajpref.train.stages import build_finetune_stage

    r0 = torch.load(runs["two"] / "control" / "rank0.pt", weights_only=True)
    r1 = torch.load(runs["two"] / "control" / "rank1.pt", weights_only=True)
    for key in r0:
        assert torch.equal(r0[key], r1[key]), key
    start = runs["start"] / "generator.safetensors"
    cfg = finetune_config(start, "control", overrides=[f"data.dataset={runs['cfg'].data.dataset}"])
    val = load_dataset(runs["cfg"].data.dataset, "val")
    fresh = build_finetune_stage(cfg, ckpt.load(start), val, torch.device("cpu")).trainable
    fresh_state = fresh.state_dict()
    assert all(torch.equal(r0[k], v) for k, v in fresh_state.items() if k.startswith("critic."))
    assert not all(torch.equal(r0[k], v) for k, v in fresh_state.items() if k.startswith("policy."))
    assert _last(runs["two"] / "control", "finetune")["step"] == 2
