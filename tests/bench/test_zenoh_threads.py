"""Zenoh calls the robot side back on its own threads, not on a Python thread per callback.

zenoh-python runs a callable handler on a new Python thread of its own ("pyo3-closure") by
default: one per declared subscriber or queryable and one per query's reply handler. The
robot side's callbacks only hand their argument to the event loop, so they are called on
Zenoh's thread (``indirect=False``; :func:`bridge_server.zenoh.inbox.direct` says why that is
safe for what Zenoh hears as declarations too).
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Iterator
from typing import Any

import pytest

from bench.ports import free_port
from bench.simrobot import Fleet, SimRobot
from bridge_server.zenoh import keys
from bridge_server.zenoh.keys import Snapshot
from bridge_server.zenoh.link import ZenohOptions, open_session
from bridge_server.zenoh.robot_link import RobotOptions
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


async def test_a_robot_starts_no_callback_thread(callback_threads: list[str]) -> None:
    """Three simulated robots joining (their liveliness subscribers, transport events, claim
    looks and uplink probes), asked for their graph (queryables) and sent samples (a data
    subscriber) start no callback thread."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = await open_session(ZenohOptions(listen=[endpoint]))
    robots: list[Any] = [SimRobot(f"threads-{i}", RobotOptions(connect=[endpoint]))
                         for i in range(3)]
    try:
        for robot in robots:
            robot.start()
        fleet = Fleet(RobotOptions(connect=[endpoint]), {r.name: r for r in robots})
        assert await fleet.until_holding([r.name for r in robots], 60) == []
        for robot in robots:
            for _ in range(3):
                key = f"{robot.name}/{keys.GRAPH}"  # answered on the loop: asked off it
                answers = await asyncio.to_thread(_asked, router, key)
                assert [r for r in answers if r.ok is not None]
                router.put(f"{robot.name}/{keys.IN}/nobody", b"")
    finally:
        for robot in robots:
            await robot.close()
        router.close()  # type: ignore[no-untyped-call]
    assert callback_threads == []


def _asked(session: Any, key: str) -> list[Any]:
    return list(session.get(key, timeout=5.0))


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
