"""What an op group (topics, services, actions) may use of its session and of the bridge.

The op groups hold a :class:`Host`, not the :class:`~bridge_server.session.session.Session`
and the bridge whole (as the client's capabilities hold ``roslibpy_lite.capabilities.Host``):
what they may touch is written down here, and a second server (a relay on Zenoh) gives them
the same members. What every session shares (who serves which name, the action clients,
the metrics) is the host's :attr:`Host.shared`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Collection, Coroutine
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from roslibpy_lite.protocol import ops

    from ..graph import Graph
    from ..http.metrics import BridgeMetrics
    from ..security import Gate, SecurityConfig
    from .actions import ActionClients, SessionActions
    from .calls import Calls
    from .config import SessionConfig
    from .outbox import Outbox
    from .ownership import Ownership
    from .services import SessionServices

__all__ = ["Host", "Shared"]


class Shared(Protocol):
    """What the sessions of one server share (the bridge is one)."""

    graph: Graph
    metrics: BridgeMetrics
    service_owners: Ownership[SessionServices]
    action_owners: Ownership[SessionActions]
    action_clients: ActionClients
    publisher_grace: float

    @property
    def sessions(self) -> Collection[Host]:
        """The live sessions."""

    def graph_changed(self) -> None:
        """The session changed the ROS graph (a subscription whose type is to be learned)."""


class Host(Protocol):
    """One client's session as its op groups see it."""

    sid: int
    loop: asyncio.AbstractEventLoop
    graph: Graph
    gate: Gate
    outbox: Outbox
    shared: Shared
    actions: SessionActions
    calls: Calls
    """The tasks its requests run in (their number is the calls in flight)."""
    frame_len: int
    acks: bool
    """Whether the client asked for verdicts on its ops (``ACKS_HEADER``)."""

    @property
    def config(self) -> SessionConfig:
        """The bridge's session settings."""

    @property
    def limits(self) -> SecurityConfig:
        """The per-connection limits as configured now."""

    @property
    def closed(self) -> bool:
        """Whether the connection has ended."""

    def send_op(self, op: ops.Op) -> None:
        """Send an op to the client."""

    def send_text(self, text: str | bytes) -> None:
        """Send a ready frame to the client."""

    def status(self, level: str, msg: str, id: ops.Id | None = None) -> None:
        """Send a ``status`` op (if the client's level lets it through)."""

    def error(self, msg: str, id: ops.Id | None = None, kind: str = "request") -> None:
        """Send an error ``status`` and count it."""

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task ended with the session."""
