"""Service calls from one client run concurrently, many at once, each with its own timeout."""

from __future__ import annotations

import threading
from typing import Any

import pytest
from rclpy.callback_groups import ReentrantCallbackGroup
from std_msgs.msg import String
from std_srvs.srv import SetBool

from tests.bridge.support import Inbox
from tests.helpers import send_until_heard
from tests.load.support import qos

pytestmark = pytest.mark.asyncio


def _blocking_service(node: Any, name: str, started: Inbox, release: threading.Event) -> Any:
    """A SetBool service: ``data`` true reports that it started, then waits for ``release``.

    ``data`` false is answered at once (to learn that the bridge sees the service).
    """

    def handle(request: Any, response: Any) -> Any:
        if request.data:
            started(request.data)
            release.wait(10.0)
        response.success = bool(request.data)
        response.message = "slow"
        return response

    return node.create_service(
        SetBool, name, handle, callback_group=ReentrantCallbackGroup(), qos_profile=qos(depth=100)
    )


def _fast_service(node: Any, name: str) -> Any:
    def handle(request: Any, response: Any) -> Any:
        response.success = bool(request.data)
        response.message = "fast"
        return response

    return node.create_service(
        SetBool, name, handle, callback_group=ReentrantCallbackGroup(), qos_profile=qos(depth=100)
    )


def _call(service: str, id: str, data: bool = True, **extra: Any) -> dict[str, Any]:
    return {"op": "call_service", "service": service, "type": "std_srvs/srv/SetBool",
            "args": {"data": data}, "id": id, **extra}


async def _until_answered(ws: Any, service: str, tries: int = 8) -> None:
    """Call (``data`` false, answered at once) until one call succeeds: the bridge sees the service.

    Retried because DDS discovery is asymmetric: a fresh client may send its first request
    before the server has matched the client's response reader, and that answer is lost.
    """
    for i in range(tries):
        await ws.send(_call(service, f"ready{i}", data=False, timeout=2))
        reply = await ws.expect(op="service_response", id=f"ready{i}", timeout=15)
        if reply["result"] is True:
            return
    raise AssertionError(f"{service} never answered through the bridge: {reply}")


async def _until_echoed(ws: Any, ping: str, pong: str) -> None:
    """Publish on ``ping`` until its echo comes back on ``pong``: both DDS paths are matched.

    Each side seeing the other is not enough: a ROS subscription can match the bridge's
    publisher before that publisher matches it, and a message sent in between is lost.
    """
    await send_until_heard(
        lambda: ws.send({"op": "publish", "topic": ping, "msg": {"data": "warm-up"}}),
        lambda wait: ws.expect(op="publish", topic=pong, timeout=wait),
        f"the echo of {ping} on {pong}", timeout=10)


async def test_slow_call_does_not_block_other_traffic(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """While a slow service call is pending, the same client's fast call and a publish->subscribe round trip complete."""
    slow, fast = f"{topic}/slow", f"{topic}/fast"
    ping, pong = f"{topic}/ping", f"{topic}/pong"
    started = Inbox()
    release = threading.Event()
    _blocking_service(ros_node, slow, started, release)
    _fast_service(ros_node, fast)
    echo_pub = ros_node.create_publisher(String, pong, 10)
    ros_node.create_subscription(  # the node keeps it
        String, ping, lambda m: echo_pub.publish(String(data=m.data)), 10,
        callback_group=ReentrantCallbackGroup(),
    )
    ws = await ws_connect()
    await ws.send({"op": "advertise", "topic": ping, "type": "std_msgs/msg/String"})
    await ws.send({"op": "subscribe", "topic": pong, "type": "std_msgs/msg/String"})
    await _until_echoed(ws, ping, pong)
    await _until_answered(ws, fast)
    await _until_answered(ws, slow)
    try:
        await ws.send(_call(slow, "slow", timeout=20))
        assert await started.get(15) is True  # the slow callback is running now
        await ws.send(_call(fast, "fast"))
        reply = await ws.expect(op="service_response", id="fast")
        assert reply["result"] is True and reply["values"] == {"success": True, "message": "fast"}
        await ws.send({"op": "publish", "topic": ping, "msg": {"data": "round trip"}})
        echoed = await ws.expect(
            lambda op: op["msg"] != {"data": "warm-up"}, op="publish", topic=pong
        )
        assert echoed["msg"] == {"data": "round trip"}
        pending = [op for op in ws.backlog if op.get("id") == "slow"]
        assert pending == [], "the slow call cannot have been answered yet"
    finally:
        release.set()
    reply = await ws.expect(op="service_response", id="slow", timeout=15)
    assert reply["result"] is True and reply["values"] == {"success": True, "message": "slow"}


async def test_fifty_calls_in_flight_all_answered(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """50 service calls sent at once by one client are all answered, each under its own id."""
    _fast_service(ros_node, topic)
    ws = await ws_connect()
    await _until_answered(ws, topic)
    n = 50
    for i in range(n):
        await ws.send(_call(topic, f"c{i}", data=i % 2 == 0))
    replies: dict[str, Any] = {}
    while len(replies) < n:
        op = await ws.expect(lambda o: str(o.get("id", "")).startswith("c"),
                             op="service_response", timeout=15)
        replies[op["id"]] = op
    failed = {k: v["values"] for k, v in replies.items() if v["result"] is not True}
    assert failed == {}, f"{len(failed)} of {n} calls failed: {sorted(failed.items())[:3]}"
    for i in range(n):
        assert replies[f"c{i}"]["values"]["success"] is (i % 2 == 0)


async def test_call_timeout_names_the_timeout(ws_connect: Any, ros_node: Any, topic: str) -> None:
    """A call with timeout 0.5 to a service that never answers fails with a message naming the timeout."""
    started = Inbox()
    release = threading.Event()
    _blocking_service(ros_node, topic, started, release)
    ws = await ws_connect()
    await _until_answered(ws, topic)
    try:
        await ws.send(_call(topic, "t", timeout=0.5))
        reply = await ws.expect(op="service_response", id="t", timeout=15)
    finally:
        release.set()
    assert reply["result"] is False
    assert isinstance(reply["values"], str)
    text = reply["values"].lower()
    assert "time" in text and "0.5" in text, reply["values"]
    assert topic in reply["values"]
