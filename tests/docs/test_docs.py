"""The documentation's examples run as written, and its option lists are the tools' own.

Each fenced Python block in ``docs/`` marked ``<!-- docs-test: bridge -->``
runs against the session's real bridge, each ``<!-- docs-test: mock -->``
without one (MockRos). ``mkdocs build --strict`` itself runs in
``scripts/test.sh``.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import io
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.docs.test_deploy_docs import RELAY_SUBCOMMANDS
from tests.docs.test_deploy_docs import SUBCOMMANDS as BRIDGE_SUBCOMMANDS
from tests.docs.test_deploy_docs import _bridge_commands as _commands_on
from tests.helpers import ROOT, BridgeProcess, marked_blocks, ros_env, run_snippet

DOCS = ROOT / "docs"
EXAMPLES = [
    pytest.param(kind, code, id=f"{page.relative_to(DOCS)}:{n}:{kind}")
    for page in sorted(DOCS.rglob("*.md"))
    for n, (kind, code) in enumerate(marked_blocks(page, "docs-test"))
    if kind != "generated"
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
    """The example exits cleanly (its own asserts hold) against the bridge or in memory, and
    each of its prints ran (one in an ``except`` that nothing raised would not)."""
    bridge: BridgeProcess | None = request.getfixturevalue("bridge") if kind == "bridge" else None
    out = run_snippet(code, bridge)
    said = {text.strip() for text in re.findall(r"\bprint\(f?[\"']([^\"'{]*)", code)} - {""}
    assert {text for text in said if text not in out} == set(), out


# Where a user looks for each entry point's options (the pages render each --help).
REFERENCE_PAGES = {
    "roslibpy-lite": "cli.md",
    "roslibpy-lite-bridge": "bridge.md",
    "roslibpy-lite-relay": "bridge.md",
    "python -m bench": "benchmarks.md",
}


def test_the_generated_package_example(bridge: BridgeProcess, tmp_path: Path) -> None:
    """The custom-messages guide's ``interface gen`` command, run as written against the
    bridge, writes the package that the guide's next example imports, and that example runs."""
    import shlex
    import subprocess
    import sys

    page = DOCS / "guides" / "custom-messages.md"
    [code] = [code for kind, code in marked_blocks(page, "docs-test") if kind == "generated"]
    command = re.search(r"^roslibpy-lite --url ws://robot:9090 interface gen .*$",
                        page.read_text(), re.M)
    assert command is not None and "from robot_types." in code
    program, *args = shlex.split(command[0].replace("ws://robot:9090", bridge.url))
    subprocess.run([str(Path(sys.executable).parent / program), *args], cwd=tmp_path,
                   env=ros_env(PYTHONPATH=str(ROOT)), check=True, timeout=60)
    run_snippet(code, bridge, cwd=tmp_path)


def _run_for_help(program: str, args: list[str]) -> None:
    """Parse ``args`` (ending in ``--help``) as ``program`` does, in this process."""
    from bench.run import parse_args as bench_args
    from bridge_server.__main__ import main as bridge_main
    from bridge_server.zenoh.relay import main as relay_main
    from roslibpy_lite.cli import build_parser

    tools: dict[str, Callable[[list[str]], object]] = {
        "roslibpy-lite": build_parser().parse_args,
        "roslibpy-lite-bridge": bridge_main,
        "roslibpy-lite-relay": relay_main,
        "python -m bench": bench_args,
    }
    tools[program](args)


def _program(command: str) -> str:
    """The entry point a command (``roslibpy-lite topic echo``) belongs to."""
    return next(p for p in REFERENCE_PAGES if command == p or command.startswith(p + " "))


def _tool_help(command: str) -> str:
    """What ``COMMAND --help`` prints (one line per option: no wrapping)."""
    program = _program(command)
    out = io.StringIO()
    with pytest.MonkeyPatch.context() as env:
        env.setenv("COLUMNS", "1000")
        with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
            _run_for_help(program, [*command[len(program):].split(), "--help"])
    return out.getvalue()


@functools.cache
def _commands() -> dict[str, str]:
    """Each entry point and every subcommand under it (as ``--help`` lists them), with the
    text of its ``--help``."""
    found: dict[str, str] = {}
    todo = [*REFERENCE_PAGES, *(f"roslibpy-lite-bridge {c}" for c in BRIDGE_SUBCOMMANDS),
            *(f"roslibpy-lite-relay {c}" for c in RELAY_SUBCOMMANDS)]
    while todo:
        command = todo.pop(0)
        found[command] = _tool_help(command)
        choices = re.search(r"^positional arguments:\n  \{([\w,-]+)\}", found[command], re.M)
        todo += [f"{command} {c}" for c in choices[1].split(",")] if choices else []
    return found


def _options(help_text: str) -> dict[str, str]:
    """The long options a ``--help`` text lists (``-f, --feedback``: the second), each
    with its help."""
    found: dict[str, str] = {}
    names: list[str] = []
    for line in help_text.splitlines():
        head = re.match(r"  (-\S.*?)(?:  +(.*))?$", line)
        if head:
            names = re.findall(r"--[a-z][\w-]*", head[1])
            found |= {name: head[2] or "" for name in names if name != "--help"}
        elif line.startswith("   ") and names:
            found |= {name: found[name] + " " + line.strip() for name in names if name in found}
        else:
            names = []
    return found


def test_every_option_of_every_command_is_on_its_reference_page() -> None:
    """Every entry point (pyproject's scripts and ``python -m bench``), each subcommand and
    each of their options is on its reference page, in that command's own --help block."""
    import tomllib

    hooks = _load_hooks()
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert set(scripts) | {"python -m bench"} == set(REFERENCE_PAGES)
    commands = _commands()
    assert {"roslibpy-lite bag record", "roslibpy-lite-bridge healthcheck"} <= set(commands)
    sections: dict[str, str] = {}
    for page in set(REFERENCE_PAGES.values()):
        rendered = hooks.on_page_markdown((DOCS / page).read_text())
        assert "<!-- help:" not in rendered
        parts = re.split(r"^\$ (.+?) --help$", rendered, flags=re.M)
        sections |= {f"{page}: {c}": text for c, text in zip(parts[1::2], parts[2::2], strict=True)}
    missing = {}
    for command, help_text in commands.items():
        page = REFERENCE_PAGES[_program(command)]
        shown = sections.get(f"{page}: {command}")
        if shown is None:
            missing[command] = f"no {command} --help on {page}"
            continue
        absent = {o for o in _options(help_text) if not re.search(rf"{o}(?![\w-])", shown)}
        if absent:
            missing[command] = f"{page} lacks {sorted(absent)}"
    assert missing == {}, "\n".join(missing.values())


def _defaults(command: str) -> dict[str, object]:
    """Each option of ``command`` with the value it takes when not given."""
    import argparse

    from bench.run import parse_args as bench_args
    from bridge_server.__main__ import parse_args as bridge_args
    from bridge_server.zenoh.relay import parse_args as relay_args
    from roslibpy_lite.cli import build_parser

    if _program(command) == "roslibpy-lite":
        parser = build_parser()
        for word in command.split()[1:]:
            sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
            parser = sub.choices[word]
        return {o: a.default for a in parser._actions for o in a.option_strings}
    parse = {"roslibpy-lite-bridge": bridge_args, "roslibpy-lite-relay": relay_args,
             "python -m bench": bench_args}[command]
    return {"--" + dest.replace("_", "-"): value for dest, value in vars(parse([])).items()}


def test_every_default_is_said() -> None:
    """Each option that has a value when not given (not unset, off or empty) says its
    default in its --help, so the reference pages show it."""
    commands = {c: text for c, text in _commands().items() if not c.startswith(
        (*(f"roslibpy-lite-bridge {s}" for s in BRIDGE_SUBCOMMANDS),
         *(f"roslibpy-lite-relay {s}" for s in RELAY_SUBCOMMANDS)))}
    unsaid = []
    for command, help_text in commands.items():
        helps = _options(help_text)
        for option, default in _defaults(command).items():
            if default not in (None, [], "") and default is not False and option in helps \
                    and "default" not in helps[option]:
                unsaid.append(f"{command} {option} (default {default!r})")
    assert unsaid == [], "\n".join(unsaid)


def test_every_option_a_page_names_exists() -> None:
    """No page, the README or bench's names an option that none of our tools has (nor the
    other programs its commands run: pip, docker, systemctl, mypy, mkdocs, nbconvert...)."""
    ours = set().union({"--help"}, *(_options(text) for text in _commands().values()))
    others = {
        "--no-deps": "pip wheel", "--now": "systemctl enable", "--network": "docker run",
        "--cap-drop": "docker run", "--security-opt": "docker run",
        "--build-context": "docker build", "--execute": "jupyter nbconvert",
        "--strict": "mypy, mkdocs build", "--interfaces": "python -m msgs.generator",
        "--share": "python -m msgs.generator", "--output": "python -m msgs.generator",
        "--command": "python -m examples.multi_robot", "--seconds": "python -m bench.dataframe",
        "--imu-seconds": "python -m bench.dataframe",
        "--list": "bash scripts/mutate.sh",
    }
    pages = [*sorted(DOCS.rglob("*.md")), ROOT / "README.md", ROOT / "SECURITY.md",
             ROOT / "bench" / "README.md"]
    unknown = [f"{page.relative_to(ROOT)}:{n}: {option}"
               for page in pages
               for n, line in enumerate(page.read_text().splitlines(), 1)
               for option in re.findall(r"(?<![\w-])--[a-z][\w-]*", line)
               if option not in ours and option not in others]
    assert unknown == [], "\n".join(unknown)


def test_every_command_a_page_shows_parses() -> None:
    """Each ``roslibpy-lite`` and ``python -m bench`` command in a page's shell blocks is
    one its tool takes (the bridge's and relay's: tests/docs/test_deploy_docs.py)."""
    from bench.run import parse_args as bench_args
    from roslibpy_lite.cli import build_parser

    pages = [*sorted(DOCS.rglob("*.md")), ROOT / "README.md", ROOT / "SECURITY.md",
             ROOT / "bench" / "README.md"]
    refused = []
    shown = 0
    for page in pages:
        for program, parse in (("roslibpy-lite", build_parser().parse_args),
                               ("python -m bench", bench_args)):
            for argv in _commands_on(page, program):
                shown += 1
                with contextlib.redirect_stderr(io.StringIO()) as err:
                    try:
                        parse(argv)
                    except SystemExit:
                        refused.append(f"{page.relative_to(ROOT)}: {program} {' '.join(argv)}: "
                                       f"{err.getvalue().strip().splitlines()[-1]}")
    assert shown > 10 and refused == [], "\n".join(refused)


def test_the_metrics_tables_are_the_bridges(bridge: BridgeProcess) -> None:
    """The README's and the operations page's metrics tables name exactly the families the
    bridge's /metrics exports."""
    import urllib.request

    with urllib.request.urlopen(f"http://127.0.0.1:{bridge.port}/metrics", timeout=10) as reply:
        exported = reply.read().decode()
    real = {name.removeprefix("roslibpy_bridge_")
            for name in re.findall(r"^# TYPE (roslibpy_bridge_\w+)", exported, re.M)}
    assert {"clients", "service_calls_total"} <= real
    for page in (ROOT / "README.md", DOCS / "operations.md"):
        table = page.read_text().split("Metrics (all `roslibpy_bridge_*`):\n\n")[1].split("\n\n")[0]
        named = {name for row in table.splitlines()[2:]
                 for name in re.findall(r"`(\w+)`", row.split("|")[1])}
        assert (sorted(named - real), sorted(real - named)) == ([], []), page.name


def _load_hooks() -> Any:
    """docs/_hooks/generated.py, as mkdocs loads it."""
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "_hooks" / "generated.py")
    assert spec is not None and spec.loader is not None
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    return hooks


def test_api_pages_show_no_raw_sphinx_roles(tmp_path: Path) -> None:
    """The built site shows Sphinx roles (:class:`x`) as code: none is left as raw text."""
    import os
    import subprocess
    import sys

    built = os.environ.get("ROSLIBPY_LITE_BUILT_SITE")  # scripts/test.sh built it already
    site = Path(built) if built and (Path(built) / "index.html").is_file() else tmp_path / "site"
    if site == tmp_path / "site":
        env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
        subprocess.run([sys.executable, "-m", "mkdocs", "build", "--quiet", "--site-dir",
                        str(site)], cwd=ROOT, env=env, check=True, capture_output=True,
                       timeout=300)
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
    repository's own dev and build-interfaces) with what each brings, no page names an
    extra that does not exist (docs/cli.md spoke of a `bag` extra), and none has pip
    install roslibpy-lite by name: the project installs from its own wheel or checkout, and
    a name on a package index could be anyone's."""
    import tomllib

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    table = re.findall(r"^\| `([\w-]+)` \|", (DOCS / "getting-started.md").read_text(),
                       re.MULTILINE)
    assert set(table) == set(extras) - {"dev", "build-interfaces", "build-interfaces-kilted"}
    rows = dict(re.findall(r"^\| `([\w-]+)` \| (.*?) \|", (DOCS / "getting-started.md").read_text(),
                           re.MULTILINE))
    for extra in table:  # each package it brings (ROS's by "ROS 2 Jazzy/Kilted wheels")
        brings = [re.split(r"[^\w.-]", r)[0] for r in extras[extra]]
        unsaid = [n for n in brings if f"`{n}`" not in rows[extra] and not (
            n.startswith("ros-") and re.search(r"ROS 2 (Jazzy|Kilted) wheels", rows[extra]))]
        assert unsaid == [], f"the {extra} extra's row does not say {unsaid}"
    for page in [*sorted(DOCS.rglob("*.md")), ROOT / "README.md"]:
        text = page.read_text()
        named = re.findall(r"\bthe `([\w-]+)` extra", text) + re.findall(
            r"(?:roslibpy_lite-[\w.-]+\.whl|\.)\[([\w,-]+)\]", text)
        from_an_index = re.findall(r"pip install [^`\n]*?'?\broslibpy[-_]lite\b(?!-|[\w.-]*\.whl)", text)
        assert from_an_index == [], f"{page.relative_to(ROOT)}: {from_an_index} (install the wheel)"
        unknown = {e for group in named for e in group.split(",")} - set(extras)
        assert unknown == set(), f"{page.relative_to(ROOT)} names extras {unknown}"
