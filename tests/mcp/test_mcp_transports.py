"""The MCP server over streamable HTTP, and through a relay held to the relay's roles, with
the mcp SDK's own client."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tests.helpers import BridgeProcess, free_port
from tests.mcp.http_support import TOKEN, http_client, mcp_http, write_token
from tests.mcp.support import mcp_stdio, serve_setbool, text, tool_names, until_listed, until_tool
from tests.relay.support import relay_with_auth


async def test_streamable_http_lists_and_calls(
    bridge: BridgeProcess, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """Over streamable HTTP (with the door's token) the SDK's client lists the typed tool of
    an rclpy service and its call reaches the service."""
    calls = serve_setbool(ros_node, topic)
    with mcp_http(bridge.url, free_port(), tmp_path,
                  "--http-token-file", write_token(tmp_path)) as server:
        async with http_client(server.url, TOKEN) as client:
            tool = await until_tool(client, "call__" + topic.strip("/"))
            result = await client.call_tool(tool.name, {"request": {"data": True}})
            assert not result.is_error, text(result)
            assert '"success": true' in text(result)
    assert calls == [True]


ROLES = """
[roles.agent]
subscribe = ["*"]
introspection = ["*"]
call_service = ["/*_ok"]
"""


async def test_through_a_relay_held_to_the_relays_role(
    ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """Through a relay (robot1 dialing out over Zenoh) an agent token whose role may call
    only /*_ok services is offered that one's tool, not the other's, and its call reaches
    the rclpy service behind the robot."""
    ok = serve_setbool(ros_node, topic + "_ok")
    other = serve_setbool(ros_node, topic + "_no")
    async with relay_with_auth(tmp_path / "auth.toml", ROLES, robots=("robot1",)) as (
            relay, tokens):
        url = f"ws://127.0.0.1:{relay.port}/robot1"
        async with mcp_stdio(url, tokens["agent"], tmp_path) as client:
            await until_listed(client, "list_services", topic + "_no")
            tool = await until_tool(client, "call__" + topic.strip("/") + "_ok")
            assert "call__" + topic.strip("/") + "_no" not in await tool_names(client)
            result = await client.call_tool(tool.name, {"request": {"data": True}})
            assert not result.is_error, text(result)
    assert ok == [True] and other == []
