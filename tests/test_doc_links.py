"""Every link between README.md and docs/*.md leads somewhere: the file
exists, and an ``#anchor`` is a heading of it, by GitHub's slug rules."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
FENCE = "```"


def prose(text: str):
    """The lines of a Markdown text outside fenced code blocks."""
    fenced = False
    for line in text.splitlines():
        if line.lstrip().startswith(FENCE):
            fenced = not fenced
        elif not fenced:
            yield line


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: the rendered text in lower case, without
    punctuation but hyphens and underscores, spaces as hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link: its text
    text = text.replace("`", "").replace("*", "").strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set:
    """The anchors of a page's headings (a repeated one gets -1, -2...)."""
    found, seen = set(), {}
    for line in prose(page.read_text()):
        heading = re.match(r"#{1,6} +(.*?) *#*$", line)
        if heading:
            name = slug(heading.group(1))
            count = seen.get(name, 0)
            seen[name] = count + 1
            found.add(name if count == 0 else f"{name}-{count}")
    return found


def test_slugs_follow_github():
    assert slug("8. Stable timestep") == "8-stable-timestep"
    assert slug("Threads for the bpm/spring and granular kernels") == \
        "threads-for-the-bpmspring-and-granular-kernels"
    assert slug("Demo: `ase-bpm demo impact`") == "demo-ase-bpm-demo-impact"
    assert slug("What `bond_style bpm/rotational` would take") == \
        "what-bond_style-bpmrotational-would-take"


def links(page: Path):
    for target in LINK.findall("\n".join(prose(page.read_text()))):  # text over lines too
        if not re.match(r"[a-z]+:", target):  # not http:, mailto:...
            yield target


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_link_resolves(page):
    broken = []
    for target in links(page):
        file, _, anchor = target.partition("#")
        linked = (page.parent / file).resolve() if file else page
        if not linked.exists():
            broken.append(f"{target}: no file {linked}")
        elif anchor and (linked.suffix != ".md" or anchor not in anchors(linked)):
            broken.append(f"{target}: no heading #{anchor} in {linked.name}")
    assert not broken, f"{page.name}: {broken}"


def test_the_check_sees_a_broken_anchor(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Top\n\n## A `b` c\n\n[ok](#a-b-c) [no](#a-c) [up\nthere](#top) [x](none.md)\n")
    assert anchors(page) == {"top", "a-b-c"}
    assert list(links(page)) == ["#a-b-c", "#a-c", "#top", "none.md"]
    with pytest.raises(AssertionError, match=r"#a-c: no heading.*none.md: no file"):
        test_every_link_resolves(page)
