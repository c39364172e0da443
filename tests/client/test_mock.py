"""MockRos specifics: type checks, validation, history, injection, drain, simulated drops."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from msgs.mult_msgs.srv import MultFloats
from msgs.std_msgs.msg import Int16, String
from roslibpy_lite import (
    ConnectionClosed,
    ConnectionState,
    Disconnected,
    InvalidMessageError,
    MockRos,
    ServiceError,
    StatusError,
    UsageError,
    define_type,
)

MULT = "mult_msgs/srv/MultFloats"


async def test_a_topic_has_one_type() -> None:
    """Another type on a topic: advertising it here is a UsageError, subscribing the bridge's StatusError."""
    ros = MockRos()
    ros.advertise("/t", "std_msgs/msg/String")
    with pytest.raises(UsageError, match="std_msgs/msg/String"):
        ros.advertise("/t", "std_msgs/msg/Int16")
    with pytest.raises(StatusError, match="std_msgs/msg/String"):
        await ros.subscribe("/t", Int16)
    ros.subscribe("/t", "std_msgs/String")  # the other spelling of the same type is fine


async def test_dicts_are_validated_against_the_generated_class() -> None:
    """A dict with a wrong field fails with InvalidMessageError naming the field."""
    ros = MockRos()
    pub = ros.advertise("/n", "std_msgs/msg/Int16")
    with pytest.raises(InvalidMessageError, match="data"):
        await pub.publish({"data": "text"})
    with pytest.raises(InvalidMessageError, match="nope"):
        await pub.publish({"nope": 1})
    with pytest.raises(UsageError, match="Int16"):
        await pub.publish(String(data="x"))  # type: ignore[arg-type]
    assert ros.published("/n") == []


async def test_unknown_types_are_refused_and_validation_can_be_off() -> None:
    """A type nobody defined is refused as the bridge refuses it; once defined
    (define_type) it is checked; validate=False skips the client's checks."""
    ros = MockRos()
    with pytest.raises(StatusError, match="mock_test_pkg/msg/Thing"):
        await ros.advertise("/u", "mock_test_pkg/msg/Thing")
    define_type("mock_test_pkg/msg/Thing", "int32[] anything\n")
    pub = ros.advertise("/u", "mock_test_pkg/msg/Thing")
    await pub.publish({"anything": [1, 2]})
    assert ros.published("/u") == [{"anything": [1, 2]}]
    loose = MockRos(validate=False)
    await loose.advertise("/n", "std_msgs/msg/Int16").publish({"data": "text"})


async def test_messages_are_copied_in_wire_form() -> None:
    """Subscribers get a JSON copy: mutating the published dict afterwards changes nothing."""
    ros = MockRos()
    sub = ros.subscribe("/c", "std_msgs/msg/String")
    msg = {"data": "before"}
    await ros.advertise("/c", "std_msgs/msg/String").publish(msg)
    msg["data"] = "after"
    assert await sub.get(1) == {"data": "before"}
    assert ros.published("/c") == [{"data": "before"}]


async def test_inject_plays_the_robot() -> None:
    """inject delivers to subscribers without appearing in published()."""
    ros = MockRos()
    got: list[Any] = []
    ros.subscribe("/imu", String, callback=got.append)
    ros.inject("/imu", {"data": "from robot"})
    ros.inject("/imu", String(data="typed"))
    assert [m.data for m in got] == ["from robot", "typed"]
    assert ros.published("/imu") == []
    with pytest.raises(UsageError, match="pass type"):
        ros.inject("/unknown", {"data": 1})


async def test_drain_waits_for_async_callbacks() -> None:
    """drain() returns only after async callbacks took every delivered message."""
    ros = MockRos()
    got: list[int] = []

    async def cb(msg: dict[str, Any]) -> None:
        await asyncio.sleep(0)
        got.append(msg["data"])

    ros.subscribe("/d", "std_msgs/msg/Int32", cb)
    pub = ros.advertise("/d", "std_msgs/msg/Int32")
    for i in range(5):
        await pub.publish({"data": i})
    await ros.drain()
    assert got == [0, 1, 2, 3, 4]


async def test_service_type_mismatch_and_bad_request() -> None:
    """Calling with another service type, or a request that does not fit, fails clearly."""
    ros = MockRos()
    ros.advertise_service("/m", MULT, lambda req: {"result": 1.0})
    with pytest.raises(ServiceError, match="has type"):
        await ros.call_service("/m", "std_srvs/srv/Trigger", {})
    with pytest.raises(InvalidMessageError, match="x"):
        await ros.call_service("/m", MULT, {"x": "a"})
    assert ros.served() == ["/m"]


async def test_bad_response_fails_the_call() -> None:
    """A handler answering with fields the response lacks fails the call with its reason."""
    ros = MockRos()
    ros.advertise_service("/m", MultFloats, lambda req: {"wrong": 1})
    with pytest.raises(ServiceError, match="wrong"):
        await ros.call_service("/m", MultFloats, MultFloats.Request(x=1.0, y=2.0))


async def test_simulated_drop_buffers_publishes_and_fails_calls() -> None:
    """disconnect(): calls in flight fail with Disconnected, publishes wait for reconnect()."""
    ros = MockRos(offline_buffer=2)
    release = asyncio.Event()

    async def handler(req: Any) -> Any:
        await release.wait()
        return {"result": 0.0}

    ros.advertise_service("/slow", MULT, handler)
    sub = ros.subscribe("/p", "std_msgs/msg/Int32")
    pub = ros.advertise("/p", "std_msgs/msg/Int32")
    call = asyncio.create_task(ros.call_service("/slow", MULT, {}))
    await asyncio.sleep(0)
    states: list[ConnectionState] = []
    ros.on_state_change(states.append)
    ros.disconnect()
    with pytest.raises(Disconnected):
        await call
    for i in range(3):
        await pub.publish({"data": i})
    assert sub.pending == 0 and pub.dropped == 1
    ros.reconnect()
    assert [(await sub.get(1))["data"] for _ in range(2)] == [1, 2]
    assert states == [ConnectionState.RECONNECTING, ConnectionState.CONNECTED]
    await ros.close()
    with pytest.raises(ConnectionClosed):
        ros.subscribe("/p", "std_msgs/msg/Int32")


async def test_offline_buffer_zero_raises() -> None:
    """With offline_buffer=0 a publish while disconnected raises Disconnected, as on the client."""
    ros = MockRos(offline_buffer=0)
    pub = ros.advertise("/p", "std_msgs/msg/Int32")
    ros.disconnect()
    with pytest.raises(Disconnected):
        await pub.publish({"data": 1})


async def test_close_fails_a_pending_call() -> None:
    """Closing the mock fails a call still waiting on its handler with ConnectionClosed."""
    ros = MockRos()
    never = asyncio.Event()

    async def handler(req: Any) -> Any:
        await never.wait()

    ros.advertise_service("/s", MULT, handler)
    call = asyncio.create_task(ros.call_service("/s", MULT, {}))
    await asyncio.sleep(0)
    await ros.close()
    with pytest.raises(ConnectionClosed):
        await call


async def test_injected_latched_message_reaches_late_subscribers() -> None:
    """inject(..., latch=True) is kept for subscriptions made afterwards."""
    ros = MockRos()
    ros.inject("/map", {"data": "grid"}, "std_msgs/msg/String", latch=True)
    late = ros.subscribe("/map", "std_msgs/msg/String")
    assert await late.get(1) == {"data": "grid"}


async def test_state_watchers_end_after_closed_and_callbacks_can_be_removed() -> None:
    """state_changes() yields each change and ends after CLOSED; a removed callback hears nothing."""
    ros = MockRos()
    heard: list[ConnectionState] = []
    remove = ros.on_state_change(heard.append)
    watcher = ros.state_changes()
    ros.disconnect()
    remove()
    ros.reconnect()
    await ros.close()
    assert [s async for s in watcher] == [
        ConnectionState.RECONNECTING, ConnectionState.CONNECTED, ConnectionState.CLOSED
    ]
    assert heard == [ConnectionState.RECONNECTING]
    with pytest.raises(ConnectionClosed):
        await ros.state_changes().next(1)


async def test_one_reader_per_subscription() -> None:
    """A second task waiting on the same subscription gets a UsageError, not a lost message."""
    ros = MockRos()
    sub = ros.subscribe("/one", "std_msgs/msg/Int32")
    first = asyncio.create_task(sub.get(5))
    await asyncio.sleep(0)
    with pytest.raises(UsageError, match="already awaited"):
        await sub.get(1)
    ros.inject("/one", {"data": 3})
    assert await first == {"data": 3}


async def test_async_callback_cannot_join_a_running_iteration() -> None:
    """Adding an async callback while a task iterates the subscription raises UsageError."""
    ros = MockRos()
    sub = ros.subscribe("/mix", "std_msgs/msg/Int32")
    reader = asyncio.create_task(sub.get(5))
    await asyncio.sleep(0)

    async def cb(msg: Any) -> None:
        pass

    with pytest.raises(UsageError, match="iterate it or give it async callbacks"):
        sub.on_message(cb)
    ros.inject("/mix", {"data": 1})
    assert await reader == {"data": 1}
