"""The /rosapi/* introspection services a session answers from its Graph, in memory (moved
from tests/bridge/test_rosapi.py, which keeps what needs rclpy).

The other node is the bench's robot (``/robot``); the bridge's own node is ``/rosbridge``.
The in-memory graph knows each change at once, so no test polls for discovery.
"""

from __future__ import annotations

import json
import time
from typing import Any

from rosbridge_core.memory.graph import MemoryRos
from tests.op_peer import rosapi, roundtrip
from tests.session.harness import Bench, Robot

BRIDGE = "/rosbridge"
ROBOT = "/robot"


async def test_topics_lists_names_and_types(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/topics lists every topic with its type at the same index."""
    robot.advertise(topic, "std_msgs/msg/String")
    ws = await ws_connect()
    values = await rosapi(ws, "/rosapi/topics")
    assert len(values["topics"]) == len(values["types"])
    assert values["types"][values["topics"].index(topic)] == "std_msgs/msg/String"


async def test_topics_for_type_both_spellings(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/topics_for_type finds topics by type, in either spelling."""
    robot.advertise(topic, "std_msgs/msg/String")
    ws = await ws_connect()
    full = await rosapi(ws, "/rosapi/topics_for_type", {"type": "std_msgs/msg/String"})
    assert topic in full["topics"]
    short = await rosapi(ws, "/rosapi/topics_for_type", {"type": "std_msgs/String"})
    assert topic in short["topics"]


async def test_topic_type(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/topic_type answers the type, or "" for an unknown topic; args may be a list."""
    robot.advertise(topic, "std_msgs/msg/String")
    ws = await ws_connect()
    assert await rosapi(ws, "/rosapi/topic_type", {"topic": topic}) == {
        "type": "std_msgs/msg/String"}
    assert (await rosapi(ws, "/rosapi/topic_type", [topic]))["type"] == "std_msgs/msg/String"
    assert await rosapi(ws, "/rosapi/topic_type", {"topic": topic + "_none"}) == {"type": ""}


async def test_services_include_ros_and_rosapi(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/services lists ROS services and the bridge's own rosapi services."""
    robot.serve(topic, "std_srvs/srv/SetBool", lambda a: {})
    ws = await ws_connect()
    values = await rosapi(ws, "/rosapi/services")
    assert topic in values["services"]
    for name in ("/rosapi/topics", "/rosapi/services", "/rosapi/nodes", "/rosapi/get_time"):
        assert name in values["services"]


async def test_service_type_and_services_for_type(ws_connect: Any, robot: Robot,
                                                  topic: str) -> None:
    """/rosapi/service_type and /rosapi/services_for_type agree on a ROS service's type."""
    robot.serve(topic, "std_srvs/srv/SetBool", lambda a: {})
    ws = await ws_connect()
    assert await rosapi(ws, "/rosapi/service_type", {"service": topic}) == {
        "type": "std_srvs/srv/SetBool"}
    found = await rosapi(ws, "/rosapi/services_for_type", {"type": "std_srvs/SetBool"})
    assert topic in found["services"]
    own = await rosapi(ws, "/rosapi/service_type", {"service": "/rosapi/topics"})
    assert own == {"type": "rosapi_msgs/srv/Topics"}


async def test_service_node(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/service_node names the node serving a service."""
    robot.serve(topic, "std_srvs/srv/SetBool", lambda a: {})
    ws = await ws_connect()
    assert await rosapi(ws, "/rosapi/service_node", {"service": topic}) == {"node": ROBOT}


async def test_service_node_of_a_client_served_service(ws_connect: Any, topic: str) -> None:
    """/rosapi/service_node names the bridge's node for a service one of its clients serves."""
    server = await ws_connect()
    await server.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
    ws = await ws_connect()
    await roundtrip(server)  # the advertise has been handled
    values = await rosapi(ws, "/rosapi/service_node", {"service": topic})
    assert values == {"node": BRIDGE}


async def test_node_details(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/node_details lists a node's publications, subscriptions and services."""
    robot.advertise(topic + "_out", "std_msgs/msg/String")
    robot.hear(topic + "_in", "std_msgs/msg/String")
    robot.serve(topic + "_srv", "std_srvs/srv/SetBool", lambda a: {})
    ws = await ws_connect()
    assert ROBOT in (await rosapi(ws, "/rosapi/nodes"))["nodes"]
    values = await rosapi(ws, "/rosapi/node_details", {"node": ROBOT})
    assert topic + "_srv" in values["services"]
    assert topic + "_out" in values["publishing"]
    assert topic + "_in" in values["subscribing"]


async def test_node_details_unknown_node_fails(ws_connect: Any) -> None:
    """/rosapi/node_details for a node not in the graph fails with result false naming it."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/node_details",
                   "args": {"node": "/no/such_node"}, "id": "nd"})
    reply = await ws.expect(op="service_response", id="nd")
    assert reply["result"] is False and "/no/such_node" in reply["values"]


async def test_publishers_and_subscribers(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/publishers and /rosapi/subscribers name the nodes on each side of a topic."""
    robot.advertise(topic, "std_msgs/msg/String")
    ws = await ws_connect()
    assert await rosapi(ws, "/rosapi/publishers", {"topic": topic}) == {"publishers": [ROBOT]}
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    assert BRIDGE in (await rosapi(ws, "/rosapi/subscribers", {"topic": topic}))["subscribers"]


async def test_action_servers(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/action_servers lists actions served in the graph."""
    node = robot.node
    node.serve_action(topic, node.resolve_action("test_msgs/action/Fibonacci"),
                      lambda goal: None, lambda goal: None)
    ws = await ws_connect()
    assert topic in (await rosapi(ws, "/rosapi/action_servers"))["action_servers"]


async def test_get_time(ws_connect: Any) -> None:
    """/rosapi/get_time gives the bridge clock as {sec, nanosec} (plus ROS 1 secs, nsecs)."""
    ws = await ws_connect()
    t = (await rosapi(ws, "/rosapi/get_time"))["time"]
    assert abs(t["sec"] - time.time()) < 60
    assert 0 <= t["nanosec"] < 1_000_000_000
    assert (t["secs"], t["nsecs"]) == (t["sec"], t["nanosec"])


async def test_get_ros_version(ws_connect: Any) -> None:
    """/rosapi/get_ros_version says ROS 2 Jazzy."""
    ws = await ws_connect()
    assert await rosapi(ws, "/rosapi/get_ros_version") == {"version": 2, "distro": "jazzy"}


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
    assert topic not in (await rosapi(ws, "/rosapi/services"))["services"]
    assert await rosapi(ws, "/rosapi/service_type", {"service": topic}) == {"type": ""}


async def test_message_details(ws_connect: Any) -> None:
    """/rosapi/message_details gives the typedef of a type, then of its nested types."""
    ws = await ws_connect()
    values = await rosapi(ws, "/rosapi/message_details",
                          {"type": "geometry_msgs/PoseWithCovariance"})
    typedefs = {t["type"]: t for t in values["typedefs"]}
    top = values["typedefs"][0]
    assert top["type"] == "geometry_msgs/msg/PoseWithCovariance"
    assert top["fieldnames"] == ["pose", "covariance"]
    assert top["fieldtypes"] == ["geometry_msgs/msg/Pose", "double"]
    assert top["fieldarraylen"] == [-1, 36]
    assert typedefs["geometry_msgs/msg/Point"]["fieldnames"] == ["x", "y", "z"]
    status = await rosapi(ws, "/rosapi/message_details", {"type": "action_msgs/msg/GoalStatus"})
    first = status["typedefs"][0]
    assert first["constvalues"][first["constnames"].index("STATUS_SUCCEEDED")] == "4"


async def test_service_request_and_response_details(ws_connect: Any) -> None:
    """/rosapi/service_request_details and _response_details describe the two halves."""
    ws = await ws_connect()
    req = await rosapi(ws, "/rosapi/service_request_details", {"type": "std_srvs/srv/SetBool"})
    assert req["typedefs"][0]["fieldnames"] == ["data"]
    resp = await rosapi(ws, "/rosapi/service_response_details", {"type": "std_srvs/SetBool"})
    assert resp["typedefs"][0]["fieldnames"] == ["success", "message"]
    assert resp["typedefs"][0]["fieldtypes"] == ["boolean", "string"]


async def test_message_details_unknown_type(ws_connect: Any) -> None:
    """/rosapi/message_details of an unknown type fails naming it."""
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/message_details",
                   "args": {"type": "nope_msgs/Nothing"}, "id": "md"})
    reply = await ws.expect(op="service_response", id="md")
    assert reply["result"] is False and "nope_msgs/Nothing" in reply["values"]


def _parameter_node(bench: Bench, params: dict[str, Any]) -> str:
    ros: MemoryRos = bench.server.ros
    ros.node("tuned", parameters=params)
    return "/tuned"


async def test_params_get_set_names(ws_connect: Any, bench: Bench) -> None:
    """Node parameters are listed, read and written as /node:param with JSON text values."""
    full = _parameter_node(bench, {"speed": 1.5, "names": ["a", "b"]})
    ws = await ws_connect()
    assert f"{full}:speed" in (await rosapi(ws, "/rosapi/get_param_names"))["names"]
    got = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:speed"})
    assert json.loads(got["value"]) == 1.5 and got["successful"] is True
    names = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:names"})
    assert json.loads(names["value"]) == ["a", "b"]
    await rosapi(ws, "/rosapi/set_param", {"name": f"{full}:speed", "value": "2.25"})
    again = await rosapi(ws, "/rosapi/get_param", {"name": f"{full}:speed"})
    assert json.loads(again["value"]) == 2.25
    assert (await rosapi(ws, "/rosapi/has_param", {"name": f"{full}:speed"}))["exists"] is True
    assert (await rosapi(ws, "/rosapi/has_param", {"name": f"{full}:nope"}))["exists"] is False
    missing = await rosapi(ws, "/rosapi/get_param",
                           {"name": f"{full}:nope", "default_value": "7"})
    assert missing["value"] == "7"


async def test_set_param_refused_names_param(ws_connect: Any, bench: Bench) -> None:
    """A value of the wrong type is refused by the node; the failure names the parameter."""
    full = _parameter_node(bench, {"count": 3})
    ws = await ws_connect()
    await ws.send({"op": "call_service", "service": "/rosapi/set_param", "id": "sp",
                   "args": {"name": f"{full}:count", "value": '"text"'}})
    reply = await ws.expect(op="service_response", id="sp")
    assert reply["result"] is False and f"{full}:count" in reply["values"]


async def test_topics_and_raw_types(ws_connect: Any, robot: Robot, topic: str) -> None:
    """/rosapi/topics_and_raw_types gives each topic's full definition text, dependencies too."""
    robot.advertise(topic, "geometry_msgs/msg/PoseStamped")
    ws = await ws_connect()
    values = await rosapi(ws, "/rosapi/topics_and_raw_types")
    assert len(values["topics"]) == len(values["types"]) == len(values["typedefs_full_text"])
    text = values["typedefs_full_text"][values["topics"].index(topic)]
    assert "std_msgs/Header header" in text
    assert "MSG: geometry_msgs/msg/Point" in text and "float64 x" in text
