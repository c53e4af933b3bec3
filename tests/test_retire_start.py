"""benchmarks/retire_start.py: after a default generator is replaced, its fine-tuning rows,
start record and run folders are renamed so that they pair with their own start and new runs
begin afresh."""

import json

import pytest
import torch
from bench import load_benchmark
from safetensors.torch import save_file

from trajpref.results import FIELDS, finetune_start


def _generator(path, weights_hash):
    path.parent.mkdir(parents=True, exist_ok=True)
    save_file(
        {"w": torch.zeros(1)}, str(path), metadata={"trajpref": json.dumps({"hash": weights_hash})}
    )


def _row(method, seed, checkpoint):
    return {k: None for k in FIELDS} | {"dataset": "robo", "method": method, "seed": seed,
                                        "checkpoint": checkpoint}  # fmt: skip


def _tree(tmp_path):
    root = tmp_path
    _generator(root / "models" / "robo" / "generator.safetensors", "new")
    results = root / "benchmarks" / "results"
    (results / "meta").mkdir(parents=True)
    (results / "pretrained_robo_tau5.json").write_text("[]")
    (results / "meta" / "finetune_start_robo.json").write_text('{"val": 1}')
    (results / "finetune_robo.json").write_text(json.dumps([
        _row("control", 0, "runs/robo-control-s0/finetune.safetensors"),
        _row("rlhf-ancestral", 0, "runs/robo-rlhf-s0/finetune.safetensors"),
    ]))  # fmt: skip
    (results / "finetune_robo_lr3e-5.json").write_text(
        json.dumps([_row("control-lr3e-5", 1, "runs/robo-control-s1-lr3e-5/finetune.safetensors")])
    )
    for folder, start in (("robo-control-s0", "old"), ("robo-control-s1-lr3e-5", "old"),
                          ("robo-rlhf-s0", "new")):  # fmt: skip
        (root / "runs" / folder).mkdir(parents=True)
        (root / "runs" / folder / "start.json").write_text(json.dumps({"hash": start}))
    return root


def test_retire_renames_rows_record_and_old_folders_only(tmp_path):
    mod = load_benchmark("retire_start")
    root = _tree(tmp_path)
    results = root / "benchmarks" / "results"
    dry = mod.retire(root, "robo", "tau5", dry_run=True)
    assert len(dry["rows"]) == 2 and (root / "runs" / "robo-control-s0").is_dir()  # untouched
    mod.retire(root, "robo", "tau5")
    rows = json.loads((results / "finetune_robo.json").read_text())
    assert [r["method"] for r in rows] == ["control-tau5", "rlhf-ancestral"]
    assert rows[0]["checkpoint"] == "runs/robo-control-s0-tau5/finetune.safetensors"
    assert finetune_start(rows[0]["method"]) == "pretrained-tau5"
    lr = json.loads((results / "finetune_robo_lr3e-5.json").read_text())[0]
    assert lr["method"] == "control-lr3e-5-tau5"
    assert lr["checkpoint"] == "runs/robo-control-s1-lr3e-5-tau5/finetune.safetensors"
    assert (root / "runs" / "robo-rlhf-s0").is_dir()  # begun from today's default: stays
    assert not (root / "runs" / "robo-control-s0").exists()
    assert (results / "meta" / "finetune_start_robo-tau5.json").read_text() == '{"val": 1}'
    assert not (results / "meta" / "finetune_start_robo.json").exists()
    again = mod.retire(root, "robo", "tau5")  # nothing left to do
    assert again == {"rows": [], "paths": [], "records": [], "folders": []}


def test_retire_suffixes_a_retired_rows_path_when_its_folder_is_missing(tmp_path):
    # a new checkout has no runs/: the path must still move off the folder new runs will use
    mod = load_benchmark("retire_start")
    root = _tree(tmp_path)
    results = root / "benchmarks" / "results"
    (results / "finetune_robo_set.json").write_text(json.dumps([
        _row("rlhf-set-tau5", 2, "runs/robo-rlhf-s2-set/finetune.safetensors"),  # no folder
        _row("rlhf-set-tau5", 3, "runs/robo-rlhf-s3-set-tau5/finetune.safetensors"),  # done before
        _row("rlhf-set-ancestral", 2, "runs/robo-rlhf-s2-set/finetune.safetensors"),  # other start
        _row("pretrained-tau5", 0, "models/robo/generator.safetensors"),
    ]))  # fmt: skip
    done = mod.retire(root, "robo", "tau5")
    rows = json.loads((results / "finetune_robo_set.json").read_text())
    assert [r["checkpoint"] for r in rows] == [
        "runs/robo-rlhf-s2-set-tau5/finetune.safetensors",
        "runs/robo-rlhf-s3-set-tau5/finetune.safetensors",
        "runs/robo-rlhf-s2-set/finetune.safetensors",
        "models/robo/generator.safetensors",
    ]
    assert "finetune_robo_set.json: runs/robo-rlhf-s2-set/finetune.safetensors -> " \
        "runs/robo-rlhf-s2-set-tau5/finetune.safetensors" in done["paths"]  # fmt: skip
    assert not (root / "runs" / "robo-rlhf-s2-set-tau5").exists()  # nothing invented on disk


def test_retire_needs_a_known_suffix_and_the_kept_start_row(tmp_path):
    mod = load_benchmark("retire_start")
    root = _tree(tmp_path)
    with pytest.raises(SystemExit, match="RETIRED_STARTS"):
        mod.retire(root, "robo", "e99")
    (root / "benchmarks" / "results" / "pretrained_robo_tau5.json").unlink()
    with pytest.raises(SystemExit, match="keep-replaced"):
        mod.retire(root, "robo", "tau5")
