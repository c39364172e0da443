"""The relay program's event loop (``--event-loop``): uvloop where installed, and a robot's
topic reaches a viewer through the relay on either loop."""

from __future__ import annotations

import asyncio
import re
import sys
from typing import Any

import pytest
from std_msgs.msg import String

from tests.helpers import open_wire, ros_env
from tests.relay.procs import Proc
from tests.relay.support import ROBOT, free_port, start_robot

pytestmark = pytest.mark.timeout(90)


@pytest.mark.parametrize(("kind", "runs"), [("auto", "uvloop"), ("asyncio", "asyncio")])
async def test_the_relay_runs_on_the_event_loop_asked_for(
    kind: str, runs: str, ros_node: Any, topic: str
) -> None:
    """``roslibpy-lite-relay --event-loop``: the relay says which loop it runs (auto: uvloop,
    which the bridge extra installs), and a robot's rclpy topic reaches a viewer through it."""
    router = f"tcp/127.0.0.1:{free_port()}"
    proc = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                 "--zenoh-listen", router, "--event-loop", kind], ros_env())
    robot = exporter = None
    pub = ros_node.create_publisher(String, topic, 10)
    try:
        port = int((await asyncio.to_thread(proc.wait_for, re.compile(
            r"accepting on ws://127\.0\.0\.1:(\d+)"))).group(1))
        loop_line = await asyncio.to_thread(proc.wait_for, re.compile(r"event loop: (\w+)"))
        assert loop_line.group(1) == runs
        robot, exporter = await start_robot(router)
        wire = None
        deadline = asyncio.get_running_loop().time() + 30
        while wire is None:  # 404 until the robot's liveliness reaches the relay (no event)
            try:
                wire = await open_wire(f"ws://127.0.0.1:{port}/{ROBOT}")
            except Exception:
                assert asyncio.get_running_loop().time() < deadline, "the robot never came"
                await asyncio.sleep(0.2)
        try:
            await wire.send({"op": "subscribe", "topic": topic, "type": "std_msgs/msg/String"})
            while True:  # discovery of the robot's subscription has no event here
                pub.publish(String(data=runs))
                try:
                    op = await wire.expect(op="publish", topic=topic, timeout=0.3)
                    break
                except AssertionError:
                    assert asyncio.get_running_loop().time() < deadline, f"never heard {topic}"
            assert op["msg"] == {"data": runs}
        finally:
            await wire.close()
    finally:
        if exporter is not None and robot is not None:
            await exporter.close()
            await robot.close()
        proc.stop()
    assert proc.proc.returncode == 0, "\n".join(proc.lines)
