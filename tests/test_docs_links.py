"""Every relative link in the README and the docs/ pages points at a file that exists."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]\n]*\]\(([^)\s]+)\)")  # [text](target)


def relative_targets(page: Path) -> list[str]:
    """The link targets of ``page`` that name a file of the repository (no URL, no anchor
    within the page), without their ``#anchor``."""
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)  # no code
    out = []
    for target in LINK.findall(text):
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # a URL (https:, mailto:) or an anchor on the same page
        out.append(target.split("#", 1)[0])
    return out


def test_the_link_finder_skips_urls_anchors_and_code():
    page = ROOT / "README.md"
    assert "docs/architecture.md" in relative_targets(page)
    assert not [t for t in relative_targets(page) if t.startswith("http")]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_resolve(page):
    broken = [t for t in relative_targets(page) if not (page.parent / t).exists()]
    assert not broken, f"{page.relative_to(ROOT)}: links to missing files: {broken}"
