"""The bridge's ROS side survives an executor round that raises."""

from __future__ import annotations

import asyncio
import logging
import os
from typing import Any

import pytest

from bridge_server.ros import RosNode
from tests.helpers import async_wait_until


async def test_a_failing_executor_round_does_not_stop_ros(caplog: pytest.LogCaptureFixture) -> None:
    """A ROS callback that raises is logged once, and work handed to the executor still runs."""
    loop = asyncio.get_running_loop()
    ros = RosNode(loop, name=f"spin_test_{os.getpid()}")
    ros.start()
    try:
        timer: Any = None

        def boom() -> None:
            timer.cancel()
            raise RuntimeError("boom in a ROS callback")

        with caplog.at_level(logging.ERROR, logger="bridge_server.ros"):
            timer = ros.node.create_timer(0.01, boom)
            await async_wait_until(lambda: ros.spin_errors >= 1, 10.0, "the failing round")
            done = asyncio.Event()
            ros.in_executor(lambda: loop.call_soon_threadsafe(done.set))
            await asyncio.wait_for(done.wait(), 10.0)
        assert ros.spin_errors == 1
        assert "ROS executor round failed; spinning on" in caplog.text
        assert "boom in a ROS callback" in caplog.text
    finally:
        ros.close()


async def test_the_topic_reader_survives_a_failing_take(caplog: pytest.LogCaptureFixture) -> None:
    """A subscription whose taking raises is logged; the reader serves the others on, lets go
    of a subscription that is removed, and stops with the bridge's ROS side."""
    from rclpy.qos import QoSProfile
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    loop = asyncio.get_running_loop()
    ros = RosNode(loop, name=f"reader_test_{os.getpid()}")
    ros.start()
    reader = ros.reader
    assert reader is not None
    got: asyncio.Queue[bytes] = asyncio.Queue()
    qos = QoSProfile(depth=10)  # type: ignore[no-untyped-call]

    def failing(handle: Any) -> list[bytes]:
        handle.take_message(String, True)
        raise RuntimeError("boom in a take")

    def take_all(handle: Any) -> list[bytes]:
        batch = []
        while (taken := handle.take_message(String, True)) is not None:
            batch.append(taken[0])
        return batch

    def deliver(batch: list[bytes], _stamp_ns: int) -> None:
        for data in batch:
            got.put_nowait(data)

    try:
        reader.subscribe(String, "/reader_bad", qos, failing, deliver)
        good = reader.subscribe(String, "/reader_good", qos, take_all, deliver)
        bad_pub = ros.node.create_publisher(String, "/reader_bad", qos)
        good_pub = ros.node.create_publisher(String, "/reader_good", qos)
        await async_wait_until(
            lambda: bad_pub.get_subscription_count() == 1 == good_pub.get_subscription_count(),
            10.0, "the reader's subscriptions matched")
        with caplog.at_level(logging.ERROR, logger="bridge_server.ros"):
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
    assert reader._thread is not None and not reader._thread.is_alive()
