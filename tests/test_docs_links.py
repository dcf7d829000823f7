"""Every markdown link of the README, the docs/ pages and the READMEs of scenarios/ and reports/
that points into the repository resolves: the file or folder exists, and a ``#fragment`` names a heading of
the page it points to (as GitHub spells heading anchors)."""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [
    ROOT / "README.md",
    *sorted((ROOT / "docs").glob("*.md")),
    ROOT / "scenarios" / "README.md",
    ROOT / "reports" / "README.md",
]

LINK = re.compile(r"(?<!!)\[(?P<text>[^\]]*)\]\((?P<target>[^)\s]+)\)")
"""An inline markdown link ``[text](target)`` (an image ``![...]`` is not a link)."""

EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.IGNORECASE)
"""``https:``, ``mailto:``...: a link out of the repository, not checked here (no network)."""

FENCE = re.compile(r"^```.*?^```", re.DOTALL | re.MULTILINE)
CODE_SPAN = re.compile(r"`[^`\n]*`")
"""Code is not markdown: a ``[x](y)`` inside a fence or a code span is not a link."""


def links(page: Path) -> list[str]:
    text = CODE_SPAN.sub("", FENCE.sub("", page.read_text()))
    return [m["target"] for m in LINK.finditer(text)]


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[`*]|\[([^\]]*)\]\([^)]*\)", lambda m: m.group(1) or "", heading)
    text = re.sub(r"[^\w\- ]", "", text.strip().lower())
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    text = FENCE.sub("", page.read_text())
    return {anchor(m[1]) for m in re.finditer(r"^#{1,6} +(.+?) *#*$", text, re.MULTILINE)}


def broken(page: Path, root: Path = ROOT) -> list[str]:
    """The page's repository links (under ``root``) that do not resolve, each with the reason."""
    found = []
    for target in links(page):
        if EXTERNAL.match(target):
            continue
        path_part, _, fragment = target.partition("#")
        path = (page.parent / unquote(path_part)).resolve() if path_part else page
        if not path.exists():
            found.append(f"{target}: no such file {path}")
        elif root not in path.parents and path != root:
            found.append(f"{target}: outside the repository")
        elif fragment and path.suffix == ".md" and fragment not in anchors(path):
            found.append(f"{target}: {path.name} has no heading #{fragment}")
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_repository_link_resolves(page):
    assert page.is_file(), page
    problems = broken(page)
    assert not problems, f"{page.relative_to(ROOT)}: " + "; ".join(problems)


def test_the_readme_links_every_docs_page():
    linked = {(ROOT / t.partition("#")[0]).resolve() for t in links(ROOT / "README.md")}
    missing = [p.name for p in sorted((ROOT / "docs").glob("*.md")) if p.resolve() not in linked]
    assert not missing, f"docs pages the README does not link: {missing}"


def test_anchors_are_spelled_as_github_spells_them():
    assert anchor("physval run --resume") == "physval-run---resume"
    assert anchor("A Dask cluster (`--scheduler`)") == "a-dask-cluster---scheduler"
    assert anchor("Restitution's band") == "restitutions-band"
    assert anchor("PHYSVAL_SABOTAGE") == "physval_sabotage"


def test_a_broken_link_would_be_caught(tmp_path):
    page = tmp_path / "page.md"
    (tmp_path / "there.md").write_text("# Here\n")
    page.write_text(
        "[ok](there.md) [gone](missing.md) [bad anchor](there.md#nowhere) [ok2](there.md#here) "
        "`[code](not-a-link.md)` [out](https://example.org/x)\n"
    )
    problems = broken(page, tmp_path)
    assert len(problems) == 2, problems
    assert problems[0].startswith("missing.md") and problems[1].startswith("there.md#nowhere")
