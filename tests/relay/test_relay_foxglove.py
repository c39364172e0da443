"""Foxglove through a relay (issues 26 and 28): the stock ``@foxglove/ws-protocol`` client
(npm, in Node: tests/peers/node/foxglove_peer.mjs) at ``ws://relay/robot1`` gets
``foxglove.websocket.v1`` on the relay's port, sees the robot's topics as channels with
their ``ros2msg`` schemas, and decodes the robot's CDR, carried over Zenoh untouched, to
what rclpy published; a rosbridge client on the same relay at the same time.

The relay runs in this process, so the blocking peer driver is called off the event loop.
"""

from __future__ import annotations

import asyncio
import base64
import functools
from typing import Any

import pytest
from std_msgs.msg import String

from tests.helpers import open_wire
from tests.peers import scenarios
from tests.peers.peer import PeerProcess, foxglove_peer
from tests.relay.support import ROBOT, tier

pytestmark = pytest.mark.timeout(120)

DEADLINE = scenarios.DEADLINE


async def _call(fn: Any, *args: Any, **kw: Any) -> Any:
    return await asyncio.to_thread(functools.partial(fn, *args, **kw))


async def _seen(fox: PeerProcess, pub: Any, topic: str, msg: Any) -> dict[str, Any]:
    """Publish from rclpy until the Foxglove client has a message on ``topic``."""
    deadline = asyncio.get_running_loop().time() + DEADLINE
    while True:
        pub.publish(msg)
        try:
            event: dict[str, Any] = await _call(
                fox.wait_event, lambda e: e.get("event") == "message" and e["topic"] == topic,
                0.5, f"message on {topic}")
            return event
        except AssertionError:
            assert asyncio.get_running_loop().time() < deadline, fox.diagnostics()


async def test_foxglove_client_through_a_relay(ros_node: Any, topic: str) -> None:
    """The Foxglove client through the relay: the protocol chosen, an rclpy Image's channel
    with its full schema, the Image decoded from the robot's CDR to what rclpy published; a
    rosbridge client of the same relay hears the robot too, and the robot's status page
    lists both, each with its protocol."""
    from sensor_msgs.msg import Image

    pub = ros_node.create_publisher(Image, topic, 10)
    chatter = ros_node.create_publisher(String, topic + "_chatter", 10)
    img = Image(height=48, width=64, encoding="rgb8", step=64 * 3, is_bigendian=0)
    img.header.frame_id = "camera"
    img.header.stamp.sec, img.header.stamp.nanosec = 12, 345
    img.data = bytes(i * 7 % 251 for i in range(64 * 48 * 3))
    async with tier() as t:
        fox = await _call(foxglove_peer, t.url())
        wire = await open_wire(t.url())
        try:
            assert fox.info["protocol"] == "foxglove.websocket.v1"
            channel = await _call(fox.request, "wait_channel", topic=topic,
                                  timeout_ms=int(DEADLINE * 1000), timeout=DEADLINE + 5)
            assert (channel["encoding"], channel["schemaEncoding"], channel["schemaName"]) == (
                "cdr", "ros2msg", "sensor_msgs/msg/Image")
            assert "uint32 height" in channel["schema"]
            assert "MSG: std_msgs/Header" in channel["schema"]
            await _call(fox.request, "subscribe", topic=topic, timeout_ms=int(DEADLINE * 1000),
                        timeout=DEADLINE + 5)
            msg = (await _seen(fox, pub, topic, img))["msg"]
            assert msg["header"] == {"stamp": {"sec": 12, "nanosec": 345},
                                     "frame_id": "camera"}
            assert (msg["height"], msg["width"], msg["encoding"], msg["step"]) == (
                48, 64, "rgb8", 192)
            assert base64.b64decode(msg["data"]["$bytes"]) == bytes(img.data)

            await wire.send({"op": "subscribe", "topic": topic + "_chatter",
                             "type": "std_msgs/msg/String"})
            deadline = asyncio.get_running_loop().time() + DEADLINE
            while True:
                chatter.publish(String(data="both"))
                try:
                    op = await wire.expect(op="publish", topic=topic + "_chatter", timeout=0.3)
                    break
                except AssertionError:
                    assert asyncio.get_running_loop().time() < deadline, "rosbridge heard nothing"
            assert op["msg"] == {"data": "both"}
            clients = t.relay.robots[ROBOT].web.local()["clients"]
            assert sorted(c["protocol"] for c in clients) == ["foxglove", "rosbridge"]
        finally:
            await wire.close()
            await _call(fox.close)
