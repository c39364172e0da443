"""Action scenarios: sending, cancelling and serving ROS actions through a stock client.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from tests.helpers import action_server_answers, wait_until
from tests.peers.peer import PeerError, PeerProcess
from tests.peers.scenarios.support import (
    DEADLINE,
    _module,
    _own_group,
)

# -- actions ----------------------------------------------------------------------------------


def _wait_future(future: Any, what: str) -> Any:
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(DEADLINE), f"no {what} within {DEADLINE} s"
    return future.result()


def send_goal(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer sends a Fibonacci goal to an rclpy action server and gets the result."""
    from test_msgs.action import Fibonacci

    def execute(goal_handle: Any) -> Any:
        sequence = [0, 1]
        for i in range(1, goal_handle.request.order):
            sequence.append(sequence[i] + sequence[i - 1])
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
        goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    server = _module("rclpy.action").ActionServer(
        node, Fibonacci, topic, execute, callback_group=_own_group()
    )
    try:
        value = peer.request(
            "send_goal", action=topic, type="test_msgs/action/Fibonacci", goal={"order": 5},
            goal_timeout=5.0, timeout=DEADLINE,
        )
    finally:
        server.destroy()
    assert value["status"] == 4  # SUCCEEDED
    assert value["values"]["sequence"] == [0, 1, 1, 2, 3, 5]
    for fb in value["feedback"]:
        assert fb["sequence"] == [0, 1, 1, 2, 3, 5][: len(fb["sequence"])]


def serve_action(peer: PeerProcess, node: Any, topic: str) -> None:
    """The peer serves a Fibonacci action; an rclpy action client gets feedback and the result."""
    from action_msgs.msg import GoalStatus
    from test_msgs.action import Fibonacci

    peer.request(
        "advertise_action", action=topic, type="test_msgs/action/Fibonacci", handler="fibonacci"
    )
    client = _module("rclpy.action").ActionClient(
        node, Fibonacci, topic, callback_group=_own_group()
    )
    answers = action_server_answers(client)
    try:

        def ready_or_refused() -> Any:
            refused = [e for e in peer.new_events() if e.get("event") == "status"]
            return refused or answers()

        outcome = wait_until(ready_or_refused, DEADLINE, f"{topic} action server in the graph")
        assert outcome is True, f"the bridge refused advertise_action: {outcome}"
        handle = _wait_future(client.send_goal_async(Fibonacci.Goal(order=5)), "goal acceptance")
        assert handle.accepted
        result = _wait_future(handle.get_result_async(), "action result")
    finally:
        client.destroy()
    assert result.status == GoalStatus.STATUS_SUCCEEDED
    assert list(result.result.sequence) == [0, 1, 1, 2, 3, 5]


def serve_action_canceled(peer: PeerProcess, node: Any, topic: str) -> None:
    """An rclpy client cancels a goal the peer serves; the peer's cancel handler ends it canceled."""
    from action_msgs.msg import GoalStatus
    from test_msgs.action import Fibonacci

    peer.request(
        "advertise_action", action=topic, type="test_msgs/action/Fibonacci",
        handler="until_canceled",
    )
    client = _module("rclpy.action").ActionClient(
        node, Fibonacci, topic, callback_group=_own_group()
    )
    first_feedback = threading.Event()
    try:
        wait_until(action_server_answers(client), DEADLINE, f"{topic} action server answering")
        goal = client.send_goal_async(
            Fibonacci.Goal(order=3), feedback_callback=lambda _msg: first_feedback.set()
        )
        handle = _wait_future(goal, "goal acceptance")
        assert handle.accepted
        result_future = handle.get_result_async()
        assert first_feedback.wait(DEADLINE), "no feedback from the peer"
        _wait_future(handle.cancel_goal_async(), "cancel answer")
        result = _wait_future(result_future, "action result")
    finally:
        client.destroy()
    assert result.status == GoalStatus.STATUS_CANCELED
    assert list(result.result.sequence) == [0, 1]


# -- cancelling --------------------------------------------------------------------------------


def cancel_goal(peer: PeerProcess, node: Any, topic: str) -> None:
    """A goal the client cancels after its first feedback ends canceled, through the client's error path."""
    from test_msgs.action import Fibonacci

    action = _module("rclpy.action")
    canceled, finished = threading.Event(), threading.Event()

    def execute(goal_handle: Any) -> Any:
        sequence = [0, 1]
        deadline = time.monotonic() + DEADLINE
        while time.monotonic() < deadline and not finished.is_set():  # a long, cancellable job
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                canceled.set()
                return Fibonacci.Result(sequence=sequence)
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
            time.sleep(0.05)
        goal_handle.abort()
        return Fibonacci.Result(sequence=sequence)

    server = action.ActionServer(
        node, Fibonacci, topic, execute,
        cancel_callback=lambda _request: action.CancelResponse.ACCEPT,
        callback_group=_module("rclpy.callback_groups").ReentrantCallbackGroup(),
    )
    try:
        # As upstream rosbridge does: a goal that ran to CANCELED ends with result true, its
        # status and values, so a stock client's result callback hears of it (roslibpy's own
        # upstream test_cancel waits for exactly that).
        # roslib (npm) reports a canceled goal as an error that names it, with its values.
        try:
            value = peer.request(
                "send_goal", action=topic, type="test_msgs/action/Fibonacci", goal={"order": 50},
                cancel_after_feedback=True, timeout=DEADLINE,
            )
        except PeerError as exc:
            assert "canceled" in str(exc).lower() and '"sequence":[0,1]' in str(exc), exc
        else:
            assert value["status"] == 5, value  # CANCELED
            assert value["values"]["sequence"] == [0, 1], value
        assert canceled.is_set(), "the rclpy action server never saw the cancel request"
    finally:
        finished.set()
        server.destroy()
