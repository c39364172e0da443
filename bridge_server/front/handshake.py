"""Between a socket and a session: TLS, origins, client limits, the lock-out and the token.

One :class:`Security` per bridge holds the configuration and the state kept across
connections; :meth:`Security.process_request` runs at each websocket handshake and
:meth:`Security.reload` on SIGHUP.
"""

from __future__ import annotations

import logging
import ssl
from collections.abc import Iterable
from typing import Any

from websockets.asyncio.server import ServerConnection
from websockets.http11 import Request, Response

from bridge_server.front.websocket import BridgeConnection, Inbound, check_websockets_internals
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.security.authority import Authority
from rosbridge_core.security.credentials import client_address, is_loopback, token_of
from rosbridge_core.security.gate import PRE_AUTH_FRAME_LIMIT, Gate
from rosbridge_core.security.options import SecurityConfig

__all__ = ["Security"]

log = logging.getLogger("bridge_server.security")


class Security(Authority):
    """The bridge's security configuration, and the state it keeps across connections: what
    its sessions share (:class:`~rosbridge_core.security.authority.Authority`), and TLS, the
    handshake's checks and the connection counts."""

    def __init__(self, config: SecurityConfig) -> None:
        super().__init__(config)
        self._ssl: ssl.SSLContext | None = None  # the live server context (reloaded in place)
        self.inbound = Inbound()
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
        try:
            self._ssl = self._load_ssl(ssl.create_default_context(ssl.Purpose.CLIENT_AUTH))
        except ssl.SSLError as exc:  # its text names no file
            c = self.config
            files = " and ".join(f"{opt} {path}" for opt, path in (
                ("--certfile", c.certfile), ("--keyfile", c.keyfile), ("--client-ca", c.client_ca),
            ) if path)
            raise BridgeError(f"{files}: not a usable PEM certificate, key or CA "
                              f"({exc.reason or exc})") from None
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
        return self.reload_auth(gates) and ok

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
        address = client_address(connection)
        origins = request.headers.get_all("Origin")
        if len(origins) > 1:
            log.warning("refused a client from %s: %d Origin headers", address, len(origins))
            return connection.respond(400, "more than one Origin header\n")
        origin = origins[0] if origins else None
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
            holder = self.accounts.holder(address)
            if connection.principal is not None:
                holder.become(connection.principal.name)
            connection.hold(holder)
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
        token, where = token_of(request)
        if token is None:  # the first op must be auth (browsers, roslib's authenticate())
            if isinstance(connection, BridgeConnection):
                connection.limit_frames(PRE_AUTH_FRAME_LIMIT)
            return None
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

    def release(self, connection: BridgeConnection) -> None:
        """A counted connection ended."""
        address, connection.counted = connection.counted, None
        if address is None:
            return
        if connection.holder is not None:
            connection.holder.close()
        self.clients -= 1
        left = self.per_address.get(address, 1) - 1
        if left > 0:
            self.per_address[address] = left
        else:
            self.per_address.pop(address, None)

