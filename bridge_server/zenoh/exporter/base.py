"""What every part of the robot's :class:`~.exporter.Exporter` shares: the robot, its Graph
and Zenoh session, the event loop Zenoh's callbacks cross to, the tasks the answers run in,
the link's routers and the names relays' clients serve.

The parts (:mod:`.policy`, :mod:`.topics`, :mod:`.publishing`, :mod:`.services`,
:mod:`.served`, :mod:`.actions`, :mod:`.parameters`, :mod:`.graph`, :mod:`.presence`) are
mixins of :class:`ExporterBase`: each declares the state it keeps, the exporter's one
``__init__`` gives it its first value.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from bridge_server.zenoh.link import ZenohOptions
from bridge_server.zenoh.uplink import Uplink
from rosbridge_core.graph import Graph, ServedAction, ServedGoal, ServedService

__all__ = ["ExporterBase", "Served", "json_bytes", "log"]

log = logging.getLogger("bridge_server.zenoh.exporter")
"""The robot's one log for its link (every part's, and :mod:`~bridge_server.zenoh.uplink`'s)."""


@dataclass
class Served:
    """A service or action a relay's client serves, in ROS on the robot."""

    relay: str
    type_name: str
    ros: ServedService | ServedAction
    goals: dict[int, ServedGoal] = field(default_factory=dict)
    """An action's ROS goals in flight, by ``id()``."""


class ExporterBase:
    """The state every part of the exporter reads, and the crossing from Zenoh's threads."""

    graph: Graph
    robot: str
    options: ZenohOptions
    epoch: str
    session: zenoh.Session | None
    zid: str
    """This robot's Zenoh session id (once the session is open)."""
    uplink: Uplink
    """Whether a router holds the robot's presence, and what it sends (:mod:`.uplink`)."""
    uplinks: set[str]
    """The Zenoh ids of the routers this robot has a transport to now."""
    _uplink_since: float  # loop time the uplink came (back)
    served: dict[str, Served]
    """Services relays' clients serve by name; actions by their goal service's name."""
    _tasks: set[asyncio.Task[None]]
    _loop: asyncio.AbstractEventLoop

    def _spawn(self, coro: Any) -> None:
        task = self._loop.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _on_loop(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """A Zenoh callback that hands its argument to ``fn`` on the event loop, called on
        Zenoh's thread (:func:`.inbox.direct` says why that is safe; a callable's default is
        a Python thread of its own per subscriber, queryable or query: 13 a robot, 1,306 for
        100)."""
        return zenoh.handlers.Callback(self._cross(fn), indirect=False)

    def _cross(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        loop = self._loop

        def cross(arg: Any) -> None:
            with contextlib.suppress(RuntimeError):  # the loop closed while Zenoh called
                loop.call_soon_threadsafe(fn, arg)

        return cross


def json_bytes(obj: Any) -> bytes:
    """``obj`` as compact JSON bytes (what relays are answered with)."""
    return json.dumps(obj, separators=(",", ":")).encode()
