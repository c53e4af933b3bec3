"""The command line's finding of the library-extension walkthrough: the folder a config
file's relative data path is read from (tests/test_own_data_training.py tests a path of one
part, where the file's folder and the path's parent are the same)."""

from __future__ import annotations

from trajpref.cli import main


def test_a_relative_dataset_of_two_parts_is_pointed_to_the_config_files_folder(
    tmp_path, monkeypatch, capsys, walks
):
    """``dataset: data/mall`` in project/rel.yaml, run elsewhere: the advice is to run from
    project/ (where data/mall resolves), not project/data/ (where it does not)."""
    home = tmp_path / "project"
    (home / "data").mkdir(parents=True)
    (home / "data" / "mall").symlink_to(walks)
    cfg = home / "rel.yaml"
    cfg.write_text("data:\n  dataset: data/mall\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    code = main(["train", "diffusion", "--config", str(cfg), "--out", str(tmp_path / "o"),
                 "--device", "cpu", "--no-progress"])  # fmt: skip
    err = " ".join(capsys.readouterr().err.split())
    assert code != 0
    assert f"beside which {home / 'data' / 'mall'} is" in err
    assert err.rstrip().endswith(f"or run trajpref from {home.resolve()}"), err
    assert f"run trajpref from {(home / 'data').resolve()}" not in err
    # the advice holds: from there, the path is the folder
    assert (home.resolve() / "data" / "mall" / "train").is_dir()
    assert not (tmp_path / "o").exists()
