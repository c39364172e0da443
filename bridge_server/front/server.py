"""The websocket server: one :class:`~rosbridge_core.session.Session` per connection.

Each connection is its session's link
(:class:`~bridge_server.front.websocket.WebSocketLink`, a
:class:`~rosbridge_core.session.link.ClientLink`), and the :class:`Bridge` is what its
sessions share (:class:`~rosbridge_core.session.host.Shared`): a session sees neither the
websocket library nor the bridge whole.

Frames: text frames carry JSON ops, binary frames CBOR-encoded ops. Inbound
frames larger than ``max_message_size`` close the connection with code 1009
("message too big", websockets' own close reason names the limit).

Compression (permessage-deflate) is off by default: deflating every message
costs far more CPU than loopback or LAN bandwidth saves, and the bridge's
throughput is CPU bound. ``--compression deflate`` turns it on for slow links.

Each connection's socket write buffer is bounded by ``write_limit`` (high
water mark); a session's writer task waits on it, and only that session's
writer, so a client that stops reading never slows the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import time
import weakref
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import MultipleValuesError

from bridge_server.foxglove import SUBPROTOCOL, FoxgloveSession, Hub, select_subprotocol
from bridge_server.front.forward import Forwarder
from bridge_server.front.handshake import Security
from bridge_server.front.websocket import WebSocketLink
from bridge_server.http.metrics import BridgeMetrics
from bridge_server.http.web import Web
from bridge_server.http.web_access import WebAccess
from rosbridge_core.graph import Graph
from rosbridge_core.protocol import keepalive
from rosbridge_core.protocol.constants import DEFAULT_PORT
from rosbridge_core.protocol.errors import RemoteProtocolError
from rosbridge_core.protocol.ops import RECEIVED_HEADER, SESSION_HEADER, parse_received
from rosbridge_core.security import SecurityConfig
from rosbridge_core.security.options import MAX_MESSAGE_SIZE
from rosbridge_core.session.actions import ActionClients, SessionActions
from rosbridge_core.session.link import LinkConfig
from rosbridge_core.session.ownership import Ownership
from rosbridge_core.session.resume import ResumeConfig, SentFrames, SessionStore
from rosbridge_core.session.session import Session, SessionConfig, wait_ended

if TYPE_CHECKING:
    from collections.abc import Awaitable

    from websockets.http11 import Request, Response

    from rosbridge_core.session.host import SessionView
    from rosbridge_core.session.services import SessionServices

__all__ = ["Bridge", "BridgeConfig", "ServedGraph"]

log = logging.getLogger("bridge_server")


WRITE_LIMIT = 256 * 1024
"""A client's socket write buffer's high-water mark by default (``--write-limit``)."""


@dataclass
class BridgeConfig:
    """Everything the command line can set."""

    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    max_message_size: int = MAX_MESSAGE_SIZE
    write_limit: int = WRITE_LIMIT
    compression: bool = False
    publisher_grace: float = 2.0
    node_name: str = field(default_factory=lambda: default_node_name())  # see default_node_name
    refresh_interval: float = 0.5
    topic_reader: str = "auto"  # who waits on the topics (rclpy_graph.reader.open_reader)
    keepalive_interval: float = keepalive.DEFAULT_INTERVAL  # 0: no keepalive of our own
    keepalive_timeout: float = keepalive.DEFAULT_TIMEOUT
    session: SessionConfig = field(default_factory=SessionConfig)
    resume: ResumeConfig = field(default_factory=ResumeConfig)  # sessions that outlive links
    security: SecurityConfig = field(default_factory=SecurityConfig)  # TLS, auth, limits
    metrics_port: int | None = None  # /metrics (and the other plain routes) on another port
    worker_index: int = 0  # with --workers: this process's index, and the peers' socket dir
    worker_dir: str | None = None
    websocket: bool = True  # False: no listener at all (a robot reached only through Zenoh)


class ServedGraph(Graph, Protocol):
    """A Graph the bridge runs: started with it, refreshed while topics are subscribed,
    closed with it (:class:`~bridge_server.rclpy_graph.graph.RclpyGraph`, or a relay's
    ``ZenohGraph``)."""

    def start(self) -> None:
        """Start serving (called on the event loop)."""

    def refresh(self) -> None:
        """Resolve late types, follow QoS changes (called every ``refresh_interval`` s while
        something is subscribed)."""

    def close(self) -> None:
        """Release everything."""


NODE_NAME_PREFIX = "roslibpy_lite_bridge"


def default_node_name() -> str:
    """A ROS node name no other bridge on the domain has: the prefix and this process's id.

    Several bridges on one ROS domain (a loopback one beside a secured one, one per robot
    on a shared network) must not share a node name: ROS graph queries by node name would
    mix them up. ``--node-name`` sets a stable name instead.
    """
    return f"{NODE_NAME_PREFIX}_{os.getpid()}"


def websockets_pings(config: BridgeConfig, tcp: bool = True) -> dict[str, Any]:
    """websockets' own ping options for a listener: none on TCP where the sessions watch
    their links themselves (keepalive.py: a silent peer is pinged first, a pong late behind
    a big frame or a stall of our own drops nobody), the keepalive figures elsewhere."""
    if tcp and config.keepalive_interval and keepalive.supported_here():
        return {"ping_interval": None, "ping_timeout": None}
    return {"ping_interval": config.keepalive_interval or None,
            "ping_timeout": config.keepalive_timeout or None}


class Bridge:
    """The running bridge: the ROS node, the websocket server and the live sessions."""

    def __init__(self, config: BridgeConfig, graph: ServedGraph) -> None:
        """``graph``: the ROS side (``RclpyGraph`` for the bridge, a ``ZenohGraph`` per robot
        in a relay); the server itself imports no ROS."""
        self.config = config
        self.session_config = config.session
        self.link_config = LinkConfig(config.max_message_size, config.keepalive_interval,
                                      config.keepalive_timeout)
        self.publisher_grace = config.publisher_grace
        self.sessions: set[Session] = set()
        # the session each handshake was given (a resume, or a new one): planned before the
        # handshake's answer (which names it), taken when the connection is served
        self.session_plans: weakref.WeakKeyDictionary[
            ServerConnection, tuple[str, Session | None]] = weakref.WeakKeyDictionary()
        # which client serves each client-served name (ownership.py)
        self.service_owners: Ownership[SessionServices] = Ownership("service")
        self.action_owners: Ownership[SessionActions] = Ownership("action")
        self.action_clients = ActionClients()
        self.resumable: SessionStore[Session] = SessionStore(  # kept for a resume (resume.py)
            config.resume, config.worker_index if config.worker_dir is not None else None)
        self.closing = False
        self._ids = itertools.count(1)
        self._server: Server | None = None
        self.forwarder: Forwarder | None = None  # with --workers (workers/forward.py)
        self._refresher: asyncio.Task[None] | None = None
        self._graph_event = asyncio.Event()
        self.ros: ServedGraph = graph
        self.graph: Graph = self.ros  # all the sessions, rosapi and the status page see of ROS
        self.metrics = BridgeMetrics()
        self.web = Web(self)  # plain-HTTP routes: status page, /metrics, health (web.py)
        self.security = Security(config.security)  # TLS, auth, origins, limits (security/)
        self.web.access = WebAccess(self.security)  # who sees the plain-HTTP routes
        # Foxglove clients (foxglove/)
        self.foxglove: Hub[FoxgloveSession] = Hub(self.graph, self.graph_changed)

    @property
    def port(self) -> int:
        """The port actually bound (useful with port 0)."""
        assert self._server is not None
        sock = next(iter(self._server.sockets))
        return int(sock.getsockname()[1])

    def listening(self) -> bool:
        """Whether the websocket port takes connections."""
        return self._server is not None and self._server.is_serving()

    async def start(self) -> None:
        """Start ROS and listen (unless ``config.websocket`` is off: then only the rates and
        ``--metrics-port``, a robot reached through relays)."""
        self.start_graph()
        if self.config.websocket:
            await self.listen()
        else:
            await self.web.start()

    def start_graph(self) -> None:
        """Start the ROS side and its refresh loop, without listening: a front that serves
        several bridges' sessions on one port (the relay) calls this, then hands connections
        to :meth:`admit` and :meth:`serve_connection`."""
        self.ros.start()
        self._refresher = asyncio.create_task(self._refresh_loop(), name="bridge-refresh")

    async def listen(self) -> None:
        """Open the websocket listener and the plain-HTTP routes (as a worker, also the unix
        socket that takes other workers' forwarded session resumes: workers/forward.py)."""
        kwargs: dict[str, Any] = dict(
            max_size=self.config.max_message_size,
            write_limit=self.config.write_limit,
            compression="deflate" if self.config.compression else None,
            max_queue=64,
            close_timeout=1.0,
            select_subprotocol=select_subprotocol,  # foxglove.websocket.v1, else rosbridge
            process_response=self.web.process_response,
            **self.security.serve_kwargs(),
        )
        # Sessions watch their links themselves where TCP can tell (keepalive.py);
        # elsewhere (and on a unix socket) websockets pings with the same figures.
        pings = websockets_pings(self.config, tcp=False)
        tcp_pings = websockets_pings(self.config)
        process_request = self._process_request
        cfg = self.config
        if cfg.worker_dir is not None:
            self.forwarder = Forwarder(cfg.worker_dir, cfg.worker_index, self._process_request)
            process_request = self.forwarder.process_request
            await self.forwarder.serve(self._handle, **kwargs, **pings)
        self._server = await serve(
            self._handle,
            cfg.host,
            cfg.port,
            process_request=process_request,
            reuse_port=cfg.worker_dir is not None,
            **kwargs,
            **tcp_pings,
        )
        await self.web.start()

    async def admit(self, connection: ServerConnection, request: Request,
                    secured: bool = False) -> Any:
        """The checks before a connection's handshake (plain-HTTP routes, security, session
        resume), for a front that serves this bridge's sessions on its own port; with
        ``secured`` the front ran the security checks itself (a relay, before it opens the
        robot) and only the session resume is planned here."""
        return await self._admit(connection, request, secured)

    async def serve_connection(self, ws: ServerConnection) -> None:
        """Serve one admitted connection until it ends (for such a front)."""
        await self._handle(ws)

    async def _process_request(self, connection: ServerConnection, request: Request) -> Any:
        """Before the handshake: plain-HTTP routes first (web.py), then the security checks."""
        return await self._admit(connection, request, False)

    async def _admit(self, connection: ServerConnection, request: Request, secured: bool
                     ) -> Any:
        """As :meth:`_process_request`; the routes and security checks only if not
        ``secured`` (done by the front)."""
        try:
            refusal = None
            if not secured:
                response = await self.web.process_request(connection, request)
                if response is not None:
                    return response
                refusal = await self.security.process_request(connection, request)
            if refusal is None and self.resumable.enabled and SESSION_HEADER in request.headers:
                refusal = await self._plan_session(connection, request)
        except MultipleValuesError as exc:  # a header given twice that must be given once
            log.warning("refused a request from %s: header %s sent more than once",
                        _peer(connection), exc)
            refusal = connection.respond(400, f"header {exc} sent more than once\n")
        if refusal is not None:  # counted by reason for /metrics
            code = refusal.status_code
            self.metrics.connection_refused(REFUSALS.get(code, f"http_{code}"))
        return refusal

    async def _plan_session(self, connection: ServerConnection, request: Request
                            ) -> Response | None:
        """A client that asks for a session gets one: the one it names if that can be
        resumed (its old connection is given up now), else a new one (resume.py). A resume
        whose received count is malformed, or more than the session sent, is refused (400)
        before the session is touched, so it stays resumable."""
        asked = request.headers.get(SESSION_HEADER, "")
        session = None
        received = 0
        if asked != "new":
            principal = getattr(connection, "principal", None)
            live = self.resumable.live.get(asked)
            sent = live.outbox.sent if live is not None and live.gate.principal is principal \
                else None  # another's session is not told apart from none
            try:
                received = parse_received(request.headers.get(RECEIVED_HEADER),
                                          None if sent is None else sent.count)
            except RemoteProtocolError as exc:
                log.warning("refused a session resume from %s: %s", _peer(connection), exc)
                return connection.respond(400, f"{exc}\n")
            session = await self.resumable.claim(asked, principal)
        token = asked if session is not None else self.resumable.new_token()
        self.session_plans[connection] = (token, session)
        if session is not None:
            session.resume_from = received
        return None

    def session_ended(self, session: SessionView) -> None:
        """A session kept for a resume ended without one."""
        if isinstance(session, Session):
            self.sessions.discard(session)

    def graph_changed(self) -> None:
        """Something needs the periodic graph check (a new subscription): run it soon."""
        self._graph_event.set()

    async def _refresh_loop(self) -> None:
        """Resolve late publishers' types, follow QoS changes; idle while nothing is subscribed."""
        interval = self.config.refresh_interval
        while True:
            if not self.ros.subscriptions:
                self._graph_event.clear()
                await self._graph_event.wait()
            # asyncio.timeout, not wait_for: on 3.11 wait_for drops a cancel that comes as the
            # event is set, and close() would wait for this task for ever.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(interval):
                    await self._graph_event.wait()
            self._graph_event.clear()
            self.ros.refresh()

    async def _handle(self, ws: ServerConnection) -> None:
        if not isinstance(ws, WebSocketLink):  # every listener's create_connection makes one
            raise TypeError(f"a {type(ws).__name__} is no session link")
        link = ws
        peer = link.address
        if ws.subprotocol == SUBPROTOCOL:
            await self._handle_foxglove(link, peer)
            return
        plan = self.session_plans.pop(ws, None)
        token, kept = plan if plan is not None else ("", None)
        if kept is not None:  # a resumed session: the same client on a new connection
            log.info("client %d reconnected from %s and resumed its session", kept.sid, peer)
            self.resumable.register(token, kept)
            session = kept
            running = session.resume(link, session.resume_from)
        else:
            sid = next(self._ids)
            log.info("client %d connected from %s", sid, peer)
            session = Session(self, link, sid)
            session.connected_at = time.time()
            self.sessions.add(session)
            if plan is not None:
                r = self.resumable.config
                session.token = token
                session.outbox.sent = SentFrames(r.resume_frames, r.resume_bytes)
                self.resumable.register(token, session)
            running = session.run()
        self.metrics.connections += 1
        try:
            await running
        finally:
            if not session.parked:
                self.sessions.discard(session)
                log.info("client %d (%s) disconnected", session.sid, peer)

    async def _handle_foxglove(self, link: WebSocketLink, peer: str) -> None:
        """A Foxglove client: its own session type, the same graph, limits and gate."""
        sid = next(self._ids)
        log.info("client %d connected from %s (foxglove.websocket.v1)", sid, peer)
        session = FoxgloveSession(self, self.foxglove, link, sid)
        self.metrics.connections += 1
        try:
            await session.run()
        finally:
            log.info("client %d (%s) disconnected", sid, peer)

    def reload(self) -> bool:
        """Read the certificates and the auth file again (SIGHUP; see :meth:`Security.reload`)."""
        gates = [session.gate for session in list(self.sessions)]
        gates += [session.gate for session in list(self.foxglove.sessions)]
        return self.security.reload(gates)

    async def close(self) -> None:
        """Stop listening, close every connection (at most ~1 s), release ROS."""
        self.closing = True
        self.resumable.close()
        await wait_ended()
        if self._refresher is not None:
            self._refresher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._refresher
        await self.web.close()
        await self.foxglove.close()
        servers = [] if self._server is None else [self._server]
        if self.forwarder is not None:
            self.forwarder.close()
            servers += [] if self.forwarder.server is None else [self.forwarder.server]
        for srv in servers:
            srv.close(close_connections=True)
        if servers:
            waiter: Awaitable[Any] = asyncio.gather(*(srv.wait_closed() for srv in servers))
            try:
                await asyncio.wait_for(waiter, 0.5)
            except TimeoutError:
                # Peers that do not answer the closing handshake are cut off.
                for link in [s.link for s in self.sessions] + [
                        s.link for s in self.foxglove.sessions]:
                    link.abort()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(
                        asyncio.gather(*(srv.wait_closed() for srv in servers)), 0.2)
        self.ros.close()


REFUSALS = {401: "auth", 403: "origin", 429: "too_many", 503: "max_clients"}
"""``connections_refused_total`` reasons, by the HTTP status of the refusal."""


def _peer(ws: ServerConnection) -> str:
    addr = ws.remote_address
    if isinstance(addr, tuple) and len(addr) >= 2:
        return f"{addr[0]}:{addr[1]}"
    return str(addr)
