"""Issue 31's client behaviour in memory (MockRos, the real client's front over the in-memory
bridge): fresh values, fail fast while the link is down, partial dicts, one callback once,
``uint8[]`` as bytes. The same rules against a real bridge: tests/client/test_behaviour_bridge.py.
"""

from __future__ import annotations

import asyncio
import base64
import warnings
from typing import Any

import pytest

from msgs.sensor_msgs.msg import Imu
from msgs.std_msgs.msg import Header
from rosbridge_core.protocol import ops
from roslibpy_lite import (
    DuplicateCallbackWarning,
    InvalidMessageError,
    MockRos,
    NoMessageYet,
    NotConnected,
    PartialMessageWarning,
    RosTimeoutError,
    sync,
)

INT = "std_msgs/msg/Int32"
TWIST = "geometry_msgs/msg/Twist"
MULT = "mult_msgs/srv/MultFloats"


async def test_latest_is_the_newest_and_get_the_oldest() -> None:
    """latest() gives the newest message with a small age, whatever waits in the buffer;
    get() gives the oldest buffered one; before any message latest() says so."""
    async with MockRos() as ros:
        sub = await ros.subscribe("/n", INT)
        with pytest.raises(NoMessageYet, match="no message on /n yet"):
            sub.latest()
        for i in range(5):
            ros.inject("/n", {"data": i})
        msg, age = sub.latest()
        assert msg == {"data": 4}
        assert 0 <= age < 1.0
        assert await sub.get() == {"data": 0}
        assert sub.pending == 4  # latest() took nothing from the buffer


async def test_latest_gives_the_age_since_receipt_and_since_the_stamp() -> None:
    """latest().age counts from receipt, .stamp_age from the header stamp (5 s before here);
    a message without a header has no stamp age."""
    import time

    async with MockRos() as ros:
        sub = await ros.subscribe("/h", "std_msgs/msg/Header")
        typed = await ros.subscribe("/h", Header)
        then = time.time() - 5.0
        ros.inject("/h", {"stamp": {"sec": int(then), "nanosec": 0}, "frame_id": "f"})
        found = sub.latest()
        assert 0 <= found.age < 1.0
        assert found.stamp_age is None  # a Header is no message with a header
        imu = await ros.subscribe("/imu", "sensor_msgs/msg/Imu")
        ros.inject("/imu", {"header": {"stamp": {"sec": int(then), "nanosec": 500_000_000}}})
        assert 4.0 < imu.latest().stamp_age < 6.0  # type: ignore[operator]
        assert typed.latest().stamp_age is None
        typed_imu = await ros.subscribe("/imu", Imu)
        ros.inject("/imu", {"header": {"stamp": {"sec": int(then), "nanosec": 0}}})
        assert 4.0 < typed_imu.latest().stamp_age < 7.0  # type: ignore[operator]


async def test_next_is_the_first_message_after_the_call() -> None:
    """next() skips what was buffered before the call and returns the next message to come."""
    async with MockRos() as ros:
        sub = await ros.subscribe("/n", INT)
        ros.inject("/n", {"data": 1})
        waiting = asyncio.create_task(sub.next(5))
        await asyncio.sleep(0)  # the task is waiting for a message now
        ros.inject("/n", {"data": 2})
        assert await waiting == {"data": 2}
        with pytest.raises(RosTimeoutError, match=r"no message on /n within 0.05 s"):
            await sub.next(0.05)


async def test_collect_gathers_the_window_for_a_dataframe() -> None:
    """collect(seconds) returns the messages of the window with their receive times, which
    to_dataframe indexes by (the messages have no header)."""
    pytest.importorskip("pandas")
    from roslibpy_lite.data import to_dataframe

    async with MockRos() as ros:
        sub = await ros.subscribe("/n", INT)
        ros.inject("/n", {"data": 0})  # before the window: not collected

        async def feed() -> None:
            await asyncio.sleep(0)
            for i in range(1, 4):
                ros.inject("/n", {"data": i})

        feeding = asyncio.create_task(feed())
        got = await sub.collect(0.2)
        await feeding
        assert got == [{"data": 1}, {"data": 2}, {"data": 3}]
        frame = to_dataframe(got)
        assert list(frame["data"]) == [1, 2, 3]
        assert frame.index.name == "time"
        assert [t.timestamp() for t in frame.index] == pytest.approx(got.times, abs=1e-6)


async def test_fresh_reads_and_calls_fail_at_once_while_the_link_is_down() -> None:
    """While reconnecting: latest/next/call_service raise NotConnected naming the state, a
    waiting next() fails when the link drops, wait_connected/allow_stale opt out."""
    async with MockRos() as ros:
        ros.advertise_service("/mult", MULT, lambda req: {"result": req["x"] * req["y"]})
        sub = await ros.subscribe("/n", INT)
        ros.inject("/n", {"data": 1})
        waiting = asyncio.create_task(sub.next(5))
        await asyncio.sleep(0)
        ros.disconnect()
        with pytest.raises(NotConnected, match="state reconnecting"):
            await waiting
        with pytest.raises(NotConnected, match=r"latest message on /n: .*state reconnecting"):
            sub.latest()
        assert sub.latest(allow_stale=True).msg == {"data": 1}
        with pytest.raises(NotConnected, match=r"next message on /n: .*state reconnecting") as e:
            await sub.next(5)
        assert e.value.state == "reconnecting"
        with pytest.raises(NotConnected, match=r"call /mult: .*state reconnecting"):
            await ros.call_service("/mult", MULT, {"x": 2.0, "y": 3.0}, timeout=5)
        assert await sub.get() == {"data": 1}  # the buffer, left from before the drop
        with pytest.raises(RosTimeoutError, match=r"within 0.05 s \(state reconnecting\)"):
            await sub.get(0.05)
        call = asyncio.create_task(ros.call_service("/mult", MULT, {"x": 2.0, "y": 3.0},
                                                    timeout=5, wait_connected=True))
        fresh = asyncio.create_task(sub.next(5, wait_connected=True))
        await asyncio.sleep(0)
        ros.reconnect()
        ros.inject("/n", {"data": 2})
        assert await call == {"result": 6.0}
        assert await fresh == {"data": 2}


async def test_unbuffered_publish_fails_naming_the_state() -> None:
    """With offline_buffer=0, publishing while reconnecting raises NotConnected at once."""
    async with MockRos(offline_buffer=0) as ros:
        pub = await ros.advertise("/n", INT)
        ros.disconnect()
        with pytest.raises(NotConnected, match=r"publish to /n: .*state reconnecting"):
            await pub.publish({"data": 1})


async def test_partial_dicts_warn_once_per_type_and_field_set() -> None:
    """A dict missing fields is sent with defaults and warned about once per (type, fields),
    naming them; a complete or empty dict is not; another field set warns again."""
    async with MockRos() as ros:
        pub = await ros.advertise("/cmd", TWIST)
        with pytest.warns(PartialMessageWarning,
                          match=r"geometry_msgs/msg/Twist dict lacks linear.y, linear.z, angular"):
            await pub.publish({"linear": {"x": 1.0}})
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            await pub.publish({"linear": {"x": 2.0}})  # the same field set: said already
            await pub.publish({})
            await pub.publish({"linear": {"x": 1.0, "y": 0.0, "z": 0.0},
                               "angular": {"x": 0.0, "y": 0.0, "z": 0.5}})
        with pytest.warns(PartialMessageWarning, match="lacks linear"):
            await pub.publish({"angular": {"x": 0.0, "y": 0.0, "z": 1.0}})
        assert ros.published("/cmd")[0]["linear"] == {"x": 1.0}  # sent as given
        ros.advertise_service("/mult", MULT, lambda req: {"result": req["x"] * req["y"]})
        with pytest.warns(PartialMessageWarning, match=r"call /mult: .*MultFloats_Request dict lacks y"):
            assert await ros.call_service("/mult", MULT, {"x": 2.5}) == {"result": 0.0}


async def test_strict_refuses_partial_dicts_naming_the_fields() -> None:
    """strict=True on the client, the publisher or the call refuses a partial dict."""
    async with MockRos(strict=True) as ros:
        pub = await ros.advertise("/cmd", TWIST)
        with pytest.raises(InvalidMessageError, match=r"lacks linear.y, linear.z, angular"):
            await pub.publish({"linear": {"x": 1.0}})
        assert ros.published("/cmd") == []
        loose = await ros.advertise("/cmd", TWIST, strict=False)
        with pytest.warns(PartialMessageWarning):
            await loose.publish({"linear": {"x": 1.0}})
    async with MockRos() as ros:
        ros.advertise_service("/mult", MULT, lambda req: {"result": req["x"] * req["y"]})
        with pytest.raises(InvalidMessageError, match="MultFloats_Request dict lacks y"):
            await ros.call_service("/mult", MULT, {"x": 2.5}, strict=True)


async def test_the_same_callback_subscribed_again_runs_once() -> None:
    """Subscribing a callback again (the same function, or a re-run cell's new definition)
    moves it to the new subscription with a warning; other callbacks are not touched."""
    got: list[Any] = []
    cell = "def on_msg(msg):\n    got.append(msg['data'])\n"
    async with MockRos() as ros:
        first: dict[str, Any] = {"got": got}
        exec(cell, first)
        old = await ros.subscribe("/n", INT, first["on_msg"])
        again: dict[str, Any] = {"got": got}
        exec(cell, again)  # the cell run again: a new function object, the same code
        with pytest.warns(DuplicateCallbackWarning, match=r"callback on_msg already ran .* /n"):
            new = await ros.subscribe("/n", INT, again["on_msg"])
        assert old.closed and ros.subscriptions() == [new]
        with pytest.warns(DuplicateCallbackWarning):
            newer = await ros.subscribe("/n", INT, again["on_msg"])
        other: list[Any] = []
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            await ros.subscribe("/n", INT, lambda m: other.append(m["data"]))
            await ros.subscribe("/n", INT, lambda m: other.append(-m["data"]))
        ros.inject("/n", {"data": 7})
        assert got == [7]
        assert sorted(other) == [-7, 7]
        assert newer in ros.subscriptions() and new not in ros.subscriptions()


async def test_the_same_method_of_two_objects_is_two_callbacks() -> None:
    """``a.on_msg`` and ``b.on_msg`` (one class, two instances) on one topic are different
    callbacks: no warning, both subscriptions stay and each runs."""

    class Counter:
        def __init__(self) -> None:
            self.got: list[int] = []

        def on_msg(self, msg: dict[str, Any]) -> None:
            self.got.append(msg["data"])

    a, b = Counter(), Counter()
    async with MockRos() as ros:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            first = await ros.subscribe("/n", INT, a.on_msg)
            second = await ros.subscribe("/n", INT, b.on_msg)
        ros.inject("/n", {"data": 3})
        assert (a.got, b.got) == ([3], [3])
        assert ros.subscriptions() == [first, second]


async def test_byte_arrays_are_bytes_under_json() -> None:
    """A uint8[] field arrives as bytes in a dict (JSON carries base64 text); such a dict
    can be published again as it is."""
    data = bytes(range(256)) * 3
    image = {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "cam"}, "height": 2,
             "width": 384, "encoding": "mono8", "is_bigendian": 0, "step": 384, "data": data}
    async with MockRos() as ros:
        sub = await ros.subscribe("/img", "sensor_msgs/msg/Image")
        ros.inject("/img", {**image, "data": base64.b64encode(data).decode()})
        msg = await sub.get(1)
        assert type(msg["data"]) is bytes and msg["data"] == data
        pub = await ros.advertise("/img2", "sensor_msgs/msg/Image")
        await pub.publish(msg)
        assert ros.published("/img2")[0]["data"] == base64.b64encode(data).decode()
    text = ops.encode(ops.Publish("/img", {"data": b"\x00\x01"}))
    assert '"data":"AAE="' in text


def test_blocking_client_has_the_same_fresh_reads() -> None:
    """sync.MockRos: latest, next, collect and subscriptions() as on the asyncio client."""
    import threading

    with sync.MockRos() as ros:
        sub = ros.subscribe("/n", INT)
        ros.inject("/n", {"data": 1})
        ros.inject("/n", {"data": 2})
        assert sub.latest().msg == {"data": 2}
        timer = threading.Timer(0.05, ros.inject, ("/n", {"data": 3}))
        timer.start()
        assert sub.next(5) == {"data": 3}
        timer.join()
        assert ros.subscriptions() == [sub]
        ros.disconnect()
        with pytest.raises(NotConnected, match="state reconnecting"):
            sub.next(5)
        ros.reconnect()
        assert sub.collect(0.01) == []


async def test_partial_goal_dicts_are_warned_about_or_refused() -> None:
    """A goal dict that leaves fields out is warned about once, or refused by a strict client."""
    nested = "test_msgs/action/NestedMessage"
    async with MockRos() as ros:
        await ros.advertise_action("/nest", nested, lambda goal, ctx: {})
        with pytest.warns(PartialMessageWarning, match=r"goal to /nest: .* lacks nested_field, "
                                                       r"nested_different_pkg"):
            goal = await ros.send_goal("/nest", nested, {"nested_field_no_pkg": {}})
        await goal.result(5)
    async with MockRos(strict=True) as ros:
        with pytest.raises(InvalidMessageError, match="lacks nested_field_no_pkg"):
            await ros.send_goal("/nest", nested, {"nested_field": {}})


def test_blocking_client_warns_on_the_callers_thread() -> None:
    """sync: subscribing a callback again warns at the caller's line (a notebook cell's
    output), not on the loop thread; the callback still runs once."""
    got: list[Any] = []
    with sync.MockRos() as ros:
        ros.subscribe("/n", INT, got.append)
        with pytest.warns(DuplicateCallbackWarning) as caught:
            ros.subscribe("/n", INT, got.append)
        assert caught[0].filename == __file__
        ros.inject("/n", {"data": 1})
        ros.drain()
        assert got == [{"data": 1}]
        assert len(ros.subscriptions()) == 1
