"""What one session may do: the ``auth`` op, the op rate, names and the role.

The session consults its :class:`Gate` before each frame (:meth:`Gate.admit_frame`) and
each op (:meth:`Gate.check`); a refusal answers the offender and nobody else. The gate
answers only "may this principal do this to this name": how many subscriptions, publishers,
served names or goals one connection may hold is the op groups' own business
(``LIMITS`` in :mod:`rosbridge_core.session`).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

from rosbridge_core.protocol import ops
from rosbridge_core.protocol.constants import POLICY_VIOLATION
from rosbridge_core.security.auth import Principal
from rosbridge_core.security.credentials import client_address
from rosbridge_core.security.names import InvalidNameError, check_name
from rosbridge_core.security.permissions import (
    Role,
    UnsafeNameError,
    filter_rosapi,
    hidden_requirement,
    requirement,
    rosapi_requirement,
    sees,
)

if TYPE_CHECKING:
    from rosbridge_core.security.auth import AuthConfig
    from rosbridge_core.security.options import SecurityConfig

__all__ = ["POLICY_VIOLATION", "PRE_AUTH_FRAME_LIMIT", "Gate", "GateFactory", "Guarded",
           "Verifier"]

log = logging.getLogger("bridge_server.security")

PRE_AUTH_FRAME_LIMIT = 16 * 1024
"""Largest frame read from a connection that has not authenticated yet."""



class GuardedLink(Protocol):
    """What a gate needs of its session's link (:class:`rosbridge_core.session.link.ClientLink`)."""

    principal: Principal | None

    @property
    def remote_address(self) -> Any:
        """Where the client is (its address is the key of the per-address limits)."""

    def limit_frames(self, size: int | None) -> None:
        """Refuse frames over ``size`` bytes from now on (``None``: the configured limit)."""

    async def close(self, code: int = 1000, reason: str = "") -> None:
        """Close the connection with ``code`` and ``reason``."""


class Guarded(Protocol):
    """The session a gate guards (a rosbridge or a Foxglove one)."""

    sid: int
    loop: asyncio.AbstractEventLoop

    @property
    def link(self) -> GuardedLink:
        """Its client's connection."""

    @property
    def closed(self) -> bool:
        """Whether the connection has ended."""

    def status(self, level: str, msg: str, id: ops.Id | None = None) -> None:
        """Tell the client (a ``status`` op, or the protocol's own)."""

    def refuse(self, op: Any, why: str) -> None:
        """Refuse ``op``: an error, and the failure answer a stock client waits for."""

    def recheck_grants(self) -> int:
        """The role changed: end what it no longer allows; how many ended."""
        ...


class Verifier(Protocol):
    """What a gate needs of the bridge's security (:class:`~.authority.Authority`)."""

    auth: AuthConfig | None
    config: SecurityConfig

    def verify_auth_op(self, address: str, mac: str, who: str) -> Principal | str:
        """The principal of an ``auth`` op's token, or why it is refused."""
        ...


class GateFactory(Protocol):
    """Where a session gets its gate (:class:`~.authority.Authority`)."""

    @property
    def config(self) -> SecurityConfig:
        """The per-connection limits as configured now."""

    def gate(self, session: Guarded, rosapi: Mapping[str, tuple[str, ...]] | None = None
             ) -> Gate:
        """The gate for a new session (``rosapi``: as :class:`Gate` takes it)."""
        ...


class Gate:
    """What one session may do: consulted for every frame and every op."""

    def __init__(self, security: Verifier, session: Guarded, principal: Principal | None,
                 rosapi: Mapping[str, tuple[str, ...]] | None = None) -> None:
        """``rosapi``: the session's own ``/rosapi/*`` services, each with its request fields
        in order (a call of one is governed by what it names, not by the service's name)."""
        self.security = security
        self.rosapi: Mapping[str, tuple[str, ...]] = rosapi or {}
        self.session = session
        self.principal = principal
        self.role: Role | None = principal.role if principal is not None else None
        self.authenticated = security.auth is None or principal is not None
        self.closing = False
        self.freed: set[str] = set()  # names this client failed to defend with a ping
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
            self._charge_to(principal)  # (the handshake did, unless a relay's auth op did)
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
        if self.closing or self.session.closed:
            return
        self.closing = True
        if self._timer is not None:
            self._timer.cancel()
        log.warning("session %d: closing: %s", self.session.sid, reason)
        task = self.session.loop.create_task(
            self.session.link.close(POLICY_VIOLATION, reason[:120]))
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
            fields = self.rosapi.get(name) if isinstance(op, ops.CallService) else None
            if fields is not None:
                governing = rosapi_requirement(name, _rosapi_args(fields, op.args))
            else:
                governing = hidden_requirement(capability, name)
        except (InvalidNameError, UnsafeNameError) as exc:
            self.deny(op, str(exc))
            return False
        return self.role is None or self.allowed(op, *governing, used=name)

    def allowed(self, op: Any, capability: str, name: str, used: str | None = None) -> bool:
        """Whether the role may use ``capability`` on ``name``; if not, ``op`` is refused.

        ``used`` is the name the op named, when ``name`` is what governs it (an action's
        internal service, a node's parameter service).
        """
        why = self._refusal(capability, name)
        if why is not None:
            why = f"forbidden: {why}"
            if used is not None and used != name and not used.startswith("/rosapi/"):
                why += f" ({used} is part of it)"
            self.deny(op, why)
        return why is None

    def forbids(self, capability: str, name: str) -> str | None:
        """Why the role may not use ``capability`` on ``name`` now (``None``: it may);
        ``*`` asks for some name (see :meth:`Role.has`)."""
        return self._refusal(*hidden_requirement(capability, name))

    def _refusal(self, capability: str, name: str) -> str | None:
        role = self.role
        if role is None:
            return None
        if role.has(capability) if name == "*" else role.allows(capability, name):
            return None
        return f"role {role.name} may not {capability} on {'any name' if name == '*' else name}"

    def sees(self, name: str) -> bool:
        """Whether an answer about the ROS graph may name ``name`` to this client
        (:func:`~rosbridge_core.security.permissions.sees`)."""
        return sees(self.role, name)

    def deny(self, op: Any, why: str) -> None:
        """Refuse ``op`` (:meth:`Guarded.refuse`)."""
        self.session.refuse(op, why)

    def _auth(self, op: ops.Auth) -> None:
        if self.security.auth is None:
            return  # no auth file: everyone is welcome, the op changes nothing
        principal = self.security.verify_auth_op(client_address(self.session.link), op.mac,
                                                 f"session {self.session.sid}")
        if isinstance(principal, str):
            self.close(principal)
            return
        if self.principal not in (None, principal):
            log.warning("session %d: auth op for another principal refused", self.session.sid)
            self.close(f"this connection is authenticated as {self.principal.name} already; "
                       "open a new connection to use another token")
            return
        if self.principal is None:
            self.principal, self.role, self.authenticated = principal, principal.role, True
            self._charge_to(principal)
            self.session.link.limit_frames(None)  # frames up to --max-message-size again
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            log.info("client %d authenticated as %s (role %s) by an auth op", self.session.sid,
                     principal.name, principal.role.name)

    def _charge_to(self, principal: Principal) -> None:
        """What the connection holds counts against ``principal``'s limits from now on
        (:mod:`.accounts`)."""
        holder = getattr(self.session.link, "holder", None)
        if holder is not None:
            holder.become(principal.name)

    # -- what the session asks -------------------------------------------------------------------

    def may_take_over(self, name: str, owner_gate: Gate | None) -> bool:
        """Whether this client may take ``name`` from its current server.

        ``owner_gate`` is the gate of the bridge client serving it, or ``None`` when a ROS
        node (or nobody the bridge knows) serves it. The same principal may (it reconnected
        before the bridge saw the old connection go); a claim may once, for that name only,
        when the owner failed to answer the claim's ping (:mod:`rosbridge_core.session.ownership`);
        otherwise only a role with ``take_over`` on the name. Without an auth file there are
        no roles: only the first two apply.
        """
        if owner_gate is not None:
            if name in owner_gate.freed:
                owner_gate.freed.discard(name)
                return True
            if self.principal is not None and owner_gate.principal is self.principal:
                return True
        return self.role is not None and self.role.allows("take_over", name)

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


def _rosapi_args(fields: tuple[str, ...], args: Mapping[str, Any] | list[Any] | None
                 ) -> Mapping[str, Any]:
    if isinstance(args, Mapping):
        return args
    if isinstance(args, list):
        return dict(zip(fields, args, strict=False))
    return {}
