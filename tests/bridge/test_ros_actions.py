"""The bridge's shared rclpy action client, in process: the reply-path probe and clean-up."""

from __future__ import annotations

import asyncio
import os
from collections.abc import AsyncIterator
from typing import Any

import pytest

from bridge_server.rclpy_graph import actions as ros_actions
from bridge_server.rclpy_graph.actions import SharedActionClient
from bridge_server.rclpy_graph.node import RosNode
from rosbridge_core.protocol.goal_status import GoalStatus
from tests.bridge.action_support import FibServer, fib
from tests.helpers import async_wait_until


class _Listener:
    """Collects what one goal reports, on the loop."""

    def __init__(self) -> None:
        self.done = asyncio.Event()
        self.accepted = False
        self.outcome: tuple[int, Any] | None = None

    def on_accepted(self) -> None:
        self.accepted = True

    def on_rejected(self) -> None:
        self.done.set()

    def on_feedback(self, feedback: Any) -> None:
        pass

    def on_cancel_answer(self, code: int) -> None:
        pass

    def on_result(self, status: int, result: Any) -> None:
        self.outcome = (status, result)
        self.done.set()

    def on_failed(self, why: str) -> None:
        self.done.set()


@pytest.fixture
async def bridge_ros() -> AsyncIterator[RosNode]:
    """The bridge's ROS side (as the bridge runs it), in this process."""
    ros = RosNode(asyncio.get_running_loop(), name=f"ros_actions_test_{os.getpid()}")
    ros.start()
    yield ros
    ros.close()


async def _on_executor(ros: RosNode, fn: Any) -> Any:
    """Run ``fn`` on the bridge's executor thread; its return value."""
    loop = asyncio.get_running_loop()
    result: asyncio.Future[Any] = loop.create_future()
    def run() -> None:
        loop.call_soon_threadsafe(result.set_result, fn())

    ros.in_executor(run)
    return await asyncio.wait_for(result, 10.0)


async def test_a_new_server_is_probed_and_goals_leave_nothing_behind(
    bridge_ros: RosNode, ros_node: Any, topic: str
) -> None:
    """ready() waits for a probe's answer; after many goals rclpy's request maps are empty."""
    from test_msgs.action import Fibonacci

    server = FibServer(ros_node, topic)
    shared = SharedActionClient(bridge_ros, topic, Fibonacci)
    try:
        await async_wait_until(shared.matched, 20.0, "the action server to be matched")
        assert not shared.ready()  # matched, but not yet heard from
        await async_wait_until(shared.ready, 10.0, "the probe's answer")
        assert shared.confirmed

        listeners = [_Listener() for _ in range(20)]
        for order, listener in enumerate(listeners):
            shared.send(Fibonacci.Goal(order=order % 5 + 1), listener, feedback=False)
        await asyncio.wait_for(asyncio.gather(*(lis.done.wait() for lis in listeners)), 20.0)
        for order, listener in enumerate(listeners):
            assert listener.accepted and listener.outcome is not None
            status, result = listener.outcome
            assert status == GoalStatus.SUCCEEDED
            assert list(result.sequence) == fib(order % 5 + 1)

        client = shared.client
        left = await _on_executor(bridge_ros, lambda: {
            "goal requests": len(client._pending_goal_requests),
            "goal sequence numbers": len(client._goal_sequence_number_to_goal_id),
            "result requests": len(client._pending_result_requests),
            "result sequence numbers": len(client._result_sequence_number_to_goal_id),
            "probes": len(shared._probes),
        })
        assert left == dict.fromkeys(left, 0)
    finally:
        shared.destroy()
        server.destroy()


async def test_a_server_that_never_answers_the_probe_is_trusted_in_the_end(
    bridge_ros: RosNode, ros_node: Any, topic: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With probes that go unanswered, ready() turns true after PROBE_GIVE_UP seconds."""
    from test_msgs.action import Fibonacci

    monkeypatch.setattr(ros_actions, "PROBE_GIVE_UP", 0.3)
    monkeypatch.setattr(SharedActionClient, "_probe", lambda self: None)
    server = FibServer(ros_node, topic)
    shared = SharedActionClient(bridge_ros, topic, Fibonacci)
    try:
        await async_wait_until(shared.matched, 20.0, "the action server to be matched")
        assert not shared.ready()
        await async_wait_until(shared.ready, 10.0, "ready() after the give-up time")
        assert shared.confirmed
    finally:
        shared.destroy()
        server.destroy()
