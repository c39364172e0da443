"""One robot's costs bounded in time, not only in bytes (issue 53, findings 5 and 6).

A robot redefining its own type four times a second (two ~190 KB definitions in turn) kept
another robot's viewer 4.2-4.4 s late; 3.4 MB graph documents of 90,000 topics, ten a
second, gave it 2.3-2.55 s. Each robot's graph documents are now read at most once a
second and its type redefinitions at most once every two seconds (the newest waiting
wins), decoded and built on a worker thread (big definitions 50 types at a time), and
applied on the loop at once (bridge_server/zenoh/typestore.py).

Real processes: the relay (the Zenoh router) and two robots played on raw Zenoh
(tests/relay/played_costly.py): robot1 puts its send time at 20 Hz to a viewer, robot2
misbehaves, watched by a viewer of its own. The viewer of robot1 reads each message's
latency; its worst over the attack stays under ``WORST`` (a wide margin over the issue's
100 ms target: the figures measured are in the module's report and the release note).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import sys
import time
from collections.abc import AsyncIterator

import pytest
from websockets.asyncio.client import ClientConnection, connect

from tests.helpers import ROOT, ros_env
from tests.relay.played_costly import BIG
from tests.relay.procs import Proc, until_robot_served
from tests.relay.support import free_port
from tests.relay.test_relay_fairness import Played as FairnessPlayed

pytestmark = pytest.mark.timeout(180)

READY = re.compile(r"relay listening on ws://127\.0\.0\.1:(\d+)")
ATTACK = 12.0
"""Seconds robot2 misbehaves while robot1's viewer is watched."""
EVIL_TYPES = {"redefine": BIG, "graphs": "std_msgs/msg/String"}
"""The type robot2's viewer subscribes ``/evil`` with, by the way robot2 plays."""
WORST = 1.0
"""robot1's viewer's worst latency (seconds) while robot2 misbehaves, at most."""


class Played(FairnessPlayed):
    """A robot of tests/relay/played_costly.py in its own process."""

    @classmethod
    async def start(cls, router: str, robot: str, mode: str, seconds: float = 0.0) -> Played:
        """Start it and wait until it is ready (``seconds``: unused, it plays until told)."""
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "tests.relay.played_costly", router, robot, mode, cwd=ROOT,
            env=ros_env(), stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE)
        played = cls(proc)
        assert await played.line() == "ready"
        return played


@contextlib.asynccontextmanager
async def _subscribed(url: str, topic: str, type_name: str) -> AsyncIterator[ClientConnection]:
    async with connect(url, max_size=None, open_timeout=30) as ws:
        await ws.send(json.dumps({"op": "subscribe", "topic": topic, "type": type_name,
                                  "queue_length": 100}))
        yield ws


async def _latencies(ws: ClientConnection, seconds: float) -> list[float]:
    """The latency of each of robot1's messages the viewer gets for ``seconds``."""
    got: list[float] = []
    end = time.time() + seconds
    while time.time() < end:
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(max(0.0, end - time.time())):
                op = json.loads(await ws.recv())
                got.append(time.time() - float(op["msg"]["data"]))
    return got


async def _worst_latency(mode: str) -> tuple[float, float, int]:
    """robot1's viewer's worst latency before robot2 plays ``mode`` and while it does, and
    how many messages it got meanwhile."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                  "--zenoh-listen", router], ros_env())
    robots: list[Played] = []
    try:
        port = int(relay.wait_for(READY).group(1))
        robots = [await Played.start(router, "robot1", "clock"),
                  await Played.start(router, "robot2", mode)]
        for name in ("robot1", "robot2"):
            await asyncio.to_thread(until_robot_served, port, name)
        base = f"ws://127.0.0.1:{port}"
        async with (_subscribed(f"{base}/robot1", "/steady", "std_msgs/msg/String") as viewer,
                    _subscribed(f"{base}/robot2", "/evil", EVIL_TYPES[mode]) as _):
            robots[0].go()
            await viewer.recv()  # flowing
            before = await _latencies(viewer, 2.0)
            robots[1].go()
            during = await _latencies(viewer, ATTACK)
        print(f"\n{mode}: robot1's viewer's worst latency {max(before) * 1000:.0f} ms before, "
              f"{max(during) * 1000:.0f} ms while robot2 plays ({len(during)} messages in "
              f"{ATTACK:g} s)")
        return max(before), max(during), len(during)
    finally:
        for robot in robots:
            await robot.stop()
        relay.stop()


@pytest.mark.parametrize("mode", ["redefine", "graphs"])
async def test_a_robots_types_and_graphs_cost_another_robots_viewer_little(mode: str) -> None:
    """robot2 redefines its type four times a second (two 190 KB definitions), or puts ten
    3.6 MB graph documents a second: robot1's viewer's worst latency stays under WORST and
    it gets at least 80 % of robot1's messages."""
    _, worst, count = await _worst_latency(mode)
    assert worst < WORST, f"robot1's viewer was {worst:.2f} s late while robot2 played {mode}"
    assert count >= 0.8 * 20 * ATTACK, f"robot1's viewer got {count} messages in {ATTACK} s"
