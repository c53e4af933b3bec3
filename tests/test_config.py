import dataclasses
import re
import typing

import pytest
import yaml
from helpers import NEW

from trajpref import config
from trajpref.config import (
    ExperimentConfig,
    FinetuneConfig,
    ModelConfig,
    experiment_from_dict,
    load_config,
    save_config,
    to_dict,
)
from trajpref.errors import ConfigError


def test_defaults_round_trip_through_yaml(tmp_path):
    cfg = ExperimentConfig()
    save_config(cfg, tmp_path / "c.yaml")
    assert load_config(tmp_path / "c.yaml") == cfg


def test_non_default_values_round_trip_through_yaml(tmp_path):
    cfg = load_config(None, ["data.val_dataset=robo", "finetune.reward_clip=null",
                             "finetune.method=rlhf", "data.flip=true", "seed=7"])  # fmt: skip
    assert cfg != ExperimentConfig()
    save_config(cfg, tmp_path / "c.yaml")
    again = load_config(tmp_path / "c.yaml")
    assert again == cfg
    assert again.finetune.reward_clip is None and again.data.val_dataset == "robo"


def test_overrides():
    cfg = load_config(None, ["finetune.lr=0.01", "model.samples=7", "data.rotate=false"])
    assert cfg.finetune.lr == 0.01 and isinstance(cfg.finetune.lr, float)
    assert cfg.model.samples == 7 and isinstance(cfg.model.samples, int)
    assert cfg.data.rotate is False
    default = ExperimentConfig()
    assert cfg.denoiser == default.denoiser and cfg.diffusion == default.diffusion


@pytest.mark.parametrize("value", [",", "|", ">", "&a", "#x", ":"])
def test_an_override_of_yaml_characters_is_refused_with_the_quoting_that_means_them(value):
    # unquoted, each is invalid YAML or reads as '' or null, which a config would take silently
    with pytest.raises(ConfigError, match=f"quote.*--set 'data.delimiter=\"{re.escape(value)}\"'"):
        load_config(None, [f"data.delimiter={value}"])
    quoted = load_config(None, [f'data.delimiter="{value}"'])
    assert quoted.data.delimiter == value


def test_an_override_with_a_yaml_tag_is_a_config_error_not_a_traceback():
    with pytest.raises(ConfigError, match=r"--set data\.dataset=!foo: not valid YAML"):
        load_config(None, ["data.dataset=!foo"])


@pytest.mark.parametrize("value", ["null", "~", ""])
def test_an_override_that_spells_null_on_purpose_is_taken(value):
    assert load_config(None, [f"finetune.reward_clip={value}"]).finetune.reward_clip is None


@pytest.mark.parametrize("value", ["''", '""'])
def test_an_override_that_spells_the_empty_text_on_purpose_is_taken(value):
    assert load_config(None, [f"data.delimiter={value}"]).data.delimiter == ""


def test_overrides_apply_on_top_of_a_file(tmp_path):
    (tmp_path / "c.yaml").write_text("model:\n  hidden: 64\n  heads: 2\nseed: 3\n")
    cfg = load_config(tmp_path / "c.yaml", ["model.hidden=32"])
    assert (cfg.model.hidden, cfg.model.heads, cfg.seed) == (32, 2, 3)
    assert cfg.model.tau == ModelConfig().tau  # unset keys keep their defaults


def test_literal_fields_name_their_choices():
    with pytest.raises(ConfigError, match="'rlhf'.*'rlhf-res'.*bogus"):
        load_config(None, ["finetune.method=bogus"])
    with pytest.raises(ConfigError, match="'rlhf'.*'rlhf-res'.*bogus"):
        FinetuneConfig(method="bogus")
    with pytest.raises(ConfigError, match="kl_form"):
        FinetuneConfig(kl_form="nope")
    assert FinetuneConfig(method="rlhf").method == "rlhf"


def test_finetune_reward_is_any_name_and_nothing_else():
    """A config names its reward: a built-in or one registered from Python, whose registry the
    config cannot see (fine-tuning checks it), so any well-formed name is a config's; a
    checkpoint whose config names a user's reward then loads without it registered."""
    for name in ("score", "set", "sda", "comfort", "Comfort_2", "my-reward"):
        assert load_config(None, [f"finetune.reward={name}"]).finetune.reward == name
    refused = r"^finetune\.reward must be a reward's name \(score, set, sda, or one registered"
    for value in ("''", "9lives", "'two words'", "a.b", "café", "1"):
        with pytest.raises(ConfigError, match=refused):
            load_config(None, [f"finetune.reward={value}"])
    with pytest.raises(ConfigError, match=r"finetune\.reward must be str, got a list"):
        load_config(None, ["finetune.reward=[sda]"])  # no list for a name (since 2026-12-06)
    with pytest.raises(ConfigError, match="may not be null"):
        load_config(None, ["finetune.reward=null"])
    with pytest.raises(ConfigError, match=r"^finetune\.reward must be .*, got 3$"):
        FinetuneConfig(reward=3)
    cfg = load_config(None, ["finetune.reward=comfort"])
    assert experiment_from_dict(to_dict(cfg)).finetune.reward == "comfort"


@pytest.mark.parametrize(
    ("override", "name"),
    [("model.bogus=1", "bogus"), ("nosection.key=1", "nosection"), ("bogus=3", "bogus")],
)
def test_unknown_keys(override, name):
    with pytest.raises(ConfigError, match=f"unknown config key.*{name}"):
        load_config(None, [override])


@pytest.mark.parametrize(
    "override",
    ["denoiser.epochs=1.5", "denoiser.epochs=abc", "finetune.lr=fast", "data.rotate=maybe",
     "model.hidden=null", "model.hidden=[1, 2]", "denoiser.epochs=true", "finetune.lr=false"],
)  # fmt: skip
def test_type_errors(override):
    with pytest.raises(ConfigError, match=override.split("=")[0]):
        load_config(None, [override])


def test_generator_layers_default_to_the_encoders_depth_and_reject_negatives():
    assert load_config(None, []).model.generator_encoder_layers == 2
    cfg = load_config(None, ["model.generator_layers=3"])
    assert (cfg.model.generator_encoder_layers, cfg.model.encoder_layers) == (3, 2)
    assert cfg.model.denoiser_part() == load_config(None, []).model.denoiser_part()
    with pytest.raises(ConfigError, match="generator_layers must be >= 0"):
        load_config(None, ["model.generator_layers=-1"])


def test_whole_floats_are_accepted_as_integers():
    assert load_config(None, ["denoiser.epochs=3.0"]).denoiser.epochs == 3


@pytest.mark.parametrize(
    "overrides",
    [["model.hidden=0"], ["model.hidden=30"], ["model.hidden=15", "model.heads=3"],
     ["diffusion.beta_end=1.5"], ["finetune.gamma=2"],
     ["data.scale_min=2"], ["finetune.baseline=antithetic", "finetune.likelihood=mean"],
     ["noequals"]],
)  # fmt: skip
def test_invalid_values(overrides):
    with pytest.raises(ConfigError):
        load_config(None, overrides)


def test_missing_or_bad_files(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "none.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_config(tmp_path / "list.yaml")
    (tmp_path / "bad.yaml").write_text("model: [unclosed\n")
    with pytest.raises(ConfigError, match="YAML"):
        load_config(tmp_path / "bad.yaml")


def test_old_layout_dict_is_converted():
    with pytest.warns(FutureWarning) as record:
        cfg = experiment_from_dict({"generator": {"samples": 7, "tau": 3, "epochs": 4}})
    messages = {str(w.message) for w in record}
    assert messages == {"config key generator.samples is now model.samples",
                        "config key generator.tau is now model.tau"}  # fmt: skip
    assert (cfg.model.samples, cfg.model.tau, cfg.generator.epochs) == (7, 3, 4)


def test_old_key_wins_over_the_new_section():
    with pytest.warns(FutureWarning):
        cfg = experiment_from_dict({"model": {"samples": 5}, "generator": {"samples": 7}})
    assert cfg.model.samples == 7


def test_old_layout_yaml_is_converted(tmp_path):
    old = to_dict(ExperimentConfig())
    del old["model"]["samples"], old["model"]["tau"]
    old["generator"].update(samples=7, tau=3)
    (tmp_path / "old.yaml").write_text(yaml.safe_dump(old))
    with pytest.warns(FutureWarning) as record:
        cfg = load_config(tmp_path / "old.yaml")
    assert any("generator.tau is now model.tau" in str(w.message) for w in record)
    assert (cfg.model.samples, cfg.model.tau) == (7, 3)
    assert not hasattr(cfg.generator, "samples")


def test_tau_cannot_exceed_the_diffusion_steps():
    with pytest.raises(ConfigError, match="tau"):
        load_config(None, ["diffusion.num_steps=4", "model.tau=5"])
    assert load_config(None, ["diffusion.num_steps=5", "model.tau=5"]).model.tau == 5


def test_denoiser_part_ignores_generator_only_fields():
    base = ModelConfig(hidden=32, heads=2)
    variant = dataclasses.replace(base, generator_width=8, samples=3, tau=2)
    assert variant != base
    assert variant.denoiser_part() == base.denoiser_part()
    assert variant.denoiser_part().hidden == 32
    assert ModelConfig(hidden=64, heads=2).denoiser_part() != base.denoiser_part()
    assert ModelConfig(hidden=32, heads=2, denoiser_blocks=1).denoiser_part() != (
        base.denoiser_part()
    )


def test_negative_history_noise_is_a_config_error():
    with pytest.raises(ConfigError, match="history_noise must be >= 0"):
        load_config(None, ["data.history_noise=-0.1"])


@pytest.mark.parametrize("rate", ["-0.1", "1.0"])
def test_a_drop_rate_outside_zero_to_one_is_a_config_error(rate):
    with pytest.raises(ConfigError, match=r"drop_agents must be in \[0, 1\)"):
        load_config(None, [f"data.drop_agents={rate}"])


def test_the_scale_range_is_none_when_the_scale_augmentation_is_off():
    assert load_config(None).data.scale_range is None
    assert load_config(None, ["data.scale_min=0.8"]).data.scale_range == (0.8, 1.0)


def test_reverse_context_needs_reversed_scenes_and_a_context_reading_generator():
    with pytest.raises(ConfigError, match="reverse_context needs data.reverse"):
        load_config(None, ["data.reverse_context=true"])
    with pytest.raises(ConfigError, match="needs model.context_agents"):
        load_config(None, ["data.reverse=true", "data.reverse_context=true"])
    cfg = load_config(None, ["data.reverse=true", "data.reverse_context=true",
                             "model.context_agents=true"])  # fmt: skip
    assert cfg.data.reverse_context


def test_the_denoiser_part_of_a_data_config_leaves_out_the_generator_only_settings():
    from trajpref.config import DataConfig

    data = DataConfig(partial_future=4, flip=True, max_agents=64)
    part = data.denoiser_part()
    assert part.partial_future == 0
    assert dataclasses.replace(part, partial_future=4) == data  # nothing else changed
    plain = DataConfig(flip=True)
    assert plain.denoiser_part() is plain  # nothing to leave out


def test_a_shipped_config_is_found_by_its_name_from_anywhere(tmp_path, monkeypatch):
    from trajpref.config import BUILTIN_CONFIGS, builtin_configs, resolve_config

    monkeypatch.chdir(tmp_path)  # outside the repository: configs/ is not here
    assert "zara1" in builtin_configs() and "robo-mix" in builtin_configs()
    assert resolve_config("zara1") == BUILTIN_CONFIGS / "zara1.yaml"
    assert resolve_config("hotel.yaml") == BUILTIN_CONFIGS / "hotel.yaml"
    assert (
        load_config("hotel").generator.epochs
        == load_config(BUILTIN_CONFIGS / "hotel.yaml").generator.epochs
    )
    (tmp_path / "zara1.yaml").write_text("generator:\n  epochs: 3\n")
    assert load_config("zara1.yaml").generator.epochs == 3  # a file here wins over the name
    with pytest.raises(
        ConfigError, match=r"nope: no such config file \(the shipped configs: eth, "
    ):
        load_config("nope")
    with pytest.raises(ConfigError, match="no such config file"):
        load_config("some/dir/zara1.yaml")  # a path is a path, not a name
    with pytest.raises(ConfigError, match="no such config file"):
        load_config("./hotel.yaml")  # so is one in this folder that is not there


def test_a_checks_message_names_the_key_as_the_user_wrote_it():
    with pytest.raises(ConfigError, match=r"^denoiser\.epochs must be > 0, got 0$"):
        load_config(None, ["denoiser.epochs=0"])
    with pytest.raises(ConfigError, match=r"^generator\.final_lr is a fraction of lr"):
        load_config(None, ["generator.final_lr=2"])  # a field of the parent OptimConfig
    with pytest.raises(ConfigError, match=r"^generator: budget_schedule anneals"):
        load_config(None, ["generator.budget_schedule=true"])  # a message naming no field
    with pytest.raises(ConfigError, match=r"^finetune\.gamma and gae_lambda must lie in"):
        load_config(None, ["finetune.gamma=2"])  # already in the user's words: unchanged
    with pytest.raises(ConfigError, match=r"^diffusion needs beta_start <= beta_end < 1"):
        load_config(None, ["diffusion.beta_start=0.5"])  # "DiffusionConfig needs ..."


def test_the_dataset_fields_docstring_names_every_built_in_dataset():
    # config show prints it; it once left out robo (walkthrough 62, item 4)
    from trajpref.config import BUILTIN_DATASETS, DataConfig, field_docs

    doc = field_docs(DataConfig)["dataset"]
    names = doc.split("``")[3].split()  # "Dataset name (``BUILTIN_DATASETS``: ``eth ...``)"
    assert names == list(BUILTIN_DATASETS)


def test_partial_future_targets_and_a_held_out_scene_are_refused_together():
    """The held-out scene's validation windows come from the training read; with partial
    futures some of its agents have NaN where unseen, and validation would be NaN (a review
    of 2026-12-06 found 741 of 909 such windows on zara1 held out at students). Refused when a
    run reads its splits, not in DataConfig, so that a checkpoint holding both still loads."""
    from trajpref.config import DataConfig
    from trajpref.data.registry import run_splits
    from trajpref.errors import ConfigError

    both = DataConfig(dataset="zara1", partial_future=4, holdout_scene="students")  # loads
    with pytest.raises(ConfigError, match="partial_future and data.holdout_scene exclude"):
        run_splits(both, root="/nonexistent")  # before any file is read


# One table of fine-tuning methods (config.FinetuneMethod, config.USES_RL,
# rl.objective.LOSS_SAMPLES): the CLI offers its names, and a name that reaches a dispatch
# without an entry there is an error, never trained as RLHF-ReS (the walkthrough's finding: a
# new method's name took the k* path of ``RLObjective.selection``).


def test_a_method_added_to_the_literal_alone_is_refused(monkeypatch):
    """Added to ``FinetuneMethod`` (the config takes it) but not to ``USES_RL``: asking
    whether it is an RL method is an error that names the table."""
    monkeypatch.setattr(config, "FinetuneMethod", typing.Literal[(*config.FINETUNE_METHODS, NEW)])
    monkeypatch.setattr(config, "FINETUNE_METHODS", (*config.FINETUNE_METHODS, NEW))
    cfg = FinetuneConfig(method=NEW)  # the config's check reads the Literal
    with pytest.raises(ConfigError, match=r"'rlhf-new'.*USES_RL"):
        config.uses_rl(cfg.method)


# A security review's findings on config values (walkthrough 67-M): a string, integer or
# float setting took any YAML value (``--set 'data.dataset=[zara1]'`` read as the dataset
# ``"['zara1']"``), and an error named the value it got in full, which a few hundred bytes of
# YAML aliases make megabytes long.


@pytest.mark.parametrize("value", ["[zara1]", "{a: 1}"])
def test_a_list_or_mapping_for_a_scalar_setting_is_refused(value):
    with pytest.raises(ConfigError, match=r"config data.dataset must be str, got a (list|dict)"):
        load_config(None, [f"data.dataset={value}"])


def test_an_error_names_a_long_value_in_brief(tmp_path):
    """6 levels of 9 aliases in the value itself: a file of a few hundred bytes whose value
    is about 4 MB of text when written out."""
    levels = ["&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    levels += [f"&a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 6)]
    path = tmp_path / "bomb.yaml"
    path.write_text(f"data:\n  max_agents: [{', '.join(levels)}]\n")
    assert path.stat().st_size < 600
    with pytest.raises(ConfigError, match="config data.max_agents must be int") as err:
        load_config(str(path))
    assert len(str(err.value)) < 400
