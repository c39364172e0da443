"""Actions, one suite on two backends: MockRos and the client on the real bridge.

The action is served by the client itself (``advertise_action``; on the real
bridge through the bridge's rclpy action server and client), so every case
runs the whole path: goal out, goal in, feedback, result, cancel.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

import pytest

from msgs.mult_msgs.action import IntegrateImu
from roslibpy_lite import InvalidMessageError, MockRos, Ros, StatusError, UsageError
from roslibpy_lite.actions import ActionError, GoalContext, GoalStatus

IMU = "mult_msgs/action/IntegrateImu"


def vec(x: float) -> dict[str, float]:
    """A geometry_msgs/Vector3 dict along x."""
    return {"x": x, "y": 0.0, "z": 0.0}


async def counting(goal: Any, ctx: GoalContext) -> dict[str, Any]:
    """Feedback 1, 2, 3 (as sums), then the total ``seconds``."""
    for i in range(1, 4):
        ctx.publish_feedback({"sum": vec(float(i)), "elapsed": float(i)})
        await asyncio.sleep(0.01)
    return {"total": vec(goal["seconds"]), "samples": 3}


async def test_goal_feedback_and_result(ros: Ros, topic: str) -> None:
    """A goal reaches the served handler; its feedback and result come back (dicts)."""
    await ros.advertise_action(topic, IMU, counting)
    goal = await ros.send_goal(topic, "mult_msgs/IntegrateImu", {"seconds": 2.5})
    feedback = [fb async for fb in goal]
    outcome = await goal.result(timeout=10)
    assert outcome.status is GoalStatus.SUCCEEDED and outcome.succeeded
    assert outcome.values == {"total": vec(2.5), "samples": 3}
    sums = [fb["sum"]["x"] for fb in feedback]
    # ROS may drop feedback under load (on the bridge it is a DDS topic): in order, no repeats
    assert sums and sums == sorted(set(sums)) and set(sums) <= {1.0, 2.0, 3.0}
    if isinstance(ros, MockRos):
        assert sums == [1.0, 2.0, 3.0]
    assert goal.status is GoalStatus.SUCCEEDED and goal.done()


async def test_typed_goal_result_and_feedback(ros: Ros, topic: str) -> None:
    """With the msgs action class, the handler gets a Goal and the sender Feedback/Result."""
    seen: list[Any] = []

    def handler(goal: Any, ctx: GoalContext) -> Any:  # sync: runs in a thread
        seen.append(goal)
        ctx.publish_feedback(IntegrateImu.Feedback(elapsed=0.5))
        return IntegrateImu.Result(samples=7)

    await ros.advertise_action(topic, IntegrateImu, handler)
    got: list[Any] = []
    goal = await ros.send_goal(topic, IntegrateImu, IntegrateImu.Goal(seconds=1.5),
                               on_feedback=got.append)
    outcome = await goal.result(timeout=10)
    assert seen == [IntegrateImu.Goal(seconds=1.5)]
    assert outcome.values == IntegrateImu.Result(samples=7)
    assert got == [IntegrateImu.Feedback(elapsed=0.5)] or (not isinstance(ros, MockRos)
                                                            and got == [])  # lost on the way


async def test_cancel(ros: Ros, topic: str) -> None:
    """cancel() reaches the handler as cancel_requested; returning then ends it CANCELED."""
    async def until_canceled(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        ctx.publish_feedback({"elapsed": 0.1})
        await ctx.wait_cancel()
        return {"samples": 1}

    await ros.advertise_action(topic, IMU, until_canceled)
    goal = await ros.send_goal(topic, IMU, {"seconds": 100.0})
    async for _ in goal:
        await goal.cancel()
        assert goal.status is GoalStatus.CANCELING
    outcome = await goal.result(timeout=10)
    assert outcome.status is GoalStatus.CANCELED
    assert outcome.values["samples"] == 1
    with pytest.raises(ActionError, match="CANCELED"):
        await goal.result(raise_on_failure=True)


async def test_accepted_is_known_before_any_feedback(ros: Ros, topic: str) -> None:
    """accepted() returns when the bridge says the server took the goal (status ACCEPTED,
    no feedback yet); for a goal that never ran it raises why."""
    async def quiet(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        await ctx.wait_cancel()
        return {"samples": 0}

    await ros.advertise_action(topic, IMU, quiet)
    goal = await ros.send_goal(topic, IMU, {"seconds": 100.0})
    await goal.accepted(timeout=10)
    assert goal.status is GoalStatus.ACCEPTED and goal.last_feedback is None
    await goal.cancel()
    assert (await goal.result(timeout=10)).status is GoalStatus.CANCELED
    nobody = await ros.send_goal(topic + "_nobody", IMU, {"seconds": 1.0})
    with pytest.raises(ActionError, match="does not exist"):
        await nobody.accepted(timeout=15)


async def test_handler_that_raises_aborts(ros: Ros, topic: str) -> None:
    """A handler that raises aborts the goal; the sender sees ABORTED."""
    async def broken(goal: Any, ctx: GoalContext) -> None:
        raise RuntimeError("gyro unplugged")

    server = await ros.advertise_action(topic, IMU, broken)
    goal = await ros.send_goal(topic, IMU, {"seconds": 1.0})
    outcome = await goal.result(timeout=10)
    assert outcome.status is GoalStatus.ABORTED
    with pytest.raises(ActionError) as err:
        await goal.result(raise_on_failure=True)
    assert err.value.status is GoalStatus.ABORTED
    assert server.failures == 1


async def test_no_such_action_server(ros: Ros, topic: str) -> None:
    """A goal to an action nobody serves fails with ActionError saying it does not exist."""
    goal = await ros.send_goal(topic, IMU, {"seconds": 1.0})
    with pytest.raises(ActionError, match="does not exist") as err:
        await goal.result(timeout=15)
    assert topic in str(err.value) and goal.status is GoalStatus.ABORTED


async def test_unknown_action_type(ros: Ros, topic: str) -> None:
    """A type msgs cannot check is refused by the bridge, naming it; a known package's at the call."""
    goal = await ros.send_goal(topic, "nosuch_pkg/Thing", {})
    with pytest.raises(ActionError, match=r"nosuch_pkg/(action/)?Thing"):
        await goal.result(timeout=10)
    with pytest.raises(UsageError, match="mult_msgs/action/IntegrateIm"):
        await ros.send_goal(topic, "mult_msgs/IntegrateIm", {})


async def test_goal_that_does_not_fit(ros: Ros, topic: str) -> None:
    """A bad goal field is caught at the call; unchecked, the bridge names the field."""
    await ros.advertise_action(topic, IMU, counting)
    with pytest.raises(InvalidMessageError, match="seconds"):
        await ros.send_goal(topic, IMU, {"seconds": "long"})
    ros.validate = False  # let the bridge see it
    goal = await ros.send_goal(topic, IMU, {"seconds": "long"})
    with pytest.raises(ActionError, match="args") as err:
        await goal.result(timeout=10)
    assert "seconds" in str(err.value) and IMU in str(err.value)


async def test_many_goals_in_flight(ros: Ros, topic: str) -> None:
    """Several goals on one action at once each get their own result."""
    async def echo(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        await asyncio.sleep(0.01)
        return {"total": vec(goal["seconds"])}

    await ros.advertise_action(topic, IMU, echo)
    goals = [await ros.send_goal(topic, IMU, {"seconds": float(n)}, feedback=False)
             for n in range(8)]
    results = await asyncio.gather(*(g.result(timeout=15) for g in goals))
    assert [r.values["total"]["x"] for r in results] == [float(n) for n in range(8)]


async def test_advertise_action_refused_at_await(ros: Ros, topic: str) -> None:
    """An action type the bridge cannot serve is refused: ``await advertise_action`` raises."""
    with pytest.raises(StatusError, match="advertise_action") as err:
        await ros.advertise_action(topic, "nosuch_pkg/Thing", counting)
    assert "nosuch_pkg" in str(err.value)
    server = await ros.advertise_action(topic, IMU, counting)  # the name is free again
    assert not server.closed


async def test_plain_handlers_run_side_by_side(ros: Ros, topic: str) -> None:
    """Eight goals with a plain (blocking) handler all run at once, in threads of the server's
    own: the loop's default executor (6 threads on 2 cores) stays free for others."""
    together = threading.Barrier(8, timeout=10)

    def blocking(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        together.wait()  # BrokenBarrierError (the goal aborts) unless all eight run at once
        return {"samples": int(goal["seconds"])}

    await ros.advertise_action(topic, IMU, blocking)
    goals = [await ros.send_goal(topic, IMU, {"seconds": float(i)}, feedback=False)
             for i in range(8)]
    assert await asyncio.to_thread(lambda: "default executor free") == "default executor free"
    outcomes = [await goal.result(timeout=20) for goal in goals]
    assert [o.status for o in outcomes] == [GoalStatus.SUCCEEDED] * 8
    assert [o.values["samples"] for o in outcomes] == list(range(8))
