"""benchmarks/zoo_index.py: a generator card's commands rebuild the published file, its
sampling settings written in after training included, and a pixel dataset's cards give its
data scale (2026-12-06 SDD walkthrough: the card of sdd/generator did not say that its cap on
the samples' sigma was set after training, and named no source for its split's peers)."""

import copy
from pathlib import Path

from bench import load_benchmark

from trajpref.config import to_dict
from trajpref.models import checkpoint as ckpt
from trajpref.models import zoo as zoo_mod

ROOT = Path(__file__).resolve().parent.parent


def _entry(zoo, name, monkeypatch):
    monkeypatch.setattr(zoo, "_meta", lambda dataset, variant: {})
    path = zoo_mod.ZOO_DIR / f"{name}{ckpt.SUFFIX}"
    return zoo.describe(name, path, [])


def test_every_generator_cards_commands_end_at_the_published_sampling_settings(monkeypatch):
    """The training command gives the config a generator was trained with; the lines after it
    must set every sampling setting the file took later, so that the two together give the
    published file's settings."""
    zoo = load_benchmark("zoo_index")
    names = [n for n in zoo_mod.published(zoo_mod.ZOO_DIR) if n.split("/")[1].startswith("gen")]
    assert "sdd/generator" in names
    for name in names:
        e = _entry(zoo, name, monkeypatch)
        head = zoo_mod.header(zoo_mod.ZOO_DIR / f"{name}{ckpt.SUFFIX}")
        published = to_dict(ckpt.config_of(head))
        trained = zoo.trained_config(published, (head.get("meta") or {}).get("changes") or [])
        rebuilt = copy.deepcopy(trained)
        after = e["train"].get("after_training") or {"settings": []}
        for s in after["settings"]:
            rebuilt["model"][s["setting"]] = s["value"]
        for setting in ckpt.POST_HOC_SETTINGS:
            assert rebuilt["model"][setting] == published["model"][setting], (name, setting)


def test_sdd_generators_card_sets_its_sigma_cap_after_training_with_its_option(monkeypatch):
    zoo = load_benchmark("zoo_index")
    text = zoo.card(_entry(zoo, "sdd/generator", monkeypatch))
    commands = text.split("## Training", 1)[1].split("## Test row", 1)[0]
    assert "--max-log-sigma 1.0" in commands and "model.max_log_sigma = 1.0" in commands
    assert ("set_generator_setting as s; s('runs/sdd/generator.safetensors', 'max_log_sigma', "
            "1.0, 'as published')") in commands  # fmt: skip
    assert "`model.max_log_sigma` set to 1 after training" in text  # the sampling paragraph
    hotel = zoo.card(_entry(zoo, "hotel/generator", monkeypatch))
    assert "--max-speed 0.3164356052875519" in hotel  # every post-hoc setting, not SDD's alone


def test_sdd_cards_give_the_pixel_scale_and_no_unsourced_peer_split(monkeypatch):
    zoo = load_benchmark("zoo_index")
    for name in ("sdd/generator", "sdd/denoiser"):
        text = zoo.card(_entry(zoo, name, monkeypatch))
        assert "as LED and MoFlow use it" not in text
        assert "58.998 px per model unit" in text and "about 295 px per step" in text
        assert "SDD and its peers" in text
    assert "px per model unit" not in zoo.card(_entry(zoo, "zara1/generator", monkeypatch))


def test_every_setting_that_may_change_after_training_has_a_flag_for_the_cards():
    """A setting added to ``checkpoint.POST_HOC_SETTINGS`` (docs/architecture.md, "Adding a
    config field") needs its command-line flag in ``SETTING_FLAGS``, or writing the cards
    fails with a bare KeyError (a contributor's walkthrough, 2026-12-06)."""
    zoo = load_benchmark("zoo_index")
    flagged = {"stochastic_steps", *zoo.SETTING_FLAGS}  # --stochastic / --deterministic
    missing = sorted(set(ckpt.POST_HOC_SETTINGS) - flagged)
    assert not missing, f"add the flag of {missing} to benchmarks/zoo_index.py's SETTING_FLAGS"
