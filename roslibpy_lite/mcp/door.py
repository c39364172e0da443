"""The MCP server's HTTP door: who may reach the agent's tools over streamable HTTP.

The tools act with the robot token's role, so whoever reaches the HTTP endpoint acts as the
agent. :class:`HttpDoor` holds what guards it, and :func:`http_app` builds the ASGI app:

- a bearer token of its own (``--http-token-file``), checked by the SDK's bearer middleware
  (a :class:`~mcp.server.auth.provider.TokenVerifier`): a request without it gets 401. On a
  loopback address too, unless ``--no-http-auth`` says otherwise (with a warning);
- on an address other machines reach, TLS as well (``--http-certfile``/``--http-keyfile``):
  without both it does not start (:meth:`HttpDoor.refusal`) unless ``--insecure`` says that
  is meant (a warning at every start, naming what is missing);
- the ``Host`` and ``Origin`` headers checked on every request on every address (the SDK's
  DNS-rebinding protection, :class:`~mcp.server.transport_security.TransportSecuritySettings`):
  loopback names, the address it listens on and ``--allowed-hosts``/``--allowed-origins``;
- each request logged with its peer's address and its status (never a header or a query).
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import logging
import re
import time
from collections.abc import Awaitable, Callable, MutableMapping
from dataclasses import dataclass, field
from typing import Any

from mcp.server.auth.provider import AccessToken
from mcp.server.auth.settings import AuthSettings
from mcp.server.transport_security import TransportSecurityMiddleware, TransportSecuritySettings
from starlette.requests import Request

__all__ = ["MCP_PATH", "MIN_TOKEN", "HttpDoor", "http_app", "is_loopback"]

log = logging.getLogger("roslibpy_lite.mcp.http")

MCP_PATH = "/mcp"
"""Where the streamable HTTP endpoint is served."""

MIN_TOKEN = 24
"""The fewest characters an HTTP bearer token may have."""

_LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
_WILDCARDS = ("0.0.0.0", "::", "")
_PORTED = re.compile(r".*[^:]:(\d+|\*)")  # name:port (a bare IPv6 address has no port)

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
App = Callable[[Scope, Receive, Send], Awaitable[None]]


def is_loopback(host: str) -> bool:
    """Whether listening on ``host`` keeps the port on this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _host_part(host: str) -> str:
    """``host`` as it appears in a Host header (an IPv6 address in brackets)."""
    return f"[{host}]" if ":" in host and not host.startswith("[") else host


@dataclass
class HttpDoor:
    """What guards the streamable HTTP endpoint (see the module docstring)."""

    host: str = "127.0.0.1"
    """The address to listen on."""
    port: int = 8765
    """The TCP port to listen on."""
    token: str | None = field(default=None, repr=False)
    """The bearer token clients must send (``Authorization: Bearer ...``); ``None``: none."""
    certfile: str | None = None
    """PEM certificate (chain): serve HTTPS."""
    keyfile: str | None = None
    """PEM private key of :attr:`certfile` (if not in it)."""
    allowed_hosts: tuple[str, ...] = ()
    """More ``Host`` header values to accept (``name`` or ``name:port``)."""
    allowed_origins: tuple[str, ...] = ()
    """More ``Origin`` header values to accept (``https://ui.example.com``)."""
    insecure: bool = False
    """Serve a non-loopback address without TLS or a token (a warning at every start)."""
    no_auth: bool = False
    """Serve without a token (on loopback only, unless :attr:`insecure`)."""

    @property
    def scheme(self) -> str:
        """``https`` with a certificate, else ``http``."""
        return "https" if self.certfile else "http"

    @property
    def url(self) -> str:
        """The endpoint's URL as this machine reaches it."""
        host = "127.0.0.1" if self.host in _WILDCARDS else _host_part(self.host)
        return f"{self.scheme}://{host}:{self.port}{MCP_PATH}"

    def _missing(self) -> list[str]:
        missing = []
        if not self.certfile:
            missing.append("TLS (--http-certfile FILE, --http-keyfile FILE)")
        if self.token is None:
            missing.append("a token (--http-token-file FILE)")
        return missing

    def refusal(self) -> str | None:
        """Why the server must not start so (``None``: it may)."""
        if self.token is not None and self.no_auth:
            return "--no-http-auth and --http-token-file contradict each other: give one"
        if self.keyfile and not self.certfile:
            return "--http-keyfile needs --http-certfile"
        if self.token is not None and len(self.token) < MIN_TOKEN:
            return (f"--http-token-file: the token has {len(self.token)} characters; use at "
                    f"least {MIN_TOKEN} (e.g. python -c 'import secrets; "
                    "print(secrets.token_urlsafe(32))' > mcp-http.token)")
        if is_loopback(self.host):
            if self.token is None and not self.no_auth:
                return ("--http serves the agent's tools to every local user and program: give "
                        "--http-token-file FILE (clients send 'Authorization: Bearer <token>'), "
                        "or --no-http-auth to serve without one")
            return None
        missing = self._missing()
        if missing and not self.insecure:
            return (f"--host {self.host or '(every address)'} is reachable from other machines "
                    f"and the MCP server would serve the agent's tools there without "
                    f"{' or '.join(missing)}: give them, or --insecure to serve so anyway, or "
                    "--host 127.0.0.1")
        return None

    def warnings(self) -> list[str]:
        """What to warn about at start (the server may start: :meth:`refusal` is ``None``)."""
        out = []
        where = f"{self.host or '(every address)'}:{self.port}"
        if is_loopback(self.host):
            if self.no_auth:
                out.append(f"--no-http-auth: MCP on {where} serves the agent's tools without a "
                           "token: every local user and program may act on the robot with "
                           "this server's role")
            return out
        missing = self._missing()
        if missing:
            out.append(f"--insecure: MCP on {where} serves the agent's tools to anyone who "
                       f"reaches the port, without {' and without '.join(missing)}")
        if self.host in _WILDCARDS and not self.allowed_hosts:
            out.append(f"MCP listens on every address but accepts only the Host headers "
                       f"{', '.join(self.security().allowed_hosts)}: give --allowed-hosts with "
                       "the names clients use to reach it")
        return out

    def security(self) -> TransportSecuritySettings:
        """The SDK's Host and Origin checks for this door (always on)."""
        hosts = [f"{h}:*" for h in _LOOPBACK_NAMES]
        if self.host not in _WILDCARDS and not is_loopback(self.host):
            hosts.append(f"{_host_part(self.host)}:*")
        for name in self.allowed_hosts:
            hosts += [name] if _PORTED.fullmatch(name) else [name, f"{name}:*"]
        origins = [f"{scheme}://{h}" for h in hosts if h.endswith(":*")
                   for scheme in ("http", "https")]
        return TransportSecuritySettings(enable_dns_rebinding_protection=True,
                                         allowed_hosts=hosts,
                                         allowed_origins=origins + list(self.allowed_origins))

    def auth(self) -> tuple[AuthSettings, _OneToken] | None:
        """The SDK's bearer-auth settings and verifier (``None``: no token asked)."""
        if self.token is None:
            return None
        settings = AuthSettings(issuer_url=self.url.removesuffix(MCP_PATH),  # type: ignore[arg-type]
                                resource_server_url=None)
        return settings, _OneToken(self.token)


class _OneToken:
    """A :class:`~mcp.server.auth.provider.TokenVerifier` of one bearer token (kept only as
    its SHA-256; compared in constant time)."""

    def __init__(self, token: str) -> None:
        self._digest = hashlib.sha256(token.encode()).digest()

    async def verify_token(self, token: str) -> AccessToken | None:
        given = hashlib.sha256(token.encode("utf-8", "surrogatepass")).digest()
        if not hmac.compare_digest(given, self._digest):
            return None
        return AccessToken(token="(the --http-token-file token)", client_id="mcp-http",
                           scopes=[])


class _Watch:
    """ASGI middleware in front of everything: checks Host and Origin (the SDK's check, on
    every path and before authentication) and logs each request with its peer."""

    def __init__(self, app: App, security: TransportSecuritySettings) -> None:
        self.app = app
        self.check = TransportSecurityMiddleware(security)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        client = scope.get("client")
        peer = f"{client[0]}:{client[1]}" if client else "(unknown peer)"
        path = scope.get("path", "")
        shown = path if path == MCP_PATH else "(another path)"  # a path may carry anything
        start = time.monotonic()
        logged = False

        def note(status: int) -> None:
            nonlocal logged
            if not logged:
                logged = True
                level = logging.INFO if status < 400 else logging.WARNING
                log.log(level, "%s %s from %s: %d (%.0f ms)", scope.get("method", "?"), shown,
                        peer, status, (time.monotonic() - start) * 1000)

        async def watched(message: Message) -> None:
            if message["type"] == "http.response.start":
                note(int(message["status"]))
            await send(message)

        refused = await self.check.validate_request(Request(scope, receive))
        if refused is not None:
            await refused(scope, receive, watched)
            return
        try:
            await self.app(scope, receive, watched)
        finally:
            note(500)


def http_app(server: Any, door: HttpDoor) -> App:
    """The ASGI app serving ``server`` (an SDK ``Server``) behind ``door``."""
    security = door.security()
    auth = door.auth()
    app = server.streamable_http_app(
        streamable_http_path=MCP_PATH, host=door.host, transport_security=security,
        auth=auth[0] if auth else None, token_verifier=auth[1] if auth else None)
    return _Watch(app, security)
