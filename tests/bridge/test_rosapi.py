"""The /rosapi/* introspection services, answered by the bridge from the ROS graph."""

from __future__ import annotations

import asyncio
import itertools
import json
import time
from collections.abc import Callable
from typing import Any

import pytest
from rclpy.action.server import ActionServer
from std_msgs.msg import String
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

from tests.bridge.support import roundtrip
from tests.helpers import BridgeProcess

pytestmark = pytest.mark.asyncio

_ids = itertools.count()


async def _call(ws: Any, service: str, args: Any = None) -> dict[str, Any]:
    rid = f"r{next(_ids)}"
    op: dict[str, Any] = {"op": "call_service", "service": service, "id": rid}
    if args is not None:
        op["args"] = args
    await ws.send(op)
    reply = await ws.expect(op="service_response", id=rid)
    assert reply["result"] is True, reply
    assert reply["service"] == service
    values: dict[str, Any] = reply["values"]
    return values


async def _until(
    ws: Any, service: str, args: Any, ok: Callable[[dict[str, Any]], bool], timeout: float = 10.0
) -> dict[str, Any]:
    """Call ``service`` until its answer satisfies ``ok`` (the graph takes a moment to settle)."""
    deadline = time.monotonic() + timeout
    while True:
        values = await _call(ws, service, args)
        if ok(values):
            return values
        if time.monotonic() > deadline:
            raise AssertionError(f"{service} never satisfied the check; last answer {values}")
        await asyncio.sleep(0.02)


def _fq(node: Any) -> str:
    return str(node.get_fully_qualified_name())


async def test_topics_lists_names_and_types(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/topics lists every topic with its type at the same index."""
    ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    values = await _until(ws, "/rosapi/topics", None, lambda v: topic in v["topics"])
    assert len(values["topics"]) == len(values["types"])
    assert values["types"][values["topics"].index(topic)] == "std_msgs/msg/String"


async def test_topics_for_type_both_spellings(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/topics_for_type finds topics by type, in either spelling."""
    ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    await _until(ws, "/rosapi/topics_for_type", {"type": "std_msgs/msg/String"},
                 lambda v: topic in v["topics"])
    short = await _call(ws, "/rosapi/topics_for_type", {"type": "std_msgs/String"})
    assert topic in short["topics"]


async def test_topic_type(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/topic_type answers the type, or "" for an unknown topic; args may be a list."""
    ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    await _until(ws, "/rosapi/topic_type", {"topic": topic},
                 lambda v: v["type"] == "std_msgs/msg/String")
    assert (await _call(ws, "/rosapi/topic_type", [topic]))["type"] == "std_msgs/msg/String"
    assert await _call(ws, "/rosapi/topic_type", {"topic": topic + "_none"}) == {"type": ""}


async def test_services_include_ros_and_rosapi(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/services lists ROS services and the bridge's own rosapi services."""
    ros_node.create_service(SetBool, topic, lambda req, resp: resp)
    ws = await ws_connect()
    values = await _until(ws, "/rosapi/services", None, lambda v: topic in v["services"])
    for name in ("/rosapi/topics", "/rosapi/services", "/rosapi/nodes", "/rosapi/get_time"):
        assert name in values["services"]


async def test_service_type_and_services_for_type(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/service_type and /rosapi/services_for_type agree on a ROS service's type."""
    ros_node.create_service(SetBool, topic, lambda req, resp: resp)
    ws = await ws_connect()
    await _until(ws, "/rosapi/service_type", {"service": topic},
                 lambda v: v["type"] == "std_srvs/srv/SetBool")
    found = await _call(ws, "/rosapi/services_for_type", {"type": "std_srvs/SetBool"})
    assert topic in found["services"]
    own = await _call(ws, "/rosapi/service_type", {"service": "/rosapi/topics"})
    assert own == {"type": "rosapi_msgs/srv/Topics"}


async def test_service_node(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/service_node names the node serving a service."""
    ros_node.create_service(SetBool, topic, lambda req, resp: resp)
    ws = await ws_connect()
    await _until(ws, "/rosapi/service_node", {"service": topic},
                 lambda v: v["node"] == _fq(ros_node))


async def test_service_node_of_a_client_served_service(
    ws_connect: Any, bridge: BridgeProcess, topic: str
) -> None:
    """/rosapi/service_node names the bridge's node for a service one of its clients serves."""
    server = await ws_connect()
    await server.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    ws = await ws_connect()
    await roundtrip(server)  # the advertise has been handled
    values = await _call(ws, "/rosapi/service_node", {"service": topic})
    assert values == {"node": bridge.node_name}


async def test_nodes_fully_qualified(ws_connect: Any, bridge: BridgeProcess, ros_node: Any) -> None:
    """/rosapi/nodes lists fully qualified node names, the bridge's own included."""
    ws = await ws_connect()
    values = await _until(ws, "/rosapi/nodes", None, lambda v: _fq(ros_node) in v["nodes"])
    assert bridge.node_name in values["nodes"]
    assert all(n.startswith("/") for n in values["nodes"])


async def test_node_details(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/node_details lists a node's publications, subscriptions and services."""
    ros_node.create_publisher(String, topic + "_out", 10)
    ros_node.create_subscription(String, topic + "_in", lambda m: None, 10)
    ros_node.create_service(SetBool, topic + "_srv", lambda req, resp: resp)
    ws = await ws_connect()
    await _until(ws, "/rosapi/nodes", None, lambda v: _fq(ros_node) in v["nodes"])
    values = await _until(
        ws, "/rosapi/node_details", {"node": _fq(ros_node)},
        lambda v: topic + "_srv" in v["services"],
    )
    assert topic + "_out" in values["publishing"]
    assert topic + "_in" in values["subscribing"]


async def test_node_details_unknown_node_fails(ws_connect: Any) -> None:
    """/rosapi/node_details for a node not in the graph fails with result false naming it."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/node_details",
                   "args": {"node": "/no/such_node"}, "id": "nd"})
    reply = await ws.expect(op="service_response", id="nd")
    assert reply["result"] is False and "/no/such_node" in reply["values"]


async def test_publishers_and_subscribers(ws_connect: Any, bridge: BridgeProcess, ros_node: Any, topic: str) -> None:
    """/rosapi/publishers and /rosapi/subscribers name the nodes on each side of a topic."""
    ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    await _until(ws, "/rosapi/publishers", {"topic": topic},
                 lambda v: v["publishers"] == [_fq(ros_node)])
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await _until(ws, "/rosapi/subscribers", {"topic": topic},
                 lambda v: bridge.node_name in v["subscribers"])


async def test_action_servers(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/action_servers lists actions served in the graph."""
    server = ActionServer(ros_node, Fibonacci, topic, lambda goal: Fibonacci.Result())  # type: ignore[no-untyped-call]
    try:
        ws = await ws_connect()
        await _until(ws, "/rosapi/action_servers", None, lambda v: topic in v["action_servers"])
    finally:
        server.destroy()  # type: ignore[no-untyped-call]


async def test_get_time(ws_connect: Any) -> None:
    """/rosapi/get_time gives the bridge clock as {sec, nanosec} (plus ROS 1 secs, nsecs)."""
    ws = await ws_connect()
    t = (await _call(ws, "/rosapi/get_time"))["time"]
    assert abs(t["sec"] - time.time()) < 60
    assert 0 <= t["nanosec"] < 1_000_000_000
    assert (t["secs"], t["nsecs"]) == (t["sec"], t["nanosec"])


async def test_get_ros_version(ws_connect: Any) -> None:
    """/rosapi/get_ros_version says ROS 2 Jazzy."""
    ws = await ws_connect()
    assert await _call(ws, "/rosapi/get_ros_version") == {"version": 2, "distro": "jazzy"}


async def test_rosapi_bad_args(ws_connect: Any) -> None:
    """A rosapi call missing its request field fails with result false naming the field."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/topic_type", "args": {}, "id": "b"})
    reply = await ws.expect(op="service_response", id="b")
    assert reply["result"] is False and "'topic'" in reply["values"]


async def test_rosapi_unknown_field_named(ws_connect: Any) -> None:
    """A rosapi call with a field its request lacks names that field and the real ones."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/topic_type",
                   "args": {"topik": "/a"}, "id": "u"})
    reply = await ws.expect(op="service_response", id="u")
    assert reply["result"] is False
    assert "args.topik" in reply["values"] and "topic" in reply["values"]


async def test_services_lists_only_served_names(ws_connect: Any, topic: str) -> None:
    """A call to a service nobody serves does not make /rosapi/services list it."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": topic, "type": "std_srvs/SetBool",
                   "id": "nobody", "timeout": 0.5})
    reply = await ws.expect(op="service_response", id="nobody")
    assert reply["result"] is False and "does not exist" in reply["values"]
    assert topic not in (await _call(ws, "/rosapi/services"))["services"]
    assert await _call(ws, "/rosapi/service_type", {"service": topic}) == {"type": ""}


async def test_message_details(ws_connect: Any) -> None:
    """/rosapi/message_details gives the typedef of a type, then of its nested types."""
    ws = await ws_connect()
    values = await _call(ws, "/rosapi/message_details", {"type": "geometry_msgs/PoseWithCovariance"})
    typedefs = {t["type"]: t for t in values["typedefs"]}
    top = values["typedefs"][0]
    assert top["type"] == "geometry_msgs/msg/PoseWithCovariance"
    assert top["fieldnames"] == ["pose", "covariance"]
    assert top["fieldtypes"] == ["geometry_msgs/msg/Pose", "double"]
    assert top["fieldarraylen"] == [-1, 36]
    assert typedefs["geometry_msgs/msg/Point"]["fieldnames"] == ["x", "y", "z"]
    status = await _call(ws, "/rosapi/message_details", {"type": "action_msgs/msg/GoalStatus"})
    first = status["typedefs"][0]
    assert first["constvalues"][first["constnames"].index("STATUS_SUCCEEDED")] == "4"


async def test_service_request_and_response_details(ws_connect: Any) -> None:
    """/rosapi/service_request_details and _response_details describe the two halves."""
    ws = await ws_connect()
    req = await _call(ws, "/rosapi/service_request_details", {"type": "std_srvs/srv/SetBool"})
    assert req["typedefs"][0]["fieldnames"] == ["data"]
    resp = await _call(ws, "/rosapi/service_response_details", {"type": "std_srvs/SetBool"})
    assert resp["typedefs"][0]["fieldnames"] == ["success", "message"]
    assert resp["typedefs"][0]["fieldtypes"] == ["boolean", "string"]


async def test_message_details_unknown_type(ws_connect: Any) -> None:
    """/rosapi/message_details of an unknown type fails naming it."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/message_details",
                   "args": {"type": "nope_msgs/Nothing"}, "id": "md"})
    reply = await ws.expect(op="service_response", id="md")
    assert reply["result"] is False and "nope_msgs/Nothing" in reply["values"]


async def test_params_get_set_names(ws_connect: Any, ros_node: Any) -> None:
    """Node parameters are listed, read and written as /node:param with JSON text values (a
    byte array as its numbers)."""
    ros_node.declare_parameter("speed", 1.5)
    ros_node.declare_parameter("names", ["a", "b"])
    ros_node.declare_parameter("blob", [b"h", b"i"])
    full = _fq(ros_node)
    ws = await ws_connect()
    await _until(ws, "/rosapi/get_param_names", None,
                 lambda v: f"{full}:speed" in v["names"], timeout=20)
    got = await _call(ws, "/rosapi/get_param", {"name": f"{full}:speed"})
    assert json.loads(got["value"]) == 1.5 and got["successful"] is True
    names = await _call(ws, "/rosapi/get_param", {"name": f"{full}:names"})
    assert json.loads(names["value"]) == ["a", "b"]
    blob = await _call(ws, "/rosapi/get_param", {"name": f"{full}:blob"})
    assert json.loads(blob["value"]) == [104, 105]
    await _call(ws, "/rosapi/set_param", {"name": f"{full}:speed", "value": "2.25"})
    assert ros_node.get_parameter("speed").value == 2.25
    assert (await _call(ws, "/rosapi/has_param", {"name": f"{full}:speed"}))["exists"] is True
    assert (await _call(ws, "/rosapi/has_param", {"name": f"{full}:nope"}))["exists"] is False
    missing = await _call(ws, "/rosapi/get_param", {"name": f"{full}:nope", "default_value": "7"})
    assert missing["value"] == "7"


async def test_set_param_refused_names_param(ws_connect: Any, ros_node: Any) -> None:
    """A value of the wrong type is refused by the node; the failure names the parameter."""
    ros_node.declare_parameter("count", 3)
    full = _fq(ros_node)
    ws = await ws_connect()
    await _until(ws, "/rosapi/get_param_names", None,
                 lambda v: f"{full}:count" in v["names"], timeout=20)
    await ws.send({"op": "call_service", "service": "/rosapi/set_param", "id": "sp",
                   "args": {"name": f"{full}:count", "value": '"text"'}})
    reply = await ws.expect(op="service_response", id="sp")
    assert reply["result"] is False and f"{full}:count" in reply["values"]


async def test_topics_and_raw_types(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """/rosapi/topics_and_raw_types gives each topic's full definition text, dependencies too."""
    from geometry_msgs.msg import PoseStamped

    ros_node.create_publisher(PoseStamped, topic, 10)
    ws = await ws_connect()
    values = await _until(ws, "/rosapi/topics_and_raw_types", None,
                          lambda v: topic in v["topics"])
    assert len(values["topics"]) == len(values["types"]) == len(values["typedefs_full_text"])
    text = values["typedefs_full_text"][values["topics"].index(topic)]
    assert "std_msgs/Header header" in text
    assert "MSG: geometry_msgs/msg/Point" in text and "float64 x" in text
