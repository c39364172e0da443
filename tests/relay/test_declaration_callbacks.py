"""What Zenoh hears as declarations reaches the robot side on Zenoh's own thread, starting no
Python thread (issue 49).

Zenoh calls a liveliness subscriber's callback, a liveliness query's replies and transport
events while it holds its session's lock. Given a Python thread each (a plain callable's
default), a simulated robot kept six and started one per liveliness query (its claim's looks,
its uplink probe each second): 1,760 threads in a process of 250 robots, which then did not
all join in 10 minutes. On Zenoh's thread (``indirect=False``) such a callback waits there for
the interpreter's lock, which is safe as long as no Python thread holding it waits for the
session's: :func:`bridge_server.zenoh.inbox.direct` says why none does now. A thread Zenoh
started shows in Python as a dummy thread.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

import pytest

from bench.ports import free_port
from bench.simrobot import Fleet, SimRobot
from bridge_server.zenoh import inbox, keys
from bridge_server.zenoh.exporter.base import ExporterBase
from bridge_server.zenoh.link import ZenohOptions, open_session
from bridge_server.zenoh.robot_link import RobotOptions

pytestmark = pytest.mark.timeout(120)

DECLARED = {"_on_claim", "_on_transport"}
"""The robot's callbacks fed by Zenoh's declarations that the test makes come: another
session's claim of the robot's name (through the router) and its link to the router."""
OTHER = "0123456789abcdef0123456789abcdef"
"""The Zenoh id in the other session's claim."""


def _no_thread_of_its_own(caller: threading.Thread) -> bool:
    """Called on a thread Zenoh started, or on the declaring thread (history replayed while
    declaring, a query answered by the session itself)."""
    here = threading.current_thread()
    return here is caller or isinstance(here, threading._DummyThread)


async def test_declarations_reach_the_robot_on_zenohs_thread(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A simulated robot (the bridge's own robot side) on a real router: the Zenoh callbacks
    of its claim and its transport events, and of its liveliness queries (its claim's look
    and its uplink probe), each run on a thread Zenoh started (or the declaring one), never
    on a Python thread of its own."""
    where: dict[str, bool] = {}
    claims = asyncio.Event()
    loop = asyncio.get_running_loop()
    caller = threading.current_thread()
    cross = ExporterBase._cross

    def watched_cross(self: ExporterBase, fn: Any) -> Any:
        inner = cross(self, fn)

        def call(arg: Any) -> None:
            where[fn.__name__] = where.get(fn.__name__, True) and _no_thread_of_its_own(caller)
            if fn.__name__ == "_on_claim" and OTHER in str(arg.key_expr):
                loop.call_soon_threadsafe(claims.set)
            inner(arg)

        return call

    made = inbox.direct

    def watched_direct(fn: Any, end: Any = None) -> Any:
        def reply(arg: Any) -> None:
            where["a liveliness query's reply"] = (where.get("a liveliness query's reply", True)
                                                   and _no_thread_of_its_own(caller))
            fn(arg)

        return made(reply, end)

    monkeypatch.setattr(ExporterBase, "_cross", watched_cross)
    monkeypatch.setattr(inbox, "direct", watched_direct)  # link and uplink import it late
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router: Any = await open_session(ZenohOptions(listen=[endpoint]))
    robot = SimRobot("direct-0", RobotOptions(connect=[endpoint]))
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
    assert all(where[name] for name in DECLARED | {"a liveliness query's reply"}), (
        f"called on a Python thread: {where}")
