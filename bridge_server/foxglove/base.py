"""What every part of a Foxglove client's session holds: its state, and the frames that tell
the client something (:class:`SessionBase`, the base of
:class:`~bridge_server.foxglove.session.FoxgloveSession`)."""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bridge_server.foxglove import ops
from bridge_server.foxglove.inbound import Inbound
from rosbridge_core.session.calls import Calls
from rosbridge_core.session.outbox import Outbox, TopicQueue

if TYPE_CHECKING:
    from bridge_server.foxglove.hub import GraphState, Hub
    from rosbridge_core.graph import Message as RosMessage
    from rosbridge_core.graph import Publisher
    from rosbridge_core.security.gate import Gate
    from rosbridge_core.security.options import SecurityConfig
    from rosbridge_core.session.host import Shared
    from rosbridge_core.session.link import ClientLink

__all__ = ["ENCODINGS", "ClientChannel", "SessionBase", "SessionTopics"]

log = logging.getLogger("bridge_server.foxglove")

ENCODINGS = ("cdr", "json")
"""Encodings a client may publish and call services in."""

_LEVELS = {"info": ops.STATUS_INFO, "warning": ops.STATUS_WARNING, "error": ops.STATUS_ERROR}


@dataclass
class ClientChannel:
    """A channel the client publishes on."""

    id: int
    topic: str
    encoding: str
    publisher: Publisher
    inbound: Inbound  # decodes and converts its messages, in order (large ones off the loop)


class SessionTopics:
    """A client's subscriptions and publishers by topic (what the bridge's per-topic
    counts read of every session kind)."""

    def __init__(self) -> None:
        self.subs: dict[str, TopicQueue] = {}
        self.publishers: dict[str, Publisher] = {}


class SessionBase:
    """A Foxglove client's state and the frames that tell it something; the parts of
    :class:`~bridge_server.foxglove.session.FoxgloveSession` (its channels, its parameters)
    build on it."""

    protocol_name = "foxglove"

    gate: Gate
    """The session's gate (made last, by :class:`~bridge_server.foxglove.session.FoxgloveSession`,
    which the gate holds)."""

    def __init__(self, shared: Shared, hub: Hub[Any], link: ClientLink, sid: int
                 ) -> None:
        """Client ``sid``'s session over ``link``, sharing ``shared`` with the other sessions
        of its server and ``hub`` with the other Foxglove ones."""
        self.shared = shared
        self.hub = hub
        self.graph = shared.graph
        self.link = link
        self.sid = sid
        self.loop = asyncio.get_running_loop()
        self.config = shared.session_config
        self.peer = link.address
        self.connected_at = time.time()
        self.calls = Calls(self.loop)
        self.outbox = Outbox(
            link, sid, self.config.control_limit, shared.security.config.max_queued_messages,
            self.config.drop_report_interval, lambda text: self.status("warning", text),
        )
        self.topics = SessionTopics()
        self.subscriptions: dict[int, tuple[TopicQueue, ops.Channel]] = {}
        self.client_channels: dict[int, ClientChannel] = {}
        self._publisher_refs: dict[str, int] = {}
        self._listeners: dict[TopicQueue, Callable[[RosMessage], None]] = {}
        self.parameter_names: set[str] | None = None  # None: not following; empty: all
        self.graph_seen: GraphState | None = None  # what it was told; None: not following
        self.shown_channels: set[int] = set()  # the ids of the channels it was told of
        self.shown_services: set[int] = set()
        self.uses_time = False

    @property
    def limits(self) -> SecurityConfig:
        """The bridge's per-connection limits (as configured now)."""
        return self.shared.security.config

    @property
    def wants_graph(self) -> bool:
        """Whether the client follows the connection graph."""
        return self.graph_seen is not None

    @property
    def closed(self) -> bool:
        """Whether the connection has ended."""
        return self.outbox.closed

    # -- sending -------------------------------------------------------------------------------

    def send_text(self, frame: str | bytes) -> None:
        """Queue one control frame (JSON text or a binary op)."""
        self.outbox.send_text(frame)

    def status(self, level: str, msg: str, id: Any = None, *, always: bool = True) -> None:
        """A ``status`` op (``level``: info, warning or error, as the gate says them)."""
        self.send_text(ops.json_frame("status", level=_LEVELS.get(level, ops.STATUS_ERROR),
                                       message=msg))

    def error(self, msg: str, kind: str = "request") -> None:
        """Tell the client of a refused or failed request; count it by kind."""
        log.info("foxglove client %d: %s", self.sid, msg)
        self.shared.metrics.error(kind)
        self.status("error", msg)

    def refuse(self, op: Any, why: str) -> None:
        """The gate's refusal of ``op`` (see :meth:`Gate.deny`)."""
        self.error(f"{getattr(op, 'OP', type(op).__name__)}: {why}")

    def send_time(self, stamp_ns: int) -> None:
        """The ``time`` op, to a client told of the ``time`` capability."""
        if self.uses_time:
            self.send_text(ops.time_frame(stamp_ns))

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task of this client's, cancelled when it leaves."""
        self.calls.spawn(coro)
