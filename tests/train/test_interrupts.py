"""A Ctrl-C stops training wherever it lands: the loop closes its progress bars itself, and a
KeyboardInterrupt that Python swallows because it landed in a finalizer (a bar's
``tqdm.__del__``: "Exception ignored in ...") still stops the run at the next step."""

import pytest
import torch
from tqdm.auto import tqdm

from trajpref.train import loop, stages
from trajpref.train.run import train_stage


def test_every_progress_bar_of_a_run_is_closed_by_the_loop(tmp_path, tiny_cfg, monkeypatch):
    """Bars the loop leaves open are closed by their finalizer, in the training thread, where
    a Ctrl-C is ignored; the test keeps every bar alive, so that only the loop can close it."""
    made = []

    class Kept(tqdm):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.closed = False
            self.label = kwargs.get("desc")  # a disabled bar keeps no ``desc``
            made.append(self)

        def close(self):
            self.closed = True
            super().close()

    monkeypatch.setattr(loop, "tqdm", Kept)
    monkeypatch.setattr(stages, "tqdm", Kept)
    for progress in (False, True):
        made.clear()
        train_stage("diffusion", tiny_cfg, tmp_path / str(progress), device="cpu",
                    progress=progress)  # fmt: skip
        # one bar per epoch, one per validation
        assert len(made) == 2 * tiny_cfg.denoiser.epochs
        assert all(bar.closed for bar in made), [bar.label for bar in made if not bar.closed]


def test_a_ctrl_c_that_lands_in_a_finalizer_still_stops_the_run(tmp_path, tiny_cfg, monkeypatch):
    """The first epoch's bar is finalized as the second epoch starts; a KeyboardInterrupt
    raised there (as a Ctrl-C landing in ``tqdm.__del__`` is) stops the run before its next
    step, its first epoch saved, instead of being printed and ignored."""
    fired = []

    class Interrupted(tqdm):
        def __del__(self):
            if not fired:
                fired.append(self.label)
                raise KeyboardInterrupt
            super().__del__()

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.label = kwargs.get("desc")  # a disabled bar keeps no ``desc``

    monkeypatch.setattr(loop, "tqdm", Interrupted)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_stage("diffusion", tiny_cfg, out, device="cpu", progress=False)
    assert fired == ["denoiser epoch 1/2"]
    state = torch.load(out / "denoiser_last.pt", weights_only=True)
    assert state["epoch"] == 0  # stopped after its first epoch: a resume continues it


def test_other_exceptions_in_finalizers_still_reach_the_previous_hook(monkeypatch):
    """The loop's hook takes the KeyboardInterrupts alone, and puts back the one it found."""
    import sys

    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda unraisable: seen.append(unraisable.exc_type))

    class Raises:
        def __init__(self, error):
            self.error = error

        def __del__(self):
            raise self.error

    def body():
        Raises(ValueError("in a finalizer"))
        return "done"

    def interrupted():
        Raises(KeyboardInterrupt())

    assert loop.keeps_interrupts(body)() == "done"
    assert seen == [ValueError]
    with pytest.raises(KeyboardInterrupt):
        loop.keeps_interrupts(interrupted)()
    assert seen == [ValueError]
    hook = sys.unraisablehook
    Raises(OSError("after"))
    assert seen == [ValueError, OSError] and sys.unraisablehook is hook


def test_a_stop_between_an_epochs_log_row_and_its_state_logs_that_epoch_once(
        tmp_path, tiny_cfg, monkeypatch):  # fmt: skip
    """A Ctrl-C after the epoch's log row but before its resume state is saved: the resumed
    run runs that epoch again, and its log holds each epoch once."""
    import dataclasses

    from trajpref.train.loop import read_metrics

    cfg = dataclasses.replace(tiny_cfg, denoiser=dataclasses.replace(tiny_cfg.denoiser,
                                                                     epochs=3))  # fmt: skip
    real, calls = loop.save_resume_state, []

    def stopped_once(path, state):
        calls.append(state["epoch"])
        if state["epoch"] == 1 and calls.count(1) == 1:
            raise KeyboardInterrupt  # as the second epoch's state is written
        real(path, state)

    monkeypatch.setattr(loop, "save_resume_state", stopped_once)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train_stage("diffusion", cfg, out, device="cpu", progress=False)
    assert [r["epoch"] for r in read_metrics(out, "denoiser")] == [1, 2]  # 2's state unsaved
    train_stage("diffusion", cfg, out, device="cpu", progress=False,
                resume=str(out / "denoiser_last.pt"))  # fmt: skip
    assert [r["epoch"] for r in read_metrics(out, "denoiser")] == [1, 2, 3]
