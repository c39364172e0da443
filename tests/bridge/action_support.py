"""rclpy action peers and wire helpers for the bridge's action tests."""

from __future__ import annotations

import asyncio
import importlib
import itertools
import threading
import time
from typing import Any

from test_msgs.action import Fibonacci

from tests.bridge.support import ros_future
from tests.helpers import action_server_answers, async_wait_until
from tests.op_peer import FIB as FIB
from tests.op_peer import fib as fib
from tests.op_peer import send_goal as send_goal

_action: Any = importlib.import_module("rclpy.action")
_groups: Any = importlib.import_module("rclpy.callback_groups")
_ids = itertools.count()

LONG = 15.0
"""Seconds a "long" goal runs unless canceled (tests end it much sooner)."""


WORK_AFTER_FEEDBACK = 0.05
"""Seconds a FibServer goal works between its last feedback and its result."""

class FibServer:
    """An rclpy Fibonacci action server that records goals and cancel requests.

    ``slow=True`` goals publish feedback every 50 ms until canceled (or ``LONG`` s);
    otherwise each goal computes its sequence at once, with one feedback per step.
    ``accept`` decides acceptance; ``gate``, if given, is awaited (in the goal
    callback) before answering.
    """

    def __init__(self, node: Any, name: str, *, slow: bool = False, accept: bool = True,
                 gate: threading.Event | None = None, abort: bool = False) -> None:
        self.slow = slow
        self.accept = accept
        self.gate = gate
        self.abort = abort
        self.goals: list[int] = []
        self.cancel_requests = threading.Event()
        self.finished = threading.Event()
        self.server = _action.ActionServer(
            node, Fibonacci, name, self._execute,
            goal_callback=self._goal,
            cancel_callback=self._cancel,
            callback_group=_groups.ReentrantCallbackGroup(),
            # rclpy's default depth of 10 loses goal requests when more arrive at once
            goal_service_qos_profile=_deep_services(),
            result_service_qos_profile=_deep_services(),
        )

    def _goal(self, goal: Any) -> Any:
        self.goals.append(goal.order)
        if self.gate is not None:
            self.gate.wait(LONG)
        return _action.GoalResponse.ACCEPT if self.accept else _action.GoalResponse.REJECT

    def _cancel(self, _handle: Any) -> Any:
        self.cancel_requests.set()
        return _action.CancelResponse.ACCEPT

    def _execute(self, handle: Any) -> Any:
        sequence = [0, 1]
        if self.slow:
            deadline = time.monotonic() + LONG
            while time.monotonic() < deadline and not self.finished.is_set():
                if handle.is_cancel_requested:
                    handle.canceled()
                    return Fibonacci.Result(sequence=sequence)
                handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
                time.sleep(0.05)
            handle.abort()
            return Fibonacci.Result(sequence=sequence)
        for i in range(1, handle.request.order):
            sequence.append(sequence[i] + sequence[i - 1])
            handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        # The work a real server does after its last feedback. Feedback (a topic) and the
        # result (a service answer) travel separately in ROS; the bridge relays feedback
        # heard up to 5 ms after the result, and a loaded machine can delay one topic
        # sample longer than that, which would make the feedback checks flaky.
        time.sleep(WORK_AFTER_FEEDBACK)
        if self.abort:
            handle.abort()
        else:
            handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    def destroy(self) -> None:
        """End slow goals and remove the server."""
        self.finished.set()
        self.server.destroy()


def _deep_services() -> Any:
    from rclpy.qos import QoSProfile

    return QoSProfile(depth=1000)  # type: ignore[no-untyped-call]


async def bridge_sees_action(ws: Any, name: str, timeout: float = 20.0,
                             gone: bool = False) -> None:
    """Poll ``/rosapi/action_servers`` until the bridge's graph lists ``name`` (with
    ``gone``: until it no longer does)."""
    deadline = time.monotonic() + timeout
    while True:
        rid = f"as{next(_ids)}"
        await ws.send({"op": "call_service", "service": "/rosapi/action_servers", "id": rid})
        reply = await ws.expect(op="service_response", id=rid)
        if (name in reply["values"]["action_servers"]) != gone:
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"the bridge {'still lists' if gone else 'never listed'} "
                                 f"the action {name}")
        await asyncio.sleep(0.02)


class RosCaller:
    """An rclpy action client of a (client-served) Fibonacci action, awaited from asyncio."""

    def __init__(self, node: Any, name: str) -> None:
        # A group of its own: a failed take on a destroyed client leaves its group busy.
        self.client = _action.ActionClient(
            node, Fibonacci, name, callback_group=_groups.MutuallyExclusiveCallbackGroup()
        )
        self.name = name
        self.feedback: asyncio.Queue[list[int]] = asyncio.Queue()
        self.loop = asyncio.get_running_loop()

    async def ready(self, timeout: float = 10.0) -> None:
        """Wait until the action server is matched and answers (see ``action_server_answers``)."""
        await async_wait_until(action_server_answers(self.client), timeout,
                               f"the action server {self.name} to answer")

    def _on_feedback(self, msg: Any) -> None:
        self.loop.call_soon_threadsafe(self.feedback.put_nowait, list(msg.feedback.sequence))

    async def send(self, order: int) -> Any:
        """Send a goal; returns the (accepted) rclpy goal handle."""
        future = self.client.send_goal_async(Fibonacci.Goal(order=order),
                                             feedback_callback=self._on_feedback)
        handle = await ros_future(future)
        assert handle.accepted
        return handle

    async def result(self, handle: Any, timeout: float = 10.0) -> Any:
        """The goal's result response (``.status``, ``.result``)."""
        return await ros_future(handle.get_result_async(), timeout)

    def destroy(self) -> None:
        """Remove the action client."""
        self.client.destroy()
