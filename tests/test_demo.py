from trajpref import demo


def test_demo_runs_and_writes_a_figure(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("TRAJPREF_DATA", raising=False)  # falls back to robo-sim's test split
    assert demo.main(["--out", str(tmp_path), "--samples", "5"]) == 0
    out = capsys.readouterr().out
    assert "robo-sim test split" in out and "constant velocity (K=5)" in out
    assert (tmp_path / "robo_scene0_cv.png").stat().st_size > 1000
