"""rosapi scenarios: topics, types, services, nodes, publishers, action servers, time, parameters
and message/service details asked through a stock client.
"""

from __future__ import annotations

import math
import time
from typing import Any

from tests.helpers import wait_until
from tests.peers.peer import PeerProcess
from tests.peers.scenarios.support import (
    DEADLINE,
    _module,
    _own_group,
    _topics,
)

# -- rosapi (introspection) -------------------------------------------------------------------


def get_topics(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's topic list names an rclpy publisher's topic (with its type where given)."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)

    def listed() -> Any:
        topics, types = _topics(peer.request("get_topics"))
        return (topics, types) if topic in topics else None

    topics, types = wait_until(listed, DEADLINE, f"{topic} in get_topics")
    if types is not None:  # roslib: the rosapi answer as is, types alongside
        assert len(types) == len(topics)
        assert types[topics.index(topic)] == "std_msgs/msg/String"
    else:  # roslibpy returns the names only; its way to the type is get_topic_type
        assert peer.request("get_topic_type", topic=topic) == "std_msgs/msg/String"


def get_topic_type(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer learns an rclpy topic's type, and the topics of that type include it."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)
    wait_until(lambda: peer.request("get_topic_type", topic=topic), DEADLINE, f"type of {topic}")
    assert peer.request("get_topic_type", topic=topic) == "std_msgs/msg/String"
    assert topic in peer.request("get_topics_for_type", type="std_msgs/msg/String")


def get_services(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's service list names an rclpy service; its type and same-type list agree."""
    from std_srvs.srv import SetBool

    node.create_service(SetBool, topic, lambda _req, resp: resp)
    wait_until(lambda: topic in peer.request("get_services"), DEADLINE, f"{topic} in get_services")
    assert peer.request("get_service_type", service=topic) == "std_srvs/srv/SetBool"
    assert topic in peer.request("get_services_for_type", type="std_srvs/srv/SetBool")


def get_nodes(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's node list names the rclpy node; its details list what it publishes and serves."""
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    node.create_publisher(String, topic, 10)
    node.create_service(SetBool, topic + "_srv", lambda _req, resp: resp)
    fqn = node.get_fully_qualified_name()
    wait_until(lambda: fqn in peer.request("get_nodes"), DEADLINE, f"{fqn} in get_nodes")

    def detailed() -> Any:
        details = peer.request("get_node_details", node=fqn)
        ok = topic in details["publishing"] and topic + "_srv" in details["services"]
        return details if ok else None

    wait_until(detailed, DEADLINE, f"{topic} and {topic}_srv in node details of {fqn}")


# -- parameters and type details through rosapi -----------------------------------------------


def params(peer: PeerProcess, node: Any) -> None:
    """The peer lists, reads and sets an rclpy node's parameter as "node:param"."""
    param = f"speed_{peer.name.replace('-', '_')}"  # the node is shared by a module's tests
    node.declare_parameter(param, 1.5)
    name = f"{node.get_fully_qualified_name()}:{param}"
    wait_until(lambda: name in peer.request("get_params"), DEADLINE, f"{name} in get_params")
    assert peer.request("get_param", name=name) == 1.5
    peer.request("set_param", name=name, value=2.5)
    assert node.get_parameter(param).value == 2.5
    assert peer.request("get_param", name=name) == 2.5


FOXGLOVE_PARAMETERS: list[tuple[str, Any, dict[str, Any]]] = [
    ("flag", True, {"value": True}),
    ("count", 7, {"value": 7}),
    ("gain", 1.5, {"value": 1.5, "type": "float64"}),
    ("whole", 2.0, {"value": 2.0, "type": "float64"}),
    ("label", "hi", {"value": "hi"}),
    ("blob", [b"\x00", b"\xff", b"h"], {"value": "AP9o", "type": "byte_array"}),
    ("flags", [True, False], {"value": [True, False]}),
    ("counts", [1, 2], {"value": [1, 2]}),
    ("gains", [1.5, 2.0], {"value": [1.5, 2.0], "type": "float64_array"}),
    ("labels", ["a", "b"], {"value": ["a", "b"]}),
    ("odd", math.inf, {"value": "inf"}),
    ("odds", [1.0, math.nan], {"value": [1.0, "nan"]}),
]


def declare_foxglove_parameters(node: Any, prefix: str) -> list[tuple[str, dict[str, Any]]]:
    """Declare :data:`FOXGLOVE_PARAMETERS` on ``node`` as ``prefix`` + name; each one's
    Foxglove name (``/node.param``) and the entry a client must get for it."""
    full = node.get_fully_qualified_name()
    for name, value, _ in FOXGLOVE_PARAMETERS:
        node.declare_parameter(prefix + name, value)
    return [(f"{full}.{prefix}{name}", {"name": f"{full}.{prefix}{name}", **entry})
            for name, _, entry in FOXGLOVE_PARAMETERS]


def message_details(peer: PeerProcess) -> None:
    """The peer gets rosapi typedefs for geometry_msgs/Twist, nested Vector3 included."""
    value = peer.request("get_message_details", type="geometry_msgs/Twist")
    typedefs = value["typedefs"]
    assert typedefs[0]["type"].replace("/msg/", "/") == "geometry_msgs/Twist", "root type first"
    # rosapi on ROS 2 names primitives the IDL way ("double", "boolean"); ROS 1 said
    # "float64", "bool". Either is accepted here.
    f64 = typedefs[-1]["fieldtypes"][0]
    assert f64 in ("float64", "double"), typedefs
    if "decoded" in value:  # roslib's Ros.decodeTypeDefs walked them
        vector = {"x": f64, "y": f64, "z": f64}
        assert value["problems"] == []
        assert value["decoded"] == {"linear": vector, "angular": vector}
    by_type = {td["type"].replace("/msg/", "/"): td for td in typedefs}
    twist = by_type["geometry_msgs/Twist"]
    assert twist["fieldnames"] == ["linear", "angular"]
    assert [t.replace("/msg/", "/") for t in twist["fieldtypes"]] == ["geometry_msgs/Vector3"] * 2
    vector = by_type["geometry_msgs/Vector3"]
    assert vector["fieldnames"] == ["x", "y", "z"]
    assert vector["fieldtypes"] == [f64] * 3


def service_details(peer: PeerProcess) -> None:
    """The peer gets typedefs for the request and the response part of std_srvs/SetBool."""
    request = peer.request("get_service_request_details", type="std_srvs/srv/SetBool")
    response = peer.request("get_service_response_details", type="std_srvs/srv/SetBool")
    req_def, resp_def = request["typedefs"][0], response["typedefs"][0]
    boolean = req_def["fieldtypes"][0]
    assert boolean in ("bool", "boolean"), req_def  # ROS 1 / ROS 2 (IDL) spelling
    assert (req_def["fieldnames"], req_def["fieldtypes"]) == (["data"], [boolean])
    assert (resp_def["fieldnames"], resp_def["fieldtypes"]) == (
        ["success", "message"], [boolean, "string"],
    )


def topics_and_raw_types(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer gets each topic with its type and the type's full definition text."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)

    def listed() -> Any:
        value = peer.request("get_topics_and_raw_types")
        return value if topic in value["topics"] else None

    value = wait_until(listed, DEADLINE, f"{topic} in topics_and_raw_types")
    i = value["topics"].index(topic)
    assert len(value["topics"]) == len(value["types"]) == len(value["typedefs_full_text"])
    assert value["types"][i] == "std_msgs/msg/String"
    assert "string data" in value["typedefs_full_text"][i]


# -- more rosapi -------------------------------------------------------------------------------


def get_action_servers(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer's action server list names an rclpy action server."""
    from test_msgs.action import Fibonacci

    server = _module("rclpy.action").ActionServer(
        node, Fibonacci, topic, lambda gh: None, callback_group=_own_group()
    )
    try:
        wait_until(lambda: topic in peer.request("get_action_servers"), DEADLINE,
                   f"{topic} in get_action_servers")
    finally:
        server.destroy()


def get_publishers(peer: PeerProcess, node: Any, topic: str) -> None:
    """Topic.getPublishers() names the rclpy node that publishes the topic."""
    from std_msgs.msg import String

    node.create_publisher(String, topic, 10)
    fqn = node.get_fully_qualified_name()
    wait_until(lambda: fqn in peer.request("get_publishers", topic=topic, type="std_msgs/String"),
               DEADLINE, f"{fqn} among the publishers of {topic}")


def get_time(peer: PeerProcess) -> None:
    """Ros.get_time() returns the bridge's clock as a roslibpy Time (secs/nsecs)."""
    value = peer.request("get_time")
    assert isinstance(value["secs"], int) and 0 <= value["nsecs"] < 1_000_000_000
    assert abs(value["secs"] - time.time()) < 600, f"not the system clock: {value}"
