"""Topic ops over rclpy: what needs a real ROS graph (rclpy publishers and subscribers on
the other side, DDS matching and QoS, latching, CDR from rclpy, a socket that fills). The
session's own topic behaviour (type spellings, throttling, fragments, CBOR, merged
subscriptions, unsubscribing, png, relative names) is tested in memory in
tests/session/test_topics.py."""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Image
from std_msgs.msg import Int32, String

from tests.bridge.support import (
    Inbox,
    bridge_sees_topic,
    publish_until_heard,
    wait_publishers,
    wait_subscribers,
)
from tests.helpers import async_wait_until, roundtrip


def _latched() -> QoSProfile:
    return QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)  # type: ignore[no-untyped-call]


async def test_advertise_publish_reaches_ros_subscriber(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A client's advertise + publish arrives at an rclpy subscriber."""
    inbox = Inbox()
    sub = ros_node.create_subscription(String, topic, inbox, 10)
    ws = await ws_connect()
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/String"})
    await wait_publishers(sub)
    # The subscription seeing the publisher does not mean the publisher sees it yet.
    msg = await publish_until_heard(ws, topic, {"data": "hello"}, inbox)
    assert msg.data == "hello"


async def test_publish_without_advertise_uses_graph_type(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """Publishing to a topic the graph knows works without advertise (the graph gives the type)."""
    inbox = Inbox()
    sub = ros_node.create_subscription(String, topic, inbox, 10)
    ws = await ws_connect()
    assert await bridge_sees_topic(ws, topic) == "std_msgs/msg/String"
    await ws.send({"op": "publish", "topic": topic, "msg": {"data": "auto"}})
    await wait_publishers(sub)
    heard = await publish_until_heard(ws, topic, {"data": "auto2"}, inbox)
    while heard.data != "auto2":  # "auto" got through: the next one heard is "auto2"
        heard = await inbox.get()


def _bridge_knows(node: Any, topic: str) -> bool:
    return any(name == topic for name, _ in node.get_topic_names_and_types())


async def test_ros_publisher_reaches_subscriber(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """An rclpy publisher's messages reach a client that subscribed with a type."""
    pub = ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String", "id": "s"})
    await wait_subscribers(pub)
    pub.publish(String(data="from ros"))
    op = await ws.expect(op="publish", topic=topic)
    assert op == {"op": "publish", "topic": topic, "msg": {"data": "from ros"}}


async def test_subscribe_infers_type_from_graph(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A subscribe without a type uses the type the ROS graph lists for the topic."""
    pub = ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    await bridge_sees_topic(ws, topic)
    await ws.send({"op": "subscribe", "topic": topic})
    await wait_subscribers(pub)
    pub.publish(String(data="typed by graph"))
    op = await ws.expect(op="publish", topic=topic)
    assert op["msg"] == {"data": "typed by graph"}


async def test_late_publisher_is_heard(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A subscribe without a type made before any publisher exists works once one appears."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "id": "late"})
    await roundtrip(ws)
    pub = ros_node.create_publisher(String, topic, 10)
    await wait_subscribers(pub)
    pub.publish(String(data="finally"))
    op = await ws.expect(op="publish", topic=topic)
    assert op["msg"] == {"data": "finally"}


async def test_queue_length_drops_oldest_for_slow_reader(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A client that does not read loses the oldest messages (newest kept) and is told so."""
    pub = ros_node.create_publisher(String, topic, 100)
    ws = await ws_connect()
    await ws.send(
        {"op": "subscribe", "topic": topic, "type": "std_msgs/String", "queue_length": 2}
    )
    await wait_subscribers(pub)
    # The test client does not read while ~24 MB are published: the socket buffers fill,
    # then the bridge's two-message queue drops the oldest ones.
    big = "x" * 400_000
    count = 60
    for i in range(count):
        pub.publish(String(data=f"{i}:{big}"))
    last = f"{count - 1}:"
    received: list[int] = []
    while True:
        op = await ws.expect(op="publish", topic=topic)
        received.append(int(op["msg"]["data"].split(":")[0]))
        if op["msg"]["data"].startswith(last):
            break
    assert received == sorted(received)
    assert len(received) < count
    warning = await ws.expect(op="status", level="warning")
    assert topic in warning["msg"] and "dropped" in warning["msg"]


async def test_compression_cbor_raw(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """compression=cbor-raw sends the CDR bytes with a receive stamp."""
    pub = ros_node.create_publisher(String, topic, 10)
    ws = await ws_connect()
    await ws.send(
        {"op": "subscribe", "topic": topic, "type": "std_msgs/String", "compression": "cbor-raw"}
    )
    await wait_subscribers(pub)
    pub.publish(String(data="raw"))
    op = await ws.expect(op="publish", topic=topic)
    msg = op["msg"]
    assert set(msg) == {"secs", "nsecs", "bytes"}
    assert msg["secs"] > 0 and 0 <= msg["nsecs"] < 1_000_000_000
    assert deserialize_message(msg["bytes"], String).data == "raw"


async def test_compression_cbor_raw_camera_frame(ws_connect: Any, ros_node: Any,
                                                 topic: str) -> None:
    """A 640x480 rgb8 frame over cbor-raw (its envelope made apart from its 921 KB and written
    in pieces) arrives as one CBOR op carrying the frame's CDR, whole."""
    pub = ros_node.create_publisher(Image, topic, 10)
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "sensor_msgs/msg/Image",
                   "compression": "cbor-raw"})
    await wait_subscribers(pub)
    image = Image(height=480, width=640, encoding="rgb8", step=1920,
                  data=bytes(range(256)) * 3600)
    pub.publish(image)
    op = await ws.expect(op="publish", topic=topic)
    assert set(op["msg"]) == {"secs", "nsecs", "bytes"}
    raw = op["msg"]["bytes"]
    assert len(raw) == len(serialize_message(image))
    assert deserialize_message(raw, Image) == image


async def test_one_ros_subscription_shared_by_clients(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """Two clients on one topic share one ROS subscription and both get every message."""
    pub = ros_node.create_publisher(String, topic, 10)
    a = await ws_connect()
    b = await ws_connect()
    await a.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await b.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await roundtrip(a)
    await roundtrip(b)
    await wait_subscribers(pub)
    assert pub.get_subscription_count() == 1
    pub.publish(String(data="both"))
    assert (await a.expect(op="publish"))["msg"]["data"] == "both"
    assert (await b.expect(op="publish"))["msg"]["data"] == "both"


async def test_latched_topic_reaches_late_subscribers(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A transient-local (latched) message reaches clients that subscribe after it was sent."""
    pub = ros_node.create_publisher(String, topic, _latched())
    pub.publish(String(data="map"))
    first = await ws_connect()
    await async_wait_until(lambda: _bridge_knows(ros_node, topic), what="topic in the graph")
    await first.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    assert (await first.expect(op="publish", topic=topic))["msg"]["data"] == "map"
    second = await ws_connect()
    await second.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    assert (await second.expect(op="publish", topic=topic))["msg"]["data"] == "map"


async def test_client_latched_advertise(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """advertise with latch=true makes a transient-local publisher a late rclpy subscriber hears."""
    ws = await ws_connect()
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/String", "latch": True})
    await ws.send({"op": "publish", "topic": topic, "msg": {"data": "kept"}})
    await roundtrip(ws)
    inbox = Inbox()
    ros_node.create_subscription(String, topic, inbox, _latched())
    assert (await inbox.get()).data == "kept"


async def test_best_effort_publisher_is_heard(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A best-effort publisher (sensor style) is matched: the bridge subscribes best effort."""
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)  # type: ignore[no-untyped-call]
    pub = ros_node.create_publisher(String, topic, qos)
    ws = await ws_connect()
    await async_wait_until(lambda: _bridge_knows(ros_node, topic), what="topic in the graph")
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await wait_subscribers(pub)
    n = 0
    while True:  # best effort may lose the first messages while matching settles
        n += 1
        pub.publish(String(data=f"be{n}"))
        try:
            op = await ws.expect(op="publish", topic=topic, timeout=0.5)
            break
        except AssertionError:
            assert n < 20
    assert op["msg"]["data"].startswith("be")


async def test_unadvertise_removes_publisher(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """unadvertise removes the bridge's ROS publisher for the topic."""
    sub = ros_node.create_subscription(String, topic, lambda m: None, 10)
    ws = await ws_connect()
    await ws.send({"op": "advertise", "topic": topic, "type": "std_msgs/String", "id": "adv"})
    await wait_publishers(sub)
    await ws.send({"op": "unadvertise", "topic": topic, "id": "adv"})
    await async_wait_until(lambda: sub.get_publisher_count() == 0, what="publisher gone")


async def test_late_best_effort_publisher_is_matched(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A best-effort publisher appearing after the subscribe is matched (the bridge re-subscribes)."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await roundtrip(ws)
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)  # type: ignore[no-untyped-call]
    pub = ros_node.create_publisher(String, topic, qos)
    await wait_subscribers(pub)
    n = 0
    while True:
        n += 1
        pub.publish(String(data=f"late{n}"))
        try:
            op = await ws.expect(op="publish", topic=topic, timeout=0.5)
            break
        except AssertionError:
            assert n < 20
    assert op["msg"]["data"].startswith("late")


async def test_late_latched_publisher_reaches_subscriber(
    ws_connect: Any, ros_node: Any, topic: str
) -> None:
    """A latched message from a publisher appearing after the subscribe still arrives."""
    ws = await ws_connect()
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
    await roundtrip(ws)
    pub = ros_node.create_publisher(String, topic, _latched())
    pub.publish(String(data="latched late"))
    op = await ws.expect(op="publish", topic=topic)
    assert op["msg"]["data"] == "latched late"


async def test_a_re_subscription_to_a_latched_topic_hands_out_nothing_twice(
    ws_connect: Any, bridge: Any, ros_node: Any, topic: str
) -> None:
    """The bridge subscribes volatile before it sees the publisher, then re-subscribes
    transient local, and the writer replays its history: every number reaches the client
    exactly once (none twice, none lost)."""
    ws = await ws_connect()
    # the replayed history comes as one burst: a queue (and a history) for the whole run
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/Int32",
                   "queue_length": 1000})
    await roundtrip(ws)
    pub = ros_node.create_publisher(
        Int32, topic, QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))  # type: ignore[no-untyped-call]
    got: list[int] = []
    sent = 0

    def re_subscribed() -> bool:
        return any(f"QoS of {topic} changed" in line for line in bridge.lines)

    deadline = time.monotonic() + 20
    while not (got and re_subscribed()):  # live messages first, then the re-subscription
        assert time.monotonic() < deadline, ("the bridge did not re-subscribe", got)
        pub.publish(Int32(data=sent))
        sent += 1
        await asyncio.sleep(0.02)  # 50 Hz: the history (1,000) outlasts the deadline
        with contextlib.suppress(AssertionError):
            got.append((await ws.expect(op="publish", topic=topic, timeout=0.001))["msg"]["data"])
    for _ in range(10):
        pub.publish(Int32(data=sent))
        sent += 1
    with contextlib.suppress(AssertionError):
        while len(got) < sent:
            got.append((await ws.expect(op="publish", topic=topic, timeout=5))["msg"]["data"])
    with contextlib.suppress(AssertionError):  # and nothing more comes: no late duplicates
        got.append((await ws.expect(op="publish", topic=topic, timeout=0.5))["msg"]["data"])
    assert sorted(got) == list(range(sent)), got
