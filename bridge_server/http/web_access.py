"""Who may see the bridge's plain-HTTP routes under its security configuration.

:mod:`bridge_server.http.web` serves the routes through an :class:`~bridge_server.http.web.Access`;
this is the one that knows tokens and roles.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from bridge_server.http.web import Access, Denied
from rosbridge_core.security.auth import Principal
from rosbridge_core.security.credentials import token_of

if TYPE_CHECKING:
    from websockets.http11 import Request

    from rosbridge_core.security.authority import Authority

__all__ = ["WebAccess"]

log = logging.getLogger("bridge_server.security")


class WebAccess(Access):
    """Who may see the plain-HTTP routes (status page, ``/status.json``, ``/metrics``).

    With an auth file, these need a token too (``Authorization: Bearer`` or
    ``?token=``), and a role sees the routes only with ``introspection`` and,
    in the status data, only the names its ``introspection`` patterns match.
    The page's own static files and ``/healthz``/``/readyz`` stay open.
    """

    def __init__(self, security: Authority, robot: str | None = None) -> None:
        """``robot``: the routes are one robot's on a relay (a role limited to other robots
        may not see them)."""
        self.security = security
        self.robot = robot

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
        token, where = token_of(request)
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

    def may_reach(self, principal: Any, robot: str) -> bool:
        """Whether ``principal`` may see robot ``robot`` of a relay at all."""
        if self.security.auth is None:
            return True
        return isinstance(principal, Principal) and principal.role.reaches(robot)

    def may_see(self, principal: Any, kind: str, name: str) -> bool:
        """Routes need introspection (and, for a relay's robot, a role reaching it); names
        need introspection on them."""
        if self.security.auth is None:
            return True
        if not isinstance(principal, Principal):
            return kind == "route" and name.startswith("/static/")
        role = principal.role
        if kind == "address":  # where other clients connect from
            return role.has("clients")
        if kind == "route" and self.robot is not None and not role.reaches(self.robot):
            return False
        if kind in ("route", "client"):
            return role.has("introspection")
        return role.allows("introspection", name)
