"""The site builds without a warning (strict mode also checks internal links and anchors),
and every page links only to pages, anchors and images that exist."""

import posixpath
import re
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urldefrag


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        values = dict(attrs)
        if values.get("id"):
            self.ids.add(values["id"])
        if tag == "a" and values.get("href"):
            self.links.append(values["href"])
        if tag == "img" and values.get("src"):  # an image is a link to its file
            self.links.append(values["src"])


def _parsed(path: Path) -> _Links:
    parser = _Links()
    parser.feed(path.read_text())
    return parser


def test_every_page_of_the_nav_is_built(site):
    for page in ("index.html", "tutorials/first-cosimulation/index.html",
                 "reference/configuration/index.html", "reference/cli/index.html",
                 "reference/api/index.html", "results/thesis/index.html",
                 "changelog/index.html"):
        assert (site / page).is_file(), page


def test_internal_links_resolve(site):
    pages = {p: _parsed(p) for p in site.rglob("*.html") if p.name != "404.html"}
    broken = []
    for page, parsed in pages.items():
        base = page.relative_to(site).as_posix()
        for href in parsed.links:
            if re.match(r"^[a-z]+:", href):  # http:, mailto:, ...
                continue
            url, anchor = urldefrag(href)
            path = posixpath.normpath(posixpath.join(posixpath.dirname(base), url)) \
                if url else base
            target = site / path
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append(f"{base}: {href}")
            elif anchor and target.suffix == ".html" and anchor not in pages.get(
                    target, _parsed(target)).ids:
                broken.append(f"{base}: {href} (no such anchor)")
    assert not broken, "\n".join(broken)
