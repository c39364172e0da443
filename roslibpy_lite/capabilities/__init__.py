"""Capabilities: the groups of ops a client carries out, each in a module of its own.

:class:`~roslibpy_lite.ros.RosBase` (under both
:class:`~roslibpy_lite.client.Client` and :class:`~roslibpy_lite.mock.MockRos`)
composes three: :class:`~roslibpy_lite.capabilities.topics.Topics`
(advertise, publish, subscribe), :class:`~roslibpy_lite.capabilities.services.Services`
(call and serve services) and :class:`~roslibpy_lite.capabilities.actions.Actions`
(send and serve goals). Each talks to the client only through :class:`Host` (topics
through :class:`TopicsHost`, the serving ones through :class:`ServingHost`), and
keeps its own state; a request the bridge may answer or refuse by id is one
:class:`Tracked` record in the host.

Adding a capability
-------------------
Write a class in a module of its own that takes a :class:`Host`; in its
``__init__`` route the ops it receives (:meth:`Host.route`), and register what
it re-sends after a reconnect (:meth:`Host.on_restore`) and what it fails when
the connection drops (:meth:`Host.on_drop`). Send with :meth:`Host.send`, make
ids with :meth:`Host.new_id`, and keep each request the bridge answers by id as
a :class:`Tracked` (:meth:`Host.request` for a handle's request,
:meth:`Host.track` for a call). Then add one line to ``RosBase.__init__`` that
makes it, and the user-facing methods that call it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from rosbridge_core.protocol import ops

    from .._api_types import ConnectionState
    from ..exceptions import ConnectionClosed, RosLibError
    from ..messages import Completeness
    from ..transports.base import Transport

__all__ = ["Host", "ServingHost", "TopicsHost", "Tracked"]


@dataclass(eq=False, slots=True)
class Tracked:
    """One request the bridge may answer or refuse by its id.

    A one-shot call has a ``future`` that the answer (or a refusal, or a dropped
    connection) settles. A long-lived handle (publisher, subscription, served
    service or action, goal) has a ``handle``; a refusal calls ``refuse`` (the
    handle's ``fail`` when not given) and, once the refusal has been raised at
    ``await handle``, ``forget`` drops the handle's registration.
    """

    name: str
    """The topic, service or action the request is about (for error texts)."""
    handle: Any = None
    future: asyncio.Future[Any] | None = None
    refuse: Callable[[RosLibError], None] | None = None
    forget: Callable[[], None] | None = None
    verdict: asyncio.Event | None = None
    """Set when a confirming bridge (``transport.acks``) accepted or refused the request."""
    confirm: Callable[[], None] | None = None
    """Called on the bridge's ``info`` status for the id (ours: an action server accepted
    the goal)."""
    awaited: bool = False
    """Someone awaits the handle: a refusal is raised there, not reported."""
    report: asyncio.Handle | None = None
    """A refusal's report, scheduled for the next loop turn (cancelled if awaited first)."""


class Host(Protocol):
    """What every capability may use of the client it belongs to (a capability that needs
    more takes :class:`TopicsHost` or :class:`ServingHost`)."""

    @property
    def transport(self) -> Transport:
        """What carries the ops (to encode and write frames on a hot path)."""
        ...

    @property
    def validate(self) -> bool:
        """Whether dicts are checked against their type's ``msgs`` class."""
        ...

    @property
    def state(self) -> ConnectionState:
        """The connection's state."""
        ...

    @property
    def completeness(self) -> Completeness:
        """The rule for dicts that leave fields out (warn once, or refuse when strict)."""
        ...

    def check_open(self) -> None:
        """Raise ConnectionClosed once the client is closed."""
        ...

    def require_link(self, what: str, hint: str = "pass wait_connected=True to wait for it"
                     ) -> None:
        """Raise NotConnected (naming ``what``, the state, then ``hint``) unless the link is
        up; ConnectionClosed once the client is closed."""
        ...

    def link_note(self) -> str:
        """``""`` while connected, else `` (state reconnecting)`` to end an error text."""
        ...

    def route(self, op_type: type[Any], handler: Callable[[Any], None]) -> None:
        """Hand every received op of ``op_type`` to ``handler`` (it must not raise)."""
        ...

    def on_restore(self, fn: Callable[[], None]) -> None:
        """Call ``fn()`` on each (re)connect, in registration order, to re-send requests."""
        ...

    def on_drop(self, fn: Callable[[ConnectionClosed], None]) -> None:
        """Call ``fn(error)`` when the connection drops or closes (``state`` says which)."""
        ...

    def send(self, op: ops.Op) -> None:
        """Send ``op`` now, or drop it while disconnected."""
        ...

    def new_id(self, kind: str, name: str) -> str:
        """A new request id (``kind:name:n``)."""
        ...

    def request(self, pending: Tracked, op: ops.Op) -> None:
        """Track a handle's request under ``pending.handle.id`` and send ``op``; a
        confirming bridge's verdict is then awaited by ``await handle``."""
        ...

    def track(self, id: str, pending: Tracked) -> None:
        """Track a request under ``id`` (sent by the caller)."""
        ...

    def untrack(self, id: str) -> Tracked | None:
        """Stop tracking ``id``; its record, if it was tracked."""
        ...

    async def settle(self, handle: Any) -> None:
        """``await handle``: its request written and, with a confirming bridge, accepted
        (raises the refusal)."""
        ...

    async def flush(self) -> None:
        """Return once everything sent so far is handed to the connection."""
        ...


class TopicsHost(Host, Protocol):
    """What :class:`~roslibpy_lite.capabilities.topics.Topics` uses besides :class:`Host`."""

    def on_stray_error(self, fn: Callable[[str, RosLibError], None]) -> None:
        """Call ``fn(text, error)`` for a bridge error that names no pending request."""
        ...


class ServingHost(Host, Protocol):
    """What the capabilities that serve (services, actions) use besides :class:`Host`."""

    def send_or(self, op: ops.Op, fallback: Callable[[str], ops.Op]) -> None:
        """Send ``op``; if it cannot be encoded, send ``fallback(reason)`` instead."""
        ...

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Return once connected."""
        ...

    def spawn(self, coro: Coroutine[Any, Any, None]) -> asyncio.Task[None]:
        """Run a handler's task; it is cancelled when the client closes."""
        ...
