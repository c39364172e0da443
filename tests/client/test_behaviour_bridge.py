"""Issue 31's client behaviour against a real bridge process with rclpy nodes on the other
side: fresh values and fail fast across a killed bridge, a re-run ``sync.connect`` that
leaves one client on the bridge, and ``uint8[]`` fields as bytes under every compression.
"""

from __future__ import annotations

import asyncio
import threading
import time
import warnings
from collections.abc import Callable
from typing import Any

import pytest

import roslibpy_lite
from roslibpy_lite import ConnectionState, NotConnected, ReplacedClientWarning, sync
from tests.bridge.support import wait_subscribers
from tests.client.support import fast_backoff
from tests.helpers import BridgeProcess, threads_since, wait_until
from tests.ops.support import scrape, value

# rclpy's type support imports lark, which imports the deprecated sre_parse (warnings are errors).
with warnings.catch_warnings():
    warnings.filterwarnings("ignore", "module 'sre_.*' is deprecated", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

from mult_msgs.srv import MultFloats as RosMultFloats
from sensor_msgs.msg import Image as RosImage
from std_msgs.msg import Int32 as RosInt32

MULT = "mult_msgs/srv/MultFloats"


async def _heard(sub: roslibpy_lite.Subscription[Any], pub: Any, value: int) -> None:
    """Publish ``value`` from rclpy until the client's subscription gets it as a fresh
    message (DDS matching has no event the client can see)."""
    deadline = time.monotonic() + 20
    while True:
        pub.publish(RosInt32(data=value))
        try:
            if (await sub.next(0.25))["data"] == value:
                return
        except roslibpy_lite.RosTimeoutError:
            if time.monotonic() > deadline:
                raise


async def test_fresh_values_and_fail_fast_across_a_killed_bridge(
    make_bridge: Callable[..., BridgeProcess], ros_node: Any, topic: str
) -> None:
    """latest() is the newest with a small age; with the bridge killed, latest/next/calls
    raise NotConnected at once (not after their timeout) naming the state; with
    wait_connected=True a call and a next() wait and succeed once the bridge is back."""
    bridge = make_bridge()

    def mult(req: Any, resp: Any) -> Any:
        resp.result = req.x * req.y
        return resp

    ros_node.create_service(RosMultFloats, topic + "_mult", mult)
    pub = ros_node.create_publisher(RosInt32, topic, 10)
    async with roslibpy_lite.connect(bridge.url, backoff=fast_backoff()) as ros:
        sub = await ros.subscribe(topic, "std_msgs/msg/Int32")
        await wait_subscribers(pub)
        await _heard(sub, pub, 1)
        for i in range(2, 6):
            pub.publish(RosInt32(data=i))
        while sub.latest().msg != {"data": 5}:  # 4 and 5 may come in one read
            await sub.next(10)
        msg, age = sub.latest()
        assert msg == {"data": 5} and 0 <= age < 2.0
        assert (await sub.get(1))["data"] == 1  # the buffer keeps the oldest first

        waiting = asyncio.create_task(sub.next(60))
        async with ros.state_changes() as changes:
            bridge.kill()
            while ros.state is not ConnectionState.RECONNECTING:
                await changes.next(30)
        with pytest.raises(NotConnected, match="state reconnecting"):
            await asyncio.wait_for(waiting, 5)
        started = time.monotonic()
        with pytest.raises(NotConnected, match=f"call {topic}_mult: .*state reconnecting"):
            await ros.call_service(topic + "_mult", MULT, {"x": 2.0, "y": 3.0}, timeout=10)
        with pytest.raises(NotConnected, match=f"next message on {topic}: .*reconnecting"):
            await sub.next(10)
        with pytest.raises(NotConnected, match=f"latest message on {topic}: .*reconnecting"):
            sub.latest()
        assert time.monotonic() - started < 1.0  # at once, not after the 10 s timeouts
        assert sub.latest(allow_stale=True).msg == {"data": 5}

        call = asyncio.create_task(ros.call_service(
            topic + "_mult", MULT, {"x": 2.0, "y": 3.0}, timeout=60, wait_connected=True))
        fresh = asyncio.create_task(sub.next(60, wait_connected=True))
        await asyncio.to_thread(bridge.start)
        assert await call == {"result": 6.0}
        await ros.wait_connected(30)
        deadline = time.monotonic() + 30
        while not fresh.done():
            pub.publish(RosInt32(data=7))
            await asyncio.wait([fresh], timeout=0.25)
            assert time.monotonic() < deadline, "no message after the restart"
        assert await fresh == {"data": 7}


def _clients(bridge: BridgeProcess) -> float:
    return value(asyncio.run(scrape(bridge.port)), "roslibpy_bridge_clients")


def test_rerun_connect_leaves_one_client_on_the_bridge(
    make_bridge: Callable[..., BridgeProcess], topic: str
) -> None:
    """Running ``ros = sync.connect(URL)`` and a subscribe three times (a notebook cell run
    again) warns, closes the earlier client with its thread and subscription, and leaves
    the bridge with one client and the process with no extra thread."""
    bridge = make_bridge()
    threads = set(threading.enumerate())
    ros = sync.connect(bridge.url)
    sub = ros.subscribe(topic, "std_msgs/msg/Int32")
    wait_until(lambda: _clients(bridge) == 1, 10, "the first client on the bridge")
    try:
        for _ in range(3):
            earlier, earlier_sub = ros, sub
            with pytest.warns(ReplacedClientWarning, match=bridge.url):
                ros = sync.connect(bridge.url)
            sub = ros.subscribe(topic, "std_msgs/msg/Int32")
            assert earlier.state is ConnectionState.CLOSED and earlier_sub.closed
            assert [s.topic for s in ros.subscriptions()] == [topic]
        wait_until(lambda: _clients(bridge) == 1, 10, "one client on the bridge")
        assert len(threads_since(threads)) == 1, threads_since(threads)  # the one loop thread
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with sync.connect(bridge.url, replace=False) as other:  # two on purpose
                assert other.is_connected and ros.is_connected
    finally:
        ros.close()
    assert not threads_since(threads), threads_since(threads)


async def test_connect_after_close_replaces_nothing(bridge: BridgeProcess) -> None:
    """Connect, close, connect again to the same URL (replace on, as in a notebook): the
    closed client is not reported as replaced, no warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        closed = await roslibpy_lite.connect(bridge.url, replace=True)
        await closed.close()
        async with roslibpy_lite.connect(bridge.url, replace=True) as again:
            assert again.is_connected and closed.state is ConnectionState.CLOSED


def test_blocking_connect_after_close_replaces_nothing(bridge: BridgeProcess) -> None:
    """sync.connect, close, sync.connect again (a notebook's cells): no warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        closed = sync.connect(bridge.url)
        closed.close()
        with sync.connect(bridge.url) as again:
            assert again.is_connected and closed.state is ConnectionState.CLOSED


@pytest.mark.parametrize("compression", ["none", "cbor", "cbor-raw"])
async def test_byte_arrays_are_bytes_whatever_the_compression(
    bridge: BridgeProcess, ros_node: Any, topic: str, compression: str
) -> None:
    """An rclpy Image's data reaches a dict subscription as bytes under JSON, CBOR and
    cbor-raw alike; a subscription that keeps the bytes as sent gets base64 text under JSON."""
    pytest.importorskip("cbor2")
    pixels = bytes(range(256)) * 12  # 64x48 mono8
    image = RosImage(height=48, width=64, encoding="mono8", step=64, data=pixels)
    image.header.frame_id = "cam"
    pub = ros_node.create_publisher(RosImage, topic, 10)
    async with roslibpy_lite.connect(bridge.url) as ros:
        sub = await ros.subscribe(topic, "sensor_msgs/msg/Image", compression=compression)
        as_sent = await ros.subscribe(topic, "sensor_msgs/msg/Image", compression=compression)
        as_sent.uint8_as_sent = True
        await wait_subscribers(pub)
        deadline = time.monotonic() + 20
        while True:
            pub.publish(image)
            try:
                msg = await sub.next(0.25)
                break
            except roslibpy_lite.RosTimeoutError:
                assert time.monotonic() < deadline, "no image"
        assert type(msg["data"]) is bytes and msg["data"] == pixels
        sent = await as_sent.get(5)
        if compression == "none":
            assert isinstance(sent["data"], str)  # roslibpy's shape: base64 text
        else:
            assert sent["data"] == pixels
