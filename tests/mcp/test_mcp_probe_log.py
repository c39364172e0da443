"""The MCP server's own permission probing is not logged as refusals (issue 50, item 5): an
operator's server asks the bridge what its role may do (``/rosapi/may_params`` among them),
and a "no" to that question read in the bridge's log as
``call_service: forbidden: role operator may not params on any name``."""

from __future__ import annotations

from pathlib import Path

from rosbridge_core.security.auth import EXAMPLE_ROLES
from roslibpy_lite.mcp.tools import PARAM_TOOLS
from tests.helpers import BridgeProcess
from tests.mcp.support import mcp_stdio, tool_names
from tests.security.support import wire, write_auth_file


async def test_an_operators_mcp_server_leaves_no_refusal_in_the_bridge_log(tmp_path: Path) -> None:
    """After an MCP server with an operator token lists its tools, the bridge has logged no refusal, and the role's missing params still withhold the parameter tools."""
    auth = write_auth_file(tmp_path / "auth.toml", EXAMPLE_ROLES, [("operator", "operator")])
    bridge = BridgeProcess(args=["--auth-file", str(auth.path)]).start()
    try:
        start = len(bridge.lines)
        async with mcp_stdio(bridge.url, auth.tokens["operator"], tmp_path) as client:
            offered = await tool_names(client)
            # A connection opened after the listing: its log line comes after any line the
            # probing wrote (one pipe, in order), so the log read up to it is complete.
            marker = await wire(bridge.url, auth.tokens["operator"])
            await marker.close()
            connected = r"client \d+ connected from"
            first = bridge.lines.index(bridge.wait_for_line(connected, start=start), start)
            bridge.wait_for_line(connected, start=first + 1, timeout=30)  # the marker's
            seen = bridge.lines[start:]
    finally:
        bridge.stop()
    assert offered and not offered & set(PARAM_TOOLS), offered
    refusals = [line for line in seen if "forbidden" in line or "may not" in line]
    assert refusals == [], refusals
