"""The pages a new user follows from the demo to a secured deployment: every bridge command
on them would start, the first one on each page is a safe one, one path for the bridge's
files, the demo's port option and what resume covers are said."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from bridge_server.__main__ import parse_args
from bridge_server.zenoh.link import options_from_args
from rosbridge_core.security import exposure_refusal, is_loopback
from tests.helpers import ROOT

PAGES = [ROOT / "README.md", ROOT / "SECURITY.md", *sorted((ROOT / "docs").rglob("*.md"))]
SUBCOMMANDS = ("add-principal", "remove-principal", "healthcheck")
RELAY_SUBCOMMANDS = ("certs",)


def _shell_blocks(page: Path) -> list[str]:
    """The text of the page's shell code blocks (```bash, ```sh or no language)."""
    blocks: list[str] = []
    lines: list[str] | None = None
    shell = False
    for line in page.read_text().splitlines():
        fence = re.match(r"\s*```(\S*)", line)
        if fence and lines is None:
            lines, shell = [], fence[1] in ("", "bash", "sh", "console")
        elif fence:
            if shell and lines is not None:
                blocks.append("\n".join(lines))
            lines = None
        elif lines is not None:
            lines.append(line)
    return blocks


def _bridge_commands(page: Path, program: str = "roslibpy-lite-bridge") -> list[list[str]]:
    """The options of each server command of ``program`` in the page's shell blocks."""
    found = []
    for block in _shell_blocks(page):
        for line in re.sub(r"\\\n\s*", " ", block).splitlines():
            if not line.strip().startswith(program + " "):
                continue
            words = shlex.split(line.strip(), comments=True)[len(program.split()):]
            if words[:1] not in ([s] for s in (*SUBCOMMANDS, *RELAY_SUBCOMMANDS)):
                found.append(words)
    return found


def test_some_pages_show_the_bridge_command() -> None:
    """The scan below finds the commands it is about (it would pass on nothing otherwise)."""
    pages = {p.name for p in PAGES if _bridge_commands(p)}
    assert {"bridge.md", "SECURITY.md"} <= pages, pages


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_bridge_command_starts_and_the_first_is_safe(page: Path) -> None:
    """Every bridge command shown would pass the bridge's own start checks, and the first on
    a page listens on loopback or with TLS and tokens."""
    commands = _bridge_commands(page)
    for argv in commands:
        args = parse_args(argv)
        assert exposure_refusal(args) is None, f"{page.name}: {' '.join(argv)}"
        assert options_from_args(args).refusal() is None, f"{page.name}: {' '.join(argv)}"
    if commands:
        first = parse_args(commands[0])
        assert is_loopback(first.host) or (first.auth_file and first.certfile), \
            f"{page.name} starts with an open bridge: {' '.join(commands[0])}"


def test_every_relay_command_starts() -> None:
    """Every relay command shown has the relay's options and passes its start checks, Zenoh's
    too: no plain link beyond loopback (the README's and the relay guide's, at least)."""
    from bridge_server.zenoh.relay import parse_args as relay_args

    pages = {p.name: _bridge_commands(p, "roslibpy-lite-relay") for p in PAGES}
    assert pages["README.md"] and pages["relay.md"], pages
    for name, commands in pages.items():
        for argv in commands:
            args = relay_args(argv)
            assert exposure_refusal(args) is None, f"{name}: {' '.join(argv)}"
            assert options_from_args(args).refusal() is None, f"{name}: {' '.join(argv)}"


def test_one_folder_for_the_bridges_files() -> None:
    """Docs, the unit and the image all keep the bridge's files in /etc/roslibpy-lite/."""
    places = [*PAGES, *sorted((ROOT / "deploy").rglob("*")), *sorted((ROOT / "scripts").glob("*"))]
    for path in places:
        if path.is_file():
            assert "/etc/rosbridge" not in path.read_text(), path
    for path in (ROOT / "deploy" / "Dockerfile", ROOT / "deploy" / "roslibpy-lite-bridge.service",
                 ROOT / "SECURITY.md", ROOT / "docs" / "operations.md"):
        assert "/etc/roslibpy-lite/auth.toml" in path.read_text(), path


def test_readme_says_the_demos_port_option() -> None:
    """Every option the demo script's header shows is in the README too."""
    header = (ROOT / "scripts" / "demo.sh").read_text().split("\nROOT=")[0]
    options = re.findall(r"^#\s+(\w+=\d+) bash scripts/demo\.sh", header, re.M)
    assert "PORT=9191" in options
    readme = (ROOT / "README.md").read_text()
    for option in options:
        assert f"{option} bash scripts/demo.sh" in readme or f"`{option}`" in readme, option


def test_resume_docs_say_what_resume_covers_and_cannot() -> None:
    """The operations page says a dropped link loses nothing, that what ROS published while
    the bridge process was stopped, frozen or restarting is gone, and that resume works
    without an auth file."""
    text = " ".join((ROOT / "docs" / "operations.md").read_text().split())
    assert "What resume covers, and what it cannot." in text
    assert "a dropped, silent or slow link, for up to `--session-keep` seconds, loses nothing" \
        in text
    assert "Messages ROS published while the bridge process was stopped, frozen or " \
           "restarting are gone" in text
    assert "Resume works without an auth file." in text


def test_the_mutation_command_names_what_exists() -> None:
    """Each scripts/mutate.sh command on a page names a module and test files that exist,
    and so does each line of a module list it is given with --list."""
    shown = [shlex.split(line.strip().partition("bash scripts/mutate.sh ")[2])
             for page in PAGES for block in _shell_blocks(page)
             for line in block.splitlines() if "bash scripts/mutate.sh " in line]
    assert shown, "no page shows scripts/mutate.sh"
    lists = [args[1] for args in shown if args[0] == "--list"]
    assert lists, "no page shows scripts/mutate.sh --list"
    shown = [args for args in shown if args[0] != "--list"] + [
        shlex.split(line) for listed in lists for line in (ROOT / listed).read_text().splitlines()
        if line.strip() and not line.startswith("#")]
    for module, *tests in shown:
        module = module.partition("::")[0]
        assert (ROOT / module).is_file() and module.endswith(".py"), module
        files = [t.split("::")[0] for t in tests if t.startswith("tests/")]
        assert files and all((ROOT / f).is_file() for f in files), tests
