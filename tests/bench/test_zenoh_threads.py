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

import pytest

from bench.ports import free_port
from bridge_server.zenoh.link import ZenohOptions, open_session, tokens
from bridge_server.zenoh.uplink import router_answers

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

