"""The documentation's examples run as written, and its option lists are the tools' own.

Each fenced Python block in ``docs/`` marked ``<!-- docs-test: bridge -->``
runs against the session's real bridge, each ``<!-- docs-test: mock -->``
without one (MockRos). ``mkdocs build --strict`` itself runs in
``scripts/test.sh``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import re
from pathlib import Path

import pytest

from tests.helpers import ROOT, BridgeProcess, marked_blocks, run_snippet

DOCS = ROOT / "docs"
EXAMPLES = [
    pytest.param(kind, code, id=f"{page.relative_to(DOCS)}:{n}:{kind}")
    for page in sorted(DOCS.rglob("*.md"))
    for n, (kind, code) in enumerate(marked_blocks(page, "docs-test"))
]


def test_the_guides_have_examples() -> None:
    """Every task guide carries at least one tested example."""
    pages = {Path(p.id.split(":")[0]) for p in EXAMPLES}  # type: ignore[union-attr]
    for guide in ["getting-started.md", "compat.md", "guides/pubsub.md", "guides/services.md",
                  "guides/blocking.md", "guides/testing.md", "guides/actions.md"]:
        assert Path(guide) in pages, guide
    assert {p.values[0] for p in EXAMPLES} == {"bridge", "mock"}


@pytest.mark.parametrize(("kind", "code"), EXAMPLES)
def test_example_runs(kind: str, code: str, request: pytest.FixtureRequest) -> None:
    """The example exits cleanly (its own asserts hold) against the bridge or in memory."""
    bridge: BridgeProcess | None = request.getfixturevalue("bridge") if kind == "bridge" else None
    run_snippet(code, bridge)


def test_option_lists_come_from_the_tools() -> None:
    """The help markers render each tool's real --help: every bridge option appears on the page."""
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "_hooks" / "generated.py")
    assert spec is not None and spec.loader is not None
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    from bridge_server.__main__ import parse_args

    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        parse_args(["--help"])
    options = set(re.findall(r"--[a-z][a-z-]+", out.getvalue()))
    assert len(options) > 10
    bridge_page = hooks.on_page_markdown((DOCS / "bridge.md").read_text())
    assert "<!-- help:" not in bridge_page
    assert {opt for opt in options if opt not in bridge_page} == set()
    cli_page = hooks.on_page_markdown((DOCS / "cli.md").read_text())
    assert "<!-- help:" not in cli_page
    from roslibpy_lite.cli import build_parser

    commands = {
        name
        for action in build_parser()._subparsers._group_actions  # type: ignore[union-attr]
        for name in getattr(action, "choices", None) or ()
    }
    assert {"topic", "bag"} <= commands
    assert {c for c in commands if f"roslibpy-lite {c} --help" not in cli_page} == set()


def test_api_pages_show_no_raw_sphinx_roles(tmp_path: Path) -> None:
    """The built site shows Sphinx roles (:class:`x`) as code: none is left as raw text."""
    import os
    import subprocess
    import sys

    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    subprocess.run([sys.executable, "-m", "mkdocs", "build", "--quiet", "--site-dir", str(site)],
                   cwd=ROOT, env=env, check=True, capture_output=True, timeout=300)
    raw = re.compile(r":(?:py:)?(?:meth|class|func|mod|attr|exc|data|obj|const):")
    pages = list(site.rglob("*.html"))
    assert any("roslibpy_lite" in p.read_text() for p in pages)  # the API reference is there
    found = {str(p.relative_to(site)): len(raw.findall(p.read_text())) for p in pages}
    assert not {k: v for k, v in found.items() if v}, found


def test_no_page_promises_what_is_coming() -> None:
    """No page (nor the README) says "Coming": what exists is documented as it is, and
    what does not exist is not announced."""
    pages = [*sorted(DOCS.rglob("*.md")), ROOT / "README.md"]
    said = [f"{page.relative_to(ROOT)}:{n}: {line.strip()}"
            for page in pages
            for n, line in enumerate(page.read_text().splitlines(), 1)
            if re.search(r"\bcoming\b", line, re.IGNORECASE)]
    assert said == []


def _rendered_modules() -> set[str]:
    """The modules whose contents the API reference renders: each ``::: target`` (a module,
    or an object whose ``__module__`` counts) and each member its ``members: [...]`` names;
    every reference page must be in the nav."""
    import importlib

    nav = (ROOT / "mkdocs.yml").read_text()
    modules: set[str] = set()
    for page in sorted((DOCS / "reference").glob("*.md")):
        assert f"reference/{page.name}" in nav, f"{page.name} is not in mkdocs.yml's nav"
        text = page.read_text()
        for target, members in re.findall(
                r"^::: ([\w.]+)\n(?:    options:\n(?:      .*\n)*?      members: \[([^\]]*)\])?",
                text, re.MULTILINE):
            module_name, _, attr = target, "", ""
            while True:
                try:
                    obj: object = importlib.import_module(module_name)
                    break
                except ModuleNotFoundError:
                    module_name, _, last = module_name.rpartition(".")
                    attr = f"{last}.{attr}".rstrip(".")
            for step in filter(None, attr.split(".")):
                obj = getattr(obj, step)
            owners = [obj] + [getattr(obj, m.strip()) for m in members.split(",") if m.strip()]
            for owner in owners:
                name = getattr(owner, "__name__", "") if isinstance(owner, type(re)) else \
                    getattr(owner, "__module__", "")
                modules.add(name)
    return modules


def test_every_public_module_is_in_the_api_reference() -> None:
    """Each module of roslibpy_lite (and of roslibpy_lite.sync) whose name does not start
    with _ is rendered by a reference page: itself, or what it defines."""
    import pkgutil

    import roslibpy_lite
    import roslibpy_lite.sync

    modules = [f"roslibpy_lite.{m.name}" for m in pkgutil.iter_modules(roslibpy_lite.__path__)]
    modules += [f"roslibpy_lite.sync.{m.name}"
                for m in pkgutil.iter_modules(roslibpy_lite.sync.__path__)]
    public = [m for m in modules if not m.rpartition(".")[2].startswith("_")]
    rendered = _rendered_modules()
    missing = [m for m in public
               if not any(r == m or r.startswith(m + ".") for r in rendered)]
    assert "roslibpy_lite.bag" in public and missing == []


def test_the_extras_named_in_the_docs_exist_and_are_all_listed() -> None:
    """Getting started's extras table lists every extra a user installs (not the
    repository's own dev and build-interfaces), and no page names an extra that does not
    exist (docs/cli.md spoke of a `bag` extra)."""
    import tomllib

    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"])
    table = re.findall(r"^\| `([\w-]+)` \|", (DOCS / "getting-started.md").read_text(),
                       re.MULTILINE)
    assert set(table) == extras - {"dev", "build-interfaces"}
    for page in [*sorted(DOCS.rglob("*.md")), ROOT / "README.md"]:
        text = page.read_text()
        named = re.findall(r"\bthe `([\w-]+)` extra", text) + re.findall(r"roslibpy-lite\[([\w,-]+)\]",
                                                                   text)
        unknown = {e for group in named for e in group.split(",")} - extras
        assert unknown == set(), f"{page.relative_to(ROOT)} names extras {unknown}"
