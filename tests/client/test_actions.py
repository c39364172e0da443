"""The client's actions: MockRos specifics, and rclpy action peers through the real bridge."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

import roslibpy_lite
from msgs.test_msgs.action import Fibonacci
from roslibpy_lite import Client, Disconnected, MockRos, RosLibError, RosTimeoutError
from roslibpy_lite.actions import ActionError, GoalContext, GoalStatus
from tests.bridge.action_support import FIB, FibServer, RosCaller, fib
from tests.client.support import fast_backoff
from tests.helpers import BridgeProcess

IMU = "mult_msgs/action/IntegrateImu"


async def forever(goal: Any, ctx: GoalContext) -> None:
    """A handler that runs until cancelled."""
    ctx.publish_feedback({"elapsed": 1.0})
    await asyncio.Event().wait()


# -- MockRos ----------------------------------------------------------------------------------


async def test_mock_drop_fails_goals_and_reconnect_restores_server() -> None:
    """A drop fails a goal in flight with Disconnected at once; the served action comes back."""
    async with MockRos() as ros:
        server = await ros.advertise_action("/a", IMU, forever)
        goal = await ros.send_goal("/a", IMU, {"seconds": 1.0})
        async for _ in goal:
            break
        assert server.active
        ros.disconnect()
        with pytest.raises(Disconnected, match="/a"):
            await goal.result(timeout=1)
        await asyncio.sleep(0)  # the cancelled handler task finishes
        assert not server.active
        ros.reconnect()
        await ros.advertise_action("/b", IMU, lambda goal, ctx: {"samples": 2})
        again = await ros.send_goal("/b", IMU, {"seconds": 1.0})
        assert (await again.result(timeout=5)).values["samples"] == 2
        first = await ros.send_goal("/a", IMU, {})  # /a is served again
        async for _ in first:
            break
        await server.unadvertise()  # its goals are aborted
        assert (await first.result(timeout=5)).status is GoalStatus.ABORTED


async def test_mock_goal_failures_are_not_reported_as_stray_errors() -> None:
    """A failed goal's status error goes to the goal only: no error hook, no stray count."""
    async with MockRos() as ros:
        hooked: list[RosLibError] = []
        ros.on_error(hooked.append)
        goal = await ros.send_goal("/none", IMU, {})
        with pytest.raises(ActionError):
            await goal.result(timeout=1)
        await asyncio.sleep(0)
        assert hooked == [] and ros.status_errors == 0


async def test_mock_sync_handler_sees_cancel_in_its_thread() -> None:
    """A sync handler runs in a thread; it sees cancel_requested and its feedback arrives."""
    started = threading.Event()

    def handler(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        assert threading.current_thread() is not threading.main_thread()
        ctx.publish_feedback({"elapsed": 0.5})
        started.set()
        while not ctx.cancel_requested:
            threading.Event().wait(0.01)
        return {"samples": 9}

    async with MockRos() as ros:
        await ros.advertise_action("/s", IMU, handler)
        goal = await ros.send_goal("/s", IMU, {"seconds": 1.0})
        async for fb in goal:  # the bridge fills in the fields the handler left out
            assert fb == {"sum": {"x": 0.0, "y": 0.0, "z": 0.0}, "elapsed": 0.5}
            await goal.cancel()
        outcome = await goal.result(timeout=5)
        assert outcome.status is GoalStatus.CANCELED and outcome.values["samples"] == 9


async def test_mock_result_timeout_leaves_the_goal_running() -> None:
    """result(timeout) raises RosTimeoutError; the goal goes on and can still be canceled."""
    async with MockRos() as ros:
        await ros.advertise_action("/t", IMU, forever)
        goal = await ros.send_goal("/t", IMU, {})
        with pytest.raises(RosTimeoutError, match=r"no result within 0\.05 s"):
            await goal.result(timeout=0.05)
        assert not goal.done()


async def test_mock_bad_feedback_and_result_raise_in_the_handler() -> None:
    """Feedback that does not fit raises in the handler; the goal is aborted with the text."""
    async def bad(goal: Any, ctx: GoalContext) -> None:
        ctx.publish_feedback({"elapsed": "soon"})

    async with MockRos() as ros:
        server = await ros.advertise_action("/f", IMU, bad)
        goal = await ros.send_goal("/f", IMU, {})
        assert (await goal.result(timeout=5)).status is GoalStatus.ABORTED
        assert server.failures == 1


# -- rclpy peers through the real bridge --------------------------------------------------------



async def listed(client: Client, name: str, timeout: float = 20.0) -> None:
    """Wait until the bridge's graph lists the action server ``name`` (discovery has no event)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        reply = await client.call_service("/rosapi/action_servers",
                                          "rosapi_msgs/srv/GetActionServers")
        if name in reply["action_servers"]:
            return
        assert asyncio.get_running_loop().time() < deadline, f"{name} never listed"
        await asyncio.sleep(0.05)


async def test_goal_to_rclpy_action_server(client: Client, ros_node: Any, topic: str) -> None:
    """A goal to an rclpy action server gets its feedback and result, typed."""
    server = FibServer(ros_node, topic)
    try:
        await listed(client, topic)
        goal = await client.send_goal(topic, Fibonacci, Fibonacci.Goal(order=5))
        feedback = [list(fb.sequence) async for fb in goal]
        outcome = await goal.result(timeout=20)
        assert outcome.status is GoalStatus.SUCCEEDED
        assert list(outcome.values.sequence) == fib(5)
        assert feedback[-1] == fib(5)
    finally:
        server.destroy()


async def test_cancel_reaches_rclpy(client: Client, ros_node: Any, topic: str) -> None:
    """cancel() reaches the rclpy server's cancel callback; the goal ends CANCELED."""
    server = FibServer(ros_node, topic, slow=True)
    try:
        await listed(client, topic)
        goal = await client.send_goal(topic, FIB, {"order": 1})
        async for _ in goal:
            await goal.cancel()
        outcome = await goal.result(timeout=20)
        assert outcome.status is GoalStatus.CANCELED and server.cancel_requests.is_set()
    finally:
        server.destroy()


async def test_rclpy_abort_and_reject(client: Client, ros_node: Any, topic: str) -> None:
    """An rclpy abort is ABORTED with its values; a rejection raises ActionError saying so."""
    server = FibServer(ros_node, topic, abort=True)
    try:
        await listed(client, topic)
        outcome = await (await client.send_goal(topic, FIB, {"order": 3})).result(timeout=20)
        assert outcome.status is GoalStatus.ABORTED and outcome.values["sequence"] == fib(3)
    finally:
        server.destroy()
    rejecting = FibServer(ros_node, topic + "_r", accept=False)
    try:
        await listed(client, topic + "_r")
        goal = await client.send_goal(topic + "_r", FIB, {"order": 3})
        with pytest.raises(ActionError, match="rejected"):
            await goal.result(timeout=20)
    finally:
        rejecting.destroy()


async def test_served_action_to_rclpy(client: Client, ros_node: Any, topic: str) -> None:
    """An rclpy action client reaches a client-served action: feedback, result, then a cancel."""
    async def handler(goal: Any, ctx: GoalContext) -> dict[str, Any]:
        ctx.publish_feedback({"sequence": [0, 1]})
        if goal["order"] > 10:
            await ctx.wait_cancel()
            return {"sequence": [0]}
        return {"sequence": fib(goal["order"])}

    await client.advertise_action(topic, FIB, handler)
    caller = RosCaller(ros_node, topic)
    try:
        await caller.ready(20)
        handle = await caller.send(4)
        assert await asyncio.wait_for(caller.feedback.get(), 10) == [0, 1]
        result = await caller.result(handle)
        assert result.status == GoalStatus.SUCCEEDED and list(result.result.sequence) == fib(4)
        handle = await caller.send(99)
        await asyncio.wait_for(caller.feedback.get(), 10)
        await asyncio.wrap_future(_as_future(handle.cancel_goal_async()))
        result = await caller.result(handle)
        assert result.status == GoalStatus.CANCELED
    finally:
        caller.destroy()


def _as_future(ros_future: Any) -> Any:
    import concurrent.futures

    out: concurrent.futures.Future[Any] = concurrent.futures.Future()
    ros_future.add_done_callback(lambda f: out.set_result(f.result()))
    return out


# -- a dropped connection -----------------------------------------------------------------------


@pytest.fixture
async def private(make_bridge: Callable[..., BridgeProcess]) -> AsyncIterator[tuple[Any, Client]]:
    """A private bridge and a client on it with fast reconnects."""
    bridge = make_bridge()
    async with roslibpy_lite.connect(bridge.url, backoff=fast_backoff()) as client:
        yield bridge, client


async def test_goal_fails_at_once_on_a_drop_and_served_action_returns(
    private: tuple[BridgeProcess, Client], ros_node: Any, topic: str
) -> None:
    """Killing the bridge fails a goal in flight with Disconnected; the served action comes back."""
    bridge, client = private
    server = FibServer(ros_node, topic, slow=True)
    served = topic + "_served"
    await client.advertise_action(served, FIB, lambda goal, ctx: {"sequence": [7]})
    try:
        await listed(client, topic)
        goal = await client.send_goal(topic, FIB, {"order": 1})
        async for _ in goal:
            break
        bridge.kill()
        with pytest.raises(Disconnected, match=topic):
            await goal.result(timeout=10)
        await restart_killed(bridge, client)
        caller = RosCaller(ros_node, served)
        try:
            deadline = asyncio.get_running_loop().time() + 30
            while True:  # the old bridge's server may linger in the graph a moment
                await caller.ready(30)
                try:
                    handle = await asyncio.wait_for(caller.send(1), 3)
                    result = await caller.result(handle, 5)
                    break
                except TimeoutError:
                    if asyncio.get_running_loop().time() > deadline:
                        raise
            assert list(result.result.sequence) == [7]
        finally:
            caller.destroy()
    finally:
        server.destroy()


async def restart_killed(bridge: BridgeProcess, client: Client) -> None:
    """Start a killed bridge again and wait for the client to reconnect."""
    await asyncio.to_thread(bridge.start)
    await client.wait_connected(30)



def test_goal_status_prints_its_name() -> None:
    """print(result.status) shows SUCCEEDED, not 4; it still equals its number."""
    assert str(GoalStatus.SUCCEEDED) == "SUCCEEDED" and f"{GoalStatus.CANCELED}" == "CANCELED"
    assert int(GoalStatus.SUCCEEDED) == 4 and f"{GoalStatus.ABORTED:d}" == "6"
