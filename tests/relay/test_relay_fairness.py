"""No robot starves another on a relay (issue 39): one event loop serves every robot, and
each robot's Zenoh callbacks reach it through a bounded inbox (bridge_server/zenoh/inbox.py).

A relay (the Zenoh router, in this process) serves robot1, a played robot in its own
process putting ``/steady`` at 20 Hz that a websocket viewer watches, and robot2, a played
malicious robot in another process (tests/relay/played_robot.py) that another viewer
watches. While robot2 floods messages, or puts 20 MB graph documents and a nested one, the
robot1 viewer keeps at least 90 % of its rate and its connection, the relay's memory grows
by less than ``RSS_BOUND``, and what robot2 sent over its limits is counted on the relay's
page. 200 bad messages of robot2, watched by two viewers, are logged a couple of times with
the count, not once per message per viewer.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import sys
import threading
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any

import psutil
import pytest
from websockets.asyncio.client import ClientConnection, connect

from bridge_server.zenoh.graph import ZenohGraph
from bridge_server.zenoh.relay import Relay
from tests.helpers import ROOT, ros_env
from tests.ops.support import aget
from tests.relay.support import free_port, robot_reachable, start_relay, until

pytestmark = pytest.mark.timeout(120)

RSS_BOUND = 96 * 1024 * 1024
"""How much more memory the relay's process may hold while a robot attacks it."""

FLOOD_TYPES = {"steady": "std_msgs/msg/String", "flood": "std_msgs/msg/Float64MultiArray",
               "graphs": "std_msgs/msg/String", "bad": "std_msgs/msg/String"}
"""The type of robot2's /flood in each way it is played."""

WINDOW = 2.0
"""Seconds robot1's viewer is watched before the attack, for its own rate."""


READER = """
import json, sys
from websockets.sync.client import connect
with connect(sys.argv[1], max_size=None) as ws:
    ws.send(json.dumps({"op": "subscribe", "topic": "/flood", "type": sys.argv[2]}))
    print("reading", flush=True)
    for _ in ws:
        pass
"""
"""A viewer of robot2's /flood in its own process that reads everything it is sent."""


class Played:
    """A played robot's process (tests/relay/played_robot.py)."""

    def __init__(self, proc: asyncio.subprocess.Process) -> None:
        self.proc = proc

    @classmethod
    async def start(cls, router: str, robot: str, mode: str, seconds: float = 4.0) -> Played:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "tests.relay.played_robot", router, robot, mode,
            str(seconds), cwd=ROOT, env=ros_env(), stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE)
        played = cls(proc)
        assert await played.line() == "ready"
        return played

    async def line(self) -> str:
        assert self.proc.stdout is not None
        return (await asyncio.wait_for(self.proc.stdout.readline(), 60)).decode().strip()

    def go(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(b"go\n")

    async def stop(self) -> None:
        if self.proc.returncode is None:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
            try:
                await asyncio.wait_for(self.proc.wait(), 10)
            except TimeoutError:
                self.proc.kill()
                await self.proc.wait()


@dataclass
class Scene:
    """The relay, robot1's viewer (the times of the messages it got) and robot2."""

    relay: Relay
    router: str
    viewer: ClientConnection
    got: list[float]
    peak_rss: list[int]

    def rate(self, start: float, end: float) -> float:
        """robot1's messages per second the viewer got between ``start`` and ``end``."""
        return sum(1 for t in self.got if start <= t < end) / (end - start)


async def _viewer(url: str, topic: str, queue_length: int = 10,
                  flood_type: str = "std_msgs/msg/String") -> ClientConnection:
    ws = await connect(url, max_size=None, open_timeout=10)
    await ws.send(json.dumps({"op": "subscribe", "topic": topic, "type": flood_type,
                              "queue_length": queue_length}))
    return ws


@contextlib.asynccontextmanager
async def scene(mode: str) -> AsyncIterator[tuple[Scene, Played]]:
    """The relay with steady robot1 flowing to its viewer, and robot2 played as ``mode``
    (not started yet: ``go``) watched on ``/flood`` by a viewer that reads nothing."""
    router = f"tcp/127.0.0.1:{free_port()}"
    relay = await start_relay(listen=router)
    robots: list[Played] = []
    watching = threading.Event()
    peak = [psutil.Process().memory_info().rss]

    def watch_rss() -> None:
        while not watching.wait(0.05):
            peak[0] = max(peak[0], psutil.Process().memory_info().rss)

    watcher = threading.Thread(target=watch_rss, daemon=True)
    try:
        robots.append(await Played.start(router, "robot1", "steady"))
        robots.append(await Played.start(router, "robot2", mode))
        for name in ("robot1", "robot2"):
            await robot_reachable(relay, name)
        base = f"ws://127.0.0.1:{relay.port}"
        viewer = await _viewer(f"{base}/robot1", "/steady")
        flood_type = FLOOD_TYPES[mode]
        idle = await _viewer(f"{base}/robot2", "/flood", flood_type=flood_type)
        reading = await asyncio.create_subprocess_exec(  # a viewer of robot2 that reads all
            sys.executable, "-c", READER, f"{base}/robot2", flood_type, cwd=ROOT, env=ros_env(),
            stdout=asyncio.subprocess.PIPE)
        assert reading.stdout is not None
        assert (await asyncio.wait_for(reading.stdout.readline(), 30)).strip() == b"reading"
        got: list[float] = []

        async def read() -> None:
            async for _ in viewer:
                got.append(time.monotonic())

        reader = asyncio.ensure_future(read())
        robots[0].go()
        await until(lambda: got, "robot1's first message to its viewer")
        watcher.start()
        try:
            yield Scene(relay, router, viewer, got, peak), robots[1]
        finally:
            reader.cancel()
            reading.kill()
            await reading.wait()
            await idle.close()
            await viewer.close()
    finally:
        watching.set()
        for played in robots:
            await played.stop()
        await relay.close()


async def _robots(relay: Relay) -> dict[str, dict[str, Any]]:
    """The relay's /status.json robots, by name."""
    code, _, body = await aget(f"http://127.0.0.1:{relay.port}/status.json")
    assert code == 200, body
    return {r["name"]: r for r in json.loads(body)["robots"]}


async def _attacked(s: Scene, robot2: Played) -> tuple[float, float]:
    """robot1's viewer's rate before robot2's attack, and during it."""
    baseline_rss = psutil.Process().memory_info().rss
    s.peak_rss[0] = baseline_rss
    start = time.monotonic()
    await asyncio.sleep(WINDOW)  # robot1's own rate, measured over time
    before = s.rate(start, time.monotonic())
    start = time.monotonic()
    robot2.go()
    assert (await robot2.line()).startswith("done")
    during = s.rate(start, time.monotonic())
    print(f"robot1's viewer: {before:.1f} msg/s before, {during:.1f} during; relay RSS "
          f"{baseline_rss / 2**20:.0f} MiB -> peak {s.peak_rss[0] / 2**20:.0f} MiB")
    assert s.peak_rss[0] - baseline_rss < RSS_BOUND
    return before, during


async def test_a_robot_flooding_messages_does_not_starve_another_robots_viewer() -> None:
    """robot2 puts messages of 1000 floats (8 KiB, costly to write as JSON) as fast as it
    can for 4 s to a viewer that reads them all:
    robot1's viewer keeps 90 % of its rate and its connection, and the relay's memory stays
    bounded."""
    async with scene("flood") as (s, robot2):
        before, during = await _attacked(s, robot2)
        assert before >= 5 and during >= 0.9 * before, (before, during)
        assert s.viewer.close_code is None
        robots = await _robots(s.relay)
        assert robots["robot1"]["dropped"] == {}, robots


async def test_a_robot_putting_huge_graph_documents_does_not_starve_another() -> None:
    """robot2 puts one graph document nested 100 000 deep, ten 20 MB ones in 4 s and 50 small
    ones at once: robot1's viewer keeps 90 % of its rate and its connection, the relay's
    memory stays bounded, the relay's page counts them as dropped for robot2 (too large; not
    a graph; replaced by a newer one before read), and the newest is the robot's graph."""
    async with scene("graphs") as (s, robot2):
        before, during = await _attacked(s, robot2)
        assert before >= 5 and during >= 0.9 * before, (before, during)
        assert s.viewer.close_code is None
        graph = s.relay.robots["robot2"].graph
        assert isinstance(graph, ZenohGraph)
        await until(lambda: graph.snapshot.node == "played49", "the newest graph")
        robots = await _robots(s.relay)
        dropped = robots["robot2"]["dropped"]
        assert dropped.pop("graph_superseded") >= 1, dropped  # read at most 4 a second
        assert dropped == {"graph_too_large": 10, "bad_graph": 1}, robots
        assert robots["robot1"]["dropped"] == {}
        code, _, body = await aget(f"http://127.0.0.1:{s.relay.port}/metrics")
        assert code == 200 and ('roslibpy_relay_robot_dropped_total{kind="graph_too_large",robot="robot2"} '
                '10.0') in body.decode()


async def test_bad_messages_are_logged_once_per_robot_with_a_count(
        caplog: pytest.LogCaptureFixture) -> None:
    """robot2 puts 200 messages whose bytes are no String and one whose stamp is out of
    range, watched by two viewers (one that reads nothing): at most two log lines, each
    naming robot2 and the count, and no traceback per message or viewer; the relay's page
    counts 201."""
    caplog.set_level(logging.INFO)
    async with scene("bad") as (s, robot2):
        second = await _viewer(f"ws://127.0.0.1:{s.relay.port}/robot2", "/flood", 1000)
        try:
            robot2.go()
            assert (await robot2.line()) == "done 201"
            graph = s.relay.robots["robot2"].graph
            assert isinstance(graph, ZenohGraph)
            faults = graph.faults.counts
            await until(lambda: faults.get("bad_messages") == 201, "robot2's 201 messages")
        finally:
            await second.close()
        lines = [r for r in caplog.records if r.levelno >= logging.WARNING
                 and r.name.startswith("bridge_server")]
        assert 1 <= len(lines) <= 2, [r.getMessage() for r in lines]
        for r in lines:
            assert "robot robot2" in r.getMessage() and "so far" in r.getMessage(), r
        robots = await _robots(s.relay)
        assert robots["robot2"]["dropped"] == {"bad_messages": 201}, robots
