"""Topic scenarios: publishing and subscribing through a stock client (plain, nested, latched,
best effort, large, in bursts, relative names, without a type), unsubscribing, unadvertising,
subscription options, and refused or unusual values.
"""

from __future__ import annotations

import base64
import math
import queue
from typing import Any

from tests.helpers import wait_until
from tests.peers.peer import PeerProcess
from tests.peers.scenarios.support import (
    ATTEMPT,
    DEADLINE,
    _latched_qos,
    _messages,
    _module,
    _publish_until_received,
    _refusal,
    _ros_publish_until_delivered,
    _status_about,
    _topics,
)

# -- topics -----------------------------------------------------------------------------------


def publish_string(peer: PeerProcess, node: Any, topic: str, type_name: str) -> None:
    """The peer advertises and publishes a std_msgs/String; an rclpy subscriber gets it."""
    from std_msgs.msg import String

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(String, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type=type_name)
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    text = f"hello from {peer.name} \u00e9\u4e16"
    got = _publish_until_received(peer, topic, type_name, {"data": text}, inbox)
    assert got.data == text


def publish_nested(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer publishes a geometry_msgs/Twist (nested float fields); rclpy sees the values."""
    from geometry_msgs.msg import Twist

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(Twist, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type="geometry_msgs/Twist")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    msg = {"linear": {"x": 0.5, "y": -1.25, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 3}}
    got = _publish_until_received(peer, topic, "geometry_msgs/Twist", msg, inbox)
    assert (got.linear.x, got.linear.y, got.linear.z) == (0.5, -1.25, 0.0)
    assert (got.angular.x, got.angular.y, got.angular.z) == (0.0, 0.0, 3.0)


def subscribe_string(peer: PeerProcess, node: Any, topic: str, type_name: str) -> None:
    """The peer subscribes; an rclpy publisher's std_msgs/String reaches it unchanged."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type=type_name)
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    text = f"hello to {peer.name} \u00e9\u4e16"
    got = _ros_publish_until_delivered(peer, pub, topic, String(data=text))
    assert got == {"data": text}


def subscribe_nested(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer gets a sensor_msgs/CompressedImage: header stamp as sec/nanosec, uint8[] as base64."""
    from sensor_msgs.msg import CompressedImage

    pub = node.create_publisher(CompressedImage, topic, 10)
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/CompressedImage")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    payload = bytes([0, 1, 2, 127, 128, 254, 255])
    msg = CompressedImage(format="png", data=payload)
    msg.header.frame_id = "camera"
    msg.header.stamp.sec = 1_700_000_000
    msg.header.stamp.nanosec = 123_456_789
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert got == {
        "header": {"stamp": {"sec": 1_700_000_000, "nanosec": 123_456_789}, "frame_id": "camera"},
        "format": "png",
        "data": base64.b64encode(payload).decode("ascii"),
    }


# -- more topic behaviour ---------------------------------------------------------------------


def unsubscribe(peer: PeerProcess, node: Any, topic: str) -> None:
    """After the peer unsubscribes, the bridge drops its ROS subscription."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    _ros_publish_until_delivered(peer, pub, topic, String(data="before"))
    peer.request("unsubscribe", topic=topic, type="std_msgs/msg/String")
    wait_until(lambda: pub.get_subscription_count() == 0, DEADLINE, "the bridge subscription to go")


def unadvertise(peer: PeerProcess, node: Any, topic: str) -> None:
    """After the peer unadvertises, the bridge's ROS publisher leaves the graph."""
    peer.request("advertise", topic=topic, type="std_msgs/String")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    peer.request("unadvertise", topic=topic, type="std_msgs/String")
    wait_until(lambda: node.count_publishers(topic) == 0, DEADLINE, "the bridge publisher to go")


def publish_latched(peer: PeerProcess, node: Any, topic: str) -> None:
    """A latched publish from the peer reaches a transient-local rclpy subscriber that joins later."""
    from std_msgs.msg import String

    peer.request("publish", topic=topic, type="std_msgs/String", msg={"data": "latched"}, latch=True)
    # A round trip on the same connection: the bridge has handled the publish before it answers.
    peer.request("get_topic_type", topic=topic)
    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(String, topic, inbox.put, _latched_qos())
    try:
        got = inbox.get(timeout=DEADLINE)
    except queue.Empty:
        raise AssertionError(
            f"a late transient-local subscriber never got the latched message\n{peer.diagnostics()}"
        ) from None
    assert got.data == "latched"


def subscribe_latched(peer: PeerProcess, node: Any, topic: str) -> None:
    """A peer subscribing late still gets the last message of a transient-local rclpy publisher."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, _latched_qos())
    pub.publish(String(data="the map"))
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    got = peer.wait_event(
        lambda e: e.get("event") == "message" and e.get("topic") == topic, DEADLINE,
        f"the latched message on {topic}",
    )
    assert got["msg"] == {"data": "the map"}


def bad_type_then_publish(peer: PeerProcess, node: Any, topic: str, sees_status: bool) -> None:
    """An unknown type is refused, and the same connection goes on publishing normally."""
    peer.request("publish", topic=topic + "_bad", type="nope_msgs/Nope", msg={"data": 1})
    if sees_status:
        status = peer.wait_event(
            lambda e: e.get("event") == "status" and e.get("about") == "advertise", DEADLINE,
            "a status about the refused advertise",
        )["msg"]
        assert status["level"] == "error"
        assert "nope_msgs/Nope" in status["msg"], status
    publish_string(peer, node, topic, "std_msgs/String")


# -- robustness through stock clients ---------------------------------------------------------


def publish_ros1_time_keys(peer: PeerProcess, node: Any, topic: str) -> None:
    """roslibpy.ros2.Header writes the stamp as secs/nsecs; rclpy gets the same time."""
    from geometry_msgs.msg import PoseStamped

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(PoseStamped, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type="geometry_msgs/PoseStamped")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    msg = {
        "header": {"stamp": {"secs": 1_700_000_001, "nsecs": 5}, "frame_id": "map"},
        "pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.0}, "orientation": {"w": 1.0}},
    }
    for _ in range(int(DEADLINE / ATTEMPT)):
        peer.request("publish", topic=topic, type="geometry_msgs/PoseStamped", msg=msg,
                     ros2_header=True)
        try:
            got = inbox.get(timeout=ATTEMPT)
            break
        except queue.Empty:
            continue
    else:
        raise AssertionError(f"rclpy never received the PoseStamped\n{peer.diagnostics()}")
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (1_700_000_001, 5)
    assert got.header.frame_id == "map"
    assert (got.pose.position.x, got.pose.position.y, got.pose.orientation.w) == (1.0, 2.0, 1.0)


def burst_in_order(peer: PeerProcess, node: Any, topic: str) -> None:
    """100 messages published back to back reach a reliable rclpy subscriber, all and in order."""
    from std_msgs.msg import Int32

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(Int32, topic, inbox.put, _module("rclpy.qos").QoSProfile(depth=1000))
    peer.request("advertise", topic=topic, type="std_msgs/Int32", queue_size=100)
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    _publish_until_received(peer, topic, "std_msgs/Int32", {"data": -1}, inbox)
    while not inbox.empty():  # later copies of the warm-up message
        inbox.get_nowait()
    seqs = [peer.send("publish", topic=topic, type="std_msgs/Int32", msg={"data": i})
            for i in range(100)]
    for seq in seqs:
        assert peer.reply(seq)["ok"]
    got: list[int] = []
    while len(got) < 100:
        try:
            data = inbox.get(timeout=DEADLINE).data
        except queue.Empty:
            raise AssertionError(f"only {len(got)} of 100 arrived: {got[-5:]}") from None
        if data != -1:
            got.append(data)
    assert got == list(range(100))


def publish_large(peer: PeerProcess, node: Any, topic: str) -> None:
    """A 1.5 MB sensor_msgs/Image (base64 data) published by the client reaches rclpy intact."""
    from sensor_msgs.msg import Image

    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(Image, topic, inbox.put, 10)
    peer.request("advertise", topic=topic, type="sensor_msgs/msg/Image")
    wait_until(lambda: node.count_publishers(topic) >= 1, DEADLINE, f"bridge publisher on {topic}")
    width, height = 800, 640
    pixels = bytes((i * 7) % 251 for i in range(width * height * 3))
    msg = {"height": height, "width": width, "encoding": "rgb8", "step": width * 3,
           "data": base64.b64encode(pixels).decode("ascii")}
    got = _publish_until_received(peer, topic, "sensor_msgs/msg/Image", msg, inbox)
    assert (got.width, got.height, got.encoding) == (width, height, "rgb8")
    assert bytes(got.data) == pixels


def subscribe_large(peer: PeerProcess, node: Any, topic: str) -> None:
    """A 1.5 MB sensor_msgs/Image from rclpy reaches the client, data as base64."""
    from sensor_msgs.msg import Image

    pub = node.create_publisher(Image, topic, 10)
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/Image")
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")
    width, height = 800, 640
    pixels = bytes((i * 13) % 251 for i in range(width * height * 3))
    msg = Image(height=height, width=width, encoding="rgb8", step=width * 3, data=pixels)
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert (got["width"], got["height"], got["encoding"]) == (width, height, "rgb8")
    assert base64.b64decode(got["data"]) == pixels


# -- subscriptions in detail, and refused input ----------------------------------------------


def two_subscriptions(
    peer: PeerProcess, node: Any, topic: str, unsubscribe_one: bool = True
) -> None:
    """Two Topic objects on one topic each get every message once; unsubscribing one keeps the other.

    roslibpy 2.1.0's ``Topic.unsubscribe`` removes every callback of the topic on
    its own side (``ros.off(name)``), so there the second half cannot be seen.
    """
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    for handle in ("a", "b"):
        peer.request("subscribe", topic=topic, type="std_msgs/msg/String", handle=handle)
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, f"bridge subscriber on {topic}")

    def both_got(data: str) -> bool:
        return _messages(peer, topic, "a", data) >= 1 and _messages(peer, topic, "b", data) >= 1

    for _ in range(int(DEADLINE / ATTEMPT)):  # until DDS has matched both ends
        pub.publish(String(data="warm-up"))
        try:
            wait_until(lambda: both_got("warm-up"), ATTEMPT, "warm-up on both")
            break
        except AssertionError:
            continue
    for data in ("x", "y", "end"):
        pub.publish(String(data=data))
    wait_until(lambda: both_got("end"), DEADLINE, "'end' on both subscriptions")
    for handle in ("a", "b"):
        counts = [_messages(peer, topic, handle, d) for d in ("x", "y")]
        assert counts == [1, 1], f"subscription {handle} got x, y {counts} times"
    if not unsubscribe_one:
        return
    peer.request("unsubscribe", topic=topic, type="std_msgs/msg/String", handle="a")
    for _ in range(int(DEADLINE / ATTEMPT)):
        pub.publish(String(data="after"))
        try:
            wait_until(lambda: _messages(peer, topic, "b", "after") >= 1, ATTEMPT, "after")
            return
        except AssertionError:
            continue
    raise AssertionError(f"the remaining subscription stopped receiving\n{peer.diagnostics()}")


def subscription_options(peer: PeerProcess, node: Any, topic: str) -> None:
    """A subscription with throttle_rate and queue_length set still delivers messages."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String", throttle_rate=20,
                 queue_length=1)
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="throttled"))
    assert got == {"data": "throttled"}


def subscribe_png(peer: PeerProcess, node: Any, topic: str) -> None:
    """A subscription asking for the legacy png compression still delivers messages."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String", compression="png")
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="png please"))
    assert got == {"data": "png please"}


def bad_fields_named(peer: PeerProcess, node: Any, topic: str) -> None:
    """A publish with an unknown field or a wrong value type gets an error naming the field."""
    peer.request("publish", topic=topic, type="std_msgs/String", msg={"dta": "x"})
    assert "dta" in _status_about(peer, "publish", topic)["msg"]
    peer.begin_test()
    peer.request("publish", topic=topic, type="std_msgs/String", msg={"data": 5})
    text = _status_about(peer, "publish", topic)["msg"]
    assert "data" in text and "string" in text, text
    publish_string(peer, node, topic + "_ok", "std_msgs/String")


def subscribe_wrong_type(peer: PeerProcess, node: Any, topic: str) -> None:
    """Subscribing with a type other than the topic's gets an error naming both types."""
    from std_msgs.msg import Int32

    node.create_publisher(Int32, topic, 10)
    wait_until(lambda: peer.request("get_topic_type", topic=topic), DEADLINE, "the topic's type")
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    text = _status_about(peer, "subscribe", topic)["msg"]
    assert "Int32" in text and "String" in text, text


# -- values JSON cannot carry as such ----------------------------------------------------------


def non_finite_floats(peer: PeerProcess, node: Any, topic: str) -> None:
    """NaN and infinities reach the client as null, and the finite values around them intact."""
    from std_msgs.msg import Float64MultiArray

    pub = node.create_publisher(Float64MultiArray, topic, 10)
    peer.request("subscribe", topic=topic, type="std_msgs/msg/Float64MultiArray")
    msg = Float64MultiArray(data=[1.5, math.nan, math.inf, -math.inf, -0.25])
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert got["data"] == [1.5, None, None, None, -0.25]


def big_integers(peer: PeerProcess, node: Any, topic: str) -> None:
    """int64 and uint64 extremes reach a Python client exactly (JSON numbers, no rounding)."""
    from test_msgs.msg import BasicTypes

    pub = node.create_publisher(BasicTypes, topic, 10)
    peer.request("subscribe", topic=topic, type="test_msgs/msg/BasicTypes")
    msg = BasicTypes(int64_value=-(2**63), uint64_value=2**64 - 1, int32_value=2**31 - 1)
    got = _ros_publish_until_delivered(peer, pub, topic, msg)
    assert (got["int64_value"], got["uint64_value"], got["int32_value"]) == (
        -(2**63), 2**64 - 1, 2**31 - 1,
    )


# -- QoS the bridge must adapt to --------------------------------------------------------------


def _sensor_qos() -> Any:
    return _module("rclpy.qos").qos_profile_sensor_data


def subscribe_best_effort(peer: PeerProcess, node: Any, topic: str, publisher_first: bool) -> None:
    """A best-effort (sensor data QoS) rclpy publisher is heard, whether it came before or after."""
    from sensor_msgs.msg import Temperature

    pub = None
    if publisher_first:
        pub = node.create_publisher(Temperature, topic, _sensor_qos())
        wait_until(lambda: topic in _topics(peer.request("get_topics"))[0], DEADLINE,
                   f"{topic} known to the bridge")
    peer.request("subscribe", topic=topic, type="sensor_msgs/msg/Temperature")
    if pub is None:
        wait_until(lambda: node.count_subscribers(topic) >= 1, DEADLINE, "the bridge subscription")
        pub = node.create_publisher(Temperature, topic, _sensor_qos())
    got = _ros_publish_until_delivered(peer, pub, topic, Temperature(temperature=21.5, variance=0.5))
    assert (got["temperature"], got["variance"]) == (21.5, 0.5)


# -- no type given, a client hearing itself, relative names ------------------------------------


def subscribe_without_type(peer: PeerProcess, node: Any, topic: str) -> None:
    """A subscription that names no type (roslib: none sent; roslibpy: null) takes the graph's."""
    from std_msgs.msg import String

    pub = node.create_publisher(String, topic, 10)
    wait_until(lambda: peer.request("get_topic_type", topic=topic), DEADLINE, "the topic's type")
    peer.request("subscribe", topic=topic, type=None)
    got = _ros_publish_until_delivered(peer, pub, topic, String(data="typeless"))
    assert got == {"data": "typeless"}


def hears_itself(peer: PeerProcess, node: Any, topic: str) -> None:
    """A client subscribed to a topic it also publishes gets its own messages back (as ROS does)."""
    peer.request("subscribe", topic=topic, type="std_msgs/msg/String")
    peer.request("advertise", topic=topic, type="std_msgs/msg/String")
    wait_until(lambda: node.count_publishers(topic) >= 1 and node.count_subscribers(topic) >= 1,
               DEADLINE, f"the bridge's publisher and subscriber on {topic}")
    for _ in range(int(DEADLINE / ATTEMPT)):
        _refusal(peer, topic)
        peer.request("publish", topic=topic, type="std_msgs/msg/String", msg={"data": "echo"})
        try:
            got = peer.wait_event(
                lambda e: e.get("event") == "message" and e.get("topic") == topic, ATTEMPT
            )
        except AssertionError:
            continue
        assert got["msg"] == {"data": "echo"}
        return
    raise AssertionError(f"{peer.name} never heard its own message\n{peer.diagnostics()}")


def relative_names(peer: PeerProcess, node: Any, topic: str) -> None:
    """Topic names without the leading slash ("chatter") mean the absolute ones ("/chatter")."""
    from std_msgs.msg import String

    relative = topic.lstrip("/")
    inbox: queue.Queue[Any] = queue.Queue()
    node.create_subscription(String, topic + "_in", inbox.put, 10)
    pub = node.create_publisher(String, topic + "_out", 10)
    peer.request("subscribe", topic=relative + "_out", type="std_msgs/msg/String")
    peer.request("advertise", topic=relative + "_in", type="std_msgs/msg/String")
    wait_until(lambda: node.count_publishers(topic + "_in") >= 1, DEADLINE, "the bridge publisher")
    got = _publish_until_received(peer, relative + "_in", "std_msgs/msg/String", {"data": "in"}, inbox)
    assert got.data == "in"
    # The bridge's subscription is matched with our publisher, so a message gets through
    # within a few attempts, or its delivery to the app is broken.
    wait_until(lambda: pub.get_subscription_count() >= 1, DEADLINE, "the bridge subscription")
    for _ in range(6):
        pub.publish(String(data="out"))
        try:
            event = peer.wait_event(
                lambda e: e.get("event") == "message"
                and e.get("topic") in (relative + "_out", topic + "_out"),
                ATTEMPT,
            )
        except AssertionError:
            continue
        assert event["msg"] == {"data": "out"}
        return
    raise AssertionError(f"{peer.name} got nothing on {relative}_out\n{peer.diagnostics()}")
