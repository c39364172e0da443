"""A rosbridge server in memory: the real sessions over a :class:`~.graph.MemoryGraph`, each
client on a :class:`~.link.MemoryLink`.

:class:`MemoryServer` is what the sessions share (:class:`~rosbridge_core.session.host.Shared`),
as the :class:`~bridge_server.front.server.Bridge` is, without a socket, a listener, a status page
or ROS: :meth:`MemoryServer.connect` opens one client's session and returns its
:class:`MemoryConnection`. :class:`~roslibpy_lite.mock.MockRos` runs on it, so what MockRos
answers is what the bridge's sessions answer.

Nothing here needs rclpy, cbor2 or prometheus_client (a client-only install runs it).
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rosbridge_core.counters import BridgeMetrics
from rosbridge_core.memory.graph import MemoryGraph, MemoryRos
from rosbridge_core.memory.link import MemoryLink
from rosbridge_core.protocol.constants import MAX_MESSAGE_SIZE
from rosbridge_core.security.authority import Authority
from rosbridge_core.security.options import SecurityConfig
from rosbridge_core.session.actions import ActionClients, SessionActions
from rosbridge_core.session.config import SessionConfig
from rosbridge_core.session.link import LinkConfig
from rosbridge_core.session.ownership import Ownership
from rosbridge_core.session.resume import ResumeConfig, SessionStore
from rosbridge_core.session.services import SessionServices
from rosbridge_core.session.session import Session

if TYPE_CHECKING:
    from rosbridge_core.graph import Graph
    from rosbridge_core.session.host import SessionView

__all__ = ["MEMORY_SESSIONS", "MemoryConnection", "MemoryServer"]

MEMORY_SESSIONS = SessionConfig(discovery_wait=0.0)
"""The sessions' settings in memory: the bridge's, but a service or an action that is not in
the graph fails at once (nothing appears by discovery in memory)."""


@dataclass
class MemoryConnection:
    """One client's session on a :class:`MemoryServer` and its link."""

    session: Session
    link: MemoryLink
    task: asyncio.Task[None] = field(repr=False)

    def send(self, frame: str | bytes) -> None:
        """The client sends ``frame``; what the session answers at once (replies, statuses,
        messages) is delivered before this returns."""
        self.link.receive(frame)
        self.flush()

    def flush(self) -> None:
        """Deliver now what the session has queued for the client."""
        self.session.outbox.write_queued()

    def drop(self, *, by_client: bool = False) -> None:
        """The link ends (``by_client``: the client closed it; else it was lost): the session
        releases what the client owned, soon after."""
        self.link.drop(by_client=by_client)

    async def ended(self) -> None:
        """Return once the session has released what the client owned."""
        await asyncio.wait([self.task])


class MemoryServer:
    """What the sessions of an in-memory server share (see the module's text).

    ``graph``: the server's node (a new graph of its own when not given); ``config``: the
    sessions' settings; ``security``: the limits and auth of the bridge's command line;
    ``resume``: how long a session whose link was lost is kept for a resume (by default
    none is kept).
    """

    def __init__(self, graph: MemoryGraph | None = None, *,
                 config: SessionConfig = MEMORY_SESSIONS,
                 security: SecurityConfig | None = None,
                 max_message_size: int = MAX_MESSAGE_SIZE,
                 resume: ResumeConfig | None = None) -> None:
        self.node = graph if graph is not None else MemoryGraph(MemoryRos(), "rosbridge")
        """The server's node of the in-memory graph."""
        self.graph: Graph = self.node
        self.metrics = BridgeMetrics()
        self.service_owners: Ownership[SessionServices] = Ownership("service")
        self.action_owners: Ownership[SessionActions] = Ownership("action")
        self.action_clients = ActionClients()
        self.security = Authority(security or SecurityConfig())
        self.resumable: SessionStore[Session] = SessionStore(
            resume or ResumeConfig(session_keep=0.0))
        self.session_config = config
        self.link_config = LinkConfig(max_message_size, 0.0, 0.0)
        self.publisher_grace = 0.0
        self.sessions: set[Session] = set()
        self._ids = itertools.count(1)
        self._running: set[asyncio.Task[None]] = set()

    @property
    def ros(self) -> MemoryRos:
        """The whole in-memory ROS graph the server's node is part of."""
        return self.node.ros

    def connect(self, deliver: Callable[[str | bytes], None], *,
                headers: Mapping[str, str] | None = None,
                on_close: Callable[[int, str], None] | None = None) -> MemoryConnection:
        """A new client: its session runs from now on (call on the loop). ``deliver`` gets
        each frame the session writes; ``on_close`` the code and reason if the session closes
        the link."""
        sid = next(self._ids)
        link = MemoryLink(deliver, headers=headers, on_close=on_close, address=f"memory:{sid}")
        session = Session(self, link, sid)
        link.hand_frames_to(session.handle_frame)  # taken in the client's call from now on
        self.sessions.add(session)
        self.metrics.connections += 1
        task = asyncio.get_running_loop().create_task(self._run(session),
                                                      name=f"memory-session-{sid}")
        self._running.add(task)
        task.add_done_callback(self._running.discard)
        return MemoryConnection(session, link, task)

    async def _run(self, session: Session) -> None:
        try:
            await session.run()
        finally:
            self.sessions.discard(session)

    def session_ended(self, session: SessionView) -> None:
        """A session kept for a resume ended."""
        if isinstance(session, Session):
            self.sessions.discard(session)

    def graph_changed(self) -> None:
        """Nothing to refresh: the in-memory graph knows every type at once."""

    async def close(self) -> None:
        """End every session, wait until each has released what it owned, and leave the
        graph."""
        for session in list(self.sessions):
            session.link.abort()
        await asyncio.gather(*self._running, return_exceptions=True)
        self.node.close()
