"""A run folder's disk filling up during training (batch walkthrough 2026-12-06): torch.save's
RuntimeError gave a traceback and exit status 1, and an ``OSError`` without a file name
(ENOSPC) reached the CLI as ``trajpref: error: No space left on device``. Each is one line
naming the file now, with exit status 2. A full disk is simulated by monkeypatching."""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

import pytest
import torch
from safetensors import SafetensorError
from synthetic import TINY_OVERRIDES

from trajpref.cli import main
from trajpref.errors import TrajprefError
from trajpref.train import loop

TINY = [a for o in TINY_OVERRIDES for a in ("--set", o)]
TORCH_FULL = ("[enforce fail at inline_container.cc:858] . PytorchStreamWriter failed writing "
              "file data/0: file write failed")  # fmt: skip
"""What torch.save raises when the disk fills (torch 2.x)."""
SAFETENSORS_FULL = ('Error while serializing: IoError(Os { code: 28, kind: StorageFull, message: '
                    '"No space left on device" })')  # fmt: skip
"""What safetensors' save_file raises when the disk fills."""


def _full_disk(*args, **kwargs):
    raise RuntimeError(TORCH_FULL)


def test_a_resume_state_that_cannot_be_written_is_one_error_naming_it(tmp_path, monkeypatch):
    path = tmp_path / "denoiser_last.pt"
    loop.save_resume_state(path, {"epoch": 0})  # an earlier epoch's
    monkeypatch.setattr(torch, "save", _full_disk)
    with pytest.raises(TrajprefError) as caught:
        loop.save_resume_state(path, {"epoch": 1})
    message = str(caught.value)
    assert re.fullmatch(rf"{re.escape(str(path))}: cannot write the resume state \(PytorchStream"
                        r"Writer failed writing file data/0: file write failed; [\d,]+ MB free "
                        r"there\)", message), message  # fmt: skip
    assert loop.load_tensors(path) == {"epoch": 0}  # the earlier state is kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["denoiser_last.pt"]  # no temp file


def test_a_checkpoint_and_the_log_that_cannot_be_written_name_their_file(tmp_path, monkeypatch):
    import trajpref.models.checkpoint as ckpt

    def full(*args, **kwargs):
        raise SafetensorError(SAFETENSORS_FULL)

    monkeypatch.setattr(ckpt, "save_file", full)
    target = tmp_path / "denoiser.safetensors"
    with pytest.raises(TrajprefError, match=re.escape(f"{target}: cannot write the checkpoint "
                                                      "(No space left on device; ")):  # fmt: skip
        ckpt.save(target, {"kind": "denoiser", "state_dict": {}, "config": {}})
    log = loop.MetricLog(tmp_path, "denoiser", enabled=True)
    real_open = Path.open

    class Full:
        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def write(self, text):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # no file name, as a write's

    monkeypatch.setattr(Path, "open", lambda p, *a, **k: Full() if p == log.path else
                        real_open(p, *a, **k))  # fmt: skip
    with pytest.raises(TrajprefError, match=re.escape(f"{log.path}: cannot write the metrics log "
                                                      "(No space left on device; ")):  # fmt: skip
        log.write({"epoch": 1})


def test_a_full_disk_during_training_is_one_line_and_status_2(tmp_path, walks, monkeypatch,
                                                              capsys):  # fmt: skip
    """Through the CLI, with the progress bars on and stderr a log (not a terminal): the error
    is a line of its own (``grep '^trajpref: error'`` finds it), and the folder is let go."""
    out = tmp_path / "run"
    monkeypatch.setattr(torch, "save", _full_disk)
    code = main(["train", "diffusion", "--set", f"data.dataset={walks}", *TINY, "--device",
                 "cpu", "--out", str(out)])  # fmt: skip
    _, err = capsys.readouterr()
    assert code == 2, err
    errors = re.findall(r"^trajpref: error: .*$", err, re.MULTILINE)
    assert errors == [f"trajpref: error: {out / 'denoiser_last.pt'}: cannot write the resume "
                      "state (PytorchStreamWriter failed writing file data/0: file write "
                      f"failed; {errors[0].rsplit('; ', 1)[-1]}"], err  # fmt: skip
    assert "Traceback" not in err and "\r" not in err
    assert not (out / ".denoiser.lock").exists()
