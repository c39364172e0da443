"""One suite, two backends: MockRos and the real client on the real bridge behave the same.

Every topic and service name comes from the ``topic`` fixture, so tests never
meet on the shared bridge. Where ROS needs time to match a new subscription
with a publisher (discovery, which sends no event), a test publishes until the
first message is heard, with a deadline.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from msgs.mult_msgs.srv import MultFloats, MultFloats_Request, MultFloats_Response
from msgs.std_msgs.msg import Int32, String
from roslibpy_lite import (
    InvalidMessageError,
    Publisher,
    Ros,
    RosTimeoutError,
    ServiceError,
    Subscription,
    UsageError,
)
from tests.op_peer import send_until_heard

MULT = "mult_msgs/srv/MultFloats"


async def heard(pub: Publisher[Any], sub: Subscription[Any], msg: Any, timeout: float = 15.0) -> Any:
    """Publish ``msg`` until ``sub`` hears it (ROS discovery has no event); returns what arrived."""
    return await send_until_heard(lambda: pub.publish(msg), sub.get, f"{msg} on {sub.topic}",
                                  timeout=timeout)


async def after_warm_up(sub: Subscription[Any], value: Any, timeout: float = 10.0) -> Any:
    """The first message that is not a copy of :func:`heard`'s ``value``.

    :func:`heard` may have published ``value`` again before its first copy arrived, and
    those copies can still be on their way; one publisher's messages arrive in order, so
    once another one arrives no copy can follow it."""
    while (msg := await sub.get(timeout)) == value:
        pass
    return msg


async def test_publish_subscribe_round_trip(ros: Ros, topic: str) -> None:
    """Dicts published on a topic arrive at a subscription of it, in order."""
    pub = await ros.advertise(topic, "std_msgs/msg/Int32")
    async with ros.subscribe(topic, "std_msgs/msg/Int32") as sub:
        assert await heard(pub, sub, {"data": -1}) == {"data": -1}
        for i in range(5):
            await pub.publish({"data": i})
        first = await after_warm_up(sub, {"data": -1})
        assert [first["data"]] + [(await sub.get(10))["data"] for _ in range(4)] == [0, 1, 2, 3, 4]
    await pub.unadvertise()


async def test_callback_style_subscription(ros: Ros, topic: str) -> None:
    """A subscription with a callback delivers every message to it."""
    got: asyncio.Queue[Any] = asyncio.Queue()

    async def on_msg(msg: Any) -> None:
        await got.put(msg)

    pub = await ros.advertise(topic, "std_msgs/msg/String")
    probe = await ros.subscribe(topic, "std_msgs/msg/String")
    await heard(pub, probe, {"data": "probe"})
    await probe.close()
    async with ros.subscribe(topic, "std_msgs/msg/String", callback=on_msg):
        await pub.publish({"data": "to callback"})
        msg = await asyncio.wait_for(got.get(), 10)
        while msg == {"data": "probe"}:
            msg = await asyncio.wait_for(got.get(), 10)
        assert msg == {"data": "to callback"}


async def test_typed_messages_round_trip(ros: Ros, topic: str) -> None:
    """A typed publisher and a typed subscription exchange instances of the class."""
    async with ros.advertise(topic, String) as pub, ros.subscribe(topic, String) as sub:
        first = await heard(pub, sub, String(data="typed"))
        assert isinstance(first, String) and first.data == "typed"
        await pub.publish({"data": "a dict is fine too"})
        assert (await after_warm_up(sub, String(data="typed"))).data == "a dict is fine too"


async def test_typed_publish_refuses_wrong_type_and_bad_fields(ros: Ros, topic: str) -> None:
    """Publishing another message type raises UsageError; a bad field raises InvalidMessageError."""
    pub = await ros.advertise(topic, Int32)
    with pytest.raises(UsageError, match="std_msgs/msg/Int32"):
        await pub.publish(String(data="x"))  # type: ignore[arg-type]
    bad = Int32()
    bad.data = 2**40  # reassigned after it was built (construction would refuse it)
    with pytest.raises(InvalidMessageError, match="data"):
        await pub.publish(bad)
    await pub.close()


async def test_latched_topic_reaches_late_subscriber(ros: Ros, topic: str) -> None:
    """A latched topic's last message reaches a subscription made after it was published."""
    pub = await ros.advertise(topic, "std_msgs/msg/String", latch=True)
    await pub.publish({"data": "the map"})
    async with ros.subscribe(topic, "std_msgs/msg/String") as late:
        assert await late.get(15) == {"data": "the map"}
    await pub.close()


async def test_service_serve_and_call(ros: Ros, topic: str) -> None:
    """A served service answers calls, with dicts and with typed requests/responses."""
    async with ros.advertise_service(topic, MULT, lambda req: {"result": req["x"] * req["y"]}):
        assert await ros.call_service(topic, MULT, {"x": 2.5, "y": 4.0}, timeout=15) == {
            "result": 10.0
        }
        reply = await ros.call_service(topic, MultFloats, MultFloats.Request(x=3.0, y=-2.0),
                                       timeout=15)
        assert isinstance(reply, MultFloats.Response) and reply.result == -6.0


async def test_typed_async_handler(ros: Ros, topic: str) -> None:
    """An async handler of a typed service gets a Request and may return a Response."""

    async def handler(req: MultFloats_Request) -> MultFloats_Response:
        await asyncio.sleep(0)
        return MultFloats.Response(result=req.x + req.y)

    async with ros.advertise_service(topic, MultFloats, handler):
        assert await ros.call_service(topic, MULT, {"x": 1.0, "y": 2.0}, timeout=15) == {
            "result": 3.0
        }


async def test_handler_exception_gives_service_error(ros: Ros, topic: str) -> None:
    """A handler that raises fails the caller's call with ServiceError carrying its text."""

    def handler(req: Any) -> Any:
        raise ValueError("no multiplying on Sundays")

    async with ros.advertise_service(topic, MULT, handler):
        with pytest.raises(ServiceError, match="no multiplying on Sundays"):
            await ros.call_service(topic, MULT, {"x": 1.0, "y": 1.0}, timeout=15)


async def test_unknown_service_fails(ros: Ros, topic: str) -> None:
    """Calling a service nobody serves raises ServiceError."""
    with pytest.raises(ServiceError, match=topic):
        await ros.call_service(topic + "_nobody", MULT, {"x": 1.0, "y": 1.0}, timeout=None)


async def test_slow_service_times_out(ros: Ros, topic: str) -> None:
    """A call whose answer does not come within the timeout raises RosTimeoutError."""
    release = asyncio.Event()

    async def never(req: Any) -> Any:
        await release.wait()
        return {"result": 0.0}

    async with ros.advertise_service(topic, MULT, never):
        with pytest.raises(RosTimeoutError, match=topic):
            await ros.call_service(topic, MULT, {"x": 1.0, "y": 1.0}, timeout=1.0)
        release.set()


async def test_unsubscribe_stops_delivery(ros: Ros, topic: str) -> None:
    """After unsubscribe a subscription gets nothing more and its iteration ends."""
    pub = await ros.advertise(topic, "std_msgs/msg/Int32")
    first = ros.subscribe(topic, "std_msgs/msg/Int32")
    await heard(pub, first, {"data": 0})
    await first.unsubscribe()
    before = first.received
    second = ros.subscribe(topic, "std_msgs/msg/Int32")
    await heard(pub, second, {"data": 1})
    await pub.publish({"data": 2})
    while (await second.get(10))["data"] != 2:
        pass
    assert first.received == before
    assert all([m == {"data": 0} async for m in first])
    await second.close()
    await pub.close()


async def test_handles_clean_up_on_exit(ros: Ros, topic: str) -> None:
    """Handles closed by ``async with`` refuse further use, and a closed service is gone."""
    async with ros.advertise(topic, "std_msgs/msg/Int32") as pub:
        pass
    with pytest.raises(UsageError, match="closed"):
        await pub.publish({"data": 1})
    async with ros.subscribe(topic, "std_msgs/msg/Int32") as sub:
        pass
    with pytest.raises(UsageError, match="closed"):
        await sub.get(1)
    service = topic + "_srv"
    async with ros.advertise_service(service, MULT, lambda req: {"result": 1.0}) as server:
        assert await ros.call_service(service, MULT, {}, timeout=15) == {"result": 1.0}
    assert server.closed
    # The ROS graph forgets a service with a delay (no event); until then a call may still
    # find the name in the graph and wait for a server that is gone.
    deadline = asyncio.get_running_loop().time() + 30
    with pytest.raises(ServiceError, match=service):
        while asyncio.get_running_loop().time() < deadline:
            await ros.call_service(service, MULT, {}, timeout=None)
