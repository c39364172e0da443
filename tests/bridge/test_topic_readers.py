"""The topic readers (bridge_server/rclpy_graph/reader.py): the middleware waking the event loop
through an eventfd, and the reader thread that serves where that cannot work."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from typing import Any

import pytest
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from std_msgs.msg import String

from bridge_server.rclpy_graph import reader as ros_reader
from bridge_server.rclpy_graph.node import RosNode
from tests.bridge.support import bridge_sees_topic, wait_subscribers
from tests.helpers import async_wait_until

KINDS = {"auto": "loop", "thread": "thread"}  # --topic-reader -> the reader it gives here


def _take_all(handle: Any, limit: int) -> tuple[list[bytes], int]:
    batch: list[bytes] = []
    while len(batch) < limit and (taken := handle.take_message(String, True)) is not None:
        batch.append(taken[0])
    return batch, len(batch)


def _open_fds() -> set[int]:
    return {int(fd) for fd in os.listdir("/proc/self/fd")}


@pytest.mark.parametrize("kind", KINDS)
async def test_a_reader_survives_a_failing_take(kind: str, caplog: pytest.LogCaptureFixture) -> None:
    """A subscription whose taking raises is logged; the reader serves the others on, lets go
    of a subscription that is removed, and stops with the bridge's ROS side (leaving no
    descriptor and no thread behind)."""
    loop = asyncio.get_running_loop()
    fds_before = _open_fds()
    ros = RosNode(loop, name=f"reader_test_{kind}_{os.getpid()}", topic_reader=kind)
    ros.start()
    reader = ros.reader
    assert reader is not None and ros.reader_kind == KINDS[kind]
    got: asyncio.Queue[bytes] = asyncio.Queue()
    qos = QoSProfile(depth=10)  # type: ignore[no-untyped-call]

    def failing(handle: Any, _limit: int) -> tuple[list[bytes], int]:
        handle.take_message(String, True)
        raise RuntimeError("boom in a take")

    def deliver(batch: list[bytes], _stamp_ns: int) -> None:
        for data in batch:
            got.put_nowait(data)

    try:
        reader.subscribe(String, "/reader_bad", qos, failing, deliver)
        good = reader.subscribe(String, "/reader_good", qos, _take_all, deliver)
        bad_pub = ros.node.create_publisher(String, "/reader_bad", qos)
        good_pub = ros.node.create_publisher(String, "/reader_good", qos)
        await wait_subscribers(bad_pub)
        await wait_subscribers(good_pub)
        with caplog.at_level(logging.ERROR, logger="bridge_server.rclpy_graph.node"):
            bad_pub.publish(String(data="lost"))
            await async_wait_until(lambda: reader.errors.count >= 1, 10.0, "the failing take")
            good_pub.publish(String(data="hello"))
            data = await asyncio.wait_for(got.get(), 10.0)
        assert deserialize_message(data, String).data == "hello"
        assert got.empty()
        assert "taking messages of /reader_bad failed" in caplog.text
        assert "boom in a take" in caplog.text
        reader.unsubscribe(good)
        await async_wait_until(lambda: good_pub.get_subscription_count() == 0, 10.0,
                               "the removed subscription gone from the graph")
    finally:
        ros.close()
    thread = getattr(reader, "_thread", None)
    assert thread is None or not thread.is_alive()
    assert not [fd for fd in _open_fds() - fds_before if _is_eventfd(fd)], "an eventfd left open"


def _is_eventfd(fd: int) -> bool:
    try:
        return os.readlink(f"/proc/self/fd/{fd}") == "anon_inode:[eventfd]"
    except OSError:
        return False


async def test_the_loop_reader_comes_back_for_what_one_batch_left(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The loop reader takes what is queued a batch at a time: what one batch left is taken
    without a new message arriving (the middleware says only what is new), after the loop's
    other work had its turn."""
    monkeypatch.setattr(ros_reader, "MAX_BATCH", 1)
    loop = asyncio.get_running_loop()
    ros = RosNode(loop, name=f"reader_batch_{os.getpid()}")
    ros.start()
    reader = ros.reader
    assert reader is not None and ros.reader_kind == "loop"
    qos = QoSProfile(depth=10)  # type: ignore[no-untyped-call]
    limits: list[int] = []
    got: list[str] = []
    done = asyncio.Event()

    def take(handle: Any, limit: int) -> tuple[list[bytes], int]:
        limits.append(limit)
        return _take_all(handle, limit)

    def deliver(batch: list[bytes], _stamp_ns: int) -> None:
        got.extend(deserialize_message(data, String).data for data in batch)
        if len(got) == 3:
            done.set()

    try:
        reader.subscribe(String, "/reader_batch", qos, take, deliver)
        pub = ros.node.create_publisher(String, "/reader_batch", qos)
        await wait_subscribers(pub)
        for i in range(3):  # in one turn of the loop: usually all come before the first take
            pub.publish(String(data=str(i)))
        await asyncio.wait_for(done.wait(), 10.0)
        assert got == ["0", "1", "2"]
        assert set(limits) == {1}
    finally:
        ros.close()


@pytest.mark.parametrize("kind", KINDS)
async def test_a_bridge_serves_topics_with_either_reader(
    kind: str, make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """``--topic-reader``: the bridge says which reader it runs, and a client gets what an
    rclpy publisher sends, in order, through it."""
    from tests.helpers import open_wire

    bridge = make_bridge("--topic-reader", kind)
    assert f"(topic reader: {KINDS[kind]})" in bridge.wait_for_line(r"ROS node /\S+ on ")
    pub = ros_node.create_publisher(String, topic, 10)
    ws = await open_wire(bridge.url)
    try:
        # the bridge knows the publisher before it subscribes: a reader that has not yet
        # matched the writer drops what the writer sends it
        await bridge_sees_topic(ws, topic)
        await ws.send({"op": "subscribe", "topic": topic, "type": "std_msgs/String"})
        await wait_subscribers(pub)
        for i in range(20):
            pub.publish(String(data=str(i)))
        got = [(await ws.expect(op="publish", topic=topic))["msg"]["data"] for _ in range(20)]
        assert got == [str(i) for i in range(20)]
    finally:
        await ws.close()


async def test_the_loop_reader_serves_a_service_on_the_loop(
    monkeypatch: pytest.MonkeyPatch, ros_node: Any, caplog: pytest.LogCaptureFixture
) -> None:
    """A service the loop reader serves: each request wakes the loop with its header, answers
    reach the caller they belong to (out of order too), what one batch left is taken without
    a new request, a failing handler is logged while the others are answered, and removing it
    takes it off the graph and leaves no eventfd open."""
    from std_srvs.srv import SetBool

    from tests.bridge.support import ros_future, wait_service

    monkeypatch.setattr(ros_reader, "MAX_BATCH", 1)
    loop = asyncio.get_running_loop()
    fds_before = _open_fds()
    ros = RosNode(loop, name=f"reader_service_{os.getpid()}")
    ros.start()
    reader = ros.reader
    assert isinstance(reader, ros_reader.LoopReader)
    name = f"/reader_service_{os.getpid()}"
    waiting: list[tuple[Any, Any]] = []
    arrived = asyncio.Event()

    def on_request(request: Any, header: Any) -> None:
        assert asyncio.get_running_loop() is loop  # on the loop, not a middleware thread
        if request.data is False and not waiting:
            raise RuntimeError("boom in a handler")
        waiting.append((request, header))
        if len(waiting) == 3:
            arrived.set()

    try:
        svc = reader.serve(SetBool, name, QoSProfile(depth=10), on_request)  # type: ignore[no-untyped-call]
        client = ros_node.create_client(SetBool, name)
        await wait_service(client)
        with caplog.at_level(logging.ERROR, logger="bridge_server.rclpy_graph.node"):
            client.call_async(SetBool.Request(data=False))  # the handler raises: not answered
            await async_wait_until(lambda: reader.errors.count >= 1, 10.0, "the failing handler")
        assert "serving a request to" in caplog.text and "boom in a handler" in caplog.text
        calls = [client.call_async(SetBool.Request(data=True)) for _ in range(3)]
        await asyncio.wait_for(arrived.wait(), 10.0)
        for i, (_request, header) in reversed(list(enumerate(waiting))):
            svc.respond(SetBool.Response(success=True, message=str(i)), header)
        answers = [(await ros_future(call)).message for call in calls]
        assert answers == ["0", "1", "2"]
        reader.unserve(svc)
        await async_wait_until(lambda: not client.service_is_ready(), 10.0, "the service gone")
    finally:
        ros.close()
    assert not [fd for fd in _open_fds() - fds_before if _is_eventfd(fd)], "an eventfd left open"


@pytest.mark.parametrize("kind", KINDS)
async def test_a_bridge_serves_client_services_with_either_reader(
    kind: str, make_bridge: Any, ros_node: Any, topic: str
) -> None:
    """A service a client advertises answers rclpy callers through a bridge with either
    reader (the loop takes the requests itself; the thread reader leaves them to rclpy's
    executor), each answer reaching its own caller when several wait at once."""
    from std_srvs.srv import SetBool

    from tests.bridge.support import ros_future, wait_service
    from tests.helpers import open_wire

    bridge = make_bridge("--topic-reader", kind)
    ws = await open_wire(bridge.url)
    try:
        await ws.send({"op": "advertise_service", "service": topic, "type": "std_srvs/SetBool"})
        client = ros_node.create_client(SetBool, topic)
        await wait_service(client)
        calls = [client.call_async(SetBool.Request(data=i % 2 == 0)) for i in range(4)]
        requests = [await ws.expect(op="call_service", service=topic) for _ in calls]
        for request in reversed(requests):  # answered last first
            await ws.send({"op": "service_response", "service": topic, "id": request["id"],
                           "result": True,
                           "values": {"success": request["args"]["data"],
                                      "message": request["id"]}})
        answers = [await ros_future(call) for call in calls]
        assert [a.success for a in answers] == [True, False, True, False]
        assert [a.message for a in answers] == [r["id"] for r in requests]
    finally:
        await ws.close()


async def test_the_loop_reader_takes_every_queued_request_before_handing_one_on(
    ros_node: Any,
) -> None:
    """Requests that wait together are all taken before the first is handed on: handing one on
    writes to a client, which on loopback may run on the loop's CPU at once, so nothing of
    the loop's own work (the last, empty take) is left to wait behind it."""
    from std_srvs.srv import SetBool

    from tests.bridge.support import wait_service

    loop = asyncio.get_running_loop()
    ros = RosNode(loop, name=f"reader_batch_{os.getpid()}")
    ros.start()
    reader = ros.reader
    assert isinstance(reader, ros_reader.LoopReader)
    name = f"/reader_batch_{os.getpid()}"
    left_when_handed: list[bool] = []
    seen = [0]  # requests handed on or taken by the handler
    handed = asyncio.Event()

    def on_request(request: Any, header: Any) -> None:
        # What is still queued when a request is handed on (taken here: it is not answered).
        got = svc.handle.service_take_request(SetBool.Request)
        left = got is not None and got[1] is not None
        left_when_handed.append(left)
        seen[0] += 1 + left
        if seen[0] >= 3:
            handed.set()

    try:
        svc = reader.serve(SetBool, name, QoSProfile(depth=10), on_request)  # type: ignore[no-untyped-call]
        client = ros_node.create_client(SetBool, name)
        await wait_service(client)
        loop.remove_reader(svc.fd)  # the three requests wait together until the loop looks
        for _ in range(3):
            client.call_async(SetBool.Request(data=True))
        woken = [0]

        def all_queued() -> bool:
            with contextlib.suppress(BlockingIOError):
                woken[0] += os.eventfd_read(svc.fd)
            return woken[0] >= 3

        await async_wait_until(all_queued, 10.0, "three requests waiting")
        os.eventfd_write(svc.fd, woken[0])
        loop.add_reader(svc.fd, reader._request_ready, svc)
        await asyncio.wait_for(handed.wait(), 10.0)
        assert left_when_handed == [False, False, False]
    finally:
        ros.close()
