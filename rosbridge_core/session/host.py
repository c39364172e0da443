"""What a session and its op groups (topics, services, actions) may use of each other and
of what every session shares.

The op groups hold a :class:`SessionView`, not the :class:`~rosbridge_core.session.session.Session`
whole (as the client's capabilities hold ``roslibpy_lite.capabilities.SessionView``), and a session
holds a :class:`Shared` and its :class:`~rosbridge_core.session.link.ClientLink`, not the bridge
and the websocket: what each may touch is written down here, and a second server (a relay on
Zenoh) or a test (``tests/session``: a fake graph and a fake link, no ROS, no socket) gives
them the same members. What every session shares (the graph, who serves which name, the
action clients, the metrics, the gate factory, the resume store, the settings, the sessions)
is :attr:`SessionView.shared`; the bridge (:class:`~bridge_server.front.server.Bridge`) is one.

These protocols name only modules below the session (graph, security's gate, the outbox, the
link, the resume store, ownership), never the session or its op groups, so nothing imports
back (``tests/core/test_import_cycles.py``).
"""

from __future__ import annotations

import asyncio
from collections.abc import Collection, Coroutine, Mapping
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from rosbridge_core.counters import BridgeMetrics
    from rosbridge_core.graph import ActionClient, Graph, ServedAction
    from rosbridge_core.protocol import ops
    from rosbridge_core.security.gate import Gate, GateFactory
    from rosbridge_core.security.options import SecurityConfig
    from rosbridge_core.session.calls import Calls
    from rosbridge_core.session.config import SessionConfig
    from rosbridge_core.session.link import ClientLink, LinkConfig
    from rosbridge_core.session.outbox import Outbox
    from rosbridge_core.session.ownership import Ownership
    from rosbridge_core.session.resume import SessionStore

__all__ = ["ActionClientPool", "GoalKeeper", "SessionView", "Shared"]


class ActionClientPool(Protocol):
    """The shared action clients (:class:`~rosbridge_core.session.actions.ActionClients`)."""

    clients: dict[tuple[str, type[Any]], ActionClient]
    """The clients made, by action name and type."""
    lingering: dict[str, ServedAction]
    """Actions no client serves any more that still answer their callers."""

    def touch(self, session: SessionView, client: ActionClient) -> None:
        """``client`` is in use now."""

    def get(self, session: SessionView, name: str, action_cls: type[Any]) -> ActionClient:
        """The shared client for ``name`` of ``action_cls`` (created on first use)."""
        ...


class GoalKeeper(Protocol):
    """A session's goals as another session's op groups see them
    (:class:`~rosbridge_core.session.actions.SessionActions`)."""

    @property
    def goals(self) -> Mapping[Any, Any]:
        """The goals this client sent, by id."""

    def cancel_refusal(self, service: str, request: Any) -> str | None:
        """Why this client may not send ``request`` to ``service`` (``None``: it may)."""


class Shared(Protocol):
    """What the sessions of one server share (the bridge is one)."""

    graph: Graph
    metrics: BridgeMetrics
    service_owners: Ownership[Any]
    action_owners: Ownership[Any]
    publisher_grace: float

    @property
    def action_clients(self) -> ActionClientPool:
        """The bridge's shared action clients."""

    @property
    def security(self) -> GateFactory:
        """The gate of each new session, and the per-connection limits as configured now."""

    @property
    def resumable(self) -> SessionStore[Any]:
        """The sessions kept for a resume (resume.py)."""

    @property
    def session_config(self) -> SessionConfig:
        """The sessions' settings."""

    @property
    def link_config(self) -> LinkConfig:
        """The links' settings: the largest frame, the keepalive."""

    @property
    def sessions(self) -> Collection[SessionView]:
        """The live sessions."""

    def session_ended(self, session: SessionView) -> None:
        """A session kept for a resume ended without one: no longer among :attr:`sessions`."""

    def graph_changed(self) -> None:
        """The session changed the ROS graph (a subscription whose type is to be learned)."""


class SessionView(Protocol):
    """One client's session as its op groups see it."""

    sid: int
    loop: asyncio.AbstractEventLoop
    graph: Graph
    gate: Gate
    outbox: Outbox
    link: ClientLink
    shared: Shared
    calls: Calls
    """The tasks its requests run in (their number is the calls in flight)."""
    frame_len: int
    acks: bool
    """Whether the client asked for verdicts on its ops (``ACKS_HEADER``)."""

    @property
    def actions(self) -> GoalKeeper:
        """Its goals and served actions."""

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

    def refuse(self, op: Any, why: str) -> None:
        """Refuse ``op``: an error, and the failure answer a stock client waits for."""

    def handle_op(self, op: ops.Op) -> None:
        """Carry out one parsed op (as if the client had just sent it)."""

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task ended with the session."""
