"""The user docs: README length, relative links that resolve, no tracker wording.

README.md and docs/ point only inside the repository: every relative link names a file or
folder that exists (and, with ``#anchor``, a heading or ``<a id>`` of that page); links to
other sites appear only in docs/references.md (the DOIs and standards' addresses).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")


def _text_outside_code(page: Path) -> str:
    text = page.read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    h = re.sub(r"`", "", heading.strip().lower())
    h = re.sub(r"[^\w\- ]", "", h)
    return h.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = page.read_text(encoding="utf-8")
    text_nocode = re.sub(r"```.*?```", "", text, flags=re.S)
    heads = [_slug(m) for m in re.findall(r"^#{1,6}\s+(.*)$", text_nocode, flags=re.M)]
    ids = re.findall(r"<a\s+id=\"([^\"]+)\"", text)
    return set(heads) | set(ids)


def _links(page: Path) -> list[str]:
    return [a or b for a, b in LINK.findall(_text_outside_code(page))]


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").count("\n")
    assert lines <= 150, f"README.md has {lines} lines (at most 150)"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    bad = []
    for link in _links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", link):  # http:, https:, mailto:
            if page.name != "references.md":
                bad.append(f"{link} (outside the repository)")
            continue
        path, _, anchor = link.partition("#")
        target = (page.parent / path).resolve() if path else page
        if not target.exists():
            bad.append(f"{link} (no such file)")
        elif ROOT not in target.parents and target != ROOT:
            bad.append(f"{link} (outside the repository)")
        elif anchor and target.suffix == ".md" and anchor not in _anchors(target):
            bad.append(f"{link} (no anchor #{anchor} in {target.relative_to(ROOT)})")
    assert not bad, f"{page.relative_to(ROOT)}: " + "; ".join(bad)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_issue_numbers(page):
    hits = re.findall(r".{0,30}issue\s*#?\s*[0-9].{0,30}", page.read_text(encoding="utf-8"), flags=re.I)
    assert not hits, f"{page.relative_to(ROOT)}: {hits}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_source_paths_exist(page):
    """A module the docs name by path (`models/vehicle/wheelset.py`) is where they say."""
    paths = re.findall(r"`((?:models|estimators|fmus|experiments|benchmarks|tests)/[\w/]+\.py)`",
                       page.read_text(encoding="utf-8"))
    missing = sorted({p for p in paths if not (ROOT / p).is_file()})
    assert not missing, f"{page.relative_to(ROOT)}: {missing}"
