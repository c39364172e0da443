"""QoS matching: latched topics reach late clients, best-effort and late publishers with other QoS are heard."""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from std_msgs.msg import String

from tests.bridge.support import wait_subscribers
from tests.helpers import roundtrip, send_until_heard
from tests.load.support import qos

pytestmark = pytest.mark.asyncio

STRING = "std_msgs/msg/String"


async def _subscribe(ws: Any, topic: str, id: str = "s") -> None:
    await ws.send({"op": "subscribe", "topic": topic, "type": STRING, "id": id})
    await roundtrip(ws)


async def test_latched_message_reaches_every_late_client(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A transient-local publisher's last message reaches clients that subscribe after it was published, one after another."""
    pub = ros_node.create_publisher(String, topic, qos(depth=1, latched=True))
    pub.publish(String(data="old"))
    pub.publish(String(data="map v2"))
    first = await ws_connect()
    await _subscribe(first, topic)
    got = await first.expect(op="publish", topic=topic)
    assert got["msg"] == {"data": "map v2"}
    second = await ws_connect()  # while the first one still holds the bridge's subscription
    await _subscribe(second, topic)
    got = await second.expect(op="publish", topic=topic)
    assert got["msg"] == {"data": "map v2"}
    await first.close()
    await second.close()
    third = await ws_connect()  # after both left
    await _subscribe(third, topic)
    got = await third.expect(op="publish", topic=topic)
    assert got["msg"] == {"data": "map v2"}
    extra = [op for op in third.backlog if op.get("op") == "publish"]
    assert extra == [], "only the last latched message is delivered"


async def test_best_effort_publisher_is_heard(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A best-effort rclpy publisher's messages reach a subscribed client."""
    pub = ros_node.create_publisher(String, topic, qos(best_effort=True))
    ws = await ws_connect()
    await _subscribe(ws, topic)
    await _publish_until_heard(ws, pub, topic)


async def _publish_until_heard(ws: Any, pub: Any, topic: str) -> dict[str, Any]:
    """Publish numbered messages (best effort may lose some) until the client hears one."""
    numbers = itertools.count()
    op: dict[str, Any] = await send_until_heard(
        lambda: pub.publish(String(data=f"m{next(numbers)}")),
        lambda wait: ws.expect(op="publish", topic=topic, timeout=wait),
        f"a message on {topic}", attempt=0.2, timeout=20)
    return op


@pytest.mark.parametrize("kind", ["best_effort", "transient_local"])
async def test_publisher_appearing_after_subscription_with_other_qos_is_matched(
    ws_connect: Any, ros_node: Any, topic: str, kind: str
) -> None:
    """A publisher with other QoS that appears after the client subscribed is matched and heard."""
    ws = await ws_connect()
    await _subscribe(ws, topic)
    if kind == "best_effort":
        pub = ros_node.create_publisher(String, topic, qos(best_effort=True))
        await wait_subscribers(pub)
        await _publish_until_heard(ws, pub, topic)
    else:
        pub = ros_node.create_publisher(String, topic, qos(depth=1, latched=True))
        pub.publish(String(data="latched before matching"))
        got = await ws.expect(op="publish", topic=topic)
        assert got["msg"] == {"data": "latched before matching"}
