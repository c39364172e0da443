"""Fixtures of the session tests: a :class:`~tests.session.harness.Bench` (a memory server
and its robot node), and ``ws_connect``, which opens in-memory clients on it as the suite's
``ws_connect`` opens websocket peers on a bridge process (same ``send``/``expect``)."""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from tests.session.harness import Bench, Client, Robot


@pytest.fixture
async def bench() -> AsyncIterator[Bench]:
    """A memory server with the bridge's session settings; its sessions ended after the test."""
    bench = Bench()
    try:
        yield bench
    finally:
        await bench.close()


@pytest.fixture
def robot(bench: Bench) -> Robot:
    """The other node of the bench's in-memory ROS graph."""
    return bench.robot


@pytest.fixture
def ws_connect(bench: Bench) -> Callable[..., Awaitable[Client]]:
    """A factory of clients (awaited, as the suite's), each with a session of its own on
    the bench."""

    async def connect(headers: dict[str, str] | None = None) -> Client:
        return bench.connect(Client(headers=headers))[1]

    return connect
