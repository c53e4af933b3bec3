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
