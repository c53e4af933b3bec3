"""One table of fine-tuning methods (config.FinetuneMethod, config.USES_RL,
rl.objective.LOSS_SAMPLES): the CLI offers its names, and a name that reaches a dispatch
without an entry there is an error, never trained as RLHF-ReS (the walkthrough's finding: a
new method's name took the k* path of ``RLObjective.selection``)."""

import argparse
import typing
from types import SimpleNamespace

import pytest
import torch

from trajpref import config
from trajpref.config import FinetuneConfig, load_config
from trajpref.data import load_dataset
from trajpref.errors import ConfigError
from trajpref.models import checkpoint as ckpt
from trajpref.rl.objective import RLObjective
from trajpref.train.stages import build_finetune_stage

NEW = "rlhf-new"
"""A method's name as a contributor adds it to the list, before its dispatch entries."""


def _finetune_parser() -> argparse.ArgumentParser:
    from trajpref.cli import build_parser

    for action in build_parser()._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices["finetune"]
    raise AssertionError("no finetune command")


def test_the_cli_offers_the_tables_methods():
    method = next(a for a in _finetune_parser()._actions if a.dest == "method")
    assert list(method.choices) == list(config.FINETUNE_METHODS)
    assert config.FINETUNE_METHODS == typing.get_args(config.FinetuneMethod)
    hints = typing.get_type_hints(FinetuneConfig)
    assert typing.get_args(hints["method"]) == config.FINETUNE_METHODS


def test_every_method_has_its_entries():
    from trajpref.rl.objective import LOSS_SAMPLES

    assert set(config.USES_RL) == set(config.FINETUNE_METHODS)
    assert set(LOSS_SAMPLES) == {m for m in config.FINETUNE_METHODS if config.USES_RL[m]}


def test_a_method_added_to_the_literal_alone_is_refused(monkeypatch):
    """Added to ``FinetuneMethod`` (the config takes it) but not to ``USES_RL``: asking
    whether it is an RL method is an error that names the table."""
    monkeypatch.setattr(config, "FinetuneMethod", typing.Literal[(*config.FINETUNE_METHODS, NEW)])
    monkeypatch.setattr(config, "FINETUNE_METHODS", (*config.FINETUNE_METHODS, NEW))
    cfg = FinetuneConfig(method=NEW)  # the config's check reads the Literal
    with pytest.raises(ConfigError, match=r"'rlhf-new'.*USES_RL"):
        config.uses_rl(cfg.method)


def test_an_rl_method_without_its_loss_samples_is_refused_by_selection(monkeypatch):
    """``RLObjective.selection`` (the walkthrough's case): a name other than ``rlhf`` got
    k* whatever it was; now a method without a ``LOSS_SAMPLES`` entry is an error."""
    monkeypatch.setitem(config.USES_RL, NEW, True)
    rl = FinetuneConfig()
    object.__setattr__(rl, "method", NEW)
    batch = SimpleNamespace(scene=torch.tensor([0, 0, 1]), num_scenes=2)
    score = torch.zeros(3, 3, 2)  # [K, N, T]
    with pytest.raises(ConfigError, match=r"'rlhf-new'.*LOSS_SAMPLES"):
        RLObjective.selection(SimpleNamespace(rl=rl), score, batch)


@pytest.mark.parametrize("in_uses_rl", [False, True])
def test_a_fine_tuning_stage_of_a_method_without_entries_is_refused(
    tiny_run, walks, monkeypatch, in_uses_rl
):
    """Before any step: the stage is not built (HEAD built it and trained RLHF-ReS)."""
    if in_uses_rl:
        monkeypatch.setitem(config.USES_RL, NEW, True)
    start = ckpt.load(tiny_run / "generator.safetensors")
    cfg = load_config(None, [], base=start["config"])
    object.__setattr__(cfg.finetune, "method", NEW)  # past the Literal, as if added to it
    train = load_dataset(str(walks), "train")
    table = "LOSS_SAMPLES" if in_uses_rl else "USES_RL"
    with pytest.raises(ConfigError, match=rf"'rlhf-new'.*{table}"):
        build_finetune_stage(cfg, start, train, torch.device("cpu"))


def test_a_checkpoint_of_a_new_supervised_method_records_no_reward(monkeypatch):
    """A fine-tuned checkpoint's reward came from ``method == "control"``: a new supervised
    method (no RL) recorded the config's reward as if it had trained with it."""
    from trajpref import config
    from trajpref.models import checkpoint

    monkeypatch.setitem(config.USES_RL, "control-ema", False)
    assert checkpoint._run_reward("control-ema", "score") is None
    assert checkpoint._run_reward("control", "score") is None
    assert checkpoint._run_reward("rlhf-res", "set") == "set"
    assert checkpoint._run_reward("rlhf-old-name", "score") == "score"  # an older file's name
