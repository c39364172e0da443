"""Real links through the fault-injecting proxy (bench/linkproxy.py): silent links are noticed
on both sides, busy slow links are not mistaken for dead ones."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from typing import Any

import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import String

import roslibpy_lite
from bench.linkproxy import LinkProxy
from roslibpy_lite.api import ConnectionState
from tests.bridge.support import wait_subscribers
from tests.helpers import BridgeProcess, async_wait_until, open_wire


@pytest.fixture
def link(make_bridge: Any) -> Iterator[tuple[BridgeProcess, LinkProxy]]:
    """A private bridge and a proxy in front of it."""
    bridge = make_bridge()
    with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
        yield bridge, proxy


async def _state(ros: Any, wanted: ConnectionState, timeout: float) -> float:
    """Wait until ``ros`` is in ``wanted``; return how long it took."""
    start = time.monotonic()
    await async_wait_until(lambda: ros.state is wanted, timeout, f"state {wanted.name}")
    return time.monotonic() - start


async def test_client_notices_a_silent_link_and_comes_back(
    link: tuple[BridgeProcess, LinkProxy], ros_node: Any, topic: str
) -> None:
    """A blackhole (no FIN, no RST) takes the client out of CONNECTED within its keepalive
    bound (2 + 3 s by default; the wait here allows 15 s); after the link returns it reconnects
    and its subscription delivers again."""
    _, proxy = link
    pub = ros_node.create_publisher(String, topic, 10)
    async with roslibpy_lite.connect(f"ws://127.0.0.1:{proxy.port}") as ros:
        sub = await ros.subscribe(topic, "std_msgs/msg/String", queue_length=10)
        await wait_subscribers(pub)
        pub.publish(String(data="before"))
        assert (await sub.get(timeout=10))["data"] == "before"
        proxy.blackhole()
        await _state(ros, ConnectionState.RECONNECTING, 15)
        proxy.restore()
        await _state(ros, ConnectionState.CONNECTED, 15)
        await wait_subscribers(pub)
        deadline = time.monotonic() + 20
        while True:  # the restored subscription may miss the first one while it is matched
            assert time.monotonic() < deadline, "nothing delivered after the reconnect"
            pub.publish(String(data="after"))
            try:
                if (await sub.get(timeout=0.5))["data"] == "after":
                    break
            except TimeoutError:
                continue


async def test_bridge_drops_a_client_behind_a_silent_link(
    link: tuple[BridgeProcess, LinkProxy], ros_node: Any, topic: str
) -> None:
    """The bridge notices a blackholed client by itself and releases what it owned: its ROS
    subscription goes away, and the log says why."""
    bridge, proxy = link
    pub = ros_node.create_publisher(String, topic, 10)
    ws = await open_wire(f"ws://127.0.0.1:{proxy.port}")
    await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
    await wait_subscribers(pub)
    start = len(bridge.lines)
    proxy.blackhole()
    await async_wait_until(lambda: pub.get_subscription_count() == 0, 20,
                           "the bridge to drop the silent client's subscription")
    assert any("no sign of it" in line for line in bridge.lines[start:])
    ws.ws.transport.abort()


async def test_a_busy_slow_link_is_not_taken_for_a_dead_one(
    link: tuple[BridgeProcess, LinkProxy], ros_node: Any, topic: str
) -> None:
    """At 250 kB/s a 640x480 rgb8 frame takes over 3.5 s to cross, longer than the keepalive
    allows for a pong; the link stays up on both sides because TCP shows it is moving."""
    bridge, proxy = link
    proxy.set_bandwidth(250_000)
    pub = ros_node.create_publisher(Image, topic, 1)
    frame = Image(height=480, width=640, encoding="rgb8", step=1920, data=bytes(921_600))
    changes: list[ConnectionState] = []
    async with roslibpy_lite.connect(f"ws://127.0.0.1:{proxy.port}") as ros:
        ros.on_state_change(changes.append)
        got = 0

        def count(msg: Any) -> None:
            nonlocal got
            got += 1

        await ros.subscribe(topic, "sensor_msgs/msg/Image", count, queue_length=1,
                            compression="cbor")
        await wait_subscribers(pub)
        start = len(bridge.lines)
        deadline = time.monotonic() + 60
        while got < 2:  # two frames crossed: the link was busy past the keepalive's 5 s
            assert time.monotonic() < deadline, f"{got} frames crossed in 60 s"
            pub.publish(frame)
            await asyncio.sleep(0.2)  # the publishing rate
        assert changes == [], changes  # never left CONNECTED
        assert not any("no sign of it" in line for line in bridge.lines[start:])
