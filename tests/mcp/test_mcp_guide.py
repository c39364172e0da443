"""docs/guides/mcp.md matches the code: its tool tables name exactly the server's tools (the
reading ones as reading), say which need ``params`` or an action, and its relay URLs have
the port the relay guide gives them."""

from __future__ import annotations

import re

from roslibpy_lite import MockRos
from roslibpy_lite.mcp.listing import FIND_TOOLS
from roslibpy_lite.mcp.tools import GOAL_TOOLS, PARAM_TOOLS, RobotTools
from tests.helpers import ROOT

GUIDE = (ROOT / "docs/guides/mcp.md").read_text()
TYPED = {"publish__<topic>", "call__<service>", "send_goal__<action>"}


def _tables() -> list[dict[str, str]]:
    """The tool tables of "What the agent sees": each a {tool name: its row} map."""
    section = GUIDE.split("## What the agent sees", 1)[1].split("\n## ", 1)[0]
    tables: list[dict[str, str]] = []
    for block in re.split(r"\n\s*\n", section):
        rows = [line for line in block.splitlines() if line.startswith("| `")]
        if rows:
            tables.append({name: row for row in rows
                           for name in re.findall(r"`([^`]+)`", row.split("|")[1])})
    return tables


async def test_the_tool_tables_are_the_servers_tools() -> None:
    """The reading table names the read-only tools (and find_tools), the changing table the
    others and the typed ones; no tool is missing or made up."""
    tools = RobotTools(MockRos())._generic
    reading, changing = _tables()
    ro = {n for n, t in tools.items() if t.tool.annotations and t.tool.annotations.read_only_hint}
    assert set(reading) == ro | {FIND_TOOLS}
    assert set(changing) == (set(tools) - ro) | TYPED


def test_the_conditional_tools_say_their_condition() -> None:
    """Each tool offered only with params says so, each goal tool that it needs an action."""
    rows = {name: row for table in _tables() for name, row in table.items()}
    for name in PARAM_TOOLS:
        assert "`params`" in rows[name], rows[name]
    for name in GOAL_TOOLS:
        assert "action" in rows[name], rows[name]


def test_relay_urls_carry_the_port() -> None:
    """Every relay URL in the guide has the port, as the relay guide writes them."""
    urls = re.findall(r"wss?://relay\.example\.com[^\s\"`]*", GUIDE)
    assert urls and all(re.match(r"wss?://relay\.example\.com:\d+/", u) for u in urls), urls
