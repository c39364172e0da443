"""The /rosapi/* services over rclpy, where they need a real ROS graph: the bridge's own node
among the graph's, an rclpy action server listed, an rclpy node's parameters (byte arrays
included) through its parameter services. Everything else rosapi answers is the session's
and is tested in memory in tests/session/test_rosapi.py; the rclpy Graph's introspection
and parameters are held to the in-memory Graph's by tests/bridge/test_graph_contract.py."""

from __future__ import annotations

import json
from typing import Any

import pytest
from rclpy.action.server import ActionServer
from test_msgs.action import Fibonacci

from tests.helpers import BridgeProcess, rosapi, rosapi_until

pytestmark = pytest.mark.asyncio


def _fq(node: Any) -> str:
    return str(node.get_fully_qualified_name())


async def test_nodes_fully_qualified(ws_connect: Any, bridge: BridgeProcess, ros_node: Any) -> None:
    """/rosapi/nodes lists fully qualified node names, the bridge's own included."""
    ws = await ws_connect()
    values = await rosapi_until(ws, "/rosapi/nodes", None, lambda v: _fq(ros_node) in v["nodes"])
    assert bridge.node_name in values["nodes"]
    assert all(n.startswith("/") for n in values["nodes"])


async def test_action_servers(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/action_servers lists actions served in the graph."""
    server = ActionServer(ros_node, Fibonacci, topic, lambda goal: Fibonacci.Result())  # type: ignore[no-untyped-call]
    try:
        ws = await ws_connect()
        await rosapi_until(ws, "/rosapi/action_servers", None, lambda v: topic in v["action_servers"])
    finally:
        server.destroy()  # type: ignore[no-untyped-call]


async def test_params_get_set_names(ws_connect: Any, ros_node: Any) -> None:
    """Node parameters are listed, read and written as /node:param with JSON text values (a
    byte array as its numbers)."""
    ros_node.declare_parameter("speed", 1.5)
    ros_node.declare_parameter("names", ["a", "b"])
    ros_node.declare_parameter("blob", [b"h", b"i"])
    full = _fq(ros_node)
    ws = await ws_connect()
    await rosapi_until(ws, "/rosapi/get_param_names", None,
                 lambda v: f"{full}:speed" in v["names"], timeout=20)
    got = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:speed"})
    assert json.loads(got["value"]) == 1.5 and got["successful"] is True
    names = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:names"})
    assert json.loads(names["value"]) == ["a", "b"]
    blob = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:blob"})
    assert json.loads(blob["value"]) == [104, 105]
    await rosapi(ws, "/rosapi/set_param", {"name": f"{full}:speed", "value": "2.25"})
    assert ros_node.get_parameter("speed").value == 2.25
    assert (await rosapi(ws, "/rosapi/has_param", {"name": f"{full}:speed"}))["exists"] is True
    assert (await rosapi(ws, "/rosapi/has_param", {"name": f"{full}:nope"}))["exists"] is False
    missing = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:nope", "default_value": "7"})
    assert missing["value"] == "7"

