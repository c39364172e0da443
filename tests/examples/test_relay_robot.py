"""examples/relay_robot.py, the robot program of the relay guide's quick start (issue 50,
item 4): its node and its bridge in robot mode (no listening port) serve a client through a
relay, and SIGTERM stops both."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT, free_port, open_wire, ros_env
from tests.relay.support import robot_reachable, start_relay

pytestmark = pytest.mark.timeout(150)


async def test_the_robot_program_is_served_through_a_relay(tmp_path: Path) -> None:
    """A client of the relay hears the example's /robot_status and gets its /robot_ping answer; SIGTERM ends it with 0 and its bridge with it."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    out = tmp_path / "robot.log"
    with out.open("w") as f:
        robot = subprocess.Popen(
            [sys.executable, "-m", "examples.relay_robot", "robot1", "--", "--zenoh-connect",
             router], cwd=ROOT, env=ros_env(PYTHONPATH=str(ROOT)), stdout=f,
            stderr=subprocess.STDOUT)
    try:
        await robot_reachable(relay, "robot1", timeout=90)
        ws = await open_wire(f"ws://127.0.0.1:{relay.port}/robot1")
        try:
            await ws.send({"op": "subscribe", "topic": "/robot_status",
                           "type": "std_msgs/msg/String"})
            heard = await ws.expect(op="publish", topic="/robot_status", timeout=60)
            assert heard["msg"]["data"].startswith("robot1 ok "), heard
            await ws.send({"op": "call_service", "service": "/robot_ping",
                           "type": "std_srvs/srv/Trigger", "id": "ping", "args": {}})
            answer = await ws.expect(op="service_response", id="ping", timeout=60)
            assert answer["result"] is True and answer["values"] == {
                "success": True, "message": "pong from robot1"}, answer
        finally:
            await ws.close()
        robot.send_signal(signal.SIGTERM)
        code = await asyncio.to_thread(robot.wait, 30)
        log = out.read_text()
        assert code == 0, log
        found = re.search(r"robot robot1: node robot1_example up, bridge pid (\d+)", log)
        assert found, log
        with pytest.raises(ProcessLookupError):  # the bridge is gone with it
            os.kill(int(found.group(1)), 0)
    finally:
        if robot.poll() is None:
            robot.kill()
            robot.wait()
        await relay.close()
