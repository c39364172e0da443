"""What Zenoh hears as declarations reaches the robot side on a Python thread, not on Zenoh's
(issue 49).

Zenoh calls a liveliness subscriber's callback, a liveliness query's replies and transport
events while it holds its session's lock. Run on Zenoh's own thread (``indirect=False``), such
a callback waits there for the interpreter's lock, while a Python thread holding that lock
(an undeclaration) waits for the session's: a 250-robot simulator process stopped for good
(gdb: ``close_queryable`` waiting for the session's lock, Zenoh's receive threads in
``send_declare`` waiting for the interpreter's). :func:`bridge_server.zenoh.link.declared`
gives them a Python thread; a thread Zenoh started shows in Python as a dummy thread.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

import pytest

from bench.ports import free_port
from bench.simrobot import Fleet, SimRobot
from bridge_server.zenoh import keys, link, uplink
from bridge_server.zenoh.exporter.base import ExporterBase
from bridge_server.zenoh.link import ZenohOptions, open_session
from bridge_server.zenoh.robot_link import RobotOptions

pytestmark = pytest.mark.timeout(120)

DECLARED = {"_on_claim", "_on_transport"}
"""The robot's callbacks fed by Zenoh's declarations that the test makes come: another
session's claim of the robot's name (through the router) and its link to the router."""
OTHER = "0123456789abcdef0123456789abcdef"
"""The Zenoh id in the other session's claim."""


def _on_zenohs_thread() -> bool:
    return isinstance(threading.current_thread(), threading._DummyThread)


async def test_declarations_reach_the_robot_on_a_python_thread(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A simulated robot (the bridge's own robot side) on a real router: the Zenoh callbacks
    of its claim and its transport events, and of its liveliness queries (its claim's look
    and its uplink probe), each run on a Python thread, not on one Zenoh started."""
    where: dict[str, bool] = {}
    claims = asyncio.Event()
    loop = asyncio.get_running_loop()
    cross = ExporterBase._cross

    def watched_cross(self: ExporterBase, fn: Any) -> Any:
        inner = cross(self, fn)

        def call(arg: Any) -> None:
            where[fn.__name__] = where.get(fn.__name__, False) or _on_zenohs_thread()
            if fn.__name__ == "_on_claim" and OTHER in str(arg.key_expr):
                loop.call_soon_threadsafe(claims.set)
            inner(arg)

        return call

    made = link.declared

    def watched_declared(fn: Any, end: Any = None) -> Any:
        def reply(arg: Any) -> None:
            where["a liveliness query's reply"] = (where.get("a liveliness query's reply", False)
                                                   or _on_zenohs_thread())
            fn(arg)

        return made(reply, end)

    monkeypatch.setattr(ExporterBase, "_cross", watched_cross)
    monkeypatch.setattr(link, "declared", watched_declared)
    monkeypatch.setattr(uplink, "declared", watched_declared)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router: Any = await open_session(ZenohOptions(listen=[endpoint]))
    robot = SimRobot("declared-0", RobotOptions(connect=[endpoint]))
    fleet = Fleet(RobotOptions(connect=[endpoint]), {robot.name: robot})
    try:
        robot.start()
        assert await fleet.until_holding([robot.name], 60) == []
        other = router.liveliness().declare_token(keys.claim_key(robot.name, OTHER))
        await asyncio.wait_for(claims.wait(), 30)  # through the router: on its receive thread
        other.undeclare()
    finally:
        await robot.close()
        router.close()
    assert DECLARED | {"a liveliness query's reply"} <= set(where), where
    assert not [name for name in DECLARED | {"a liveliness query's reply"} if where[name]], (
        f"called on a thread Zenoh started: {where}")
