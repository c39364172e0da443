"""The stock Foxglove client's handshake, subscribing, publishing, service calls and parameters against our bridge."""

from __future__ import annotations

import base64
import queue
import time
from typing import Any

from tests.helpers import BridgeProcess, wait_until
from tests.peers import scenarios
from tests.peers.foxglove.support import (
    DEADLINE,
    _errors,
    _messages,
    _parameter_values,
    _publish_until_seen,
    _schema,
    _update,
)
from tests.peers.peer import PeerPool, PeerProcess

# -- the handshake -------------------------------------------------------------------------------


def test_server_info(fox: PeerProcess) -> None:
    """The client offering foxglove.websocket.v1 gets it, and a serverInfo with what we do."""
    assert fox.info["protocol"] == "foxglove.websocket.v1"
    info = fox.info["serverInfo"]
    assert {"clientPublish", "parameters", "parametersSubscribe", "services",
            "connectionGraph"} <= set(info["capabilities"])
    assert "assets" not in info["capabilities"]
    assert info["supportedEncodings"] == ["cdr", "json"]


def test_channels_have_full_schemas(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """An rclpy publisher's topic is advertised as a cdr channel with the ros2msg definition
    text, its dependencies included."""
    from sensor_msgs.msg import Image

    ros_node.create_publisher(Image, topic, 10)
    channel = fox.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    assert channel["encoding"] == "cdr"
    assert channel["schemaEncoding"] == "ros2msg"
    assert channel["schemaName"] == "sensor_msgs/msg/Image"
    schema = channel["schema"]
    assert "uint32 height" in schema
    # dependencies as the fields name them, the spelling @foxglove/rosmsg matches
    assert "MSG: std_msgs/Header" in schema and "MSG: builtin_interfaces/Time" in schema


def test_channel_goes_with_its_topic(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """When the last publisher of a topic goes, the client is told the channel went."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    channel = fox.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    ros_node.destroy_publisher(pub)
    fox.wait_event(lambda e: e.get("event") == "unadvertise"
                   and channel["id"] in e["channelIds"], DEADLINE, "unadvertise")


# -- subscribing ---------------------------------------------------------------------------------


def test_subscribe_image(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A 640x480 rgb8 Image arrives as CDR that the client decodes to what rclpy published."""
    from sensor_msgs.msg import Image

    pub = ros_node.create_publisher(Image, topic, 10)
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    img = Image(height=480, width=640, encoding="rgb8", step=640 * 3, is_bigendian=0)
    img.header.frame_id = "camera"
    img.header.stamp.sec, img.header.stamp.nanosec = 12, 345
    pixels = bytes(i * 7 % 251 for i in range(640 * 480 * 3))
    img.data = pixels
    event = _publish_until_seen(fox, pub, topic, img)
    msg = event["msg"]
    assert msg["header"] == {"stamp": {"sec": 12, "nanosec": 345}, "frame_id": "camera"}
    assert (msg["height"], msg["width"], msg["encoding"], msg["step"]) == (480, 640, "rgb8",
                                                                            1920)
    assert base64.b64decode(msg["data"]["$bytes"]) == pixels
    stamp = int(event["timestamp"]["$bigint"])  # the receive time, in ns
    assert abs(stamp - time.time_ns()) < 60 * 10**9


def test_subscribe_imu(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """An Imu (nested messages, float64[9] covariances) decodes to rclpy's numbers."""
    from sensor_msgs.msg import Imu

    pub = ros_node.create_publisher(Imu, topic, 10)
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    imu = Imu()
    imu.header.frame_id = "imu_link"
    imu.orientation.x, imu.orientation.w = 0.25, 0.75
    imu.angular_velocity.z = -1.5
    imu.linear_acceleration.z = 9.81
    imu.orientation_covariance = [float(i) / 8 for i in range(9)]
    msg = _publish_until_seen(fox, pub, topic, imu)["msg"]
    assert msg["header"]["frame_id"] == "imu_link"
    assert msg["orientation"] == {"x": 0.25, "y": 0.0, "z": 0.0, "w": 0.75}
    assert msg["angular_velocity"]["z"] == -1.5
    assert msg["linear_acceleration"]["z"] == 9.81
    assert msg["orientation_covariance"]["values"] == [float(i) / 8 for i in range(9)]


def test_unsubscribe(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """After unsubscribe the bridge drops its ROS subscription of the topic."""
    from std_msgs.msg import String

    pub = ros_node.create_publisher(String, topic, 10)
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    _publish_until_seen(fox, pub, topic, String(data="x"))
    fox.request("unsubscribe", topic=topic)
    wait_until(lambda: pub.get_subscription_count() == 0, DEADLINE, "the bridge to unsubscribe")


# -- publishing, services, parameters ----------------------------------------------------------


def test_client_publishes(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """clientAdvertise and binary CDR message data reach an rclpy subscriber."""
    from geometry_msgs.msg import Twist

    inbox: queue.Queue[Any] = queue.Queue()
    ros_node.create_subscription(Twist, topic, inbox.put, 10)
    fox.request("advertise", topic=topic, schemaName="geometry_msgs/msg/Twist",
                schema=_schema("geometry_msgs/msg/Twist"))
    sent = {"linear": {"x": 1.5, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": -0.5}}
    deadline = time.monotonic() + DEADLINE
    got = None
    while got is None and time.monotonic() < deadline:
        fox.request("publish", topic=topic, msg=sent)
        try:
            got = inbox.get(timeout=scenarios.ATTEMPT)
        except queue.Empty:
            assert not _errors(fox), _errors(fox)
    assert got is not None, fox.diagnostics()
    assert (got.linear.x, got.angular.z) == (1.5, -0.5)
    fox.request("unadvertise", topic=topic)


def test_call_service(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """An rclpy SetBool service is advertised, and a CDR call gets its CDR answer."""
    from std_srvs.srv import SetBool

    def answer(request: Any, response: Any) -> Any:
        response.success = request.data
        response.message = f"rclpy got {request.data}"
        return response

    ros_node.create_service(SetBool, topic, answer)
    service = fox.request("service", service=topic, timeout_ms=int(DEADLINE * 1000))
    assert service["type"] == "std_srvs/srv/SetBool"
    assert service["request"]["schemaName"] == "std_srvs/srv/SetBool_Request"
    reply = fox.request("call_service", service=topic, request={"data": True},
                        timeout=DEADLINE)
    assert reply == {"encoding": "cdr", "value": {"success": True, "message": "rclpy got True"}}


def test_what_goes_is_withdrawn(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A service whose server goes is unadvertised to the client; a client channel it
    unadvertises takes the bridge's ROS publisher with it."""
    from std_srvs.srv import SetBool

    server = ros_node.create_service(SetBool, topic + "_srv", lambda req, res: res)
    service = fox.request("service", service=topic + "_srv", timeout_ms=int(DEADLINE * 1000))
    ros_node.destroy_service(server)
    fox.wait_event(lambda e: e.get("event") == "unadvertiseServices"
                   and service["id"] in e["serviceIds"], DEADLINE, "unadvertiseServices")
    fox.request("advertise", topic=topic, schemaName="std_msgs/msg/String",
                schema=_schema("std_msgs/msg/String"))
    wait_until(lambda: ros_node.count_publishers(topic) == 1, DEADLINE, "the bridge's publisher")
    fox.request("unadvertise", topic=topic)
    wait_until(lambda: ros_node.count_publishers(topic) == 0, DEADLINE,
               "the bridge's publisher to go")


def test_parameters(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A node's parameters of every type are read as the spec has them (one by one and all
    at once), set (the node sees it) and followed (/node.param names); a byte array reads,
    sets and follows as base64 text typed byte_array, whoever set it."""
    from rclpy.parameter import Parameter

    prefix = topic.strip("/").replace("/", "_") + "_"
    declared = scenarios.declare_foxglove_parameters(ros_node, prefix)
    names = [name for name, _ in declared]
    entries = [entry for _, entry in declared]
    full, blob = (f"{ros_node.get_fully_qualified_name()}.{prefix}{short}"
                  for short in ("gain", "blob"))
    try:
        fox.request("subscribe_parameters", names=[full, blob])
        deadline = time.monotonic() + DEADLINE
        n = 0
        while not (values := _parameter_values(fox, f"get{n}", "get_parameters", names=names)):
            assert time.monotonic() < deadline, "the bridge never saw the node"
            n += 1  # until the bridge sees the node (no event)
        assert values == entries
        every = _parameter_values(fox, "all", "get_parameters", names=[])
        assert [p for p in every if p["name"] in names] == entries
        assert _parameter_values(fox, "set1", "set_parameters", parameters=[
            {"name": full, "value": 3, "type": "float64"}]) == [
            {"name": full, "value": 3.0, "type": "float64"}]
        assert ros_node.get_parameter(prefix + "gain").value == 3.0
        _update(fox, {"name": full, "value": 3.0, "type": "float64"})
        hi = {"name": blob, "value": "aGk=", "type": "byte_array"}
        assert _parameter_values(fox, "set2", "set_parameters", parameters=[hi]) == [hi]
        assert ros_node.get_parameter(prefix + "blob").value == [b"h", b"i"]
        _update(fox, hi)
        by_ros = Parameter(prefix + "blob", Parameter.Type.BYTE_ARRAY,  # type: ignore[no-untyped-call]
                           [b"r", b"o", b"s"])
        ros_node.set_parameters([by_ros])
        ros = {"name": blob, "value": "cm9z", "type": "byte_array"}
        _update(fox, ros)
        assert _parameter_values(fox, "get_blob", "get_parameters", names=[blob]) == [ros]
    finally:
        for name, _, _ in scenarios.FOXGLOVE_PARAMETERS:
            ros_node.undeclare_parameter(prefix + name)


def test_connection_graph(fox: PeerProcess, ros_node: Any, topic: str) -> None:
    """A connection graph update names the rclpy node publishing a topic."""
    from std_msgs.msg import String

    ros_node.create_publisher(String, topic, 10)
    fox.request("wait_channel", topic=topic, timeout_ms=int(DEADLINE * 1000))
    fox.request("subscribe_graph")
    me = f"/{ros_node.get_name()}"
    fox.wait_event(lambda e: e.get("event") == "connectionGraphUpdate" and any(
        t["name"] == topic and me in t["publisherIds"]
        for t in e["update"]["publishedTopics"]), DEADLINE, "a graph update with the topic")


def test_rosbridge_and_foxglove_at_once(fox: PeerProcess, peer_pool: PeerPool, ros_node: Any,
                                        topic: str, bridge: BridgeProcess) -> None:
    """A roslib client and a Foxglove client on one bridge get the same topic each their way,
    and the status page lists each with its protocol."""
    import json
    import urllib.request

    from std_msgs.msg import String

    roslib = peer_pool.get("roslib")
    pub = ros_node.create_publisher(String, topic, 10)
    roslib.request("subscribe", topic=topic, type="std_msgs/msg/String")
    fox.request("subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000))
    deadline = time.monotonic() + DEADLINE
    while time.monotonic() < deadline and not (
            _messages(fox, topic) and [e for e in roslib.new_events()
                                       if e.get("event") == "message"]):
        pub.publish(String(data="both"))
        time.sleep(scenarios.ATTEMPT)  # publish again until both were matched (DDS)
    assert _messages(fox, topic)[0]["msg"] == {"data": "both"}
    assert next(e for e in roslib.new_events() if e.get("event") == "message")["msg"] == {
        "data": "both"}
    with urllib.request.urlopen(bridge.url.replace("ws:", "http:") + "/status.json",
                                timeout=DEADLINE) as response:
        status = json.load(response)
    protocols = {c["protocol"] for c in status["clients"]}
    assert {"rosbridge", "foxglove"} <= protocols
