"""Calls and goals in flight to a robot known to be gone fail at once (issue 38, item 5).

A relay (the Zenoh router, in this process) and a robot's real bridge in a child process
(``python -m bridge_server --robot robot1 --zenoh-connect ...``); the slow service and the
slow action server are rclpy nodes of this test, which the robot's bridge reaches over ROS.
The robot's process is frozen (SIGSTOP) while a call and a goal wait on it: its link goes
silent, as a cut cable leaves it (a killed process is not the case here: its socket closes,
and Zenoh ends the queries at once). The relay sees the robot's liveliness go when the link's
lease ends and fails both with a reason naming the robot, instead of leaving them to the
caller's own (large) timeout.
"""

from __future__ import annotations

import asyncio
import re
import signal
import sys
import threading
from typing import Any

import pytest
from std_srvs.srv import Trigger

import roslibpy_lite
from roslibpy_lite.actions import ActionError
from roslibpy_lite.exceptions import RemoteError
from tests.bridge.action_support import FIB, FibServer
from tests.helpers import ros_env
from tests.relay.procs import Proc
from tests.relay.support import ROBOT, free_port, robot_reachable, start_relay, until

pytestmark = pytest.mark.timeout(90)

CALLER_TIMEOUT = 600.0
"""The client's own timeout: far beyond the test's bound, so only the relay can end it."""

GONE = re.compile(rf"robot {ROBOT} went away \(its link to the Zenoh network ended\) while "
                  r"this (call|goal) was in flight")


def robot_process(router: str) -> Proc:
    """The robot's bridge, dialing out to ``router`` (no websocket)."""
    robot = Proc([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot", ROBOT,
                  "--zenoh-connect", router], ros_env())
    robot.wait_for(re.compile(rf"robot {ROBOT} is on Zenoh"))
    return robot


async def test_a_call_and_a_goal_in_flight_fail_when_the_robots_link_goes_silent(
        ros_node: Any, topic: str) -> None:
    """A slow service call and a slow goal in flight through the relay when the robot's
    link goes silent: both end with an error naming the robot and that it went away while
    they were in flight, long before the caller's own timeout."""
    entered, release = threading.Event(), threading.Event()

    def slow(_request: Any, response: Any) -> Any:
        entered.set()
        release.wait(60)
        return response

    ros_node.create_service(Trigger, topic, slow)
    action = FibServer(ros_node, topic + "_action", slow=True)
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    robot = robot_process(router)
    try:
        await robot_reachable(relay)
        graph = relay.robots[ROBOT].graph
        async with roslibpy_lite.connect(f"ws://127.0.0.1:{relay.port}/{ROBOT}") as ros:
            await until(lambda: graph.server_types(topic + "_action/_action/send_goal"),
                        "the relay to list the action server")
            feedback = asyncio.Event()
            goal = await ros.send_goal(topic + "_action", FIB, {"order": 3},
                                       on_feedback=lambda _f: feedback.set())
            await asyncio.wait_for(feedback.wait(), 30)
            call = asyncio.ensure_future(ros.call_service(topic, "std_srvs/srv/Trigger", {},
                                                          timeout=CALLER_TIMEOUT))
            assert await asyncio.to_thread(entered.wait, 30), "the service was never called"
            robot.proc.send_signal(signal.SIGSTOP)
            with pytest.raises(RemoteError) as failed:
                await asyncio.wait_for(call, 60)  # the bound of this test, not the caller's
            assert GONE.search(str(failed.value)), failed.value
            with pytest.raises(ActionError) as ended:
                await asyncio.wait_for(goal.result(), 60)
            assert GONE.search(str(ended.value)), ended.value
    finally:
        release.set()
        robot.proc.send_signal(signal.SIGKILL)
        robot.stop()
        action.destroy()
        await relay.close()
