"""docs/backbone_candidates.md points each candidate at the section of docs/pretraining.md
(or docs/selection.md) that holds its rule, commands and runs: every pointer must lead
somewhere, so that a reader can search for it as written."""

import re
from pathlib import Path

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _headings(text: str) -> list[str]:
    return [h.strip() for h in re.findall(r"^#+ (.*)$", text, flags=re.M)]


def _dangling(candidates: str, sections: dict[str, list[str]]) -> list[str]:
    """The last cells of the candidates' table rows that name no heading: a cell names a
    heading when it is the heading's beginning or part of it (headings end with their
    "(rule fixed ...)" note); ``docs/selection.md: X`` looks X up in that file."""
    missing = []
    for line in candidates.splitlines():
        if not re.match(r"^\| 20\d\d-", line):
            continue
        cell = line.rstrip().rstrip("|").split("|")[-1].strip()
        doc, _, name = cell.partition(": ") if cell.startswith("docs/") else ("", "", cell)
        heads = sections.get(doc or "docs/pretraining.md", [])
        if not any(name in h for h in heads):
            missing.append(cell)
    return missing


def test_every_candidate_row_names_an_existing_section():
    sections = {
        f"docs/{name}": _headings((DOCS / name).read_text())
        for name in ("pretraining.md", "selection.md")
    }
    candidates = (DOCS / "backbone_candidates.md").read_text()
    rows = [ln for ln in candidates.splitlines() if re.match(r"^\| 20\d\d-", ln)]
    assert len(rows) > 50  # the two tables were read
    assert _dangling(candidates, sections) == []


def test_a_pointer_to_a_missing_section_is_reported():
    sections = {"docs/pretraining.md": ["A real section (rule fixed 2026-11-29)"],
                "docs/selection.md": ["Oversampling"]}  # fmt: skip
    table = (
        "| 2026-11-29 | x | zara1 | 0.29 | A real section |\n"
        "| 2026-11-29 | y | zara1 | 0.29 | A section nobody wrote |\n"
        "| 2026-11-29 | z | zara1 | 0.29 | docs/selection.md: Oversampling |\n"
        "| 2026-11-29 | w | zara1 | 0.29 | docs/selection.md: Missing |\n"
    )
    assert _dangling(table, sections) == ["A section nobody wrote", "docs/selection.md: Missing"]
