"""Robots back from a router's restart (issue 49): they hold their names again without a
storm of their own.

A robot whose last router went and came back looks, for two leases, at whether another robot
took its name meanwhile (a query of its name's claims). 1,000 simulated robots through a
restarted router held their names again only after 8 s: each took a snapshot of its graph
at each look at its claims, every 0.25 s (half of a 250-robot process's loop); the looks
now come at once, then at waits doubling from 0.25 s. Here a few
simulated robots go through a real router's restart and each look is counted.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from bench.ports import free_port
from bench.simrobot import Fleet, SimRobot
from bridge_server.zenoh import link
from bridge_server.zenoh.exporter import CLAIM_WAIT, RETURN_LEASES
from bridge_server.zenoh.exporter import exporter as exporter_module
from bridge_server.zenoh.link import ZenohOptions, open_session
from bridge_server.zenoh.robot_graph import GraphSnapshots
from bridge_server.zenoh.robot_link import RobotOptions

pytestmark = pytest.mark.timeout(120)

ROBOTS = 3
LEASE = 3.0
MOST_LOOKS = 9
"""Looks at its claims a robot back from an outage makes at most: one at once, then after
0.25, 0.5, 1 and 2 s more and at the end of two leases of 3 s (six), a few more the
network's news of claims may add. A look every 0.25 s for those 6 s would be 24."""


async def test_robots_back_from_a_router_restart_look_calmly(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Three simulated robots through a router killed and restarted on its port: all hold
    their names again; while back from the outage each looks at its claims a bounded number
    of times (:data:`MOST_LOOKS` in its time away) and takes no graph snapshot before its snapshot
    interval is due."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router: Any = await open_session(ZenohOptions(listen=[endpoint]))
    options = RobotOptions(connect=[endpoint], lease=LEASE)
    robots = [SimRobot(f"restart-{i}", options) for i in range(ROBOTS)]
    fleet = Fleet(options, {r.name: r for r in robots})
    looks: list[str] = []
    snapshots: list[int] = []
    try:
        for robot in robots:
            robot.start()
        assert await fleet.until_holding(list(fleet.robots), 60) == []
        take, claims = GraphSnapshots.take, link.tokens

        def counted_take(self: GraphSnapshots, served: dict[str, str]) -> Any:
            snapshots.append(1)
            return take(self, served)

        async def counted_claims(session: Any, key: str, timeout: float,
                                 first: bool = False) -> set[str]:
            looks.append(key)
            return await claims(session, key, timeout, first)

        monkeypatch.setattr(GraphSnapshots, "take", counted_take)
        monkeypatch.setattr(exporter_module, "tokens", counted_claims)
        router.close()
        await _until(lambda: all(not r.exporter.uplinks for r in robots), 30,
                     "the robots to lose their router")
        router = await open_session(ZenohOptions(listen=[endpoint]))
        assert await fleet.until_holding(list(fleet.robots), 60) == []
        await _until(lambda: all(r.exporter.uplinks for r in robots), 30, "the robots' links")
        loop = asyncio.get_running_loop()
        await _until(lambda: all(r.exporter._away_until < loop.time() for r in robots),
                     RETURN_LEASES * LEASE + 30, "the robots' time away to end")
        await asyncio.sleep(CLAIM_WAIT)  # the last look's answer (its query's longest wait)
    finally:
        for robot in robots:
            await robot.close()
        router.close()
    per_robot = len(looks) / ROBOTS
    assert 1 <= per_robot <= MOST_LOOKS, f"{per_robot:.1f} looks at the claims a robot"
    assert snapshots == [], "a robot back from an outage looked at its graph at each look"


async def _until(done: Any, timeout: float, what: str) -> None:
    """Wait until ``done()`` (polled each 0.1 s), failing on ``what`` after ``timeout`` s."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while not done():
        assert loop.time() < deadline, f"waited {timeout:g} s for {what}"
        await asyncio.sleep(0.1)
