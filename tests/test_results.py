"""Result rows and the README tables made from them."""

import json
import re
from pathlib import Path

import pytest
from bench import load_benchmark

from trajpref.results import (
    FIELDS,
    PEER_COLUMNS,
    PEER_HEADERS,
    RUNNABLE_STARTS,
    SECONDARY_MARK,
    SELECTION_FREE,
    START_SUFFIXES,
    ResultConflict,
    accuracy_table,
    base_method,
    cpu_name,
    finetune_start,
    make_row,
    merge_rows,
    peers_notes,
    peers_table,
    read_rows,
    selection_table,
    start_record,
    start_suffix,
    table_lines,
    upsert_rows,
    write_meta,
    write_rows,
)
from trajpref.score.selection import METHODS, USES_SCORE

ROOT = Path(__file__).resolve().parent.parent
FOLDS = ("eth", "hotel", "univ", "zara1", "zara2")


def _row(dataset, method="pretrained", protocol=None, ade=0.2, fde=0.4, seed=0):
    return make_row(dataset=dataset, split="test", protocol=protocol, method=method, seed=seed,
                    samples=20, min_ade=ade, min_fde=fde, date="2026-11-23", machine="m",
                    command="c")  # fmt: skip


def test_rows_default_to_the_all_protocol_and_keep_the_schema(tmp_path):
    row = _row("eth")
    assert row["protocol"] == "all" and set(row) == set(FIELDS)
    write_rows(tmp_path / "a.json", [row, _row("eth", protocol="sgan", ade=0.3)])
    assert [r["protocol"] for r in read_rows(tmp_path)] == ["all", "sgan"]
    assert [r["min_ade"] for r in read_rows(tmp_path, protocol="sgan")] == [0.3]
    with pytest.raises(KeyError, match="unknown result fields"):
        make_row(dataset="eth", protokol="sgan")


def test_the_same_measurement_under_two_protocols_is_not_merged():
    rows = merge_rows([_row("eth", ade=0.2), _row("eth", protocol="sgan", ade=0.3)])
    assert sorted(r["min_ade"] for r in rows) == [0.2, 0.3]


def _scored(model_hash, max_ats=0.7):
    return make_row(dataset="zara1", split="test", method="pretrained", seed=0, samples=20,
                    max_ats=max_ats, model_hash=model_hash, date="2026-11-25",
                    command="score")  # fmt: skip


def test_rows_of_one_checkpoint_merge_and_unknown_hashes_merge_as_before():
    acc = {**_row("zara1", ade=0.18, fde=0.33), "model_hash": "aaaaaaaaaaaa"}
    (merged,) = merge_rows([acc, _scored("aaaaaaaaaaaa")])
    assert (merged["min_fde"], merged["max_ats"]) == (0.33, 0.7)
    (merged,) = merge_rows([_row("zara1", ade=0.18, fde=0.33), _scored("aaaaaaaaaaaa")])
    assert merged["max_ats"] == 0.7 and merged["model_hash"] == "aaaaaaaaaaaa"


def test_rows_of_one_measurement_on_different_checkpoints_are_refused():
    acc = {**_row("zara1", ade=0.18, fde=0.33), "model_hash": "aaaaaaaaaaaa"}
    with pytest.raises(ResultConflict, match="bbbbbbbbbbbb .2026-11-25: score.*re-run the stale"):
        merge_rows([acc, _scored("bbbbbbbbbbbb")])
    # another seed is another measurement, whatever its checkpoint
    other_seed = {**_scored("bbbbbbbbbbbb"), "seed": 1}
    assert len(merge_rows([acc, other_seed])) == 2


def test_accuracy_table_shows_one_protocol():
    rows = [_row("eth", ade=0.111), _row("eth", protocol="sgan", ade=0.222)]
    assert "0.111" in accuracy_table(rows) and "0.222" not in accuracy_table(rows)
    sgan = accuracy_table(rows, protocol="sgan")
    assert "0.222" in sgan and "0.111" not in sgan


def test_peers_table_averages_our_folds_only_when_all_five_are_there():
    peers = {"methods": {"Peer": {"protocol": "sgan", "eth": [0.35, 0.42], "source": "s"}}}
    rows = [_row(f, ade=0.1 * (i + 1), fde=0.2 * (i + 1)) for i, f in enumerate(FOLDS)]
    rows.append(_row("eth", protocol="sgan", ade=0.5, fde=0.9))
    lines = peers_table(peers, rows).splitlines()
    ours_all, ours_sgan, peer = lines[2], lines[3], lines[4]
    assert ours_all.startswith("| **trajpref** (`pretrained`) | all |")
    assert "**0.30 / 0.60**" in ours_all  # mean of 0.1..0.5 and of 0.2..1.0
    assert "| sgan | **0.50 / 0.90** |" in ours_sgan and "0.30 / 0.60" not in ours_sgan
    assert peer == "| Peer | sgan | 0.35 / 0.42 | – | – | – | – | – | – | – | – | – |"


def test_peers_table_gives_each_named_method_its_own_line():
    rows = [_row(f, ade=0.2, fde=0.4) for f in FOLDS]
    rows += [_row(f, method="pretrained-long", ade=0.1, fde=0.3) for f in FOLDS]
    rows.append(_row("eth", method="rlhf", ade=0.9, fde=0.9))  # not named: not shown
    lines = peers_table({"methods": {}}, rows, methods=("pretrained", "pretrained-long"))
    ours = lines.splitlines()[2:]
    assert [line.split("|")[1].strip() for line in ours] == [
        "**trajpref** (`pretrained`)",
        "**trajpref** (`pretrained-long`)",
    ]  # no sgan rows
    assert "**0.10 / 0.30**" in ours[1] and "0.90" not in lines


def test_our_nba_rows_have_their_own_column_beside_the_peers_nba_split():
    """Our NBA is the rebound split (8 + 12, the ball an agent); the peers' is LED's 10 + 20:
    the two never share a column."""
    peers = {"methods": {"Peer": {"protocol": "all", "nba": [0.81, 1.10], "source": "s"}}}
    rows = [_row("nba", ade=0.21, fde=0.35)]
    header, _, ours, peer = peers_table(peers, rows).splitlines()
    names = [c.strip() for c in header.split("|")[1:-1]]
    ours_cells = dict(zip(names, [c.strip() for c in ours.split("|")[1:-1]], strict=True))
    peer_cells = dict(zip(names, [c.strip() for c in peer.split("|")[1:-1]], strict=True))
    led, rebound = PEER_HEADERS["nba"], PEER_HEADERS["nba-rebound"]
    assert "10 + 20" in led and "8 + 12" in rebound and "ball" in rebound
    assert ours_cells[led] == "–" and ours_cells[rebound] == "**0.21 / 0.35**"
    assert peer_cells[led] == "0.81 / 1.10" and peer_cells[rebound] == "–"


def test_a_peer_number_quoted_second_hand_is_marked():
    peers = {"methods": {"Peer": {"protocol": "sgan", "eth": [0.35, 0.42], "sdd": [7.5, 12.0],
                                  "secondary": ["sdd"], "source": "s"}}}  # fmt: skip
    (peer,) = peers_table(peers, []).splitlines()[2:]
    assert "| 0.35 / 0.42 |" in peer and f"| 7.50 / 12.00 {SECONDARY_MARK} |" in peer


def test_the_peers_notes_state_the_average_the_nba_split_and_protocol_sources():
    peers = {"methods": {"Peer": {"protocol": "sgan", "source": "s", "protocol_source": {
        "repository": "org/peer", "commit": "abc1234", "lines": ["loader.py:104"],
        "reads": "keeps windows with more than one agent"}}}}  # fmt: skip
    note = peers_notes(peers)
    assert "unweighted mean of the five fold means" in note
    assert "ball" in note and "10 + 20" in note and SECONDARY_MARK in note
    assert "Peer: `sgan` (org/peer at abc1234, loader.py:104" in note


def test_the_peers_files_paper_rows_are_the_papers_table():
    """The seed paper's rows in the peers table are typed in twice (benchmarks/peers.json and
    benchmarks/paper_tables.json); every cell the peers table has a column for agrees."""
    peers = json.loads((ROOT / "benchmarks" / "peers.json").read_text())["methods"]
    paper = json.loads((ROOT / "benchmarks" / "paper_tables.json").read_text())
    rows = paper["tables"]["table1"]["rows"]
    for name, column in (("the paper: LED column", "LED"), ("the paper: RLHF-ReS", "RLHF-ReS")):
        for dataset in paper["datasets"]:  # the seven datasets, not the paper's 7-set avg
            assert dataset in PEER_COLUMNS, dataset
            assert peers[name].get(dataset) == rows[dataset][column], (name, dataset)


def test_the_peers_file_has_a_source_and_a_protocol_for_every_method():
    peers = json.loads((ROOT / "benchmarks" / "peers.json").read_text())
    for name, entry in peers["methods"].items():
        assert entry["source"], name
        assert entry["protocol"] in ("all", "sgan", "unknown"), name
        for col in peers["columns"]:
            if col in entry:
                ade, fde = entry[col]
                assert 0 < ade < fde, (name, col)
        assert set(entry.get("secondary", [])) <= set(entry) & set(PEER_COLUMNS), name
        assert "nba-rebound" not in entry, name  # no peer's number is on our split yet
        if "protocol_source" in entry:  # read from the peer's public code
            src = entry["protocol_source"]
            assert entry["protocol"] != "unknown" and src["repository"] and src["lines"], name
            assert re.fullmatch(r"[0-9a-f]{7,40}", src["commit"]), name
    assert set(peers["columns"]) == set(PEER_COLUMNS)
    assert peers["methods"]["MART (ECCV 2024)"]["protocol"] == "sgan"


def test_write_meta_records_where_and_how_then_the_fields(tmp_path, monkeypatch):
    monkeypatch.setattr("sys.argv", ["benchmarks/speed.py", "--scenes", "5"])
    path = tmp_path / "deep" / "speed.json"
    written = write_meta(path, models={"a/generator": {"ratio": 12.5}}, bad=float("nan"))
    loaded = json.loads(path.read_text())
    assert loaded == written | {"bad": None}  # strict JSON: NaN is written as null
    assert loaded["command"] == "python benchmarks/speed.py --scenes 5"
    assert loaded["threads"] >= 1 and "CPU cores" in loaded["machine"]
    assert loaded["models"]["a/generator"]["ratio"] == 12.5


def test_the_cpu_is_named_by_its_model_and_falls_back_when_the_system_does_not_say(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: GenuineIntel\n"
                    "model name\t: Intel(R)  Xeon(R) Processor\nflags\t: avx2\n\n"
                    "processor\t: 1\nmodel name\t: Intel(R) Xeon(R) Processor\n")  # fmt: skip
    assert cpu_name(info) == "Intel(R) Xeon(R) Processor"
    fallback = cpu_name(tmp_path / "missing")
    assert fallback and "model name" not in fallback
    info.write_text("processor\t: 0\nmodel name\t:   \n")  # an empty name is not a name
    assert cpu_name(info) == fallback


def test_upsert_rows_adds_other_seeds_and_replaces_the_same_measurement(tmp_path):
    path = tmp_path / "select_zara1.json"
    seed0 = [_row("zara1", "select-a", fde=0.30), _row("zara1", "select-b", fde=0.31)]
    upsert_rows(path, seed0)
    upsert_rows(path, [_row("zara1", "select-a", seed=1, fde=0.32)])  # another seed: added
    upsert_rows(path, [_row("zara1", "select-b", fde=0.29)])  # a re-run: replaced
    rows = json.loads(path.read_text())
    got = {(r["method"], r["seed"]): r["min_fde"] for r in rows}
    assert got == {("select-a", 0): 0.30, ("select-b", 0): 0.29, ("select-a", 1): 0.32}


def test_upsert_rows_drops_the_old_rows_the_caller_marks_stale(tmp_path):
    path = tmp_path / "pretrained_nba.json"
    upsert_rows(path, [_row("nba", "pretrained", fde=0.38), _row("nba", "full-sampler", fde=0.5)])
    upsert_rows(path, [_row("nba", "pretrained", fde=0.40)],
                drop=lambda r: r["method"].startswith("full"))  # fmt: skip
    got = {r["method"]: r["min_fde"] for r in json.loads(path.read_text())}
    assert got == {"pretrained": 0.40}
    upsert_rows(path, [_row("nba", "full-sampler", fde=0.5)], drop=lambda r: False)
    assert len(json.loads(path.read_text())) == 2


def _sel(dataset, method, seed, fde, uses_score):
    return make_row(dataset=dataset, split="test", method=f"select-{method}", seed=seed,
                    samples=5, min_fde=fde, joint_min_fde=2 * fde, min_ade=fde / 2,
                    joint_min_ade=fde, ms_per_scene=10.0,
                    uses_score=uses_score, date="2026-11-23", machine="m", command="c")  # fmt: skip


def test_selection_table_averages_seeds_and_computes_the_change_within_each_seed():
    rows = [_sel("zara1", "kmeans", 0, 0.70, False), _sel("zara1", "kmeans", 1, 0.80, False),
            _sel("zara1", "facility", 0, 0.60, False), _sel("zara1", "facility", 1, 0.80, False),
            _sel("zara1", "score-fps", 0, 0.54, True),
            _sel("zara1", "score-fps", 1, 0.80, True)]  # fmt: skip
    line = selection_table(rows).splitlines()[2]
    cells = [c.strip() for c in line.strip("|").split("|")]
    # facility's mean (0.70) beats kmeans' (0.75); the change is -10 % and 0 % within the seeds
    assert cells[:3] == ["zara1", "5", "2"]
    assert cells[5] == "0.750" and cells[7] == "0.700" and cells[9] == "0.700"
    assert cells[8] == "–"  # no medoids rows
    assert cells[10] == "0.670 (`score-fps`)"
    assert cells[11] == "-5.0 ± 7.1 %"
    assert cells[12] == "1.400 / 1.340"
    # the same two selections' per-agent and joint minADE
    assert cells[14] == "0.350 / 0.335" and cells[15] == "0.700 / 0.670"


def test_selection_table_gives_a_published_variant_its_own_line():
    rows = [_sel("eth", "facility", 0, 1.0, False), _sel("eth", "score-fps", 0, 1.2, True)]
    for r in rows:
        r["checkpoint"] = "models/eth/generator.safetensors"
    variant = [_sel("eth", "facility-speedaug", 0, 0.8, False),
               _sel("eth", "score-fps-speedaug", 0, 0.6, True)]  # fmt: skip
    for r in variant:
        r["checkpoint"] = "models/eth/generator-speedaug.safetensors"
    lines = selection_table(rows + variant).splitlines()[2:]
    assert [line.split("|")[1].strip() for line in lines] == ["eth", "eth (speedaug)"]
    assert "1.200 (`score-fps`) | +20.0 %" in lines[0]
    assert "0.600 (`score-fps`) | -25.0 %" in lines[1]


def test_selection_table_shows_the_chosen_selection_even_where_another_is_better():
    rows = [_sel("eth", "facility", 0, 1.0, False), _sel("eth", "score-facility", 0, 0.9, True),
            _sel("eth", "score-facility-gate", 0, 0.95, True)]  # fmt: skip
    line = selection_table(rows, chosen={"eth": "select-score-facility-gate"}).splitlines()[2]
    assert "0.950 (`score-facility-gate`) | -5.0 %" in line
    assert "0.900" not in line  # the other setting is not picked on the test split
    assert "0.900 (`score-facility`)" in selection_table(rows).splitlines()[2]  # no choice
    with pytest.raises(ValueError, match="no test rows"):
        selection_table(rows, chosen={"eth": "select-top"})


def test_each_finetuning_row_compares_with_the_start_of_its_time():
    assert finetune_start("rlhf-res") == "pretrained"
    assert finetune_start("control-lr3e-5") == "pretrained"
    assert finetune_start("rlhf-res-steps36-ancestral") == "pretrained-ancestral"
    assert finetune_start("control-lr3e-5-long") == "pretrained-long"
    # the runs from a default that was replaced later compare with that default's row
    assert finetune_start("control-lr3e-5-tau5") == "pretrained-tau5"
    assert finetune_start("rlhf-set-h128") == "pretrained-h128"
    assert finetune_start("rlhf-set-noflip") == "pretrained-noflip"
    assert base_method("rlhf-res-raw") == "rlhf-res"
    assert base_method("control-lr3e-5-noflip") == "control-lr3e-5"


def test_the_rlhf_report_orders_every_start_it_can_meet():
    report = load_benchmark("finetune_report")
    assert {finetune_start("rlhf" + s) for s in (*START_SUFFIXES, "")} <= set(report.START_ORDER)


def test_every_runnable_start_names_its_rows_and_its_validation_record_in_one_place():
    assert start_suffix("generator") == "" and start_suffix("generator-long") == "-long"
    assert set(RUNNABLE_STARTS.values()) - {""} <= set(START_SUFFIXES)
    assert finetune_start("control" + start_suffix("generator-long")) == "pretrained-long"
    assert start_record("zara1") == "finetune_start_zara1.json"
    assert start_record("eth", "generator-long") == "finetune_start_eth_generator-long.json"
    with pytest.raises(ValueError, match="unknown fine-tuning start 'generator-short'"):
        start_suffix("generator-short")
    with pytest.raises(ValueError, match="known: generator, generator-long"):
        start_record("eth", "generator-short")


def test_selection_table_gives_each_chosen_setting_of_a_list_its_own_line():
    rows = [_sel("zara1", "facility", 0, 1.0, False), _sel("zara1", "score-fps", 0, 0.9, True),
            _sel("zara1", "score-fps-s2", 0, 0.95, True),
            _sel("zara1", "top", 0, 0.33, True)]  # fmt: skip
    picks = {"zara1": ["select-score-fps", "select-score-fps-s2"]}
    lines = selection_table(rows, chosen=picks).splitlines()[2:]
    assert len(lines) == 2
    assert "0.900 (`score-fps`) | -10.0 %" in lines[0]
    assert "0.950 (`score-fps-s2`) | -5.0 %" in lines[1]
    assert not any("0.330" in line for line in lines)  # the unchosen setting is not shown


def test_the_reward_report_reads_only_the_validated_epochs(tmp_path, monkeypatch):
    """Validation by the budget clock (``eval_every_minutes``) leaves epochs without
    validation keys; the report crashed on them (KeyError 'val_mean_ats') until 2026-11-27."""
    report = load_benchmark("finetune_report")
    monkeypatch.setattr(report, "ROOT", tmp_path)
    meta = tmp_path / "benchmarks" / "results" / "meta"
    meta.mkdir(parents=True)
    val = {"mean_ats": -0.5, "max_ats": 0.3, "min_fde": 0.33}
    (meta / "finetune_start_zara1.json").write_text(json.dumps({"val": val}))
    run = tmp_path / "runs" / "zara1-rlhf-s0"
    run.mkdir(parents=True)
    epochs = [{"epoch": 1, "step": 3, "val_mean_ats": -0.4, "val_max_ats": 0.31,
               "val_min_fde": 0.34, "best": True},
              {"epoch": 2, "step": 6},  # not validated
              {"epoch": 3, "step": 9, "val_mean_ats": -0.2, "val_max_ats": 0.32,
               "val_min_fde": 0.35}]  # fmt: skip
    (run / "finetune_metrics.jsonl").write_text("\n".join(json.dumps(e) for e in epochs))
    rows = [_row("zara1", fde=0.30), _row("zara1", method="rlhf", fde=0.33)]
    line = report.reward_section(rows, ["zara1"]).splitlines()[2]
    assert "| 9 |" in line  # the run's steps, from its last epoch
    assert "-0.500 -> -0.400 -> -0.200 (-0.200)" in line  # start -> first -> last (peak)
    assert "+10.0 %" in line


def test_the_rlhf_report_keeps_lines_of_runs_not_on_this_machine_unless_retired(
    tmp_path, monkeypatch
):
    """A checkout without ``runs/`` regenerated docs/rlhf_results.md without the zara1 and
    eth diagnostics until 2026-11-29; now their lines stay, unless the runs were retired (the
    method name now means other runs, whose test minFDE differs)."""
    report = load_benchmark("finetune_report")
    old = "\n".join([
        "## Test accuracy against the pretrained start (K = 20, per agent unless joint)",
        "| zara1 | rlhf | 3 | 0.172 | accuracy line |",
        report.DIAGNOSTICS,
        "| dataset | method | runs |",
        "|---|---|---|",
        "| zara1 | rlhf | 3 | zara1 diagnostics |",
        "| robo | rlhf | 3 | robo diagnostics of retired runs |",
        report.REWARD,
        "| zara1 | rlhf | defaults | 1 | 9 | x | x | x | 1 | 0.330 (+10.0 %) | CPU |",
        "| robo | rlhf | defaults | 1 | 9 | x | x | x | 1 | 0.469 (+4.4 %) | CPU |",
    ])  # fmt: skip
    assert table_lines(old, report.DIAGNOSTICS)["zara1", "rlhf"].endswith(
        "zara1 diagnostics |"
    )  # not the accuracy table's line of the same key
    rows = [_row("zara1", method="rlhf", fde=0.33), _row("robo", method="rlhf", fde=0.40)]
    current = report.still_current(table_lines(old, report.REWARD), rows)
    assert set(current) == {("zara1", "rlhf")}  # robo's line had another test minFDE
    monkeypatch.setattr(report, "ROOT", tmp_path)  # no run folders, no start records
    diag = report.diagnostics_section(
        ["zara1", "robo"],
        {k: v for k, v in table_lines(old, report.DIAGNOSTICS).items() if k in current},
    )
    assert "zara1 diagnostics" in diag and "robo" not in diag


def test_table_lines_keys_data_lines_by_their_first_two_cells_under_a_heading():
    text = "\n".join(["## A", "| dataset | method |", "|---|---|", "| eth | rlhf | 1 |",
                      "| eth | rlhf | 2 |", "## B", "| zara1 | control | 3 |"])  # fmt: skip
    assert table_lines(text) == {("eth", "rlhf"): "| eth | rlhf | 1 |",
                                 ("zara1", "control"): "| zara1 | control | 3 |"}  # fmt: skip
    assert table_lines(text, "## B") == {("zara1", "control"): "| zara1 | control | 3 |"}


# ``results.SELECTION_FREE`` (the selection table's columns) is a copy of the score-free
# selection methods that ``results`` may not import (``score`` is above it in the layers):
# this test is what keeps the two the same when a selection method is added.


def test_the_selection_tables_columns_are_the_score_free_methods():
    assert len(set(SELECTION_FREE)) == len(SELECTION_FREE)
    assert set(SELECTION_FREE) == {m for m in METHODS if not USES_SCORE[m]}
    # in the order of score.selection.Method, as --select lists them
    assert list(SELECTION_FREE) == [m for m in METHODS if not USES_SCORE[m]]
