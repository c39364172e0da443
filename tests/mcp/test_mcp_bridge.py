"""The MCP server against a real bridge with rclpy nodes, driven by the mcp SDK's own client
over stdio: typed tools from the robot's definitions, held to the token's role."""

from __future__ import annotations

import asyncio
import signal
import threading
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from mcp import Client
from std_msgs.msg import String

import roslibpy_lite
from roslibpy_lite.mcp import build_server, tools
from roslibpy_lite.mcp.listing import tool_name
from tests.helpers import BridgeProcess, async_wait_until
from tests.mcp.support import (
    agent_auth,
    mcp_stdio,
    serve_setbool,
    text,
    tool_names,
    until_listed,
    until_tool,
)
from tests.security.support import AuthFile

MUTATING = ("publish__", "call__", "send_goal__")



async def test_a_service_is_a_typed_tool_and_a_bad_request_names_its_field(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """call__<service> has the request's schema from its definition, calls the rclpy server, and
    a request that does not fit is an error naming the field that never reaches ROS."""
    calls = serve_setbool(ros_node, topic)
    async with mcp_stdio(auth_bridge.url, auth.tokens["admin"], tmp_path) as client:
        tool = await until_tool(client, "call__" + topic.strip("/"))
        schema = tool.input_schema
        assert schema["properties"]["request"]["properties"]["data"]["type"] == "boolean"
        good = {"request": {"data": True}, "timeout": 10}
        jsonschema.validate(good, schema)
        result = await client.call_tool(tool.name, good)
        assert not result.is_error, text(result)
        assert '"message": "set to True"' in text(result)
        assert calls == [True]
        bad = {"request": {"data": "yes"}}
        error = jsonschema.Draft202012Validator(schema).iter_errors(bad)
        assert [list(e.absolute_path) for e in error] == [["request", "data"]]
        result = await client.call_tool(tool.name, bad)
        assert result.is_error
        assert "data: expected bool" in text(result)
    assert calls == [True]  # the bad request was refused here, never sent


async def test_read_a_topic_and_publish_on_one(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """read_topic returns the next message of a live rclpy publisher; publish__<topic> delivers
    one message to an rclpy subscriber."""
    pub = ros_node.create_publisher(String, topic, 10)
    ros_node.create_timer(0.05, lambda: pub.publish(String(data="from-ros")))
    got: list[str] = []
    arrived = threading.Event()

    def on_message(msg: Any) -> None:
        got.append(msg.data)
        arrived.set()

    ros_node.create_subscription(String, topic + "_in", on_message, 10)
    async with mcp_stdio(auth_bridge.url, auth.tokens["admin"], tmp_path) as client:
        await until_listed(client, "list_topics", topic)
        result = await client.call_tool("read_topic", {"topic": topic, "timeout": 10})
        assert not result.is_error, text(result)
        assert '"data": "from-ros"' in text(result)
        tool = await until_tool(client, "publish__" + topic.strip("/") + "_in")
        result = await client.call_tool(tool.name, {"message": {"data": "from-agent"}})
        assert not result.is_error, text(result)
        await async_wait_until(arrived.is_set, 10, "the agent's message at the rclpy subscriber")
    assert got[0] == "from-agent"


async def test_a_viewer_is_offered_nothing_that_changes_the_robot(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """A viewer token sees the service listed but gets no call, publish, goal or parameter tool
    (the bridge says what its role may use); calling one anyway reaches nothing."""
    calls = serve_setbool(ros_node, topic)
    ros_node.create_publisher(String, topic + "_pub", 10)
    async with mcp_stdio(auth_bridge.url, auth.tokens["viewer"], tmp_path) as client:
        await until_listed(client, "list_services", topic)
        await until_listed(client, "list_topics", topic + "_pub")
        names = await tool_names(client)
        assert not [n for n in names if n.startswith(MUTATING)], names
        assert "set_param" not in names and "read_topic" in names
        result = await client.call_tool("call__" + topic.strip("/"), {"request": {"data": True}})
        assert result.is_error and "no tool" in text(result)
    assert calls == []


async def test_a_parameter_change_the_role_may_not_make_is_refused_by_the_bridge(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, tmp_path: Path
) -> None:
    """The prober role may change only *_display parameters: set_param on another is refused
    by the bridge (the node's value stays), on an allowed one it is made."""
    ros_node.declare_parameter("speed", 1.0)
    ros_node.declare_parameter("gain_display", 1.0)
    node = ros_node.get_fully_qualified_name()
    async with mcp_stdio(auth_bridge.url, auth.tokens["prober"], tmp_path) as client:
        await until_tool(client, "set_param")
        result = await client.call_tool("set_param", {"name": f"{node}:speed", "value": 5.0})
        assert result.is_error
        assert f"forbidden: role prober may not params on {node}:speed" in text(result)
        result = await client.call_tool("set_param", {"name": f"{node}:gain_display",
                                                      "value": 3.0})
        assert not result.is_error, text(result)
    assert ros_node.get_parameter("speed").value == 1.0
    assert ros_node.get_parameter("gain_display").value == 3.0


async def test_read_only_offers_no_tool_that_changes_anything(
    auth_bridge: BridgeProcess, auth: AuthFile, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """--read-only: even an admin token gets no publish, call, goal or set_param tool, and a
    call to one by name reaches nothing."""
    calls = serve_setbool(ros_node, topic)
    async with mcp_stdio(auth_bridge.url, auth.tokens["admin"], tmp_path,
                         "--read-only") as client:
        await until_listed(client, "list_services", topic)
        names = await tool_names(client)
        assert not [n for n in names if n.startswith(MUTATING)], names
        assert {"set_param", "cancel_goal"} & names == set()
        assert {"read_topic", "get_param", "list_services"} <= names
        result = await client.call_tool("call__" + topic.strip("/"), {"request": {"data": True}})
        assert result.is_error
    assert calls == []


async def test_a_dropped_link_is_a_tool_error_naming_its_state_and_recovers(
    make_bridge: Any, tmp_path: Path
) -> None:
    """With the bridge gone a tool call fails at once naming the link's state; once a bridge
    is back on the port the client reconnects and the same call works."""
    bridge = make_bridge()
    async with mcp_stdio(bridge.url, None, tmp_path) as client:
        assert not (await client.call_tool("list_nodes", {})).is_error
        bridge.stop()
        result = await client.call_tool("list_nodes", {})
        assert result.is_error
        assert "NotConnected" in text(result) and "reconnecting" in text(result), text(result)
        make_bridge(port=bridge.port)
        for _ in range(200):  # the client's backoff (no event reaches an MCP client)
            result = await client.call_tool("list_nodes", {})
            if not result.is_error:
                break
            await asyncio.sleep(0.1)
        assert not result.is_error, text(result)


async def test_a_tool_the_role_lost_is_refused_by_the_bridge_and_withdrawn(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path
) -> None:
    """After SIGHUP takes call_service from the agent's role, the tool listed before is
    refused by the bridge (Forbidden, the rclpy handler never runs), the server tells the
    client its tool list changed (tools/list_changed, on the handshake era hosts speak), and
    the next listing lacks it."""
    auth_file = tmp_path / "auth.toml"
    token = agent_auth(auth_file, 'call_service = ["*"]\n')
    bridge = make_bridge("--auth-file", str(auth_file))
    calls = serve_setbool(ros_node, topic)
    changed = asyncio.Event()

    async def on_message(message: Any) -> None:
        if getattr(getattr(message, "root", message), "method", "") == \
                "notifications/tools/list_changed":
            changed.set()

    async with mcp_stdio(bridge.url, token, tmp_path, message_handler=on_message,
                         mode="legacy") as client:
        tool = await until_tool(client, "call__" + topic.strip("/"))
        auth_file.write_text(auth_file.read_text().replace('call_service = ["*"]\n', ""))
        start = len(bridge.lines)
        assert bridge.proc is not None
        bridge.proc.send_signal(signal.SIGHUP)
        await asyncio.to_thread(bridge.wait_for_line, r"reloaded the auth file", 10, start)
        result = await client.call_tool(tool.name, {"request": {"data": True}})
        assert result.is_error
        assert "Forbidden" in text(result) and "role agent may not call_service" in text(result)
        await asyncio.wait_for(changed.wait(), 10)
        assert tool.name not in await tool_names(client)
    assert calls == []


async def test_the_role_is_asked_in_batches(
    make_bridge: Any, ros_node: Any, topic: str, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch
) -> None:
    """The bridge takes a bounded number of names per may_* question: asked one name at a
    time, a role that may publish on /zz* only is still offered exactly those topics (the
    server in process on our client, the SDK's client in memory)."""
    monkeypatch.setattr(tools, "_ASK_AT_ONCE", 1)
    auth_file = tmp_path / "auth.toml"
    token = agent_auth(auth_file, 'publish = ["/zz*"]\n')
    bridge = make_bridge("--auth-file", str(auth_file))
    for name in ("/zz" + topic + "_a", "/zz" + topic + "_b", topic + "_no"):
        ros_node.create_publisher(String, name, 10)
    expected = {tool_name("publish", "/zz" + topic + s, set()) for s in ("_a", "_b")}
    async with roslibpy_lite.connect(bridge.url, token=token) as ros, \
            Client(build_server(ros)) as client:
        await until_listed(client, "list_topics", topic + "_no")
        for name in expected:
            await until_tool(client, name)
        offered = {n for n in await tool_names(client) if n.startswith("publish__")}
    assert offered == expected
