"""The documentation site renders its lists as lists: Python-Markdown (mkdocs) needs a blank line
before a list that follows a paragraph, GitHub does not, and ``mkdocs build --strict`` does not
notice. Without it docs/diagnosis.md's "How it decides" was one paragraph of ``- Split. …
- Baseline …`` on the site (issue 27: documentation a lab engineer can navigate)."""

from __future__ import annotations

import re
from pathlib import Path

from tests.support.paths import REPO

_ITEM = re.compile(r"^\s*([-*+]|\d+\.)\s")


def site_pages() -> list[Path]:
    """docs/*.md and the files they include (pymdownx.snippets: ``--8<-- "PATH"``)."""
    pages = sorted((REPO / "docs").glob("*.md"))
    included = [REPO / m for p in pages
                for m in re.findall(r'^--8<-- "([^"]+)"', p.read_text(encoding="utf-8"), re.M)]
    return pages + included


def glued_lists(text: str) -> list[int]:
    """1-based lines where a list starts right under a paragraph line (outside code fences)."""
    lines = text.split("\n")
    fence, in_list, bad = False, False, []
    for i, line in enumerate(lines):
        if line.lstrip().startswith("```"):
            fence = not fence
            continue
        if fence:
            continue
        item = _ITEM.match(line) is not None
        prev = lines[i - 1] if i else ""
        if (item and not in_list and prev.strip() and not _ITEM.match(prev)
                and not prev.startswith((" ", "\t", "|"))):
            bad.append(i + 1)
        if item:
            in_list = True
        elif not line.strip():
            in_list = False
    return bad


def test_the_checker_finds_a_glued_list() -> None:
    assert glued_lists("How it decides:\n- Split.\n- Gap.\n") == [2]
    assert glued_lists("How it decides:\n\n- Split.\n- Gap.\n  more\n") == []
    assert glued_lists("```sh\nrun:\n- not a list\n```\n") == []


def test_every_list_of_the_site_starts_after_a_blank_line() -> None:
    pages = site_pages()
    assert any(p.name == "SECURITY.md" for p in pages)  # the includes are checked too
    bad = [f"{p.relative_to(REPO)}:{n}" for p in pages
           for n in glued_lists(p.read_text(encoding="utf-8"))]
    assert not bad, f"a list right under a paragraph renders as that paragraph: {bad}"
