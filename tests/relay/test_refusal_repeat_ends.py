"""A robot's repeated refusal under ``@refused`` ends when the refused token goes (issue 54:
with the popped repeat left uncancelled, its timer still fired and put itself back, so the
refusal went on every 4 s for ever)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

import pytest
import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter import Exporter
from bridge_server.zenoh.link import ZenohOptions, open_session
from tests.relay.support import ROBOT, free_port, start_relay, start_robot, until

pytestmark = pytest.mark.timeout(120)

MARGIN = 0.2
"""Seconds past a repeat's due time before the test looks whether it ran."""


class _PopsSeen(dict[str, asyncio.TimerHandle]):
    """The exporter's ``refusing`` table, keeping every handle popped from it."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.popped: list[asyncio.TimerHandle] = []

    def pop(self, key: str, *default: Any) -> Any:
        """dict.pop, the handle it took kept in ``popped``."""
        handle = super().pop(key, *default)
        if handle is not None:
            self.popped.append(handle)
        return handle


@pytest.fixture
async def robot_and_router() -> AsyncIterator[tuple[Exporter, str]]:
    """The robot's exporter, dialing a relay that is the Zenoh router; and its endpoint."""
    router = f"tcp/127.0.0.1:{free_port()}"
    hub = await start_relay(listen=router)
    robot, exporter = await start_robot(router)
    try:
        yield exporter, router
    finally:
        await hub.close()
        await exporter.close()
        await robot.close()


async def test_the_refusal_stops_being_put_once_its_token_goes(
        robot_and_router: tuple[Exporter, str], topic: str) -> None:
    """A played relay's ``@serve`` token of a type the robot lacks is refused and the refusal
    put again; once the token goes, the pending repeat is cancelled, and past its due time
    the refusal is still not scheduled again."""
    exporter, router = robot_and_router
    loop = asyncio.get_running_loop()
    refusing = _PopsSeen(exporter.refusing)
    exporter.refusing = refusing
    session = await open_session(ZenohOptions(connect=[router]))
    refused_at = keys.refused_key(ROBOT, "played", topic)
    refusals: list[str] = []
    subscriber: Any = session.declare_subscriber(
        refused_at, lambda s: refusals.append(s.payload.to_string()))
    token: Any = session.liveliness().declare_token(
        keys.serve_key(ROBOT, "played", topic, "nopkg/srv/Nope"))
    try:
        await until(lambda: refusals, "the robot's refusal")
        assert refused_at in refusing, "the robot does not repeat its refusal"
        seen = len(refusing.popped)
        token.undeclare()
        await until(lambda: len(refusing.popped) > seen, "the robot to see the token go")
        assert refused_at not in refusing
        (repeat,) = refusing.popped[seen:]
        assert repeat.cancelled(), "the repeat due when the token went is still scheduled"
        await asyncio.sleep(max(0.0, repeat.when() - loop.time()) + MARGIN)
        assert refused_at not in refusing, "the refusal was scheduled again after its token went"
    finally:
        subscriber.undeclare()
        with contextlib.suppress(zenoh.ZError):
            token.undeclare()
        session.close()  # type: ignore[no-untyped-call]
