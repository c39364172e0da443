"""The bridge's ROS side survives an executor round that raises."""

from __future__ import annotations

import asyncio
import logging
import os
from typing import Any

import pytest

from bridge_server.rclpy_graph.node import RosNode
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

        with caplog.at_level(logging.ERROR, logger="bridge_server.rclpy_graph.node"):
            timer = ros.node.create_timer(0.01, boom)
            await async_wait_until(lambda: ros.spin_errors >= 1, 10.0, "the failing round")
            done = asyncio.Event()
            def wake() -> None:
                loop.call_soon_threadsafe(done.set)

            ros.in_executor(wake)
            await asyncio.wait_for(done.wait(), 10.0)
        assert ros.spin_errors == 1
        assert "ROS executor round failed; spinning on" in caplog.text
        assert "boom in a ROS callback" in caplog.text
    finally:
        ros.close()
