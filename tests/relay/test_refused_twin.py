"""A robot refused its name feeds nothing to the name's clients (issue 53, finding 11): a
second robot announcing robot1 after robot1 was logged as refused, yet 40 of 198 messages
robot1's viewer got were its.

Real processes: the relay (the Zenoh router), robot1 and its twin played on raw Zenoh
(tests/relay/played_twin.py), each saying its Zenoh session in every put as the exporter
does, in its graph documents too. robot1's viewer gets only robot1's messages and topics,
and the relay counts the twin's as dropped (so they did reach it).
"""

from __future__ import annotations

import asyncio
import json
import re
import sys
from typing import Any

import pytest

from tests.helpers import ROOT, open_wire, ros_env
from tests.ops.support import aget
from tests.relay.procs import Proc, until_robot_served
from tests.relay.support import free_port

pytestmark = pytest.mark.timeout(120)

READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")
HEARD = 60
"""robot1's messages the viewer hears while the twin puts (3 s of both)."""


async def _played(router: str, role: str) -> asyncio.subprocess.Process:
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "tests.relay.played_twin", router, "robot1", role, cwd=ROOT,
        env=ros_env(), stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE)
    assert proc.stdout is not None
    line = await asyncio.wait_for(proc.stdout.readline(), 60)
    assert line.decode().strip() == "ready", line
    return proc


async def test_a_robot_refused_its_name_reaches_no_viewer() -> None:
    """robot1 holds the name; its twin, refused (the relay logs it), puts on /steady and
    its graph document too: of the viewer's messages none is the twin's, the robot's
    topics are the holder's, and the relay counts the twin's puts dropped."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                  "--zenoh-listen", router], ros_env())
    played: list[asyncio.subprocess.Process] = []
    try:
        port = int(relay.wait_for(READY).group(1))
        played.append(await _played(router, "holder"))
        await asyncio.to_thread(until_robot_served, port, "robot1")
        viewer = await open_wire(f"ws://127.0.0.1:{port}/robot1")
        await viewer.send({"op": "subscribe", "topic": "/steady",
                           "type": "std_msgs/msg/String"})
        await viewer.expect(op="publish", topic="/steady", timeout=30)
        played.append(await _played(router, "twin"))
        await asyncio.to_thread(relay.wait_for, re.compile(r"refused robot robot1 "))
        got: list[str] = []
        while sum(1 for text in got if text.startswith("holder")) < HEARD:
            got.append((await viewer.expect(op="publish", topic="/steady",
                                            timeout=30))["msg"]["data"])
        assert not [text for text in got if not text.startswith("holder")], got
        # the twin put its graph document twice a second meanwhile: not the robot's graph
        await viewer.send({"op": "call_service", "service": "/rosapi/topics", "id": "t"})
        topics = (await viewer.expect(op="service_response", id="t"))["values"]["topics"]
        assert "/steady" in topics and "/twin_topic" not in topics, topics
        status: dict[str, Any] = json.loads((await aget(
            f"http://127.0.0.1:{port}/status.json"))[2])
        dropped = next(r["dropped"] for r in status["robots"] if r["name"] == "robot1")
        assert dropped.get("not_holder", 0) > 0, dropped
        await viewer.close()
    finally:
        for proc in played:
            if proc.returncode is None:
                assert proc.stdin is not None
                proc.stdin.close()
                try:
                    await asyncio.wait_for(proc.wait(), 10)
                except TimeoutError:
                    proc.kill()
                    await proc.wait()
        relay.stop()
