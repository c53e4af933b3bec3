"""benchmarks/zoo_index.py: what a model card says about where it was trained."""

import json
import re
import subprocess
from pathlib import Path

import pytest
from bench import load_benchmark
from helpers import _row

from trajpref.models import checkpoint as ckpt

ROOT = Path(__file__).resolve().parent.parent


def test_a_card_names_the_training_process_machine_before_the_publishing_one(monkeypatch):
    """pretrain.py records the machine (threads included) the checkpoint was trained on
    (``trained_on``, from the checkpoint's meta since 2026-11-27); the card prefers it to the
    machine of the process that evaluated the test row."""
    zoo = load_benchmark("zoo_index")
    path = ROOT / "models" / "zara2" / "generator.safetensors"
    rows = [{"dataset": "zara2", "method": "pretrained", "seed": 0, "split": "test",
             "protocol": "all", "checkpoint": "models/zara2/generator.safetensors",
             "machine": "publisher, 2 threads", "min_ade": 0.1, "min_fde": 0.2,
             "joint_min_ade": 0.3, "joint_min_fde": 0.4, "date": "2026-11-27"}]  # fmt: skip
    meta = {"stage_seconds": {"generator": 60.0}}
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: meta)
    assert zoo.describe("zara2/generator", path, rows)["train"]["machine"] == "publisher, 2 threads"
    meta["trained_on"] = "trainer, 1 threads"
    assert zoo.describe("zara2/generator", path, rows)["train"]["machine"] == "trainer, 1 threads"
    meta["train_machine"] = "1x H100"  # stated by hand for a run trained elsewhere
    assert zoo.describe("zara2/generator", path, rows)["train"]["machine"] == "1x H100"


def test_a_card_quotes_the_cost_estimate_only_for_the_epochs_it_measured(tmp_path, monkeypatch):
    """The card adds train_cost.py's minutes alone beside the as-run minutes, and leaves them
    out when the record measured another number of epochs (a config changed since)."""
    import json

    zoo = load_benchmark("zoo_index")
    (tmp_path / "meta").mkdir()
    record = {"machine": "Linux, 2 CPU cores, 2 threads", "date": "2026-11-27", "datasets": {
        "zara2": {"denoiser": {"epochs": 60, "minutes": 6.0},
                  "generator": {"epochs": 160, "minutes": 9.5}}}}  # fmt: skip
    (tmp_path / "meta" / "train_cost.json").write_text(json.dumps(record))
    monkeypatch.setattr(zoo, "RESULTS", tmp_path)
    cfg = {"denoiser": {"epochs": 60}, "generator": {"epochs": 160}}
    estimate = zoo._cost_estimate("zara2", "generator", cfg)
    assert estimate["minutes"] == {"denoiser": 6.0, "generator": 9.5}
    line = zoo._estimate_lines(estimate)[1]
    assert "denoiser 6.0 min + generator 9.5 min = 15.5 min" in line and "CPU (2 cores)" in line
    assert zoo._cost_estimate("zara2", "denoiser", cfg)["minutes"] == {"denoiser": 6.0}
    cfg["generator"]["epochs"] = 320  # the record is stale for this file
    assert zoo._cost_estimate("zara2", "generator", cfg) is None
    assert zoo._cost_estimate("zara2", "denoiser", cfg) is not None  # its own stage still holds
    assert zoo._cost_estimate("eth", "generator", cfg) is None and zoo._estimate_lines(None) == []


def test_a_card_says_when_its_generator_trained_on_mirrored_scenes():
    """The training-time settings that shape a generator are on its card; the mirror is one
    (configs/zara1.yaml since 2026-11-27) and is stated only when the file was trained so."""
    zoo = load_benchmark("zoo_index")
    base = {"tau": 0, "stochastic_steps": False, "dropout": 0.2, "changes": []}
    assert "mirrored" in " ".join(zoo._sampling_lines({**base, "flip": True}))
    assert "mirrored" not in " ".join(zoo._sampling_lines({**base, "flip": False}))
    assert "mirrored" not in " ".join(zoo._sampling_lines(base))  # files from before the field
    assert "leave the view" in " ".join(zoo._sampling_lines({**base, "context_agents": True}))
    assert "leave the view" not in " ".join(zoo._sampling_lines(base))


def test_a_card_states_consecutive_rewrites_of_one_setting_once():
    """univ's clamp was written twice on one day (0.2996 rounded, then all its digits); the
    card said "set to 0.300" twice. Consecutive changes of one setting make one sentence with
    every note; a change of another setting in between keeps them apart."""
    zoo = load_benchmark("zoo_index")
    first = {"max_speed": 0.2996, "previous": 0.0, "date": "2026-12-01", "note": "the 90 % clamp"}
    second = {"max_speed": 0.29963, "previous": 0.2996, "date": "2026-12-01", "note": "all digits"}
    steps = {"stochastic_steps": False, "previous": True, "date": "2026-12-01", "note": "mean"}
    base = {"tau": 0, "stochastic_steps": False, "changes": [first, second]}
    text = " ".join(zoo._sampling_lines(base))
    assert text.count("Speed clamp set to") == 1
    assert "(2026-12-01: the 90 % clamp; 2026-12-01: all digits)" in text
    apart = " ".join(zoo._sampling_lines({**base, "changes": [first, steps, second]}))
    assert apart.count("Speed clamp set to") == 2


def test_a_generator_cards_denoiser_command_rebuilds_the_published_denoiser(monkeypatch):
    """univ's config turns on data flags for its generator stage (data.flip, data.reverse)
    that its published denoiser was not trained with; the card's diffusion command must switch
    them off, as the denoiser's own card does, or it trains a different denoiser."""
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    path = ROOT / "models" / "univ" / "generator.safetensors"
    gen = zoo.describe("univ/generator", path, [])["train"]["commands"]
    den = zoo.describe("univ/denoiser", path.with_name("denoiser.safetensors"), [])
    assert gen[0].startswith("trajpref train diffusion") and gen[0] == den["train"]["commands"][0]
    assert "--set data.flip=false" in gen[0] and "--set data.reverse=false" in gen[0]
    assert "--set data" not in gen[1]  # the generator's own stage keeps the config's flags


def test_a_published_fine_tune_from_a_replaced_start_keeps_its_own_row():
    mod = load_benchmark("zoo_index")
    rows = [
        {"dataset": "zara2", "method": "rlhf-res", "seed": 0, "min_fde": 0.21},
        {"dataset": "zara2", "method": "rlhf-res-scene", "seed": 0, "min_fde": 0.25},
        {"dataset": "zara2", "method": "rlhf-res-scene", "seed": 1, "min_fde": 0.26},
    ]
    assert mod.tuned_row(rows, "zara2", "rlhf-res", from_today=False)["min_fde"] == 0.25
    assert mod.tuned_row(rows, "zara2", "rlhf-res", from_today=True)["min_fde"] == 0.21
    assert mod.tuned_row(rows[1:], "zara2", "rlhf-res", from_today=True) is None


def test_a_cards_training_command_states_the_threads_its_cpu_run_used(monkeypatch):
    """A seed repeats its run exactly only at the same thread count, so a CPU run's recorded
    threads go in front of the card's generator command; a GPU run's command has none."""
    zoo = load_benchmark("zoo_index")
    one = "Linux x86_64 (AMD EPYC), 2 CPU cores, torch 2.13, 1 threads"
    assert zoo.thread_prefix(one) == "OMP_NUM_THREADS=1 "
    assert zoo.thread_prefix("Linux, 2 CPU cores, 2 threads") == "OMP_NUM_THREADS=2 "
    assert zoo.thread_prefix("Linux, 2 CPU cores") == "" and zoo.thread_prefix(None) == ""
    assert zoo.thread_prefix("1x H200, 16 CPU cores, 16 threads") == ""
    path = ROOT / "models" / "zara2" / "generator.safetensors"
    meta = {"trained_on": "trainer, 2 CPU cores, 1 threads"}
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: meta)
    cmds = zoo.describe("zara2/generator", path, [])["train"]["commands"]
    assert cmds[-1].startswith("OMP_NUM_THREADS=1 trajpref train generator")
    assert not cmds[0].startswith("OMP")  # the denoiser's stage: its threads are not recorded
    meta["train_machine"] = "1x H100"
    cmds = zoo.describe("zara2/generator", path, [])["train"]["commands"]
    assert cmds[-1].startswith("trajpref train generator") and "--device cuda" in cmds[-1]


def test_a_cards_overrides_read_back_as_the_values_they_set():
    """A card's ``--set`` values are YAML that the config reads back: null, true, false and
    quoted strings, not Python's None and False (``--set x=None`` is not a number)."""
    from trajpref.config import load_config

    zoo = load_benchmark("zoo_index")
    assert [zoo._scalar(v) for v in (None, False, True, 0.5, 3, "a b")] == [
        "null",
        "false",
        "true",
        "0.5",
        "3",
        '"a b"',
    ]
    sets = [f"generator.max_minutes={zoo._scalar(None)}",
            f"generator.budget_schedule={zoo._scalar(False)}"]  # fmt: skip
    cfg = load_config(zoo.ROOT / "configs" / "hotel.yaml", sets)
    assert cfg.generator.max_minutes is None and cfg.generator.budget_schedule is False


def _rows(dataset, method, checkpoint, **fields):
    row = {"dataset": dataset, "method": method, "seed": 0, "split": "test", "samples": 20,
           "protocol": "all", "checkpoint": checkpoint, "machine": "m, 2 CPU cores, 1 threads",
           "min_ade": 0.1, "min_fde": 0.2, "joint_min_ade": 0.3, "joint_min_fde": 0.4,
           "date": "2026-12-01", "command": "python benchmarks/x.py"}  # fmt: skip
    return {**row, **fields}


def test_a_cards_test_row_is_the_all_protocol_row_and_says_so(monkeypatch):
    """The same checkpoint and method has a row per protocol (``sgan`` rows are often the
    newer); the card's and the index's test row is the ``all`` one, and says so."""
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    path = ROOT / "models" / "zara2" / "generator.safetensors"
    ckpt = "models/zara2/generator.safetensors"
    rows = [_rows("zara2", "pretrained", ckpt, min_fde=0.21),
            _rows("zara2", "pretrained", ckpt, protocol="sgan", min_fde=0.99,
                  date="2026-12-06")]  # fmt: skip
    entry = zoo.describe("zara2/generator", path, rows)
    assert entry["test"]["protocol"] == "all" and entry["test"]["min_fde"] == 0.21
    assert "test split, protocol `all`, K = 20, seed 0" in zoo.card(entry)
    den = zoo.describe(
        "zara2/denoiser",
        path.with_name("denoiser.safetensors"),
        [_rows("zara2", "full-sampler", ckpt, protocol="sgan", min_fde=0.99)],
    )
    assert den["test"] is None  # an sgan row alone is not the card's test row


def test_a_denoiser_card_says_whose_machine_it_names_and_its_commands_carry_the_threads(
    monkeypatch,
):
    """No training record names a published denoiser's machine: the card names the machine
    that evaluated its test row as such, and its command carries that run's thread count as
    the generator commands do."""
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {"stage_seconds": {
        "denoiser": 600.0}})  # fmt: skip
    path = ROOT / "models" / "zara2" / "denoiser.safetensors"
    rows = [_rows("zara2", "full-sampler", "models/zara2/generator.safetensors",
                  machine="evaluator, 2 CPU cores, 2 threads")]  # fmt: skip
    entry = zoo.describe("zara2/denoiser", path, rows)
    assert entry["train"]["machine_from"] == "test row"
    assert entry["train"]["commands"][0].startswith("OMP_NUM_THREADS=2 trajpref train diffusion")
    text = zoo.card(entry)
    assert "No training record names the machine; the one that evaluated its test row" in text
    assert "thread count in front of its command is that run's" in text
    gen = zoo.describe("zara2/generator", path.with_name("generator.safetensors"), rows)
    assert gen["train"]["commands"][0] == entry["train"]["commands"][0]  # the same denoiser
    assert "the thread count of the run that evaluated" in zoo.card(gen)


def test_the_denoisers_speed_limit_quotes_the_timing_file():
    zoo = load_benchmark("zoo_index")
    speed = {"date": "2026-12-03", "models": {
        "eth/generator": {"full_over_leapfrog": 26.07},
        "eth/generator-pace": {"full_over_leapfrog": 10.55},
        "univ/generator": {"full_over_leapfrog": 98.76}}}  # fmt: skip
    text = zoo.speed_note(speed, "eth")
    assert "10.6-98.8x" in text and "benchmarks/results/meta/speed.json" in text
    assert "2026-12-03" in text and "26.1x beside `eth/generator`" in text
    assert "15x" not in zoo.speed_note(speed, "robo")  # no line of its own: the range only
    assert zoo.speed_note({"models": {}}, "eth") == ""


def test_robos_distance_to_the_papers_led_row_is_computed_from_its_row():
    zoo = load_benchmark("zoo_index")
    row = {"min_ade": 0.24617, "min_fde": 0.34564}
    text = zoo.led_gap(row, [0.22, 0.35])
    assert text.startswith("Its test minFDE20 is 0.004 m below the paper's LED row (0.22 / 0.35)")
    assert "its minADE20 0.026 m above" in text
    assert "0.005 m above" in zoo.led_gap({"min_ade": 0.2, "min_fde": 0.355}, [0.22, 0.35])


def test_a_fine_tune_from_a_replaced_start_names_that_start_not_todays_generator(monkeypatch):
    """A published fine-tune whose start is no longer the dataset's default (its ``from`` hash
    differs from today's generator's) gets a card whose command starts from that replaced
    start, not from today's ``zara2/generator``, and whose row is the start's suffixed one."""
    zoo = load_benchmark("zoo_index")
    today = ROOT / "models" / "zara2" / "generator.safetensors"
    real = zoo.zoo.header
    tuned = dict(real(today), meta={"method": "rlhf-res", "from": "0123456789abcdef",
                                    "train_seconds": 180.0})  # fmt: skip
    fake = today.parent / "rlhf-res.safetensors"  # never read: the header is the test's
    monkeypatch.setattr(zoo.zoo, "header", lambda p: tuned if Path(p) == fake else real(p))
    start = "runs/zara2-scene/generator.safetensors"  # the replaced start's kept row
    tuned_file = "models/zara2/rlhf-res.safetensors"
    rows = [{"dataset": "zara2", "method": m, "seed": 0, "split": "test", "protocol": "all",
             "checkpoint": c, "machine": "publisher, 1 threads", "min_ade": 0.1,
             "min_fde": f, "joint_min_ade": 0.3, "joint_min_fde": 0.4, "date": "2026-11-24"}
            for m, c, f in (("rlhf-res", None, 0.21), ("pretrained-scene", start, 0.24),
                            ("rlhf-res-scene", tuned_file, 0.25))]  # fmt: skip
    entry = zoo.describe("zara2/rlhf-res", fake, rows)
    commands = "\n".join(entry["train"]["commands"])
    assert "weights hash 0123456789abcdef, since replaced" in commands
    assert f"since replaced ({start})" in commands
    assert "--from START.safetensors" in commands and "--from zara2/generator" not in commands
    assert entry["test"]["method"] == "rlhf-res-scene" and entry["test"]["min_fde"] == 0.25


RETIRED = {"zara2/rlhf-res": "62cc5a7"}
"""Published models that left the zoo -> a commit whose tree still holds their weights."""

GIT_SHOW = re.compile(
    r"git show ([0-9a-f]{7,40}):(src/trajpref/zoo/[a-z][\w-]*/[\w.-]+\.safetensors)"
)
"""A ``git show COMMIT:PATH`` of published weights (a placeholder such as ``D/`` or ``<name>``
does not match)."""


def _docs_text() -> str:
    """README, docs/*.md, the model cards and zoo_index.py's limits on one line each (prose
    wraps anywhere, a ``git show`` included)."""
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
             *sorted((ROOT / "src" / "trajpref" / "zoo").glob("*/*.md")),
             ROOT / "benchmarks" / "zoo_index.py"]  # fmt: skip
    return " ".join(" ".join(f.read_text().split()) for f in files)


def test_a_retired_model_has_left_the_zoo_and_the_readme_names_its_weights_in_git():
    index = json.loads((ROOT / "src" / "trajpref" / "zoo" / "index.json").read_text())
    names = {m["name"] for m in index["models"]}
    zoo = load_benchmark("zoo_index")
    readme = " ".join((ROOT / "README.md").read_text().split())
    for name, commit in RETIRED.items():
        dataset, stem = name.split("/")
        assert name not in names and name not in zoo.LIMITS
        assert not (ROOT / "src" / "trajpref" / "zoo" / dataset / f"{stem}.safetensors").exists()
        assert not (ROOT / "src" / "trajpref" / "zoo" / dataset / f"{stem}.md").exists()
        assert f"git show {commit}:src/trajpref/zoo/{dataset}/{stem}.safetensors" in readme


def test_every_git_show_of_zoo_weights_in_the_docs_names_a_file_that_commit_holds():
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    found = set(GIT_SHOW.findall(_docs_text()))
    assert found >= {(c, f"src/trajpref/zoo/{n}.safetensors") for n, c in RETIRED.items()}
    missing = [f"{c}:{p}" for c, p in sorted(found)
               if subprocess.run(["git", "cat-file", "-e", f"{c}:{p}"], cwd=ROOT,
                                 capture_output=True).returncode]  # fmt: skip
    assert not missing, f"named in the docs but not in those commits: {missing}"


def test_a_subset_full_sampler_cell_is_quoted_where_no_whole_split_row_exists(
    tmp_path, monkeypatch
):
    import json

    zoo = load_benchmark("zoo_index")
    (tmp_path / "meta" / "reproduce").mkdir(parents=True)
    cell = {"result": {"min_ade": 0.2959, "min_fde": 0.5275}, "agents": 5998,
            "split_agents": 24334, "date": "2026-12-05"}  # fmt: skip
    (tmp_path / "meta" / "reproduce" / "univ_full-sampler.json").write_text(json.dumps(cell))
    monkeypatch.setattr(zoo, "RESULTS", tmp_path)
    text = zoo.subset_note("univ")
    assert "0.296 / 0.527" in text and "5,998 of its 24,334" in text
    assert "docs/reproduce.md" in text and "2026-12-05" in text
    assert zoo.subset_note("hotel") == ""


def test_a_limit_that_sends_to_a_generator_in_git_says_to_copy_its_denoiser_beside_it():
    """A published generator names its denoiser instead of embedding it, so the file from
    `git show` alone fails to load ("it needs denoiser.safetensors (hash ...) beside it"):
    a card that sends users to one says to copy the denoiser beside it."""
    zoo = load_benchmark("zoo_index")
    shows = 0
    for text in zoo.LIMITS.values():
        found = re.findall(r"git show ([0-9a-f]{7,40}):src/trajpref/zoo/([a-z][\w-]*)/"
                           r"generator\.safetensors", text)  # fmt: skip
        for commit, dataset in found:
            shows += 1
            assert f"src/trajpref/zoo/{dataset}/denoiser.safetensors" in text, (commit, dataset)
    assert shows >= 2  # robo's and robo-mix's generators without roles


def test_cards_train_with_the_shipped_configs_name_and_place_what_they_cite(monkeypatch):
    """`trajpref models zara1/generator` in an installed package printed `--config
    configs/zara1.yaml`, a path only a checkout has; `--config zara1` finds the shipped config
    anywhere, and in the repository it is the same file. The `benchmarks/` scripts and results
    a card cites are in the source repository, and the card says so (2026-12-06 walkthrough
    of a wheel install)."""
    from trajpref.config import resolve_config
    from trajpref.models import zoo as zoo_mod

    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    for dataset in ("zara1", "robo-mix"):
        shipped = resolve_config(dataset).resolve()
        assert shipped == (ROOT / "configs" / f"{dataset}.yaml").resolve()
    for name, path in zoo_mod.published().items():
        text = zoo.card(zoo.describe(name, path, []))
        commands = [line for line in text.splitlines() if "trajpref train " in line]
        assert commands, name
        for line in commands:
            assert f"--config {name.split('/')[0]} " in line and "configs/" not in line, line
        assert "are in the source repository" in text, name
        stored = path.with_suffix(".md").read_text()  # the cards the package ships
        assert "--config configs/" not in stored and "are in the source repository" in stored


# Which weights a published number measured (the reproducibility audit of walk 67): a card's
# test row must name its file's digest, rows without one whose file is gone are counted, and
# the README's latencies are checked against the files they timed.


ZARA2 = ROOT / "models" / "zara2"


def test_a_denoiser_card_shows_the_row_that_names_its_files_digest(monkeypatch):
    """zara2/denoiser's card showed the full-sampler row of 2026-11-22, which names
    ``generator.pt`` (replaced by fp16 .safetensors on 2026-11-23) and no digest: the first
    row of that path won, whatever its hash. A row naming the file's digest is preferred,
    even when an undigested row is newer."""
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    digest = ckpt.model_hash(ZARA2 / "denoiser.safetensors", "full")
    old = _row("full-sampler", "models/zara2/generator.pt", "2026-11-22", min_fde=0.325)
    new = _row("full-sampler", "models/zara2/generator.safetensors", "2026-12-06", digest,
               min_fde=0.326)  # fmt: skip
    later = _row("full-sampler", "models/zara2/generator.safetensors", "2026-12-07",
                 min_fde=0.999)  # fmt: skip
    entry = zoo.describe("zara2/denoiser", ZARA2 / "denoiser.safetensors", [old, new, later])
    assert entry["test"]["min_fde"] == 0.326
    assert "_unverified" not in entry


def test_a_card_whose_rows_name_none_of_its_files_digest_is_reported(monkeypatch):
    zoo = load_benchmark("zoo_index")
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    old = _row("full-sampler", "models/zara2/generator.pt", "2026-11-22")
    entry = zoo.describe("zara2/denoiser", ZARA2 / "denoiser.safetensors", [old])
    assert entry["test"]["date"] == "2026-11-22"  # still shown, but reported
    assert "names no model_hash" in entry.get("_unverified", "")
    # a generator's newest row of other weights does not stand for the file either
    path = ZARA2 / "generator.safetensors"
    digest = ckpt.model_hash(path)
    rows = [_row("pretrained", "models/zara2/generator.safetensors", "2026-12-01", digest,
                 min_fde=0.21),
            _row("pretrained", "models/zara2/generator.safetensors", "2026-12-05",
                 "0123456789ab", min_fde=0.5)]  # fmt: skip
    assert zoo.describe("zara2/generator", path, rows)["test"]["min_fde"] == 0.21
    entry = zoo.describe("zara2/generator", path, rows[1:])
    assert "measured 0123456789ab" in entry.get("_unverified", "")


def test_the_zoo_check_says_when_everything_is_up_to_date(tmp_path, monkeypatch, capsys):
    """``--check`` printed nothing when it passed."""
    zoo = load_benchmark("zoo_index")
    (tmp_path / "zoo").mkdir()
    (tmp_path / "README.md").write_text("x\n<!-- models:start -->\n<!-- models:end -->\n")
    monkeypatch.setattr(zoo.zoo, "ZOO_DIR", tmp_path / "zoo")
    monkeypatch.setattr(zoo, "ROOT", tmp_path)
    monkeypatch.setattr("sys.argv", ["zoo_index.py"])
    zoo.main()
    capsys.readouterr()
    monkeypatch.setattr("sys.argv", ["zoo_index.py", "--check"])
    with pytest.raises(SystemExit) as done:
        zoo.main()
    assert done.value.code == 0
    assert "models/index.json and 0 cards are up to date" in capsys.readouterr().out


def test_a_denoiser_card_says_its_generators_ratio_was_timed_before_the_file_changed():
    """eth/denoiser's card quoted 26.1x beside `eth/generator`, timed on 2026-12-03 before
    the file changed (2026-12-06)."""
    zoo = load_benchmark("zoo_index")
    speed = {"date": "2026-12-03", "models": {"eth/generator": {"full_over_leapfrog": 26.07}}}
    assert "as it was then" not in zoo.speed_note(speed, "eth")
    text = zoo.speed_note(speed, "eth", changed=True)
    assert "26.1x beside `eth/generator` as it was then (its file has changed since" in text


# benchmarks/zoo_index.py: a card's test-row command names no machine's data path
# (walkthrough 67, F6).


def test_an_absolute_data_root_becomes_the_portable_one():
    zoo = load_benchmark("zoo_index")
    cmd = (
        "python benchmarks/pretrain.py --dataset sdd --run-dir runs/x --data-root /work/shared/data"
    )
    assert zoo.portable_command(cmd) == (
        "python benchmarks/pretrain.py --dataset sdd --run-dir runs/x --data-root ../shared/data"
    )
    assert zoo.portable_command("score.py --data-root=/home/me/data --x 1") == (
        "score.py --data-root=../shared/data --x 1"
    )
    relative = "python benchmarks/score.py --dataset eth --data-root ../shared/data"
    assert zoo.portable_command(relative) == relative
    assert zoo.portable_command("trajpref evaluate --dataset data/x") == (
        "trajpref evaluate --dataset data/x"
    )
    assert zoo.portable_command(None) is None


def test_the_card_and_index_show_the_portable_command_and_the_row_keeps_its_own():
    zoo = load_benchmark("zoo_index")
    cmd = "python benchmarks/score.py --dataset zara2 --data-root /work/shared/data"
    row = {"dataset": "zara2", "method": "pretrained", "seed": 0, "split": "test",
           "samples": 20, "min_ade": 0.1, "min_fde": 0.2, "joint_min_ade": 0.3,
           "joint_min_fde": 0.4, "date": "2026-12-06", "machine": "m", "command": cmd}  # fmt: skip
    test = zoo._test_row(row)
    assert (
        test["command"] == "python benchmarks/score.py --dataset zara2 --data-root ../shared/data"
    )
    assert row["command"] == cmd  # the results row is not rewritten


def test_no_published_card_or_index_names_an_absolute_data_root():
    zoo_dir = ROOT / "src" / "trajpref" / "zoo"
    for path in [zoo_dir / "index.json", *sorted(zoo_dir.glob("*/*.md"))]:
        text = path.read_text()
        assert "--data-root /" not in text and "--data-root=/" not in text, path
