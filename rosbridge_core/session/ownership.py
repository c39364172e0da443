"""Which client serves each name: one registry each for client-served services and actions.

A name a client serves stays with its first owner. Another client's advertise
of it fails, unless

- the same principal asks (a reconnect), or its role has ``take_over`` on the
  name (:meth:`rosbridge_core.security.Gate.may_take_over`): the owner loses the
  name at once and hears why; or
- the owner's connection does not answer a ping within
  :data:`OWNER_PING_TIMEOUT` seconds (a network drop the bridge has not noticed
  yet): the name is freed for this one claim.

A name an rclpy node already serves (not through this bridge) needs
``take_over`` too: two servers of one name would both answer each request.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine, Iterator
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from rosbridge_core.protocol import ops

if TYPE_CHECKING:
    from rosbridge_core.security.gate import Gate
    from rosbridge_core.session.link import ClientLink

__all__ = ["OWNER_PING_TIMEOUT", "Ownership", "Provider"]

log = logging.getLogger("bridge_server.session.ownership")

OWNER_PING_TIMEOUT = 2.0
"""Seconds an owner has to answer a ping before another client may claim its name."""


class Claimant(Protocol):
    """The session of a client that serves, or claims, a name."""

    sid: int
    gate: Gate
    link: ClientLink

    @property
    def closed(self) -> bool:
        """Whether the connection has ended."""

    def error(self, msg: str, id: ops.Id | None = None, kind: str = "request") -> None:
        """Send an error ``status`` and count it."""

    def handle_op(self, op: ops.Op) -> None:
        """Carry out one parsed op."""

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task ended with the session."""


class Provider(Protocol):
    """One client's side of a registry: what it serves of one kind (services or actions)."""

    served: dict[str, Any]
    """What the client serves, by full name."""

    @property
    def session(self) -> Claimant:
        """The client's session."""
        ...

    def remove_served(self, served: Any, why: str) -> None:
        """Stop serving ``served`` (already out of :attr:`served`); ``why`` is logged."""
        ...

    def drop_served(self, name: str, why: str) -> None:
        """Stop serving ``name`` (taken over by another client) and tell the client why."""
        ...


P = TypeVar("P", bound=Provider)


class Ownership(Generic[P]):
    """The names of one kind (``"service"`` or ``"action"``) and the client serving each."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._owners: dict[str, P] = {}

    def get(self, name: str) -> P | None:
        """The provider serving ``name``, if a client of this bridge does."""
        return self._owners.get(name)

    def __contains__(self, name: object) -> bool:
        return name in self._owners

    def __iter__(self) -> Iterator[str]:
        return iter(self._owners)

    def items(self) -> list[tuple[str, P]]:
        """Each name and its provider, sorted by name."""
        return sorted(self._owners.items())

    def take(self, name: str, provider: P) -> None:
        """Record ``provider`` as serving ``name`` (after :meth:`admit` said yes)."""
        self._owners[name] = provider

    def release(self, name: str, provider: P) -> None:
        """``provider`` stops serving ``name`` (no effect if another client owns it now)."""
        if self._owners.get(name) is provider:
            del self._owners[name]

    def admit(
        self,
        provider: P,
        op: ops.AdvertiseService | ops.AdvertiseAction,
        name: str,
        ros_servers: Callable[[], list[str]],
    ) -> bool:
        """Whether ``provider`` may serve ``name`` now (``op`` is its advertise).

        Another client's name is taken over at once (``take_over``), or claimed after a
        ping the owner does not answer (the op is carried out again then, and this returns
        False meanwhile). ``ros_servers`` lists the nodes outside this bridge that serve
        the name; asked only when no client of ours does. A refusal is sent to the client.
        """
        session = provider.session
        owner = self._owners.get(name)
        if owner is not None and owner is not provider:
            if not session.gate.may_take_over(name, owner.session.gate):
                session.spawn(self._claim(provider, op, name, owner))
                return False
            owner.drop_served(name, f"taken over by client {session.sid}")
        elif owner is None:
            others = ros_servers()
            if others and not session.gate.may_take_over(name, None):
                session.error(
                    f"{op.OP}: {name} is already served by {others[0]}; a bridge client may "
                    "serve it too only with the take_over capability",
                    op.id,
                )
                return False
        return True

    def unadvertise(
        self, provider: P, op: ops.UnadvertiseService | ops.UnadvertiseAction, name: str
    ) -> None:
        """The client stops serving ``name`` (an error if it does not serve it)."""
        served = provider.served.pop(name, None)
        if served is None:
            provider.session.error(f"{op.OP}: {name} is not served by this client", op.id)
            return
        provider.remove_served(served, "the client unadvertised it")

    def recheck(self, provider: P, gate: Gate) -> int:
        """Stop serving the names the client's role no longer allows; how many ended."""
        ended = 0
        for name in list(provider.served):
            why = gate.forbids(f"serve_{self.kind}", name)
            if why is not None:
                provider.drop_served(name, f"no longer served: {why}")
                ended += 1
        return ended

    async def _claim(
        self, provider: P, op: ops.AdvertiseService | ops.AdvertiseAction, name: str, owner: P
    ) -> None:
        """Serve a name another client serves only if that client is gone (no pong).

        A connection whose client vanished should not hold the name until the keepalive
        gives up, or the client could never serve it again after it reconnects.
        """
        gone: tuple[type[BaseException], ...] = (TimeoutError, *owner.session.link.closed_errors)
        try:
            pong = await owner.session.link.ping()
            await asyncio.wait_for(pong, OWNER_PING_TIMEOUT)
            alive = True
        except gone:
            alive = False
        session = provider.session
        if session.closed:
            return
        if self._owners.get(name) is not owner:
            session.handle_op(op)  # the name changed hands meanwhile: decide again
            return
        if alive:
            session.error(
                f"{op.OP}: {name} is already served by client {owner.session.sid}; the first "
                "owner keeps it (a role with take_over may take it over)",
                op.id,
            )
            return
        log.warning("client %d serves %s but did not answer a ping in %s s: client %d takes "
                    "the %s", owner.session.sid, name, OWNER_PING_TIMEOUT, session.sid,
                    self.kind)
        owner.session.gate.freed.add(name)  # this name, for this claim (see may_take_over)
        session.handle_op(op)
