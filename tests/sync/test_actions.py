"""The blocking client's actions, on sync.MockRos and on the real bridge."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from msgs.mult_msgs.action import IntegrateImu
from roslibpy_lite import sync
from roslibpy_lite.actions import ActionError, GoalContext, GoalStatus
from roslibpy_lite.exceptions import RosTimeoutError

IMU = "mult_msgs/action/IntegrateImu"


def test_goal_feedback_result(ros: sync.Client, topic: str) -> None:
    """A blocking handler (in a worker thread) serves; the sender iterates feedback, gets the result."""
    def handler(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        assert threading.current_thread() is not threading.main_thread()
        for i in range(3):
            ctx.publish_feedback({"elapsed": float(i)})
        return {"samples": int(goal["seconds"])}

    with ros.advertise_action(topic, IMU, handler):
        goal = ros.send_goal(topic, IMU, {"seconds": 4.0})
        seen = [fb["elapsed"] for fb in goal.feedback(timeout=10)]
        # ROS may drop feedback under load (the bridge's path is a DDS topic): in order, no repeats
        assert seen and seen == sorted(set(seen)) and set(seen) <= {0.0, 1.0, 2.0}
        if isinstance(ros, sync.MockRos):
            assert seen == [0.0, 1.0, 2.0]
        outcome = goal.result(timeout=10)
        assert outcome.status is GoalStatus.SUCCEEDED and outcome.values["samples"] == 4
        assert goal.done() and goal.status is GoalStatus.SUCCEEDED


def test_cancel_and_typed(ros: sync.Client, topic: str) -> None:
    """cancel() from the caller's thread reaches a blocking handler; typed Result comes back."""
    started = threading.Event()

    def handler(goal: Any, ctx: GoalContext) -> Any:
        started.set()
        while not ctx.cancel_requested:
            threading.Event().wait(0.01)
        return IntegrateImu.Result(samples=1)

    with ros.advertise_action(topic, IntegrateImu, handler):
        goal = ros.send_goal(topic, IntegrateImu, IntegrateImu.Goal(seconds=9.0))
        assert started.wait(10)
        goal.cancel()
        outcome = goal.result(timeout=10)
        assert outcome.status is GoalStatus.CANCELED
        assert outcome.values == IntegrateImu.Result(samples=1)


def test_no_such_action(ros: sync.Client, topic: str) -> None:
    """A goal to an action nobody serves raises ActionError from result()."""
    goal = ros.send_goal(topic, IMU, {})
    with pytest.raises(ActionError, match="does not exist"):
        goal.result(timeout=15)


def test_feedback_goes_on_after_a_timeout(ros: sync.Client, topic: str) -> None:
    """A feedback timeout leaves the goal running; feedback() again gets what comes next."""
    go_on, got_it = threading.Event(), threading.Event()

    def handler(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        ctx.publish_feedback({"elapsed": 1.0})
        assert go_on.wait(10)
        ctx.publish_feedback({"elapsed": 2.0})
        assert got_it.wait(10)  # the result does not overtake the feedback on ROS's side
        return {"samples": 2}

    with ros.advertise_action(topic, IMU, handler):
        goal = ros.send_goal(topic, IMU, {"seconds": 1.0})
        feedback = goal.feedback(timeout=0.3)
        assert next(feedback)["elapsed"] == 1.0
        with pytest.raises(RosTimeoutError):
            next(feedback)
        assert not goal.done()
        go_on.set()
        feedback = goal.feedback(timeout=10)
        assert next(feedback)["elapsed"] == 2.0
        got_it.set()
        assert list(feedback) == []
        assert goal.result(timeout=10).values["samples"] == 2
