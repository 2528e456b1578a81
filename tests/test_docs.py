"""Every relative link and image in the README and docs/ resolves: the file
exists and, where the link names a heading (`page.md#anchor`), so does the
heading. External links (http, https, mailto) are not checked."""

import re
from pathlib import Path

import pytest
from conftest import REPO

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
# [text](target) and ![alt](target "title"); <img src="target">.
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
IMG = re.compile(r"<img\s[^>]*src=\"([^\"]+)\"")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE_SPAN = re.compile(r"`[^`\n]*`")
HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*#*\s*$", re.M)
EXTERNAL = ("http://", "https://", "mailto:")


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation but hyphens and
    underscores dropped, spaces as hyphens."""
    text = re.sub(r"[^\w\- ]", "", CODE_SPAN.sub(lambda m: m.group(0)[1:-1], heading).lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every heading anchor of a markdown page, repeats numbered as GitHub does."""
    seen: dict[str, int] = {}
    out = set()
    for heading in HEADING.findall(FENCE.sub("", page.read_text())):
        base = slug(heading)
        n = seen.get(base, 0)
        out.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1
    return out


def broken_links(page: Path) -> list[str]:
    """The relative links and images of `page` that do not resolve, as 'target: why'."""
    text = CODE_SPAN.sub("", FENCE.sub("", page.read_text()))
    broken = []
    for target in LINK.findall(text) + IMG.findall(text):
        if target.startswith(EXTERNAL):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            broken.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target}: no heading #{anchor} in {dest.name}")
    return broken


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_links_resolve(page):
    assert broken_links(page) == []


def test_readme_shows_a_committed_picture():
    images = [t for t in LINK.findall(CODE_SPAN.sub("", (REPO / "README.md").read_text())) if t.endswith(".png")]
    assert images and all((REPO / t).is_file() for t in images)


def test_checker_finds_broken_links(tmp_path):
    (tmp_path / "other.md").write_text("# A heading: with `code`, punctuation\n\n## Twice\n\n## Twice\n")
    (tmp_path / "img.png").write_bytes(b"")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](other.md) [ok](other.md#a-heading-with-code-punctuation) [ok](other.md#twice-1)\n"
        "![ok](img.png) [ok](https://example.org/missing.md) [ok](#local)\n\n## Local\n"
        "[gone](missing.md) ![gone](img/none.png) [gone](other.md#nowhere) [gone](#elsewhere)\n"
        "`[in code](not-checked.md)`\n\n```\n[in a block](not-checked.md)\n```\n"
    )
    assert broken_links(page) == [
        "missing.md: no such file",
        "img/none.png: no such file",
        "other.md#nowhere: no heading #nowhere in other.md",
        "#elsewhere: no heading #elsewhere in page.md",
    ]
