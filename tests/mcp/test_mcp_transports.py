"""The MCP server over streamable HTTP, and through a relay held to the relay's roles, with
the mcp SDK's own client."""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mcp import Client

from tests.helpers import ROOT, BridgeProcess, free_port, ros_env
from tests.mcp.support import mcp_stdio, serve_setbool, text, tool_names, until_listed, until_tool
from tests.relay.support import relay_with_auth


@contextlib.contextmanager
def _mcp_http(url: str, port: int) -> Iterator[str]:
    """``roslibpy-lite mcp --http PORT`` as a child process; yields its MCP URL once it
    listens (a TCP connect is the only sign a listener gives)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "roslibpy_lite.cli", "mcp", "--url", url, "--http", str(port)],
        cwd=ROOT, env=ros_env(PYTHONPATH=str(ROOT)), stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 20
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1):
                break
            assert proc.poll() is None, f"the mcp server exited with {proc.returncode}"
            assert time.monotonic() < deadline, "the mcp server never listened"
            time.sleep(0.05)
        yield f"http://127.0.0.1:{port}/mcp"
    finally:
        proc.terminate()
        proc.wait(10)


async def test_streamable_http_lists_and_calls(
    bridge: BridgeProcess, ros_node: Any, topic: str
) -> None:
    """Over streamable HTTP the SDK's client lists the typed tool of an rclpy service and
    its call reaches the service."""
    calls = serve_setbool(ros_node, topic)
    with _mcp_http(bridge.url, free_port()) as url:
        async with Client(url, read_timeout_seconds=60) as client:
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
