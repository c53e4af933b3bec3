"""Two CPU processes under torchrun (gloo): after a few DDP steps both ranks hold identical
parameters (the generator's with a time budget that sets its learning rate), and rank 0 alone
writes the run files."""

import dataclasses
import importlib.util
import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from synthetic import TINY_OVERRIDES, write_dataset
from tqdm.auto import tqdm

from trajpref import cli
from trajpref.config import OptimConfig
from trajpref.models import checkpoint as ckpt
from trajpref.train import loop
from trajpref.train.distributed import DistInfo, RankBatches, split_batch
from trajpref.train.run import finished, train_stage


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


# Several processes, from a walkthrough of torchrun training (gloo on the CPU):
#
# - a time budget is the busiest rank's everywhere: the stop, the log, the resume state, the
#   "budget ended" line and a resume's check read one number (they read rank 0's own, while the
#   stop took the largest: a run stopped by its budget recorded less than it and resumed again
#   and again);
# - ``--equal-budget`` is refused under torchrun, and a CPU-time budget says its clock is each
#   process's own;
# - SIGTERM (``Terminated``) is kept when it lands in a finalizer, as Ctrl-C is, and no
#   ``except Exception`` takes it for an error of its own;
# - the ranks compare their config, data, seed and batches before any step (another dataset on
#   rank 1 hung until the timeout; ``--seed $RANK`` trained without a word);
# - an error that one rank alone meets is printed by that rank (only rank 0 printed);
# - smaller notes: no thread count below 1 advised, the idle batches' epoch, dropout among the
#   draws a resume on another process count changes, no collective per step without a limit.


def _torchrun(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2",
           "--master_addr=127.0.0.1", f"--master_port={_free_port()}", *args]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1", **(env or {})}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)


def _sets(folder) -> list[str]:
    return [a for o in [*TINY_OVERRIDES, f"data.dataset={folder}"] for a in ("--set", o)]


# --- one torchrun launch (ddp_rank_worker.py): the budget, and the ranks' facts compared


@pytest.fixture(scope="module")
def launch(tmp_path_factory, walks):
    out = tmp_path_factory.mktemp("walk66")
    other = write_dataset(tmp_path_factory.mktemp("other"), seed=1)
    worker = Path(__file__).with_name("ddp_rank_worker.py")
    proc = _torchrun(str(worker), str(walks), str(other), str(out))
    return {"out": out, "proc": proc}


def _read(launch, name):
    path = launch["out"] / name
    assert path.is_file(), launch["proc"].stderr[-3000:]
    return json.loads(path.read_text())


def test_a_time_budget_records_the_busiest_ranks_seconds(launch):
    """Rank 1 alone spends the budget (its clock runs fast): the ranks stop together, and the
    seconds that every rank returns, the log's and the resume state's are rank 1's, at least
    the budget: the stage says that its budget ended it, and a resume is refused (rank 0's own
    seconds, below the budget, were recorded, and the state was resumed three times more)."""
    budget = 60 * 0.02
    ranks = [_read(launch, f"budget_rank{r}.json") for r in (0, 1)]
    assert ranks[0] == ranks[1]  # one number: seconds, steps, and whether the budget ended it
    assert ranks[0]["spent"] >= budget and ranks[0]["reached"]
    folder = launch["out"] / "budget"
    state = torch.load(folder / "denoiser_last.pt", weights_only=True)
    assert state["spent"] == ranks[0]["spent"] and state["step"] == ranks[0]["steps"]
    row = json.loads((folder / "denoiser_metrics.jsonl").read_text().splitlines()[-1])
    assert row["budget_cpu_seconds"] >= budget
    assert "the time budget of 0.02 min (cpu clock) ended the stage" in launch["proc"].stdout
    optim = OptimConfig(epochs=3, max_minutes=0.02)
    assert finished(folder / "denoiser_last.pt", optim)


def test_ranks_that_agree_pass_the_check(launch):
    assert _read(launch, "check_same_rank0.json") is None
    assert _read(launch, "check_same_rank1.json") is None


@pytest.mark.parametrize(("case", "named"), [
    ("data", "data_files.train.walk0.txt: "),
    ("seed", "config.seed: 0 -> 1"),
])  # fmt: skip
def test_a_rank_with_other_data_or_its_own_seed_is_refused_on_every_rank(launch, case, named):
    """Every rank raises the same error (rank 0 alone prints it), which names rank 1 and what
    differs, before any step."""
    found = [_read(launch, f"check_{case}_rank{r}.json") for r in (0, 1)]
    assert found[0] == found[1] and found[0]["type"] == "EveryRankError"
    assert "rank 1 differs from rank 0" in found[0]["message"]
    assert named in found[0]["message"]


def test_a_per_rank_seed_is_refused_through_the_cli_before_anything_is_written(tmp_path, walks):
    """``--seed $RANK`` (a wrapper giving each process its own): the launch fails at once,
    rank 0 alone says which rank differs and how, and no run file is written (it trained,
    each rank on its own shuffle, without a word)."""
    wrapper = tmp_path / "per_rank_seed.py"
    wrapper.write_text("import os, sys\nfrom trajpref.cli import main\n"
                       "seed = ['--seed', os.environ['RANK']]\n"
                       "sys.exit(main([*sys.argv[1:], *seed]))\n")  # fmt: skip
    out = tmp_path / "run"
    proc = _torchrun(str(wrapper), "train", "diffusion", "--out", str(out), "--device", "cpu",
                     "--no-progress", *_sets(walks))  # fmt: skip
    assert proc.returncode != 0, proc.stderr[-3000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("trajpref: error:")]
    assert len(errors) == 1, proc.stderr[-3000:]
    assert "rank 1 differs from rank 0" in errors[0] and "config.seed: 0 -> 1" in errors[0]
    assert not out.exists()


# --- errors under torchrun: printed by the rank that meets them


def _as_rank(monkeypatch, rank: int) -> None:
    for key, value in (("WORLD_SIZE", "2"), ("LOCAL_WORLD_SIZE", "2"), ("RANK", str(rank)),
                       ("LOCAL_RANK", str(rank))):  # fmt: skip
        monkeypatch.setenv(key, value)
    for key in ("MASTER_ADDR", "MASTER_PORT"):  # no group can be joined: nothing waits
        monkeypatch.delenv(key, raising=False)


def test_an_error_of_rank_1_alone_is_printed_by_rank_1(tmp_path, walks, monkeypatch, capsys):
    """A --denoiser missing on rank 1's machine: rank 1 says so, prefixed with its rank
    (only torchrun's exit code was seen)."""
    _as_rank(monkeypatch, 1)
    missing = tmp_path / "missing" / "denoiser.safetensors"
    code = cli.main(["train", "generator", "--denoiser", str(missing), "--out",
                     str(tmp_path / "run"), "--device", "cpu", *_sets(walks)])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert f"trajpref: error: [rank 1] {missing}: no such checkpoint" in err


@pytest.mark.parametrize("rank", [0, 1])
def test_equal_budget_is_refused_under_torchrun_and_said_once(tmp_path, tiny_run, monkeypatch,
                                                             capsys, rank):  # fmt: skip
    """Its budget is one process's CPU time: N processes spent N times the protocol's. Every
    rank refuses it alike, rank 0 alone prints it."""
    _as_rank(monkeypatch, rank)
    code = cli.main(["finetune", "--method", "control", "--from",
                     str(tiny_run / "generator.safetensors"), "--out", str(tmp_path / "ft"),
                     "--device", "cpu", "--equal-budget", "0.1"])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    if rank == 0:
        assert "the equal-budget protocol is one process on one thread" in err
    else:
        assert "trajpref: error" not in err
    assert not (tmp_path / "ft").exists()


def test_a_cpu_budget_on_several_processes_is_said_to_be_per_process():
    from trajpref.train.run import cpu_budget_note

    cpu = OptimConfig(max_minutes=5, budget_clock="cpu")
    note = cpu_budget_note("generator", cpu, DistInfo(0, 2))
    assert note is not None and "each process's own CPU time" in note
    assert cpu_budget_note("generator", cpu, DistInfo()) is None
    wall = dataclasses.replace(cpu, budget_clock="wall")
    assert cpu_budget_note("generator", wall, DistInfo(0, 2)) is None


# --- SIGTERM: kept where it lands in a finalizer, and never taken for an error


class _RaisesWhenFreed:
    def __init__(self, error):
        self.error = error

    def __del__(self):
        raise self.error


def test_a_sigterm_raised_in_a_finalizer_stops_the_run():
    """The CLI's ``Terminated`` was an Exception, which the loop's hook passed on to Python's:
    printed as "Exception ignored" and dropped, the run trained on."""

    def body():
        _RaisesWhenFreed(cli.Terminated())
        return "trained on"

    with pytest.raises(cli.Terminated):
        loop.keeps_interrupts(body)()
    assert not issubclass(cli.Terminated, Exception)


def test_sigterm_in_a_bars_finalizer_ends_the_cli_run_with_143(tmp_path, walks, monkeypatch,
                                                               capsys):  # fmt: skip
    """As seen under torchrun: the signal's handler ran while the first epoch's bar was
    freed; the run trained its second epoch and exited 0."""
    fired = []

    class Terminating(tqdm):
        def __del__(self):
            if not fired:
                fired.append(True)
                signal.raise_signal(signal.SIGTERM)  # the handler runs here, in the finalizer
            super().__del__()

    monkeypatch.setattr(loop, "tqdm", Terminating)
    out = tmp_path / "run"
    code = cli.main(["train", "diffusion", "--out", str(out), "--device", "cpu",
                     "--no-progress", *_sets(walks)])  # fmt: skip
    assert fired and code == 143
    assert "trajpref: terminated (SIGTERM)" in capsys.readouterr().err
    assert torch.load(out / "denoiser_last.pt", weights_only=True)["epoch"] == 0


def test_sigterm_while_a_resume_state_is_read_is_no_config_error(tmp_path, monkeypatch):
    """``load_resume_state`` turns any Exception of torch's reader into "not a resume
    state"; a SIGTERM landing there was reported so."""
    path = tmp_path / "denoiser_last.pt"
    path.write_bytes(b"\x80\x02not a safetensors file")

    def terminated(path):
        raise cli.Terminated

    monkeypatch.setattr(loop, "load_tensors", terminated)
    with pytest.raises(cli.Terminated):
        loop.load_resume_state(path, "denoiser")


# --- notes


def test_the_thread_warning_never_advises_fewer_than_one(monkeypatch):
    from trajpref.train.run import set_threads

    before = torch.get_num_threads()
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    try:
        torch.set_num_threads(1)
        with pytest.warns(UserWarning, match="4 processes of 1 thread") as seen:
            set_threads(DistInfo(0, 4, 0, 4))
        message = str(seen[0].message)
        assert "OMP_NUM_THREADS" not in message and "start at most 2 processes" in message
        monkeypatch.setenv("OMP_NUM_THREADS", "2")
        torch.set_num_threads(2)
        with pytest.warns(UserWarning, match="set OMP_NUM_THREADS=1"):
            set_threads(DistInfo(0, 2, 0, 2))
    finally:
        torch.set_num_threads(before)


def test_idle_batches_are_counted_in_the_epoch_and_steps_the_stage_takes(walks):
    """The count was of epoch 0's batches, all of them, whatever epoch a resumed run starts
    at and however many steps of an epoch the stage takes (``steps_per_epoch``)."""
    from trajpref.data import load_dataset

    train = load_dataset(str(walks), "train")
    ranks = RankBatches(train, max_agents=8, seed=0, info=DistInfo(0, 4))
    sizes = ranks.sizes

    def expected(epoch, limit=None):
        ranks.loader.set_epoch(epoch)
        batches = ranks.loader.batches()[:limit]
        return sum(any(len(s) == 0 for s in split_batch(sizes[b], 4)) for b in batches)

    counts = {(e, k): expected(e, k) for e in range(4) for k in (None, 2)}
    ranks.loader.set_epoch(0)
    for (epoch, limit), count in counts.items():
        assert ranks.idle_batches(epoch, limit) == count
        assert ranks.loader.epoch == 0  # the loader's own epoch is left as it was
    note = loop.idle_note("denoiser", 3, 12, 4, 2)
    assert "3 of the 12 batches of epoch 5" in note and "of an epoch" not in note


def test_a_resume_on_another_process_count_names_dropout_among_its_draws(tmp_path, tiny_cfg,
                                                                         capsys):  # fmt: skip
    out = tmp_path / "run"
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False, max_steps=1)
    state = torch.load(out / "denoiser_last.pt", weights_only=True)
    state["world_size"] = 2  # written on two processes
    torch.save(state, out / "denoiser_last.pt")
    capsys.readouterr()
    train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False,
                resume=str(out / "denoiser_last.pt"))  # fmt: skip
    assert "(noise, augmentation, dropout)" in capsys.readouterr().err


def test_no_collective_per_step_without_a_step_or_time_limit():
    """``_should_stop`` all-reduced its flag at every step even when nothing could stop the
    stage early; with no group joined here, a collective would raise."""
    assert not loop._should_stop(5, None, 1e9, None, DistInfo(0, 2), torch.device("cpu"))
