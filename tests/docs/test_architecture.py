"""The maintainer's map (docs/architecture.md) names only files that exist, each holding the
names the page writes after it, and the site's navigation shows it."""

from __future__ import annotations

import re

from tests.helpers import ROOT

PAGE = ROOT / "docs" / "architecture.md"
ROOTS = ("msgs/", "rosbridge_core/", "roslibpy_lite/", "bridge_server/", "tests/", "docs/", "README.md")


def _named() -> dict[str, set[str]]:
    """Each path the page names in backticks, with the names in backticks in the
    parentheses right after it."""
    text = PAGE.read_text()
    named: dict[str, set[str]] = {}
    for path, after in re.findall(r"`([\w./-]+)`(?: \(([^)]*)\))?", text):
        if path.startswith(ROOTS) and (path.endswith("/") or "." in path.rsplit("/", 1)[-1]):
            named.setdefault(path, set()).update(re.findall(r"`(\w+)`", after or ""))
    return named


def test_every_file_the_map_names_exists_with_its_names() -> None:
    """Every file or folder the page names exists, and each name written after a file (a
    class, a table, a function) is in that file's text."""
    named = _named()
    assert len(named) > 40 and "rosbridge_core/graph.py" in named
    missing = [path for path in named if not (ROOT / path).exists()]
    assert missing == []
    absent = {path: sorted(n for n in names
                           if not re.search(rf"\b{re.escape(n)}\b", (ROOT / path).read_text()))
              for path, names in named.items() if names and (ROOT / path).is_file()}
    assert {p: n for p, n in absent.items() if n} == {}


def test_the_map_is_in_the_navigation() -> None:
    """mkdocs.yml's nav lists the page (mkdocs build --strict would only warn of it)."""
    assert "architecture.md" in (ROOT / "mkdocs.yml").read_text()
