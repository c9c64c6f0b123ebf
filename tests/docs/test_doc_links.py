"""The README's and docs' relative links lead to files that exist, and the docs index lists every page."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = ["README.md", *sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").glob("*.md"))]
# pages the index lists that are being written beside this one; a link to one is fine until it exists
COMING = {"docs/design.md", "docs/lerobot.md", "docs/rerun.md", "docs/mcap.md", "docs/contact.md"}
LINK = re.compile(r"\]\(([^)\s]+)\)|<img src=\"([^\"]+)\"")


def links(page: str) -> list[tuple[int, str]]:
    """(line, target) of each relative link or image of ``page`` (anchors and web addresses left out)."""
    out = []
    for n, line in enumerate((ROOT / page).read_text().splitlines(), 1):
        for a, b in LINK.findall(line):
            target = (a or b).split("#")[0]
            if target and not re.match(r"[a-z]+:", target):
                out.append((n, target))
    return out


@pytest.mark.parametrize("page", PAGES)
def test_relative_links_resolve(page):
    base = (ROOT / page).parent
    broken = [f"{page}:{n}: {target}" for n, target in links(page)
              if not (base / target).exists() and (base / target).resolve().relative_to(ROOT).as_posix() not in COMING]
    assert not broken, "links to nothing:\n" + "\n".join(broken)


def test_docs_index_lists_every_page():
    listed = {(ROOT / "docs" / target).resolve() for _, target in links("docs/README.md")}
    missing = [p.name for p in sorted((ROOT / "docs").glob("*.md"))
               if p.name != "README.md" and p.resolve() not in listed]
    assert not missing, f"docs/README.md does not list: {', '.join(missing)}"


def test_readme_links_the_docs_index_and_its_picture_is_committed():
    targets = {t for _, t in links("README.md")}
    assert "docs/README.md" in targets
    pictures = [t for t in targets if t.endswith(".png")]
    assert pictures and all((ROOT / t).is_file() for t in pictures)


SCRIPT = re.compile(r"python (?:-m (benchmarks\.\w+)|((?:examples|tasks|benchmarks)/\w+\.py))")


@pytest.mark.parametrize("page", PAGES)
def test_named_scripts_exist(page):
    """`python -m benchmarks.x`, `python examples/x.py` and `python tasks/x.py` name files that exist."""
    text = (ROOT / page).read_text()
    missing = sorted({m or p for m, p in SCRIPT.findall(text)
                      if not (ROOT / (p or m.replace(".", "/") + ".py")).is_file()})
    assert not missing, f"{page} names scripts that do not exist: {', '.join(missing)}"
