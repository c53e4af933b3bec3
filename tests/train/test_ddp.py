"""Two CPU processes under torchrun (gloo): after a few DDP steps both ranks hold identical
parameters (the generator's with a time budget that sets its learning rate), and rank 0 alone
writes the run files."""

import socket
import subprocess
import sys
from pathlib import Path

import torch
from synthetic import write_dataset


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
    ``train.run`` (which waits for every rank before leaving the process group)."""
    from synthetic import TINY_OVERRIDES

    folder = write_dataset(tmp_path / "walks")
    out = tmp_path / "run"
    sets = [arg for o in [*TINY_OVERRIDES, f"data.dataset={folder}"] for arg in ("--set", o)]
    for stage in ("diffusion", "generator"):
        cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2",
               "--master_addr=127.0.0.1", f"--master_port={_free_port()}", "-m",
               "trajpref.cli", "train", stage, "--out", str(out), "--device", "cpu",
               "--no-progress", *sets]  # fmt: skip
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert "terminate called" not in proc.stderr
    for name in ("denoiser", "generator"):
        assert (out / f"{name}.safetensors").is_file()
        assert (out / f"{name}_metrics.jsonl").read_text().count("\n") == 2  # 2 epochs, rank 0
