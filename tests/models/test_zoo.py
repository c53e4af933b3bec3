"""The model zoo: names resolve to the published files, the listing and the cards ship with
them, and the repository's index is what benchmarks/zoo_index.py writes."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from bench import load_benchmark

from trajpref.cli import main
from trajpref.errors import TrajprefError
from trajpref.models import checkpoint, zoo

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def fake_zoo(tiny_run, tmp_path, monkeypatch) -> Path:
    """A zoo of one dataset, ``walks``: the tiny run's generator published with its
    denoiser (referenced by path and hash, as the real zoo's are). The cwd is elsewhere."""
    root = tmp_path / "zoo"
    checkpoint.publish(tiny_run / "generator.safetensors", root / "walks" / "generator.safetensors")
    monkeypatch.setattr(zoo, "ZOO_DIR", root)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    return root


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("zara1/generator", True),
        ("zara1/rlhf-res", True),
        ("eth/generator-speedaug", True),
        ("cv", False),
        ("models/zara1/generator.safetensors", False),
        ("zara1/generator.safetensors", False),
        ("zara1/generator.pt", False),
        ("/abs/zara1/generator", False),
        ("a/b/c", False),
    ],
)
def test_what_counts_as_a_published_name(spec, expected):
    assert zoo.is_name(spec) is expected


def test_a_name_resolves_and_loads_the_denoiser_it_names(fake_zoo):
    assert checkpoint.resolve_path("walks/generator") == fake_zoo / "walks/generator.safetensors"
    # the generator names its denoiser by a path relative to its own folder, not the cwd
    payload = checkpoint.load("walks/generator")
    den = zoo.header(fake_zoo / "walks/denoiser.safetensors")
    assert payload["denoiser"]["hash"] == den["hash"]
    assert zoo.published() == {
        "walks/denoiser": fake_zoo / "walks/denoiser.safetensors",
        "walks/generator": fake_zoo / "walks/generator.safetensors",
    }


def test_generators_lists_each_datasets_generators_only(fake_zoo):
    checkpoint.publish(fake_zoo / "walks/generator.safetensors",
                       fake_zoo / "walks/generator-long.safetensors")  # fmt: skip
    checkpoint.publish(fake_zoo / "walks/generator.safetensors",
                       fake_zoo / "runs/generator.safetensors")  # fmt: skip
    assert list(zoo.generators()) == ["runs/generator", "walks/generator", "walks/generator-long"]
    assert list(zoo.generators(["walks"])) == ["walks/generator", "walks/generator-long"]
    assert zoo.generators(["nowhere"]) == {}


def test_an_unknown_name_lists_the_published_ones(fake_zoo):
    with pytest.raises(TrajprefError, match=r"walks/nope: .*published: walks/denoiser, "
                       r"walks/generator \(`trajpref models`"):  # fmt: skip
        checkpoint.resolve_path("walks/nope")


def test_an_existing_file_wins_over_a_published_name(fake_zoo):
    local = Path("walks/generator")
    local.parent.mkdir()
    shutil.copy(fake_zoo / "walks/denoiser.safetensors", local)
    assert checkpoint.resolve_path("walks/generator") == local
    assert checkpoint.load("walks/generator")["kind"] == "denoiser"


def test_unindexed_files_are_listed_from_their_headers(fake_zoo):
    rows = {e["name"]: e for e in zoo.entries()}
    assert rows["walks/generator"]["kind"] == "generator"
    assert rows["walks/denoiser"]["kind"] == "denoiser"
    assert not rows["walks/generator"]["indexed"]
    table = zoo.table(list(rows.values())).splitlines()
    assert table[0].split()[:2] == ["name", "kind"]
    assert table[2].split()[:3] == ["walks/generator", "generator", "(not"]


def test_indexed_entries_show_their_test_row_machine_and_minutes(fake_zoo):
    entry = {
        "name": "walks/generator", "kind": "generator", "method": "pretrained",
        "test": {"min_ade": 0.12345, "min_fde": 0.5},
        "train": {"machine_short": "CPU (2 cores)", "minutes": {"generator": 14.04}},
    }  # fmt: skip
    index = {"format": zoo.INDEX_FORMAT, "models": [entry]}
    (fake_zoo / zoo.INDEX).write_text(json.dumps(index))
    rows = {e["name"]: e for e in zoo.entries()}
    assert rows["walks/generator"]["indexed"] and not rows["walks/denoiser"]["indexed"]
    line = next(x for x in zoo.table(list(rows.values())).splitlines() if "walks/gen" in x)
    assert line.split() == ["walks/generator", "generator", "pretrained", "0.123", "/", "0.500",
                            "CPU", "(2", "cores)", "14.0"]  # fmt: skip


def test_a_bad_index_is_a_one_line_error(fake_zoo):
    (fake_zoo / zoo.INDEX).write_text(json.dumps({"format": "something/9", "models": []}))
    with pytest.raises(TrajprefError, match="not a zoo index"):
        zoo.entries()
    (fake_zoo / zoo.INDEX).write_text("{not json")
    with pytest.raises(TrajprefError, match="unreadable zoo index"):
        zoo.entries()


def test_cli_lists_the_zoo_and_prints_cards(fake_zoo, capsys):
    assert main(["models"]) == 0
    out = capsys.readouterr().out
    assert "walks/denoiser" in out and "walks/generator" in out
    assert main(["models", "--json"]) == 0
    assert [e["name"] for e in json.loads(capsys.readouterr().out)] == [
        "walks/denoiser", "walks/generator"]  # fmt: skip
    assert main(["models", "walks/generator"]) == 2  # no card written yet
    assert "published without a model card" in capsys.readouterr().err
    (fake_zoo / "walks" / "generator.md").write_text("# walks/generator\n\nA card.\n")
    assert main(["models", "walks/generator"]) == 0
    assert capsys.readouterr().out == "# walks/generator\n\nA card.\n"
    assert main(["models", "walks/nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("trajpref: error: walks/nope: ")


def test_cli_model_and_scorer_accept_names(fake_zoo, walks, capsys):
    def evaluate(model, scorer):
        argv = ["evaluate", "--dataset", str(walks), "--model", model, "--scorer", scorer,
                "--samples", "3", "--json", "--no-progress", "--device", "cpu"]  # fmt: skip
        assert main(argv) == 0
        return json.loads(capsys.readouterr().out)

    by_name = evaluate("walks/generator", "walks/denoiser")
    by_path = evaluate(str(fake_zoo / "walks/generator.safetensors"),
                       str(fake_zoo / "walks/denoiser.safetensors"))  # fmt: skip
    for key in ("min_ade", "min_fde", "max_ats"):
        assert by_name[key] == by_path[key]
    assert main(["evaluate", "--dataset", str(walks), "--model", "walks/nope"]) == 2
    assert "published: walks/denoiser, walks/generator" in capsys.readouterr().err


# ------------------------------------------------------------------- the repository's zoo


def test_every_published_model_is_indexed_with_a_card():
    published = zoo.published()
    index = zoo.load_index()
    assert published and set(index) == set(published)
    for name, path in published.items():
        entry = index[name]
        assert entry["hash"] == zoo.header(path)["hash"], name
        assert (zoo.ZOO_DIR / entry["card"]).is_file(), name
        assert entry["train"]["minutes"] and entry["train"]["machine"], name
        if entry["kind"] == "generator":
            assert entry["denoiser"] in published, name
            assert entry["test"]["samples"] == 20 and entry["test"]["split"] == "test", name


def test_the_index_cards_and_readme_listing_are_up_to_date():
    """After publishing a model, `python benchmarks/zoo_index.py` rewrites them."""
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "zoo_index.py"), "--check"],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_the_repository_models_folder_is_the_packaged_zoo():
    assert (ROOT / "models").resolve() == zoo.ZOO_DIR
    assert (ROOT / "models" / "zara1" / "generator.safetensors").is_file()


def _zoo_index():
    return load_benchmark("zoo_index")


def test_a_sampling_change_after_training_shows_on_the_card_not_in_the_training_command():
    zoo_index = _zoo_index()
    config = {"model": {"stochastic_steps": False, "tau": 5}}
    change = {"stochastic_steps": False, "note": "2026-11-24: posterior-mean by default"}
    # the training command must reproduce the run: trained with ancestral steps
    assert zoo_index.trained_config(config, [change])["model"]["stochastic_steps"] is True
    assert zoo_index.trained_config(config, [])["model"]["stochastic_steps"] is False
    assert config["model"]["stochastic_steps"] is False  # not modified in place
    lines = zoo_index._sampling_lines({"tau": 5, "stochastic_steps": False, "changes": [change]})
    assert "tau = 5 denoising steps, each the posterior mean" in lines[0]
    assert "Set to posterior-mean steps after training (2026-11-24" in lines[0]
    assert "ancestral noise." in zoo_index._sampling_lines(
        {"tau": 5, "stochastic_steps": True, "changes": []})[0]  # fmt: skip


def test_a_files_test_row_is_its_newest_not_a_studys_older_copy():
    zi = _zoo_index()
    ck = "models/eth/generator.safetensors"
    rows = [
        {"checkpoint": ck, "method": "pretrained", "date": "2026-11-26", "min_fde": 0.7},
        {"checkpoint": ck, "method": "pretrained", "date": "2026-11-25", "min_fde": 0.8},
        {"checkpoint": "models/eth/generator.pt", "method": "rlhf", "date": None, "min_fde": 1},
    ]
    newest = zi.newest_rows(rows)
    assert newest[("eth/generator", "pretrained")]["min_fde"] == 0.7
    assert newest[("eth/generator", "rlhf")]["min_fde"] == 1


def test_a_card_tells_a_clamp_set_after_training_from_one_trained_with():
    zi = _zoo_index()

    def text(*changes):
        sampling = {"tau": 5, "stochastic_steps": False, "max_speed": 0.3, "changes": changes}
        return zi._sampling_lines(sampling)[0]

    after = text({"max_speed": 0.3, "previous": 0.0, "note": "n"})
    assert "Speed clamp set to 0.300 after training, same weights (n)." in after
    trained = text({"max_speed": 0.14714, "previous": 0.1471, "note": "m"})
    assert "Trained with the speed clamp at 0.1471, set to 0.1471 (m)." in trained
    # a post-hoc clamp changed again stays a post-hoc clamp
    twice = text({"max_speed": 0.4, "previous": 0.0, "note": "a"},
                 {"max_speed": 0.3, "previous": 0.4, "note": "b"})  # fmt: skip
    assert "Trained with" not in twice and "set to 0.300 after training" in twice


def test_a_card_names_the_history_encoder_the_spread_and_the_weight_average():
    zi = _zoo_index()
    base = {"tau": 5, "stochastic_steps": False, "changes": []}
    plain = zi._sampling_lines(base)[0]
    assert "GRU" not in plain and "spread" not in plain and "moving average" not in plain
    text = zi._sampling_lines({**base, "history_encoder": "temporal", "spread_scale": 0.9,
                               "ema_epochs": 4.0})[0]  # fmt: skip
    assert "(`model.history_encoder: temporal`)" in text
    assert "scaled by 0.9 (`model.spread_scale`)" in text
    assert "time constant 4 epochs, `generator.ema_epochs`" in text
    assert "polynomial" not in text
    smooth = zi._sampling_lines({**base, "future_rank": 5})[0]
    assert "degree at most 5 in time (`model.future_rank`)" in smooth


def test_a_card_says_when_there_are_no_denoising_steps_and_names_the_dropout():
    zi = _zoo_index()
    base = {"tau": 5, "stochastic_steps": False, "changes": []}
    assert "tau = 5 denoising steps" in zi._sampling_lines(base)[0]
    assert "dropout" not in zi._sampling_lines(base)[0]
    text = zi._sampling_lines({**base, "tau": 0, "dropout": 0.1})[0]
    assert "no denoising step (`model.tau: 0`" in text and "tau = 0" not in text
    assert "trained with dropout 0.1 (`model.generator_dropout`)" in text


def test_a_change_shows_its_stamped_date_once_on_the_card():
    zoo_index = _zoo_index()
    stamped = {"max_speed": 0.3, "previous": 0.0, "date": "2026-11-27", "note": "90 % clamp"}
    assert zoo_index.change_note(stamped) == "2026-11-27: 90 % clamp"
    dated_by_hand = {**stamped, "note": "2026-11-27: 90 % clamp"}  # not repeated
    assert zoo_index.change_note(dated_by_hand) == "2026-11-27: 90 % clamp"
    assert zoo_index.change_note({"max_speed": 0.3, "note": "old file"}) == "old file"


def test_both_load_predictor_functions_take_sampler_and_device_by_keyword(fake_zoo):
    """``registry.load_predictor`` and ``checkpoint.load_predictor`` once took sampler and
    device in opposite orders; both now refuse them positionally, and agree by keyword."""
    from trajpref.models import registry

    path = fake_zoo / "walks" / "generator.safetensors"
    positional = r"load_predictor\(\) takes 1 positional argument but 3 were given"
    with pytest.raises(TypeError, match=positional):
        checkpoint.load_predictor(path, "leapfrog", "cpu")
    with pytest.raises(TypeError, match=positional):
        registry.load_predictor(str(path), "cpu", "leapfrog")
    a = registry.load_predictor("walks/generator", device="cpu", sampler="full")
    b = checkpoint.load_predictor(path, sampler="full", device="cpu")
    assert a.sampler == b.sampler == "full"


def test_a_published_name_given_with_its_suffix_is_named_without_it(fake_zoo):
    from trajpref.models import registry

    with pytest.raises(TrajprefError, match="the published model is named walks/generator"):
        registry.load_predictor("walks/generator.safetensors")


# A sports analyst's walkthrough of the NBA models (walkthrough 67): the cards say which axes
# and inputs the models read; feet given to a metre model are told the factor; a scene with no
# ball or two balls is said, in Python and on a split; float agent types from pandas (0.0 / 1.0)
# are types.


CARDS = ROOT / "src" / "trajpref" / "zoo" / "nba"


# 1. what the cards say


def test_the_nba_cards_say_the_axes_and_the_inputs():
    generator = (CARDS / "generator.md").read_text(encoding="utf-8")
    for said in ("x along the court's 94 ft (28.65 m) length", "any origin", "`agent_type` (1 "
                 "the ball, 0 a player); no team, no court or basket position",
                 "`data.rotate: false`", "(+57 %)", "--agents persons",
                 "0.180 / 0.322 m (0.59 / 1.06 ft)"):  # fmt: skip
        assert said in generator, said
    denoiser = (CARDS / "denoiser.md").read_text(encoding="utf-8")
    assert "94 ft length" in denoiser and "changed in 50 of 50" in denoiser
    index = json.loads((CARDS.parent / "index.json").read_text())
    limits = {row["name"]: " ".join(row["limits"]) for row in index["models"]
              if row["dataset"] == "nba"}  # fmt: skip
    assert all("94 ft" in text for text in limits.values()), limits
