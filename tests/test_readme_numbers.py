"""Hand-written README numbers that a file in the repository holds: each is checked against
that file, so a re-measurement that changes the file fails here until the prose follows."""

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
RESULTS = ROOT / "benchmarks" / "results"
META = RESULTS / "meta"
FOLDS = ("eth", "hotel", "univ", "zara1", "zara2")


def _text() -> str:
    return " ".join(README.read_text().split())  # one line: prose wraps anywhere


def test_the_reproduce_cost_is_the_invocation_logs():
    """docs/reproduce.md's cost of every run that built the stored state, from its log."""
    log = json.loads((META / "reproduce" / "invocations.json").read_text())
    hours = sum(e["cpu_seconds_own"] + e["cpu_seconds_children"] for e in log) / 3600
    (found,) = re.findall(r"([\d.]+) CPU-hours over (\d+) invocations", _text())
    assert (found[0], int(found[1])) == (f"{hours:.3f}", len(log))


def test_the_readme_names_every_published_noise_sample():
    """The cards that state a noise sample must be the ones the README's planning advice names
    as having one today (none since 2026-12-06, when sdd/generator was retrained like
    eth/generator, and zara2/rlhf-res was retired): with none, the README says so."""
    text = " ".join(_text().split())  # line breaks as spaces
    cards = {}
    for card in (ROOT / "src" / "trajpref" / "zoo").glob("*/*.md"):
        found = re.search(r"One of its 20 samples \(index (\d+)\)", card.read_text())
        if found:
            cards[f"{card.parent.name}/{card.stem}"] = int(found.group(1))
    if not cards:
        assert "No published generator draws a noise sample" in text
        return
    stated = dict(re.findall(r"`([\w-]+/[\w-]+)` \(sample (\d+)\) is noise", text))
    assert {k: int(v) for k, v in stated.items()} == cards


def test_the_in_context_claim_states_its_rows_date_and_windows():
    runs = [next(iter(json.loads((META / f"in_context_{d}_test.json").read_text())["rows"]
                      .values())) for d in FOLDS]  # fmt: skip
    change = [sum(100 * (r["after"][k] / r["before"][k] - 1) for r in runs) / len(runs)
              for k in ("min_ade", "min_fde")]  # fmt: skip
    text = _text()
    assert f"{change[0]:+.1f} % / {change[1]:+.1f} % on average over the five" in text
    (windows,) = {r["windows"] for r in runs}
    (day,) = {r["date"] for r in runs}
    claim = text[text.index("In-context adaptation (Sec. 8.4") :][:1200]
    assert f"{windows} test windows per fold" in claim and day in claim


def test_the_zara2_fine_tuning_numbers_are_the_tables_rounding():
    rows = [r for p in RESULTS.glob("finetune_zara2*.json") for r in json.loads(p.read_text())]
    rows += json.loads((RESULTS / "pretrained_zara2.json").read_text())

    def fde(method: str) -> str:
        (row,) = [r for r in rows if r["method"] == method and r["split"] == "test"
                  and r["protocol"] == "all" and r["seed"] == 0 and r["samples"] == 20]  # fmt: skip
        return f"{row['min_fde']:.3f}"

    want = f"zara2 {fde('pretrained')} -> {fde('rlhf')}, {fde('rlhf-res')}, {fde('rlhf-set')}"
    assert want in _text()


def test_eths_pace_ratio_is_the_data_docs():
    data = " ".join((ROOT / "docs" / "data.md").read_text().split())
    (ratio,) = re.findall(r"look about ([\d.]+) times faster", data)
    assert f"look about {ratio}x faster" in _text()


def test_the_error_share_of_eths_fast_walkers_is_the_stored_breakdowns_range():
    shares = [json.loads(p.read_text())["bins"][-1]["share_of_model_error"]
              for p in META.glob("speed_breakdown_eth*.json")]  # fmt: skip
    low, high = round(100 * min(shares)), round(100 * max(shares))
    assert f"carry {low}-{high} % of the error" in _text()


SOCIAL_ROW = re.compile(r"\| (zara[12]) \| ([\w-]+) \| ([\d.]+) / ([\d.]+) / ([\d.]+) \| "
                        r"([\d.]+) \| ([\d.]+) \| ([\d.]+) \|")  # fmt: skip


def social_rows(text: str) -> dict[tuple[str, str], list[str]]:
    """The README's scene-size table: (dataset, model) -> minFDE per bin <= 5 / 6-10 / 11-20,
    Col-I, Col-II and ground truth %, as printed."""
    return {(m[0], m[1]): list(m[2:]) for m in SOCIAL_ROW.findall(text)}


def stored_social_rows() -> dict[tuple[str, str], list[str]]:
    """The same cells from benchmarks/results/meta/social_<D>.json (benchmarks/social.py)."""
    out = {}
    for dataset in ("zara1", "zara2"):
        run = json.loads((META / f"social_{dataset}.json").read_text())
        for name, res in run["models"].items():
            fde = [f"{res['bins'][b]['min_fde']:.3f}" for b in ("<=5", "6-10", "11-20")]
            rates = [f"{res[k]:.2f}" for k in ("col_i_pct", "col_ii_pct", "col_gt_pct")]
            out[(dataset, name)] = fde + rates
    return out


def test_the_scene_size_table_is_the_stored_social_runs():
    """Every row of the README's "Social plausibility and scene size" table is a model of the
    stored runs, with their numbers, and every stored model has its row."""
    section = _text()[_text().index("### Social plausibility and scene size") :][:3000]
    assert social_rows(section) == stored_social_rows()
