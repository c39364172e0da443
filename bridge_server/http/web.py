"""The bridge's plain-HTTP routes, answered on its websocket port before any upgrade.

======================  =================================================================
``GET /``               the live status page (``static/index.html``; it polls
                        ``/status.json`` once a second)
``GET /static/<file>``  the page's own CSS and JavaScript (no CDN, nothing external)
``GET /status.json``    the whole bridge (every worker) as JSON, filtered for the viewer
``GET /metrics``        Prometheus text exposition (:mod:`bridge_server.http.metrics`)
``GET /healthz``        200 while the process runs (liveness)
``GET /readyz``         200 once rclpy is up and the port is listening, else 503
======================  =================================================================

A websocket upgrade request on any path goes on to the websocket handshake
(and to the security checks that run after these routes). Every response
carries ``X-Bridge-Worker: <index>``, as do websocket handshake responses.

Who sees what
-------------
An :class:`Access` decides, for the data routes (``/status.json`` and
``/metrics``; the page and its assets hold no data): ``principal(request, address)``
says who is asking (or raises :class:`Denied`, e.g. 401 without a valid
token, 429 for an address locked out after failed attempts) and
``may_see(principal, kind, name)`` whether that viewer may see a ``route``,
a ``topic``, a ``service``, an ``action`` or a ``client``.
:func:`visible` applies it to the status data and to the metrics, so neither
shows what the role may not. This plain :class:`Access` shows everything
(authentication off); the bridge sets ``bridge.web.access`` to
:class:`bridge_server.http.web_access.WebAccess` (tokens, roles' ``introspection``
patterns). The page passes its own ``?token=`` on to ``/status.json``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from bridge_server.http import metrics, rates, snapshot
from bridge_server.workers.peers import serve_peer_socket
from rosbridge_core.protocol.ops import ACKS_HEADER, AUTH_HEADER, RECEIVED_HEADER, SESSION_HEADER

if TYPE_CHECKING:
    from prometheus_client.core import Metric
    from websockets.asyncio.server import ServerConnection
    from websockets.http11 import Request, Response

    from rosbridge_core.security.auth import AuthConfig

__all__ = ["Access", "Denied", "Reply", "Served", "Web", "address_of", "handshake_headers",
           "open_route", "respond", "static_files", "viewer", "visible"]

log = logging.getLogger("bridge_server.http.web")

STATIC = Path(__file__).resolve().parent / "static"
_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".ico": "image/x-icon",
}
RATE_INTERVAL = 1.0
"""Seconds between rate measurements (the status page's ``/s`` figures)."""


class Denied(Exception):
    """Raised by :meth:`Access.principal` to refuse a request (e.g. 401, 403)."""

    def __init__(self, status: int, reason: str, headers: list[tuple[str, str]] | None = None
                 ) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason
        self.headers = headers or []


class Access:
    """Who is asking, and what they may see. This default: anyone, everything."""

    def principal(self, request: Request, address: str) -> Any:
        """The viewer of ``request`` from client ``address`` (``None``: anonymous); raise
        :class:`Denied` to refuse."""
        return None

    def may_see(self, principal: Any, kind: str, name: str) -> bool:
        """Whether ``principal`` may see ``name`` of ``kind`` (route, topic, service, action,
        client)."""
        return True


def visible(status: Mapping[str, Any], principal: Any, access: Access) -> dict[str, Any]:
    """The status data with everything ``principal`` may not see left out."""
    def ok(kind: str, name: str) -> bool:
        return access.may_see(principal, kind, name)

    out = dict(status)
    out["topics"] = {k: v for k, v in status.get("topics", {}).items() if ok("topic", k)}
    out["services"] = [s for s in status.get("services", []) if ok("service", s["name"])]
    out["actions"] = [a for a in status.get("actions", []) if ok("action", a["name"])]
    clients = []
    for c in status.get("clients", []):
        if not ok("client", c["id"]):
            continue
        c = dict(c)
        if not ok("address", c["id"]):
            c["address"] = ""
        c["subscriptions"] = [s for s in c["subscriptions"] if ok("topic", s["topic"])]
        c["publishes"] = [t for t in c["publishes"] if ok("topic", t)]
        c["serves"] = [s for s in c["serves"] if ok("service", s)]
        clients.append(c)
    out["clients"] = clients
    for key in ("service_calls", "action_goals"):
        kind = "service" if key == "service_calls" else "action"
        out[key] = {k: v for k, v in status.get(key, {}).items() if ok(kind, k)}
    return out


@dataclass
class Reply:
    """A plain HTTP response."""

    status: int
    body: bytes
    content_type: str = "text/plain; charset=utf-8"
    headers: list[tuple[str, str]] = field(default_factory=list)


class WebConfig(snapshot.Worker, Protocol):
    """The settings the routes follow (:class:`~bridge_server.front.server.BridgeConfig`)."""

    @property
    def host(self) -> str:
        """Where ``--metrics-port`` listens."""

    @property
    def metrics_port(self) -> int | None:
        """The plain-HTTP routes' own port, if any."""

    @property
    def worker_dir(self) -> str | None:
        """With ``--workers``: where the workers' sockets are."""


class Authenticating(Protocol):
    """The security, as far as the handshake's answer goes."""

    @property
    def auth(self) -> AuthConfig | None:
        """The auth file's principals (``None``: no authentication)."""


class Received(Protocol):
    """A session resumed by a handshake: the frames it received, told in the answer."""

    @property
    def received(self) -> int:
        """Frames received in the session."""


class Served(snapshot.Observed, Protocol):
    """What the routes read of a bridge (:class:`~bridge_server.front.server.Bridge`)."""

    @property
    def config(self) -> WebConfig:
        """The settings."""

    @property
    def security(self) -> Authenticating:
        """The security."""

    @property
    def session_plans(self) -> Mapping[ServerConnection, tuple[str, Received | None]]:
        """The session each handshake under way was given (resume.py)."""

    def listening(self) -> bool:
        """Whether the websocket port takes connections."""


class Web:
    """The routes, the rate meter, and (with workers) the view of the other workers."""

    def __init__(self, bridge: Served) -> None:
        self.bridge = bridge
        self.access = Access()
        self.caps = metrics.new_caps()
        self.meter = rates.RateMeter()
        self.peers: Callable[[], Awaitable[list[dict[str, Any]]]] | None = None
        """Set by the worker machinery: fetches the other workers' snapshots."""
        self._ticker: asyncio.Task[None] | None = None
        self._servers: list[asyncio.Server] = []
        self._static = static_files()
        self.metrics_port: int | None = None
        self.extra_metrics: list[Callable[[Callable[[str], bool]], Iterable[Metric]]] = []
        """More families for ``/metrics``, each given whether the viewer may see a topic
        (a robot's replay windows)."""
        self.extra_status: list[Callable[[], Mapping[str, Any]]] = []
        """More sections of this process's ``/status.json`` (a robot's ``relay_uplink``)."""
        self.readiness: Callable[[], str | None] | None = None
        """Why the bridge is not ready besides ROS, if not its listener (``None``: ready);
        a robot reached only through relays is ready when its uplink is."""
        self.serving: Callable[[], bool] = bridge.listening
        """Whether the websocket port takes connections (a front that serves this bridge's
        sessions on its own port, the relay, sets its own)."""

    async def start(self) -> None:
        """Measure rates; serve ``--metrics-port`` and (as a worker) the peer socket."""
        cfg = self.bridge.config
        self._ticker = asyncio.create_task(self._tick(), name="bridge-rates")
        if cfg.metrics_port is not None:
            server = await serve_metrics_port(self, cfg.host, cfg.metrics_port)
            self._servers.append(server)
            self.metrics_port = int(next(iter(server.sockets)).getsockname()[1])
            log.info("metrics on http://%s:%d/metrics", cfg.host, self.metrics_port)
        if cfg.worker_dir is not None:
            self._servers.append(
                await serve_peer_socket(self, cfg.worker_dir, cfg.worker_index)
            )

    async def close(self) -> None:
        """Stop measuring and serving."""
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._ticker
        for server in self._servers:
            server.close()

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(RATE_INTERVAL)
            try:
                self.meter.tick(snapshot.topic_totals(self.bridge))
            except Exception:  # never let the meter take the bridge down
                log.exception("measuring rates failed")

    def local(self) -> dict[str, Any]:
        """This process's snapshot."""
        snap = snapshot.take(self.bridge, self.meter.rates)
        snap["rate_window_s"], snap["history"] = rates.RATE_WINDOW, self.meter.history()
        for section in self.extra_status:
            snap.update(section())
        return snap

    async def whole(self) -> dict[str, Any]:
        """The merged snapshot of every worker."""
        snaps = [self.local()]
        if self.peers is not None:
            snaps += await self.peers()
        return snapshot.merge(snaps)

    def ready(self) -> str | None:
        """Why the bridge is not ready (``None``: ready)."""
        trouble = self.bridge.graph.trouble()
        if trouble is not None:
            return trouble
        if self.readiness is not None:
            return self.readiness()
        return None if self.serving() else "not listening"

    # -- routing -------------------------------------------------------------------------------

    async def process_request(
        self, connection: ServerConnection, request: Request
    ) -> Response | None:
        """websockets' ``process_request``: answer a plain-HTTP route, or ``None`` to go on."""
        if any("upgrade" in v.lower() for v in request.headers.get_all("Connection")):
            return None
        reply = await self.answer(request, address_of(connection))
        return None if reply is None else respond(connection, reply)

    def process_response(
        self, connection: ServerConnection, request: Request, response: Response
    ) -> None:
        """websockets' ``process_response``: name the worker on every response."""
        if "X-Bridge-Worker" not in response.headers:
            response.headers["X-Bridge-Worker"] = str(self.bridge.config.worker_index)
        plan = self.bridge.session_plans.get(connection)
        if plan is not None and response.status_code == 101:  # resume.py
            token, kept = plan
            response.headers[SESSION_HEADER] = token
            if kept is not None:
                response.headers[RECEIVED_HEADER] = str(kept.received)
        handshake_headers(connection, request, response, self.bridge.security.auth is not None)

    async def answer(self, request: Request, address: str) -> Reply | None:
        """The reply to a plain GET of one of the routes from client ``address`` (``None``:
        not one of them)."""
        path = request.path.split("?", 1)[0]
        if path == "/":
            path = "/static/index.html"
        if path not in ("/status.json", "/metrics", "/healthz", "/readyz") and not (
            path.startswith("/static/") and path[8:] in self._static
        ):
            return None
        reply = open_route(path, self._static, self.ready)
        if reply is not None:
            return reply
        principal, refusal = viewer(self.access, request, address, path)
        if refusal is not None:
            return refusal
        nocache = [("Cache-Control", "no-store")]
        if path == "/status.json":
            data = visible(await self.whole(), principal, self.access)
            data["now"] = time.time()
            data["answered_by"] = self.bridge.config.worker_index
            body = json.dumps(data, separators=(",", ":")).encode()
            return Reply(200, body, "application/json", nocache)
        extra = [family for families in self.extra_metrics for family in families(
            lambda topic: self.access.may_see(principal, "topic", topic))]
        body = metrics.render(visible(await self.whole(), principal, self.access), self.caps,
                              extra)
        return Reply(200, body, metrics.CONTENT_TYPE, nocache)


def address_of(connection: ServerConnection) -> str:
    """The client's address (its host, without the port)."""
    addr = connection.remote_address
    return str(addr[0]) if isinstance(addr, tuple) else str(addr)


def handshake_headers(connection: ServerConnection, request: Request, response: Response,
                      auth: bool) -> None:
    """What any rosbridge handshake answer says (a bridge's, or a relay's before it knows
    the robot): acknowledgements confirmed if asked for (session.py), and with an auth file
    (``auth``) and no token yet that the first op must be ``auth``."""
    if "1" in request.headers.get_all(ACKS_HEADER):  # we confirm requests (session.py)
        response.headers[ACKS_HEADER] = "1"
    if (response.status_code == 101 and auth
            and getattr(connection, "principal", None) is None):
        response.headers[AUTH_HEADER] = "required"  # no token yet: the first op must be auth


def respond(connection: ServerConnection, reply: Reply) -> Response:
    """The websockets response carrying ``reply``."""
    response = connection.respond(reply.status, "")
    response.body = reply.body
    headers = response.headers
    del headers["Content-Length"], headers["Content-Type"]
    headers["Content-Length"] = str(len(reply.body))
    headers["Content-Type"] = reply.content_type
    for name, value in reply.headers:
        headers[name] = value
    return response


def static_files() -> dict[str, Path]:
    """The page's files by name (``static/``)."""
    return {p.name: p for p in STATIC.iterdir() if p.is_file()}


def open_route(path: str, static: Mapping[str, Path], ready: Callable[[], str | None]
               ) -> Reply | None:
    """The routes that hold no data, so need no token: ``/healthz``, ``/readyz`` (``ready()``
    says why not), the page's files in ``static`` (``None``: none of them)."""
    if path == "/healthz":
        return Reply(200, b"ok\n")
    if path == "/readyz":
        why = ready()
        return Reply(200, b"ready\n") if why is None else Reply(503, f"{why}\n".encode())
    file = static.get(path[8:]) if path.startswith("/static/") else None
    if file is None:
        return None
    return Reply(200, file.read_bytes(), _TYPES.get(file.suffix, "application/octet-stream"),
                 [("Cache-Control", "no-cache")])


def viewer(access: Access, request: Request, address: str, path: str
           ) -> tuple[Any, Reply | None]:
    """Who asks for data route ``path`` and, if they may not see it, the refusal (401 without
    a valid token, 429 locked out, 403 for a role that may not)."""
    try:
        principal = access.principal(request, address)
    except Denied as exc:
        return None, Reply(exc.status, f"{exc.reason}\n".encode(), headers=exc.headers)
    if not access.may_see(principal, "route", path):
        return principal, Reply(403, f"{path}: this role may not see it\n".encode())
    return principal, None


async def serve_metrics_port(web: Web, host: str, port: int) -> asyncio.Server:
    """A plain HTTP server for ``--metrics-port`` answering the same routes (GET only)."""
    from websockets.datastructures import Headers
    from websockets.http11 import Request

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            head = await asyncio.wait_for(reader.readuntil(b"\r\n\r\n"), 10)
            line, *rest = head.decode("latin-1").split("\r\n")
            method, target, _ = [*line.split(" "), "", ""][:3]
            headers = Headers()
            for h in rest:
                if ":" in h:
                    k, v = h.split(":", 1)
                    headers[k.strip()] = v.strip()
            peer = writer.get_extra_info("peername")
            address = str(peer[0]) if isinstance(peer, tuple) else str(peer)
            reply = (
                await web.answer(Request(target, headers), address) if method == "GET" else None
            ) or Reply(404, b"not found\n")
            writer.write((
                f"HTTP/1.1 {reply.status} {'OK' if reply.status == 200 else 'Error'}\r\n"
                f"Content-Type: {reply.content_type}\r\nContent-Length: {len(reply.body)}\r\n"
                f"X-Bridge-Worker: {web.bridge.config.worker_index}\r\n"
                + "".join(f"{k}: {v}\r\n" for k, v in reply.headers)
                + "Connection: close\r\n\r\n"
            ).encode() + reply.body
            )
            await writer.drain()
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, TimeoutError):
            pass
        finally:
            writer.close()

    return await asyncio.start_server(handle, host, port, reuse_port=True)
