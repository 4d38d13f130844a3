"""The documentation site browses from ``file://`` (``make docs``, then ``build/site/index.html``
opened in a browser): every link of every built page to another page of the site names a file
that exists, not a directory, which a browser without a server shows as a listing."""

from __future__ import annotations

import os
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

REPO = Path(__file__).resolve().parents[2]
pytest.importorskip("mkdocs")


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        href = a.get("href") if tag in ("a", "link") else a.get("src") if tag in (
            "img", "script") else None
        if href:
            self.links.append(href)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("docs") / "site"
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet", "--site-dir", str(out)],
        cwd=REPO, capture_output=True, text=True, timeout=600,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_every_link_between_pages_names_a_file(site: Path) -> None:
    # 404.html is a web server's page (its links are absolute: it is served at any depth)
    pages = sorted(p for p in site.rglob("*.html") if p.name != "404.html")
    assert len(pages) >= 15
    checked, broken = 0, []
    for page in pages:
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8"))
        for href in parser.links:
            url = urlsplit(href)
            if url.scheme or url.netloc or not url.path:  # another site, or an anchor
                continue
            target = (page.parent / unquote(url.path)).resolve()
            checked += 1
            if not target.is_file():
                broken.append(f"{page.relative_to(site)}: {href}")
    assert not broken, "\n".join(broken[:40])
    assert checked > 100  # the navigation of every page was read


def test_the_navigation_names_the_pages_as_files(site: Path) -> None:
    index = (site / "index.html").read_text(encoding="utf-8")
    assert 'href="getting-started.html"' in index
    assert 'href="getting-started/"' not in index
