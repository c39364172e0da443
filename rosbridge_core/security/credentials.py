"""Where a client's address and token come from in a handshake request."""

from __future__ import annotations

import ipaddress
from typing import Any, Protocol
from urllib.parse import parse_qs, urlsplit

from websockets.http11 import Request

__all__ = ["UNKNOWN_ADDRESS", "client_address", "is_loopback", "token_of"]


class Addressed(Protocol):
    """A connection (or a session's link), as far as its address goes."""

    @property
    def remote_address(self) -> Any:
        """The peer's address as the socket gives it."""


UNKNOWN_ADDRESS = "unknown"
"""The address of a connection whose socket closed before anyone asked (uvloop raises
for its peer then, where asyncio answers from its cache): counted, limited and logged
under this one name."""


def client_address(connection: Addressed) -> str:
    """The IP address a connection comes from (the key of per-address limits);
    :data:`UNKNOWN_ADDRESS` once its socket has closed (a client gone before its handshake
    was read: nothing to log a traceback about)."""
    try:
        addr = connection.remote_address
    except (OSError, AttributeError):  # uvloop: the socket is gone (None.getpeername)
        return UNKNOWN_ADDRESS
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


def token_of(request: Request) -> tuple[str | None, str]:
    """The token a handshake request carries and where (``None``: none at all; ``""``: a
    malformed ``Authorization`` header, which counts as a wrong token)."""
    headers = request.headers.get_all("Authorization")
    if len(headers) > 1:
        return "", "Authorization header (sent more than once)"
    header = headers[0] if headers else None
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
