import pytest

from trajpref import demo

TINY = ["model.hidden=16", "model.heads=2", "model.encoder_layers=1", "model.denoiser_width=32",
        "model.denoiser_blocks=1", "model.generator_width=32", "diffusion.num_steps=10",
        "model.samples=5", "model.tau=2", "denoiser.epochs=1", "generator.epochs=1",
        "finetune.epochs=1", "denoiser.eval_max_scenes=50", "generator.eval_max_scenes=50",
        "finetune.eval_max_scenes=50", "finetune.score_every=3"]  # fmt: skip


def test_demo_runs_the_whole_pipeline(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TRAJPREF_DATA", raising=False)  # falls back to robo-sim's test split
    argv = ["--out", str(tmp_path), "--samples", "5"]
    for o in TINY:
        argv += ["--set", o]
    assert demo.main(argv) == 0
    out = capsys.readouterr().out
    assert "robo-sim test split" in out
    for name in ("constant velocity (K=5)", "pretrained (leapfrog)", "RLHF-ReS"):
        assert name in out
    # the tiny model is named as the demo's, not mistaken for the published Robo model
    assert "demo model (1 generator epoch," in out and "not the published" in out
    assert (tmp_path / "robo_scene0_scored.png").stat().st_size > 1000
    assert (tmp_path / "run" / "rlhf-res" / "finetune.safetensors").is_file()


def test_ctrl_c_stops_the_demo_with_one_line(capsys, monkeypatch):
    """Ctrl-C ends the demo as it ends `trajpref train`: one line on stderr and status 130,
    not a KeyboardInterrupt traceback (walkthrough of a wheel install, 2026-12-06)."""

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(demo, "run", interrupted)
    try:
        code = demo.main(["--out", "unused"])
    except KeyboardInterrupt:  # caught here, or it would stop the test session
        pytest.fail("the KeyboardInterrupt escaped demo.main")
    assert code == 130
    captured = capsys.readouterr()
    assert captured.err == "trajpref demo: interrupted (run it again to start over)\n"


def test_sigint_during_the_demos_training_prints_no_traceback(tmp_path):
    """The real signal, in training (the loop's own handling of a Ctrl-C in a finalizer
    included): ``python -m trajpref.demo`` exits 130 with the one line last on stderr."""
    import os
    import signal
    import subprocess
    import sys
    import time

    sets = [a for o in [*TINY, "denoiser.epochs=200"] for a in ("--set", o)]
    argv = [sys.executable, "-m", "trajpref.demo", "--out", str(tmp_path / "out"), "--samples",
            "5", *sets]  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "TRAJPREF_DATA"}
    env.update(PYTHONUNBUFFERED="1", OMP_NUM_THREADS="1")
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, cwd=tmp_path)  # fmt: skip
    try:
        assert proc.stdout.readline().startswith("[1/5]")  # simulated; training starts now
        time.sleep(3)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-2000:]
    last = err.rstrip("\n").splitlines()[-1]  # after the progress bar's carriage returns
    assert last.endswith("trajpref demo: interrupted (run it again to start over)"), last
