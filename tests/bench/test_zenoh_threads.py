"""Zenoh calls the robot side back on its own threads, not on a Python thread per callback.

zenoh-python runs a callable handler on a new Python thread of its own ("pyo3-closure") by
default: one per declared subscriber or queryable and one per query's reply handler. The
robot side's query callbacks only hand their answer to the event loop, so they are called
on Zenoh's thread (``indirect=False``): each simulated robot's uplink probe started a
Python thread a second (100 robots: 100 thread starts a second), and each robot a relay
opened one more for its liveliness look-up.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import pytest

from bench.ports import free_port
from bench.simrobot import Fleet, SimRobot
from bridge_server.zenoh.keys import Snapshot
from bridge_server.zenoh.link import ZenohOptions, open_session, tokens
from bridge_server.zenoh.robot_link import RobotOptions
from bridge_server.zenoh.uplink import router_answers
from msgs import dynamic

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def callback_threads(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """The names of the Python threads zenoh-python starts for callbacks meanwhile."""
    started: list[str] = []
    start = threading.Thread.start

    def counted(self: threading.Thread) -> None:
        if "pyo3" in self.name:
            started.append(self.name)
        start(self)

    monkeypatch.setattr(threading.Thread, "start", counted)
    yield started


async def test_queries_start_no_thread(callback_threads: list[str]) -> None:
    """The uplink's probe and the token look-up start no Python thread per query."""
    router = await open_session(ZenohOptions(listen=[f"tcp/127.0.0.1:{free_port()}"]))
    try:
        for _ in range(3):
            await router_answers(router, "nobody/@alive/*", "", 0.2)
            await tokens(router, "nobody/@alive/*", 0.2)
    finally:
        router.close()  # type: ignore[no-untyped-call]
    assert callback_threads == []


async def test_robot_side_starts_no_callback_thread(callback_threads: list[str]) -> None:
    """Three simulated robots (the exporter's claims, queryables, liveliness subscribers
    and probes) holding their names start no callback thread."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = await open_session(ZenohOptions(listen=[endpoint]))
    robots: list[Any] = [SimRobot(f"threads-{i}", RobotOptions(connect=[endpoint]))
                         for i in range(3)]
    try:
        for robot in robots:
            robot.start()
        fleet = Fleet(RobotOptions(connect=[endpoint]), {r.name: r for r in robots})
        assert await fleet.until_holding([r.name for r in robots], 60) == []
    finally:
        for robot in robots:
            await robot.close()
        router.close()  # type: ignore[no-untyped-call]
    assert callback_threads == []


async def test_unchanged_graph_is_not_encoded_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """The exporter's periodic graph look encodes its snapshot only when the graph changed
    (a simulated robot's encode was 30 ms; 1,000 robots each looked every 30 s)."""
    robot = SimRobot("snapshots", RobotOptions(connect=["tcp/127.0.0.1:1"]))
    exporter: Any = robot.exporter
    exporter.snapshot = exporter._take_snapshot()
    encoded: list[int] = []
    encode = Snapshot.encode

    def counted(snap: Snapshot) -> bytes:
        encoded.append(1)
        return encode(snap)

    monkeypatch.setattr(Snapshot, "encode", counted)
    try:
        for _ in range(3):
            exporter._refresh_snapshot()
        assert encoded == []
        robot.nodes[0].acquire_publisher(
            "/new_topic", dynamic.DEFAULT.lookup_message("std_msgs/msg/String"), False, 1)
        exporter._refresh_snapshot()
        assert encoded == [1]
    finally:
        await robot.close()
