"""benchmarks/holdout_frame.py: the jobs of the held-out-location frame decision, their order,
resuming, and the rule (the lower held-out minFDE20 wins, no margin)."""

import json
import sys

import pytest
from bench import load_benchmark


def _metrics(folder, stage, epochs, scores):
    folder.mkdir(parents=True, exist_ok=True)
    lines = [{"epoch": e + 1, "train_seconds": 60.0 * (e + 1)} for e in range(epochs)]
    for epoch, score in scores.items():
        lines[epoch - 1]["val_score"] = score
    (folder / f"{stage}_metrics.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def test_a_generator_job_names_its_held_out_denoiser_frame_and_resume_state(tmp_path):
    hf = load_benchmark("holdout_frame")
    cmd = hf.job_command("hotel", "heading", tmp_path, "/data")
    assert "data.holdout_scene=crowds_zara" in cmd and "model.agent_frame=heading" in cmd
    assert cmd[cmd.index("--denoiser") + 1] == str(tmp_path / "hotel/denoiser/denoiser.safetensors")
    assert "--resume" not in cmd and cmd[-2:] == ["--data-root", "/data"]
    (tmp_path / "univ" / "denoiser").mkdir(parents=True)
    (tmp_path / "univ" / "denoiser" / "denoiser_last.pt").write_bytes(b"")
    cmd = hf.job_command("univ", "denoiser", tmp_path, None)
    assert cmd[3:5] == ["train", "diffusion"] and "data.holdout_scene=biwi_hotel" in cmd
    assert cmd[-2:] == ["--resume", str(tmp_path / "univ/denoiser/denoiser_last.pt")]
    assert not any(a.startswith("model.agent_frame") for a in cmd)


def test_a_job_is_finished_when_its_metrics_reach_the_configs_last_epoch(tmp_path):
    hf = load_benchmark("holdout_frame")
    cfg = hf.load_config(hf.ROOT / "configs" / "univ.yaml", [])
    assert not hf.finished("univ", "scene", tmp_path)
    _metrics(tmp_path / "univ" / "scene", "generator", cfg.generator.epochs - 1, {})
    assert not hf.finished("univ", "scene", tmp_path)
    _metrics(tmp_path / "univ" / "scene", "generator", cfg.generator.epochs, {})
    assert hf.finished("univ", "scene", tmp_path)
    assert not hf.finished("univ", "denoiser", tmp_path)


def test_generators_wait_for_their_denoiser_and_finished_jobs_are_skipped(tmp_path, monkeypatch):
    hf = load_benchmark("holdout_frame")
    order = tmp_path / "order.txt"
    done = {("zara1", "denoiser")}  # already trained: not run again
    monkeypatch.setattr(hf, "finished", lambda f, j, runs: (f, j) in done)

    def command(fold, job, runs, data_root):
        code = f"import sys; open({str(order)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n')"
        return [sys.executable, "-c", code, fold, job]

    real_popen = hf.subprocess.Popen

    class Popen(real_popen):  # a job counts as finished once its process has exited
        def poll(self):
            code = super().poll()
            if code == 0:
                done.add(tuple(self.args[-2:]))
            return code

    monkeypatch.setattr(hf, "job_command", command)
    monkeypatch.setattr(hf.subprocess, "Popen", Popen)
    monkeypatch.setattr(hf.time, "sleep", lambda s: None)
    monkeypatch.setattr(hf, "ROOT", tmp_path)
    hf.train(["univ", "zara1"], tmp_path, workers=2, data_root=None)
    ran = order.read_text().split("\n")[:-1]
    assert sorted(ran) == ["univ denoiser", "univ heading", "univ scene",
                           "zara1 heading", "zara1 scene"]  # fmt: skip
    assert ran.index("univ denoiser") < min(ran.index("univ scene"), ran.index("univ heading"))


@pytest.mark.parametrize("scene, heading, chosen", [(0.30, 0.29, "heading"), (0.30, 0.30, "scene")])
def test_the_lower_held_out_min_fde_wins_and_a_tie_keeps_the_scene_frame(
    tmp_path, monkeypatch, scene, heading, chosen
):
    hf = load_benchmark("holdout_frame")
    monkeypatch.setattr(hf, "finished", lambda *a: True)
    monkeypatch.setattr(hf.subprocess, "run", lambda *a, **k: pytest.fail("re-evaluated"))
    for frame, fde in (("scene", scene), ("heading", heading)):
        out = tmp_path / "zara2" / frame
        _metrics(out, "generator", 4, {2: 0.5, 4: 0.4})
        result = {"min_ade": fde / 2, "min_fde": fde, "joint_min_ade": 1.0,
                  "joint_min_fde": 2.0, "agents": 10, "scenes": 3}  # fmt: skip
        (out / "holdout_val.json").write_text(json.dumps(result))
    row = hf.measure("zara2", tmp_path, None)
    assert row["chosen"] == chosen and row["holdout_scene"] == "biwi_hotel"
    assert row["scene"]["best_epoch"] == 4 and row["scene"]["train_minutes"] == 4.0
    assert row["heading_vs_scene_pct"] == pytest.approx(100 * (heading / scene - 1), abs=0.01)
    table = hf.report({"folds": {"zara2": row}})
    assert f"| zara2 | biwi_hotel | 3 (10) | {scene / 2:.4f} / {scene:.4f} (4 of 4)" in table
    assert table.endswith(f"| {chosen} |")


def test_a_fold_is_not_measured_before_both_generators_are_trained(tmp_path, monkeypatch):
    hf = load_benchmark("holdout_frame")
    monkeypatch.setattr(hf, "finished", lambda fold, job, runs: job != "heading")
    assert hf.measure("eth", tmp_path, None) is None


def test_generators_whose_denoiser_never_finishes_stop_the_script(tmp_path, monkeypatch):
    hf = load_benchmark("holdout_frame")
    monkeypatch.setattr(hf, "finished", lambda *a: False)
    monkeypatch.setattr(hf, "job_command", lambda *a: [sys.executable, "-c", "pass"])
    monkeypatch.setattr(hf.time, "sleep", lambda s: None)
    monkeypatch.setattr(hf, "ROOT", tmp_path)
    with pytest.raises(SystemExit, match="unfinished denoiser"):
        hf.train(["eth"], tmp_path, workers=1, data_root=None)


def test_the_report_sets_the_known_file_level_and_test_changes_beside_and_plots_them(tmp_path):
    hf = load_benchmark("holdout_frame")
    res = {"min_ade": 0.1, "min_fde": 0.2, "joint_min_fde": 0.3, "scenes": 4, "agents": 9,
           "best_epoch": 3, "epochs": 4}  # fmt: skip
    row = {"holdout_scene": "biwi_hotel", "scene": res, "heading": {**res, "min_fde": 0.19},
           "heading_vs_scene_pct": -5.0, "chosen": "heading"}  # fmt: skip
    known = {"file_val": {"eth": {"scene": 0.4, "heading": 0.38}},
             "test": {"eth": {"scene": 0.5, "heading": 0.55}}}  # fmt: skip
    record = {"folds": {"eth": row}}
    assert "| -5.0 % | -5.0 % | +10.0 % |" in hf.report(record, known)
    assert "| -5.0 % | – | – |" in hf.report(record)  # nothing known: dashes, not zeros
    hf.plot(record, known, tmp_path / "fig" / "frames.png")
    assert (tmp_path / "fig" / "frames.png").stat().st_size > 1000


def test_a_temporal_job_keeps_its_frame_and_adds_the_encoder(tmp_path):
    hf = load_benchmark("holdout_frame")
    cmd = hf.job_command("zara1", "heading-temporal", tmp_path, None)
    assert "model.agent_frame=heading" in cmd and "model.history_encoder=temporal" in cmd
    assert cmd[cmd.index("--out") + 1] == str(tmp_path / "zara1" / "heading-temporal")
    assert "model.history_encoder=temporal" not in hf.job_command(
        "zara1", "heading", tmp_path, None
    )


@pytest.mark.parametrize("fde, adopted", [(0.198, True), (0.1985, False)])
def test_the_temporal_encoder_needs_one_percent_below_its_frame(
    tmp_path, monkeypatch, fde, adopted
):
    hf = load_benchmark("holdout_frame")
    monkeypatch.setattr(hf, "finished", lambda *a: True)
    out = tmp_path / "eth" / "scene-temporal"
    _metrics(out, "generator", 4, {4: 0.3})
    result = {"min_ade": 0.1, "min_fde": fde, "joint_min_ade": 1.0, "joint_min_fde": 2.0,
              "agents": 10, "scenes": 3}  # fmt: skip
    (out / "holdout_val.json").write_text(json.dumps(result))
    base = {**result, "min_fde": 0.2, "best_epoch": 4, "epochs": 4, "train_minutes": 9.0}
    row = {"chosen": "scene", "scene": base}
    tmp = hf.measure_temporal("eth", row, tmp_path, None)
    assert tmp["adopted"] is adopted and tmp["frame"] == "scene"
    assert "| eth | scene | 0.1000 / 0.2000 |" in hf.temporal_report(
        {"folds": {"eth": {**row, "temporal": tmp}}}
    )


def test_the_temporal_study_needs_a_decided_frame(tmp_path, monkeypatch, capsys):
    hf = load_benchmark("holdout_frame")
    monkeypatch.setattr(hf, "RECORD", tmp_path / "none.json")
    with pytest.raises(SystemExit):
        hf.main(["--temporal", "--folds", "hotel"])
    assert "needs folds whose frame is decided" in capsys.readouterr().err


def test_direction_shares_count_moving_agents_along_x_per_location(monkeypatch):
    import numpy as np

    from trajpref.types import Scene, TrajectoryDataset

    hf = load_benchmark("holdout_frame")

    def walkers(file, steps):  # one agent per step vector, 20 frames of straight walking
        t = np.arange(20)[None, :, None]
        track = (np.array(steps, np.float32)[:, None, :] * t).astype(np.float32)  # [P, 20, 2]
        return Scene(track[:, :8], track[:, 8:], np.zeros(len(steps), np.int64), f"{file}@0")

    splits = {
        "train": [walkers("biwi_hotel_train.txt", [(0.0, 0.5), (0.1, -0.4), (0.01, 0.0)]),
                  walkers("crowds_zara02_train.txt", [(0.5, 0.2), (-0.3, 0.1)])],
        "test": [walkers("crowds_zara01.txt", [(0.4, 0.5), (0.6, 0.0)])],
    }  # fmt: skip

    def load(name, split, root):
        return TrajectoryDataset(splits[split], None)

    monkeypatch.setattr("trajpref.data.load_dataset", load)
    shares = hf.direction_shares("zara1", None)
    # hotel: two movers along y (the third is below 0.1 per step); zara: both along x
    assert shares["hotel"] == {"agents": 2, "along_x": 0.0}
    assert shares["zara"] == {"agents": 2, "along_x": 1.0}
    assert shares["zara1 (test)"] == {"agents": 2, "along_x": 0.5}
