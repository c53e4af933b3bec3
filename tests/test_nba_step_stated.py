"""NBA's step as the generated texts state it follows the registry (``SPECS["nba"]``): the
README's peers caption (``results.peers_notes``), the model zoo's description and its cards.
Until 2026-12-06 they said 0.48 s; the files' own game clock says 0.12 s (docs/data.md,
tests/data/test_registry.py)."""

import json
from pathlib import Path

from trajpref.data.registry import SPECS
from trajpref.results import peers_notes

ROOT = Path(__file__).resolve().parents[1]
STEP = f"{SPECS['nba'].frame_interval:g} s"  # "0.12 s"


def test_the_peers_caption_states_the_registrys_nba_step_and_the_real_differences():
    notes = peers_notes(json.loads((ROOT / "benchmarks" / "peers.json").read_text()))
    nba = notes[notes.index("NBA: the peers' column") :]
    assert f"8 + 12 steps at {STEP}" in nba and "0.48" not in nba
    assert "0.96 s observed, 1.44 s predicted" in nba
    assert "94/28" in nba and "2.3 %" in nba  # LED's and MART's feet against our 0.3048
    assert "players only" in nba  # SocialVAE, the split's source, leaves the ball out


def test_the_nba_model_cards_state_the_registrys_step():
    for card in sorted((ROOT / "src" / "trajpref" / "zoo" / "nba").glob("*.md")):
        text = card.read_text(encoding="utf-8")
        assert f"{STEP} apart" in text and "0.48" not in text, card.name
    index = json.loads((ROOT / "src" / "trajpref" / "zoo" / "index.json").read_text())
    rows = [row for row in index["models"] if row["dataset"] == "nba"]
    assert rows and all(row["data"]["frame_interval"] == SPECS["nba"].frame_interval
                        for row in rows)  # fmt: skip


def test_a_checkpoint_that_recorded_nbas_old_step_takes_the_registrys():
    """Checkpoints trained between the step record (a022274) and the correction recorded
    nba's 0.48 s; a built-in dataset's step is the registry's fact, so they load at 0.12 s
    and are not told to resample the right data to the wrong step."""
    from types import SimpleNamespace

    from trajpref.data.registry import SPECS
    from trajpref.models.timing import attach_timing

    header = {"config": {"data": {"dataset": "nba", "time_step": 1.0}},
              "meta": {"data_timing": {"frame_interval": 0.48, "interval_from": "dataset",
                                       "time_step": 1.0, "units": "m"}}}  # fmt: skip
    model = attach_timing(SimpleNamespace(), header)
    assert model.frame_interval == SPECS["nba"].frame_interval == 0.12
    header["meta"]["data_timing"].update(interval_from="given", frame_interval=0.3)
    assert attach_timing(SimpleNamespace(), header).frame_interval == 0.3  # a folder's own
