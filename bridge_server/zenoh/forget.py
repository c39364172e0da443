"""A relay forgets the robots that left: their bridges, graphs, types and feeds go.

A relay opens a robot (a :class:`~bridge_server.front.server.Bridge` on a
:class:`~bridge_server.zenoh.graph.ZenohGraph`: its graph snapshot, its types, its feeds,
its status page) the first time a client asks for it, and used to keep it for ever: a fleet
where robots come and go (1,000 joining and leaving, one a second) left every one of them
on every relay that had served it, some 400 KB each (``bench/fleet.py``'s churn).

:class:`Forgetter` looks at the relay's robots every :data:`FORGET_AFTER` seconds: one that
is away from Zenoh (its graph's ``trouble()``) with no client session left (a session kept
for a resume counts) at two looks in a row is closed and dropped. A robot that comes back
later is opened again by the next client that asks, as any robot is. A look that forgot
robots ends with a full garbage collection: a closed robot is reference cycles (its bridge,
graph, feeds and callbacks) that hold Zenoh's native memory, which the collector's own
thresholds left for rounds (issue 49: the relay's RSS +8 MiB per 30 robots churned, flat
with a collection after each look). A robot that is away
while its clients wait for it is kept: their subscriptions resume when it is back.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from bridge_server.front.server import Bridge

__all__ = ["FORGET_AFTER", "Forgetter"]

log = logging.getLogger("bridge_server.relay")

FORGET_AFTER = 10.0
"""Seconds between two looks: a robot gone and unwatched is forgotten within twice this."""


class Forgetter:
    """Drops the relay's robots that are gone and unwatched (see the module's text)."""

    def __init__(self, robots: dict[str, Bridge], interval: float = FORGET_AFTER) -> None:
        self.robots = robots
        """The relay's robots by name (the relay's own dict, changed in place)."""
        self.interval = interval
        self.forgotten = 0
        """Robots forgotten so far (closed, and their memory collected)."""
        self.closing = 0
        """Robots being forgotten now: no longer listed, not yet closed and collected."""
        self._idle: set[str] = set()
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Look every :attr:`interval` seconds, from now on."""
        self._task = asyncio.get_running_loop().create_task(self._run(), name="relay-forget")

    async def _run(self) -> None:
        while True:
            await asyncio.sleep(self.interval)
            await self.sweep()

    async def sweep(self) -> None:
        """One look: forget the robots idle at the last look and still idle now."""
        idle = {name for name, bridge in self.robots.items() if _idle(bridge)}
        gone = idle & self._idle
        self._idle = idle - self._idle
        if not gone:
            return
        closing = [(name, self.robots.pop(name)) for name in gone]
        self.closing = len(closing)
        while closing:
            name, bridge = closing.pop()
            log.info("robot %s left and nobody waits for it: forgotten", name)
            try:
                await bridge.close()
            except Exception:  # one robot's close must not stop the others'
                log.exception("closing the bridge of robot %s failed", name)
            del bridge
        gc.collect()  # a closed robot is cycles holding Zenoh's native memory (issue 49)
        self.forgotten += self.closing
        self.closing = 0

    def stop(self) -> None:
        """Stop looking."""
        if self._task is not None:
            self._task.cancel()
            self._task = None


def _idle(bridge: Bridge) -> bool:
    """Away from Zenoh and without a session (a kept one too)."""
    with contextlib.suppress(Exception):
        return (bridge.graph.trouble() is not None and not bridge.sessions
                and not bridge.foxglove.sessions)
    return False
