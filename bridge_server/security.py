"""TLS, authentication, origins and limits: everything between a socket and a session.

One :class:`Security` per bridge holds the configuration (:class:`SecurityConfig`,
set from the command line) and does three jobs:

* at the handshake (:meth:`Security.process_request`, called from the server's
  ``process_request`` hook after any plain-HTTP routes): the browser origin,
  the client limits (in all and per address), the failed-attempt lock-out and
  a token from an ``Authorization: Bearer`` header or a ``?token=`` query
  parameter. A wrong token is HTTP 401; no token at all, when the auth file
  requires one, lets the connection open but its first op must be ``auth``
  (what browsers and roslib can send);
* per connection (:class:`BridgeConnection`): a byte budget for inbound data
  waiting to be handled, per connection and in all; over it, the bridge stops
  reading that socket (TCP pushes back on the sender) until it has caught up;
* per session (:class:`Gate`, consulted by the session before each frame and
  each op): the ``auth`` op, the op rate, name validity, the role's
  permissions and the caps on subscriptions, publishers and services.

:meth:`Security.reload` (SIGHUP) reads the certificate files and the auth file
again: new handshakes use them, sessions get their principal's role as now
defined, and sessions of a removed principal are closed.

Refusals answer the offender and nobody else: an HTTP status with a one-line
text at the handshake, a ``status`` error naming the op, the name and the role
for a forbidden op, and a close with code 1008 (policy violation) and a reason
for a failed ``auth`` op or an op flood. Tokens never reach a log line or an
error text (:class:`RedactTokens` also scrubs other libraries' log lines).
"""

from __future__ import annotations

import argparse
import asyncio
import ipaddress
import logging
import re
import ssl
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.messages import Assembler, SimpleQueue
from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed
from websockets.frames import Frame
from websockets.http11 import Request, Response

from roslibpy_lite import ops

from . import rosapi
from .auth import AuthConfig, AuthFileError, FailureTracker, Principal, load_auth_file
from .names import InvalidNameError, check_name
from .permissions import Role, filter_rosapi, requirement, rosapi_requirement
from .types import BridgeError
from .web import Access, Denied

if TYPE_CHECKING:
    from .session import Session

__all__ = [
    "BridgeConnection",
    "Gate",
    "RedactTokens",
    "Security",
    "SecurityConfig",
    "WebAccess",
    "add_arguments",
    "config_from_args",
    "install_log_redaction",
    "is_loopback",
    "parse_origins",
    "redact",
]

log = logging.getLogger("bridge_server.security")

PRE_AUTH_FRAME_LIMIT = 16 * 1024
"""Largest frame read from a connection that has not authenticated yet."""

OWNER_PING_TIMEOUT = 2.0
"""Seconds the client serving a name has to answer a ping before another client may take it."""

POLICY_VIOLATION = 1008
"""Close code for a failed ``auth`` op, ops before authentication and op floods."""


@dataclass
class SecurityConfig:
    """The security options of the command line (0 or None: no limit / off)."""

    certfile: str | None = None
    keyfile: str | None = None
    client_ca: str | None = None
    auth_file: str | None = None
    allowed_origins: list[str] | None = None
    max_clients: int = 1000
    max_clients_per_address: int = 0
    handshake_timeout: float = 10.0
    max_op_rate: float = 0.0
    op_burst: int = 0
    max_subscriptions: int = 1000
    max_publishers: int = 1000
    max_services: int = 1000
    max_goals: int = 1000
    inbound_budget: int = 32 * 1024 * 1024
    inbound_budget_total: int = 256 * 1024 * 1024


_TOKEN_PATTERNS = (
    re.compile(r"(?i)(bearer\s+)[^\s'\",]+"),
    re.compile(r"(?i)([?&]token=)[^&\s'\"]+"),
    re.compile(r"(?i)('mac':\s*'|\"mac\":\s*\")[^'\"]+"),
    # websockets' DEBUG line of a received data frame shows its start and end, not its keys:
    # an auth op's token can be there (as hex in a CBOR frame) where the key is elided.
    re.compile(r"(?m)^(< (?:TEXT|BINARY|CONT) ).+?(?= \[[^\]]*\]$)"),
)


def redact(text: str) -> str:
    """``text`` with anything that looks like a token replaced by ``<redacted>``."""
    for rx in _TOKEN_PATTERNS:
        text = rx.sub(r"\1<redacted>", text)
    return text


class RedactTokens(logging.Filter):
    """A logging filter that scrubs tokens from every record (install it on handlers)."""

    def filter(self, record: logging.LogRecord) -> bool:
        """Scrub ``record``'s message; never drop the record."""
        try:
            text = record.getMessage()
        except Exception:
            return True
        clean = redact(text)
        if clean != text:
            record.msg, record.args = clean, None
        return True


def _address(connection: ServerConnection) -> str:
    addr = connection.remote_address
    if isinstance(addr, tuple) and addr:
        return str(addr[0])
    return str(addr)


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` keeps the port on this machine."""
    if host in ("localhost", ""):
        return host == "localhost"
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _CountingQueue(SimpleQueue[Frame]):
    """websockets' frame queue, counting the bytes it holds (per connection and in all)."""

    def __init__(self, totals: _Inbound) -> None:
        super().__init__()
        self.totals = totals
        self.bytes = 0

    def put(self, item: Frame) -> None:
        n = len(item.data)
        self.bytes += n
        self.totals.bytes += n
        super().put(item)

    async def get(self, block: bool = True) -> Frame:
        item = await super().get(block)
        n = len(item.data)
        self.bytes -= n
        self.totals.bytes -= n
        return item

    def put_back(self, items: Any) -> None:
        n = sum(len(i.data) for i in items)
        self.bytes += n
        self.totals.bytes += n
        super().put_back(items)

    def abort(self) -> None:
        self.totals.bytes -= self.bytes
        self.bytes = 0
        self.totals = _Inbound()  # what is read after the end is no longer counted in all
        super().abort()


@dataclass
class _Inbound:
    bytes: int = 0


class _BudgetAssembler(Assembler):
    """Pauses reading when a connection holds more than its byte budget (or all do)."""

    def __init__(self, budget: int, total_budget: int, totals: _Inbound, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.frames = self.queue = _CountingQueue(totals)
        self.budget = budget
        self.total_budget = total_budget
        self.totals = totals

    def maybe_pause(self) -> None:
        if self.paused:
            return
        q = self.queue
        if (
            (self.high is not None and len(q) > self.high)
            or (self.budget and q.bytes > self.budget)
            or (self.total_budget and self.totals.bytes > self.total_budget)
        ):
            self.paused = True
            self.pause()

    def maybe_resume(self) -> None:
        if not self.paused:
            return
        q = self.queue
        if (self.low is None or len(q) <= self.low) and q.bytes <= self.budget // 4:
            self.paused = False
            self.resume()


class BridgeConnection(ServerConnection):
    """A server connection with an inbound byte budget and the principal it proved to be."""

    security: Security

    principal: Principal | None = None
    counted: str | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """websockets' hook: read frames through the budgeted assembler."""
        super().connection_made(transport)
        sec = self.security
        self.recv_messages = _BudgetAssembler(
            sec.config.inbound_budget,
            sec.config.inbound_budget_total,
            sec.inbound,
            high=self.max_queue_high,
            low=self.max_queue_low,
            pause=self.transport.pause_reading,
            resume=self.transport.resume_reading,
        )

    def connection_lost(self, exc: Exception | None) -> None:
        """websockets' hook: no longer count this connection against the client limits."""
        super().connection_lost(exc)
        self.security.release(self)


WEBSOCKETS_TESTED = ">=17,<18"
"""The websockets versions whose internals :class:`_BudgetAssembler` is tested with."""


def check_websockets_internals() -> None:
    """Fail at start-up, clearly, if websockets' private internals differ from what the byte
    budget builds on (its ``Assembler``, ``SimpleQueue`` and the connection's queue limits).

    Call with an event loop running. Raises :class:`BridgeError` naming the version.
    """
    from importlib.metadata import version

    from websockets.asyncio.connection import Connection
    from websockets.frames import Opcode
    from websockets.server import ServerProtocol

    try:
        totals = _Inbound()
        asm = _BudgetAssembler(1, 1, totals, high=4, low=1)
        asm.put(Frame(Opcode.TEXT, b"xy"))
        held = (totals.bytes, asm.paused, asm.frames is asm.queue)
        asm.close()
        conn = Connection(ServerProtocol())
        limits = (conn.max_queue_high, conn.max_queue_low)
        problem = None if held == (2, True, True) and totals.bytes == 0 else f"counted {held}"
        if not hasattr(Connection, "connection_made") or len(limits) != 2:
            problem = "no connection_made or queue limits"
    except Exception as exc:
        problem = f"{type(exc).__name__}: {exc}"
    if problem is not None:
        raise BridgeError(
            f"websockets {version('websockets')} is not supported by the bridge: its inbound "
            f"byte budget (bridge_server/security.py) builds on websockets' private Assembler "
            f"internals, tested with websockets{WEBSOCKETS_TESTED} ({problem}); install "
            f"'websockets{WEBSOCKETS_TESTED}'"
        )


class Security:
    """The bridge's security configuration, and the state it keeps across connections."""

    def __init__(self, config: SecurityConfig) -> None:
        self.config = config
        self.auth: AuthConfig | None = (
            load_auth_file(config.auth_file) if config.auth_file else None
        )
        self.failures = FailureTracker()
        self._ssl: ssl.SSLContext | None = None  # the live server context (reloaded in place)
        self.inbound = _Inbound()
        self.clients = 0
        self.per_address: dict[str, int] = {}
        self.connection_class: type[BridgeConnection] = type(
            "BridgeConnection", (BridgeConnection,), {"security": self}
        )

    # -- start-up ------------------------------------------------------------------------------

    def ssl_context(self) -> ssl.SSLContext | None:
        """The server TLS context (``None`` without ``--certfile``)."""
        if not self.config.certfile:
            return None
        self._ssl = self._load_ssl(ssl.create_default_context(ssl.Purpose.CLIENT_AUTH))
        return self._ssl

    def _load_ssl(self, ctx: ssl.SSLContext) -> ssl.SSLContext:
        c = self.config
        assert c.certfile
        ctx.minimum_version = max(ctx.minimum_version, ssl.TLSVersion.TLSv1_2)
        ctx.load_cert_chain(c.certfile, c.keyfile or None)
        if c.client_ca:
            ctx.verify_mode = ssl.CERT_REQUIRED
            ctx.load_verify_locations(c.client_ca)
        return ctx

    # -- reloading (SIGHUP) ----------------------------------------------------------------------

    def reload(self, gates: Iterable[Gate]) -> bool:
        """Read the certificate files and the auth file again; True if all of them loaded.

        New handshakes use the new certificate (open connections keep theirs; a new
        client CA is added to the trusted ones). Each session keeps its principal if
        the new file still has it with the same token, and gets its role as the file
        now defines it; a session whose principal was removed or got a new token is
        closed (1008, "credentials revoked"). A file that does not load changes
        nothing: the error is logged and the running configuration stays.
        """
        ok = True
        c = self.config
        if self._ssl is not None:
            try:
                self._load_ssl(ssl.create_default_context(ssl.Purpose.CLIENT_AUTH))  # a dry run
                self._load_ssl(self._ssl)
                log.info("reloaded the TLS certificate %s", c.certfile)
            except (OSError, ssl.SSLError) as exc:
                ok = False
                log.error("reloading the TLS certificate failed, the old one stays: %s", exc)
        if c.auth_file:
            try:
                auth = load_auth_file(c.auth_file)
            except AuthFileError as exc:
                log.error("reloading the auth file failed, the old one stays: %s", exc)
                return False
            self.auth = auth
            now = {(p.name, p.salt, p.digest): p for p in auth.principals}
            revoked = 0
            for gate in gates:
                old = gate.principal
                if old is None:
                    continue
                new = now.get((old.name, old.salt, old.digest))
                if new is None:
                    revoked += 1
                    gate.close(f"credentials revoked: principal {old.name} is no longer "
                               "in the auth file with that token")
                else:
                    gate.principal, gate.role = new, new.role
            log.info("reloaded the auth file %s: %d principal(s), %d role(s); %d session(s) "
                     "closed as revoked", c.auth_file, len(auth.principals), len(auth.roles),
                     revoked)
        return ok

    def serve_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for websockets' ``serve`` (checks websockets' internals first)."""
        check_websockets_internals()
        return {
            "ssl": self.ssl_context(),
            "open_timeout": self.config.handshake_timeout or None,
            "create_connection": self.connection_class,
        }

    def startup_warnings(self, host: str) -> None:
        """Log what is dangerous about this configuration."""
        tls = bool(self.config.certfile)
        if is_loopback(host):
            return
        if self.auth is None and not tls:
            log.warning(
                "!!! SECURITY: listening on %s with neither authentication (--auth-file) nor "
                "TLS (--certfile): anyone who reaches this port can drive the robot, read its "
                "sensors and change its parameters. See SECURITY.md. !!!",
                host,
            )
        elif self.auth is None:
            log.warning("SECURITY: no --auth-file: every client that reaches %s may do anything",
                        host)
        elif not tls:
            log.warning("SECURITY: tokens travel in clear text on %s: add --certfile/--keyfile "
                        "or put a TLS proxy in front (SECURITY.md)", host)

    # -- the handshake ---------------------------------------------------------------------------

    async def process_request(
        self, connection: ServerConnection, request: Request
    ) -> Response | None:
        """Origins, client limits, lock-out and token: an HTTP refusal, or ``None`` to go on."""
        c = self.config
        address = _address(connection)
        origin = request.headers.get("Origin")
        if c.allowed_origins is not None and origin is not None and origin not in c.allowed_origins:
            log.warning("refused a client from %s: origin %.100r is not allowed", address, origin)
            return connection.respond(403, f"origin {origin[:100]!r} is not allowed here\n")
        if c.max_clients and self.clients >= c.max_clients:
            log.warning("refused a client from %s: %d clients already", address, self.clients)
            return connection.respond(
                503, f"too many clients: this bridge serves at most {c.max_clients}\n"
            )
        here = self.per_address.get(address, 0)
        if c.max_clients_per_address and here >= c.max_clients_per_address:
            log.warning("refused a client from %s: %d clients from there already", address, here)
            return connection.respond(
                429,
                f"too many clients from {address}: at most {c.max_clients_per_address}\n",
            )
        if self.auth is not None:
            refusal = self._authenticate(connection, request, address)
            if refusal is not None:
                return refusal
        self.clients += 1
        self.per_address[address] = here + 1
        if isinstance(connection, BridgeConnection):
            connection.counted = address
        return None

    def _authenticate(
        self, connection: ServerConnection, request: Request, address: str
    ) -> Response | None:
        assert self.auth is not None
        locked = self.locked_out(address)
        if locked is not None:
            log.warning("refused a client from %s: locked out after failed attempts", address)
            response = connection.respond(429, f"{locked[0]}\n")
            response.headers["Retry-After"] = locked[1]
            return response
        token, where = _token_of(request)
        if token is None:
            return None  # the first op must be auth (browsers, roslib's authenticate())
        principal = self.auth.verify(token)
        if principal is None:
            count = self.failures.failed(address)
            log.warning("refused a client from %s: wrong token in the %s (failure %d)",
                        address, where, count)
            response = connection.respond(
                401, f"authentication failed: the token in the {where} is not valid\n"
            )
            response.headers["WWW-Authenticate"] = 'Bearer realm="rosbridge"'
            return response
        self.failures.succeeded(address)
        if isinstance(connection, BridgeConnection):
            connection.principal = principal
        return None

    def locked_out(self, address: str) -> tuple[str, str] | None:
        """Why ``address`` may not try a token now, and its ``Retry-After`` (``None``: it may)."""
        wait = self.failures.locked_for(address)
        if wait <= 0:
            return None
        return (f"too many failed authentication attempts from {address}; retry in {wait:.0f} s",
                str(max(1, round(wait))))

    def release(self, connection: BridgeConnection) -> None:
        """A counted connection ended."""
        address, connection.counted = connection.counted, None
        if address is None:
            return
        self.clients -= 1
        left = self.per_address.get(address, 1) - 1
        if left > 0:
            self.per_address[address] = left
        else:
            self.per_address.pop(address, None)

    def web_access(self) -> WebAccess:
        """The access rules of the plain-HTTP routes (web.py) under this configuration."""
        return WebAccess(self)

    def gate(self, session: Session) -> Gate:
        """The gate for a new session."""
        principal = getattr(session.ws, "principal", None)
        return Gate(self, session, principal)


def _token_of(request: Request) -> tuple[str | None, str]:
    header = request.headers.get("Authorization")
    if header is not None:
        scheme, _, value = header.strip().partition(" ")
        if scheme.lower() == "bearer" and value.strip():
            return value.strip(), "Authorization header"
        return "", "Authorization header"  # present but not a bearer token: a failure
    query = parse_qs(urlsplit(request.path).query)
    values = query.get("token")
    if values:
        return values[0], "?token= query parameter"
    return None, ""


class Gate:
    """What one session may do: consulted for every frame and every op."""

    def __init__(self, security: Security, session: Session, principal: Principal | None):
        self.security = security
        self.session = session
        self.principal = principal
        self.role: Role | None = principal.role if principal is not None else None
        self.authenticated = security.auth is None or principal is not None
        self.closing = False
        self.unresponsive = False  # set when this client failed to answer a ping in time
        c = security.config
        self.rate = c.max_op_rate
        self.burst = float(c.op_burst or max(1, int(c.max_op_rate)))
        self.tokens = self.burst
        self.stamp = time.monotonic()
        self.warned = False
        self._timer: asyncio.TimerHandle | None = None
        if principal is not None:
            log.info("client %d authenticated as %s (role %s)", session.sid, principal.name,
                     principal.role.name)
        elif not self.authenticated:
            self._timer = session.loop.call_later(
                c.handshake_timeout or 10.0,
                self.close,
                "authentication required: send a token (Authorization: Bearer, ?token= or "
                "an auth op) within the handshake timeout",
            )

    # -- frames --------------------------------------------------------------------------------

    def admit_frame(self, size: int = 0) -> bool:
        """Whether to handle the next frame (the op rate, and nothing after a close).

        Before authentication only small frames are read (an ``auth`` op is
        small), so an unauthenticated client cannot make the bridge hold large
        fragments while it has not proved who it is.
        """
        if self.closing:
            return False
        if not self.authenticated and size > PRE_AUTH_FRAME_LIMIT:
            self.close(f"authentication required before a frame of {size} bytes")
            return False
        if not self.rate:
            return True
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.stamp) * self.rate)
        self.stamp = now
        self.tokens -= 1
        if self.tokens >= 0:
            if self.warned and self.tokens > self.burst / 2:
                self.warned = False
            return True
        if self.tokens < -self.burst:
            self.close(f"too many ops: more than {self.rate:g} per second")
            return False
        if not self.warned:
            self.warned = True
            log.info("session %d: over the op rate", self.session.sid)
            self.session.status(
                "warning",
                f"op rate limit: at most {self.rate:g} ops per second (burst {self.burst:g}); "
                "ops over it are dropped, and the connection closes if this goes on",
            )
        return False

    def close(self, reason: str) -> None:
        """Close the connection with code 1008 and ``reason``; handle nothing more."""
        if self.closing or self.session._closed:
            return
        self.closing = True
        if self._timer is not None:
            self._timer.cancel()
        log.warning("session %d: closing: %s", self.session.sid, reason)
        task = self.session.loop.create_task(self.session.ws.close(POLICY_VIOLATION, reason[:120]))
        _CLOSING.add(task)  # a strong reference until it is done (the loop keeps only weak ones)
        task.add_done_callback(_CLOSING.discard)

    def end(self) -> None:
        """The session ended: stop the authentication timer (it would hold the session)."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    # -- ops -------------------------------------------------------------------------------------

    def check(self, op: Any) -> bool:
        """Whether the session may carry out ``op``; if not, the client has been told."""
        if isinstance(op, ops.Auth):
            self._auth(op)
            return False
        if not self.authenticated:
            self.close(f"authentication required before {op.OP!r}: send the auth op first")
            return False
        need = requirement(op)
        if need is None:
            return True
        capability, name = need
        try:
            check_name(name, _WHAT[capability])
        except InvalidNameError as exc:
            self.deny(op, str(exc))
            return False
        if self.role is not None and not self._allowed(op, capability, name):
            return False
        return self._within_caps(op, name)

    def _allowed(self, op: Any, capability: str, name: str) -> bool:
        role = self.role
        assert role is not None
        if isinstance(op, ops.CallService) and (name in rosapi.HANDLERS
                                                or name in rosapi.ASYNC_HANDLERS):
            capability, name = rosapi_requirement(name, _rosapi_args(name, op.args))
        ok = role.has(capability) if name == "*" else role.allows(capability, name)
        if not ok:
            what = "any name" if name == "*" else name
            self.deny(op, f"forbidden: role {role.name} may not {capability} on {what}")
        return ok

    def _within_caps(self, op: Any, name: str) -> bool:
        c = self.security.config
        s = self.session
        have: Mapping[str, Any]
        if isinstance(op, ops.Subscribe):
            have, cap, what = s.subs, c.max_subscriptions, "subscriptions"
        elif isinstance(op, ops.Advertise | ops.Publish):
            have, cap, what = s.publishers, c.max_publishers, "publishers"
        elif isinstance(op, ops.AdvertiseService):
            have, cap, what = s.served, c.max_services, "served services"
        elif isinstance(op, ops.AdvertiseAction):  # each is an rclpy action server
            have, cap, what = s.actions.served, c.max_services, "served actions"
        elif isinstance(op, ops.SendActionGoal):  # keyed by goal id, so every new goal counts
            have, cap, what = s.actions.goals, c.max_goals, "goals in flight"
        else:
            return True
        if cap and name not in have and len(have) >= cap:
            self.deny(op, f"too many {what} on this connection (at most {cap})")
            return False
        return True

    def deny(self, op: Any, why: str) -> None:
        """Refuse ``op``: a status error, plus the failure shape a stock client waits for."""
        op_id = getattr(op, "id", None)
        self.session.error(f"{op.OP}: {why}", op_id)
        if isinstance(op, ops.CallService):
            self.session.send_op(ops.ServiceResponse(
                service=op.service, result=False, values=f"{op.OP}: {why}", id=op_id))
        elif isinstance(op, ops.SendActionGoal) and op_id is not None:
            self.session.send_op(ops.ActionResult(
                id=op_id, action=op.action, values=f"{op.OP}: {why}", result=False, status=6))

    def _auth(self, op: ops.Auth) -> None:
        auth = self.security.auth
        if auth is None:
            return  # no auth file: everyone is welcome, the op changes nothing
        address = _address(self.session.ws)
        locked = self.security.locked_out(address)
        if locked is not None:  # connections opened before the lock-out get no guess either
            log.warning("session %d: auth op from %s refused: locked out after failed attempts",
                        self.session.sid, address)
            self.close(locked[0])
            return
        principal = auth.verify(op.mac)
        if principal is None or (self.principal is not None and principal is not self.principal):
            count = self.security.failures.failed(address)
            log.warning("session %d: auth op from %s with a wrong token (failure %d)",
                        self.session.sid, address, count)
            self.close("authentication failed: the auth op's token (mac) is not valid")
            return
        self.security.failures.succeeded(address)
        if self.principal is None:
            self.principal, self.role, self.authenticated = principal, principal.role, True
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            log.info("client %d authenticated as %s (role %s) by an auth op", self.session.sid,
                     principal.name, principal.role.name)

    # -- what the session asks -------------------------------------------------------------------

    def may_take_over(self, name: str, owner_gate: Gate | None) -> bool:
        """Whether this client may take ``name`` from the client that serves it now.

        The same principal may (it reconnected before the bridge saw the old
        connection go), and anyone may once the owner's connection failed to
        answer a ping; otherwise only a role with ``take_over`` on the name.
        """
        if owner_gate is not None and (owner_gate.unresponsive or (
                self.principal is not None and owner_gate.principal is self.principal)):
            return True
        return self.role is not None and self.role.allows("take_over", name)

    def claim_if_owner_gone(self, op: ops.AdvertiseService, owner: Session) -> None:
        """Advertise a service another client serves only if that client is gone.

        The first owner keeps a name; but a connection whose client vanished
        (a network drop the bridge has not noticed yet) should not hold it until
        the keepalive gives up, or the client could never serve it again after
        it reconnects. So the owner is pinged: no pong within
        :data:`OWNER_PING_TIMEOUT` seconds and the name is freed for this client.
        """
        session = self.session
        task = session.loop.create_task(self._claim(op, owner))
        session.calls.add(task)  # cancelled with the session's calls
        task.add_done_callback(session.calls.discard)

    async def _claim(self, op: ops.AdvertiseService, owner: Session) -> None:
        name = op.service if op.service.startswith("/") else "/" + op.service
        try:
            pong = await owner.ws.ping()
            await asyncio.wait_for(pong, OWNER_PING_TIMEOUT)
            alive = True
        except (TimeoutError, ConnectionClosed):
            alive = False
        session = self.session
        if session._closed or session.bridge.service_owners.get(name) is not owner:
            if not session._closed:
                session.handle_op(op)  # the name changed hands meanwhile: decide again
            return
        if alive:
            session.error(
                f"advertise_service: {name} is already served by client {owner.sid}; the "
                "first owner keeps it (a role with take_over may take it over)",
                op.id,
            )
            return
        log.warning("client %d serves %s but did not answer a ping in %s s: client %d takes "
                    "the service", owner.sid, name, OWNER_PING_TIMEOUT, session.sid)
        owner.gate.unresponsive = True  # its names may be taken now (see may_take_over)
        session.handle_op(op)

    def filter_rosapi(self, service: str, values: dict[str, Any]) -> dict[str, Any]:
        """A rosapi answer reduced to what the role may see."""
        if self.role is None:
            return values
        return filter_rosapi(self.role, service, values)


_CLOSING: set[asyncio.Task[None]] = set()
"""Close handshakes under way that :meth:`Gate.close` started."""

_WHAT = {
    "subscribe": "topic",
    "publish": "topic",
    "call_service": "service",
    "serve_service": "service",
    "send_action_goal": "action",
    "serve_action": "action",
}


def _rosapi_args(service: str, args: Mapping[str, Any] | list[Any] | None) -> Mapping[str, Any]:
    if isinstance(args, Mapping):
        return args
    if isinstance(args, list):
        return dict(zip(rosapi.FIELDS.get(service, ()), args, strict=False))
    return {}


def parse_origins(text: str | None) -> list[str] | None:
    """``--allowed-origins`` ("https://a.example,https://b.example") as a list."""
    if text is None:
        return None
    return [o.strip() for o in text.split(",") if o.strip()]



# -- the command line ----------------------------------------------------------------------------


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The security options of ``roslibpy-lite-bridge`` (see SECURITY.md)."""
    g = p.add_argument_group("security (see SECURITY.md)")
    d = SecurityConfig()
    g.add_argument("--certfile", help="PEM certificate chain: serve wss:// (TLS)")
    g.add_argument("--keyfile", help="PEM private key of --certfile (if not in it)")
    g.add_argument("--client-ca", help="PEM CA bundle: require client certificates (mutual TLS)")
    g.add_argument("--auth-file", help="TOML file of roles and principals: require a token "
                   "(make one with: roslibpy-lite-bridge add-principal NAME --role ROLE "
                   "--auth-file FILE)")
    g.add_argument("--allowed-origins", help="comma-separated browser origins allowed to "
                   "connect, e.g. https://ui.example.com (clients without Origin always may)")
    g.add_argument("--max-clients", type=int, default=d.max_clients,
                   help=f"most connected clients in all (default {d.max_clients}; 0: no limit)")
    g.add_argument("--max-clients-per-address", type=int, default=d.max_clients_per_address,
                   help="most clients from one IP address (default 0: no limit; behind a "
                   "proxy every client has the proxy's address)")
    g.add_argument("--handshake-timeout", type=float, default=d.handshake_timeout,
                   help="seconds to finish TLS, the websocket handshake and (with an auth file) "
                   f"authentication (default {d.handshake_timeout:g})")
    g.add_argument("--max-op-rate", type=float, default=d.max_op_rate,
                   help="ops per second per client; over it: a warning, ops dropped, then a "
                   "close with 1008 (default 0: no limit)")
    g.add_argument("--op-burst", type=int, default=d.op_burst,
                   help="ops a client may send at once above the rate (default: one second's)")
    g.add_argument("--max-subscriptions", type=int, default=d.max_subscriptions,
                   help=f"topics one client may subscribe to (default {d.max_subscriptions})")
    g.add_argument("--max-publishers", type=int, default=d.max_publishers,
                   help=f"topics one client may publish on (default {d.max_publishers})")
    g.add_argument("--max-services", type=int, default=d.max_services,
                   help=f"services one client may serve, and actions likewise "
                   f"(default {d.max_services})")
    g.add_argument("--max-goals", type=int, default=d.max_goals,
                   help=f"action goals one client may have in flight (default {d.max_goals})")
    g.add_argument("--inbound-budget", type=int, default=d.inbound_budget,
                   help="bytes of received, not yet handled data per client before the bridge "
                   f"stops reading it (default {d.inbound_budget >> 20} MiB)")
    g.add_argument("--inbound-budget-total", type=int, default=d.inbound_budget_total,
                   help="the same for all clients together "
                   f"(default {d.inbound_budget_total >> 20} MiB)")


def config_from_args(args: argparse.Namespace) -> SecurityConfig:
    """The :class:`SecurityConfig` of parsed command-line arguments."""
    return SecurityConfig(
        certfile=args.certfile,
        keyfile=args.keyfile,
        client_ca=args.client_ca,
        auth_file=args.auth_file,
        allowed_origins=parse_origins(args.allowed_origins),
        max_clients=args.max_clients,
        max_clients_per_address=args.max_clients_per_address,
        handshake_timeout=args.handshake_timeout,
        max_op_rate=args.max_op_rate,
        op_burst=args.op_burst,
        max_subscriptions=args.max_subscriptions,
        max_publishers=args.max_publishers,
        max_services=args.max_services,
        max_goals=args.max_goals,
        inbound_budget=args.inbound_budget,
        inbound_budget_total=args.inbound_budget_total,
    )


def install_log_redaction() -> None:
    """Scrub tokens from every line the root logger's handlers write."""
    for handler in logging.getLogger().handlers:
        handler.addFilter(RedactTokens())


class WebAccess(Access):
    """Who may see the plain-HTTP routes (status page, ``/status.json``, ``/metrics``).

    With an auth file, these need a token too (``Authorization: Bearer`` or
    ``?token=``), and a role sees the routes only with ``introspection`` and,
    in the status data, only the names its ``introspection`` patterns match.
    The page's own static files and ``/healthz``/``/readyz`` stay open.
    """

    def __init__(self, security: Security) -> None:
        self.security = security

    def principal(self, request: Request, address: str) -> Any:
        """The principal of the request's token; 401 without a valid one.

        A wrong token counts as a failed attempt of ``address`` exactly as at the
        websocket handshake, and a locked-out address gets 429 here too, so these
        routes are no way around the lock-out.
        """
        sec = self.security
        auth = sec.auth
        if auth is None or request.path.startswith("/static/"):
            return None
        locked = sec.locked_out(address)
        if locked is not None:
            log.warning("refused a plain-HTTP request from %s: locked out after failed attempts",
                        address)
            raise Denied(429, locked[0], [("Retry-After", locked[1])])
        token, where = _token_of(request)
        if token is None:
            raise Denied(401, "authentication required: send a token (Authorization: Bearer "
                         "or ?token=)")
        principal = auth.verify(token)
        if principal is None:
            count = sec.failures.failed(address)
            log.warning("refused a plain-HTTP request from %s: wrong token in the %s "
                        "(failure %d)", address, where, count)
            raise Denied(401, f"authentication failed: the token in the {where} is not valid")
        sec.failures.succeeded(address)
        return principal

    def may_see(self, principal: Any, kind: str, name: str) -> bool:
        """Routes need introspection; names need introspection on them."""
        if self.security.auth is None:
            return True
        if not isinstance(principal, Principal):
            return kind == "route" and name.startswith("/static/")
        role = principal.role
        if kind in ("route", "client"):
            return role.has("introspection")
        return role.allows("introspection", name)
