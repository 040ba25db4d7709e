"""The documentation points only at what the repository holds, in at most 15 pages.

Every relative link and image of README.md and docs/*.md names a file or folder
that exists (and, for a ``#fragment`` into a markdown page, one of its headings,
as GitHub spells their anchors); every repository path written in code spans
(``docs/...``, ``benchmarks/...``, ``slicerecon/...``, ``pipelines/...``, also
inside a command) exists.
Fenced code blocks are skipped: they hold commands and their outputs.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
MAX_PAGES = 15

_FENCE = re.compile(r"^\s*(```|~~~)")
_CODE = re.compile(r"`([^`\n]+)`")
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
_REPO_PATH = re.compile(r"^(?:docs|benchmarks|slicerecon|pipelines)/[\w./-]*$")


def _prose_lines(page: Path) -> list[tuple[int, str]]:
    """The page's lines outside fenced code blocks, with their 1-based numbers."""
    lines, fenced = [], False
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if _FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            lines.append((number, line))
    return lines


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_anchor(line.lstrip("#")) for _, line in _prose_lines(page) if line.startswith("#")}


def _broken(page: Path) -> list[str]:
    problems = []
    for number, line in _prose_lines(page):
        for match in _LINK.finditer(_CODE.sub("", line)):
            target = match.group(1)
            if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            path, _, fragment = target.partition("#")
            resolved = (page.parent / path) if path else page
            if not resolved.exists():
                problems.append(f"{page.name}:{number}: link to missing {target}")
            elif fragment and resolved.suffix == ".md" and fragment not in _anchors(resolved):
                problems.append(f"{page.name}:{number}: no heading for #{fragment} in {path}")
        for match in _CODE.finditer(line):
            for word in match.group(1).split():
                candidate = word.split("::")[0]
                if _REPO_PATH.match(candidate) and not (ROOT / candidate).exists():
                    problems.append(f"{page.name}:{number}: `{candidate}` is not in the repository")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_link_and_path_resolves(page: Path) -> None:
    assert _broken(page) == []


def test_docs_hold_at_most_15_pages() -> None:
    pages = sorted(p.name for p in DOCS.glob("*.md"))
    assert len(pages) <= MAX_PAGES, pages


def test_readme_lists_every_page() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    missing = [p.name for p in DOCS.glob("*.md") if f"(docs/{p.name})" not in readme]
    assert missing == []


def test_the_checks_catch_what_they_promise(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    (tmp_path / "there.md").write_text("# A heading: here\n", encoding="utf-8")
    page.write_text(
        "[ok](there.md#a-heading-here) [gone](results_x.md) [bad](there.md#nowhere)\n"
        "`docs/results_x.md` `python benchmarks/none.py --out x`\n"
        "```\n[in a fence](missing.md)\n```\n",
        encoding="utf-8",
    )
    assert _broken(page) == [
        "page.md:1: link to missing results_x.md",
        "page.md:1: no heading for #nowhere in there.md",
        "page.md:2: `docs/results_x.md` is not in the repository",
        "page.md:2: `benchmarks/none.py` is not in the repository",
    ]
