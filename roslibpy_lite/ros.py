"""The whole user API once, over any transport: :class:`RosBase`.

:class:`RosBase` is what :class:`~roslibpy_lite.client.Client` (over a
websocket) and :class:`~roslibpy_lite.mock.MockRos` (over an in-memory bridge)
share: every method a user calls, the connection state, the error rules and
restoring everything after a reconnect. What each group of ops does lives in a
capability (:mod:`roslibpy_lite.capabilities`: topics, services, actions); the
capabilities share one host (:class:`~roslibpy_lite._host._Host`: sending, routing
received ops, request ids, the requests the bridge may answer or refuse by id, and the
connection's hooks). Under it a transport (:mod:`roslibpy_lite.transports`)
only moves ops. So a rule written here holds in production and in unit tests
alike.

The error rules
---------------
- What is known locally raises at the call, naming the fix: a malformed or
  unknown type name (``did you mean``), a message field the type lacks or a
  value of the wrong kind (dicts are checked against the ``msgs`` class of
  their type when there is one, unless ``validate=False``), a closed handle.
- What only the bridge knows reaches the caller as an exception where it can:
  when the bridge confirms requests (``transport.acks``: our bridge does, on
  request), ``await ros.advertise(...)`` / ``subscribe`` / ``advertise_service``
  wait (at most ``verdict_timeout``) for its verdict and raise
  :class:`~roslibpy_lite.exceptions.StatusError` if it refused. Against a
  stock rosbridge they return at once, as it sends no verdict. A refusal that
  nobody awaits goes to the error hooks (:meth:`RosBase.on_error`), is
  logged, sets the handle's ``error`` (the next ``publish`` raises it, an
  ``async for`` raises it), and never only to the log.

Adding a capability: see :mod:`roslibpy_lite.capabilities`.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Literal, Self, overload

from rosbridge_core.protocol import ops
from rosbridge_core.protocol.constants import ADVERTISE_QUEUE_SIZE

from ._api_types import ConnectionState, ErrorCallback, MessageCallback, StateCallback
from ._host import _Host
from .capabilities.actions import Actions
from .capabilities.introspection import Introspection
from .capabilities.services import Services
from .capabilities.topics import Topics
from .exceptions import ConnectionClosed, UsageError
from .state import StateWatcher, add_callback

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Action, Message, Service

    from ._api_types import DEFAULT_CALL_TIMEOUT, M, ServiceHandler
    from .actions import ActionHandler, ActionServer, FeedbackCallback, GoalHandle
    from .handles import Publisher, ServiceCall, ServiceServer, Subscription
    from .messages import RawMessage
    from .transports.base import Transport
else:
    from ._api_types import DEFAULT_CALL_TIMEOUT

__all__ = ["ErrorCallback", "RosBase", "RosFront"]


class RosBase:
    """The user API over a transport (see the module docstring).

    Args:
        transport: what carries the ops.
        offline_buffer: messages kept per publisher while disconnected (0: raise).
        max_pending: frames queued for sending before ``publish`` waits.
        validate: check dict messages against the ``msgs`` class of their type
            when there is one (on by default; off saves the check's time).
        verdict_timeout: how long ``await ros.advertise(...)`` (and subscribe,
            advertise_service) waits for the bridge's verdict when it sends one.
        strict: refuse a message or request dict that leaves fields out
            (:class:`~roslibpy_lite.exceptions.InvalidMessageError` naming them) instead of
            letting the bridge fill in defaults with a
            :class:`~roslibpy_lite.exceptions.PartialMessageWarning` (once per type and
            field set); ``advertise`` and ``call_service`` take ``strict=`` too. Needs the
            type's ``msgs`` class (a typed class, or ``validate``).
    """

    def __init__(
        self,
        transport: Transport,
        *,
        offline_buffer: int = 100,
        max_pending: int = 1024,
        validate: bool = True,
        verdict_timeout: float = 5.0,
        strict: bool = False,
    ) -> None:
        if offline_buffer < 0:
            raise UsageError(f"offline_buffer must be >= 0, got {offline_buffer}")
        if max_pending < 1:
            raise UsageError(f"max_pending must be >= 1, got {max_pending}")
        self.offline_buffer = offline_buffer
        self.max_pending = max_pending
        self.verdict_timeout = verdict_timeout
        self._transport = transport
        self._host = host = _Host(transport, validate, verdict_timeout, strict)
        # The capabilities, in the order their requests are restored after a reconnect.
        self._topics = Topics(host, offline_buffer=offline_buffer, max_pending=max_pending)
        self._services = Services(host)
        self._actions = Actions(host)
        self._graph = Introspection(self)
        self._topics.graph = self._graph  # a wait that ends empty asks it for a misspelling
        host.on_restore(self._topics.flush_offline)  # messages go after every request
        transport.bind(host)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self._transport.url} {self._host.state.value}>"

    @property
    def validate(self) -> bool:
        """Whether dict messages are checked against their type's ``msgs`` class."""
        return self._host.validate

    @validate.setter
    def validate(self, value: bool) -> None:
        self._host.validate = value

    @property
    def strict(self) -> bool:
        """Whether dicts that leave fields out are refused (see the class's ``strict``)."""
        return self._host.completeness.strict

    @strict.setter
    def strict(self, value: bool) -> None:
        self._host.completeness.strict = value

    @property
    def status_errors(self) -> int:
        """``status`` errors from the bridge that named none of our pending requests."""
        return self._host.status_errors

    @property
    def graph(self) -> Introspection:
        """The ROS graph and parameters (topics, services, actions, nodes, params), asked of
        the bridge's ``/rosapi``: see :mod:`roslibpy_lite.capabilities.introspection`."""
        return self._graph

    # -- state ---------------------------------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        """The current connection state."""
        return self._host.state

    @property
    def is_connected(self) -> bool:
        """True while the state is ``CONNECTED``."""
        return self._host.state is ConnectionState.CONNECTED

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Return once connected (raises RosTimeoutError, or ConnectionClosed once closed)."""
        await self._host.wait_connected(timeout)

    def on_state_change(self, callback: StateCallback) -> Callable[[], None]:
        """Call ``callback(state)`` on every change; returns a function that removes it."""
        return self._host.hub.on_change(callback)

    def state_changes(self) -> StateWatcher:
        """An async iterator of the state changes from now on (ends after ``CLOSED``)."""
        return self._host.hub.watch()

    def on_status(self, callback: Callable[[ops.Status], None]) -> Callable[[], None]:
        """Call ``callback(status_op)`` for every ``status`` op the bridge sends."""
        return add_callback(self._host.status_callbacks, callback)

    def on_error(self, callback: ErrorCallback) -> Callable[[], None]:
        """Call ``callback(error)`` for every bridge error no caller is waiting for.

        That is: a refused ``advertise``/``subscribe``/``advertise_service``
        that was not awaited (or whose verdict came after ``await`` returned),
        a message the bridge could not publish, and errors naming no request.
        Each is logged too. Returns a function that removes the callback.
        """
        return add_callback(self._host.error_callbacks, callback)

    # -- topics --------------------------------------------------------------------------------

    @overload
    def advertise(
        self, topic: str, type: str, *, latch: bool = False,
        queue_size: int = ADVERTISE_QUEUE_SIZE,
        strict: bool | None = None,
    ) -> Publisher[dict[str, Any]]: ...

    @overload
    def advertise(
        self, topic: str, type: type[M], *, latch: bool = False,
        queue_size: int = ADVERTISE_QUEUE_SIZE,
        strict: bool | None = None,
    ) -> Publisher[M]: ...

    def advertise(
        self, topic: str, type: str | type[Message], *, latch: bool = False,
        queue_size: int = ADVERTISE_QUEUE_SIZE,
        strict: bool | None = None,
    ) -> Publisher[Any]:
        """Announce a publisher on ``topic``.

        ``type`` is a type string (publish dicts) or a msgs class (publish
        instances or dicts). ``latch``: late subscribers get the last message.
        ``strict``: refuse dicts that leave fields out (None: the client's ``strict``;
        otherwise they are sent, the bridge fills in defaults, and a
        :class:`~roslibpy_lite.exceptions.PartialMessageWarning` names the fields once).
        Use as ``pub = await ros.advertise(...)`` or ``async with ros.advertise(...) as pub``;
        awaiting waits for the bridge's verdict when it sends one.

        Raises:
            UsageError: a bad topic or type (an unknown type says "did you mean").
            StatusError: the bridge refused (raised at ``await``; else see :meth:`on_error`).
            ConnectionClosed: the client is closed.
        """
        return self._topics.advertise(topic, type, latch, queue_size, strict)

    @overload
    def subscribe(
        self,
        topic: str,
        type: str | type[Message],
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
        raw: Literal[True],
    ) -> Subscription[RawMessage]: ...

    @overload
    def subscribe(
        self,
        topic: str,
        type: str,
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
        raw: Literal[False] = False,
    ) -> Subscription[dict[str, Any]]: ...

    @overload
    def subscribe(
        self,
        topic: str,
        type: type[M],
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
        raw: Literal[False] = False,
    ) -> Subscription[M]: ...

    def subscribe(
        self,
        topic: str,
        type: str | type[Message],
        callback: MessageCallback | None = None,
        *,
        throttle_rate: int = 0,
        queue_length: int = 0,
        compression: str = "none",
        fragment_size: int | None = None,
        buffer_size: int = 100,
        raw: bool = False,
    ) -> Subscription[Any]:
        """Subscribe to ``topic``.

        Messages are dicts for a type string, instances for a msgs class.
        Options: ``throttle_rate`` (ms between messages, at the bridge),
        ``queue_length`` (the bridge's queue for us; 0: its default),
        ``compression`` (``"none"``; ``"cbor"``, which needs cbor2; ``"cbor-raw"``:
        the robot's CDR bytes, decoded here),
        ``fragment_size`` (the bridge splits larger messages into fragments of
        this many characters; they are reassembled here),
        ``buffer_size`` (this side's buffer; the oldest message is dropped
        when full; who keeps and drops what, from the robot to here, is the
        "Buffers" section of the Publish and subscribe guide), ``raw`` (messages are
        :class:`~roslibpy_lite.messages.RawMessage`:
        the CDR bytes as the robot serialized them and the bridge's stamp, nothing
        decoded; the bridge sends ``cbor-raw``, and a server that cannot is served by
        serializing here, as is MockRos). Iterate the handle, ``await sub.get()`` (both
        read the buffer, oldest first), or pass ``callback`` (sync or async); for fresh
        values ``sub.latest()``, ``await sub.next(timeout)``, ``await sub.collect(seconds)``.
        A ``callback`` this client already runs for ``topic`` (the same function, or the
        same code from a re-run cell) moves to the new subscription instead of running
        twice (:class:`~roslibpy_lite.exceptions.DuplicateCallbackWarning`). ``uint8[]``
        fields of dict messages are ``bytes`` whatever the compression. Use as
        ``async with`` or ``await`` (which waits for the bridge's verdict when it sends one).

        Raises:
            UsageError: a bad topic, type or option (or cbor2 missing).
            StatusError: the bridge refused (raised at ``await``; else see :meth:`on_error`).
            ConnectionClosed: the client is closed.
        """
        return self._topics.subscribe(
            topic, type, callback, throttle_rate=throttle_rate, queue_length=queue_length,
            compression=compression, fragment_size=fragment_size, buffer_size=buffer_size,
            raw=raw,
        )

    def subscriptions(self) -> list[Subscription[Any]]:
        """The open subscriptions of this client, oldest first (close the ones a re-run
        cell left behind with ``await sub.close()``)."""
        return [s for s in self._topics.subscriptions.values() if not s.closed]

    async def load_types(
        self, *type_names: str, timeout: float | None = DEFAULT_CALL_TIMEOUT
    ) -> list[type[Message] | type[Service] | type[Action]]:
        """Typed classes for the robot's own interfaces, built from the bridge's definitions.

        Each name (``pkg/msg/Name``, ``pkg/srv/Name``, ``pkg/action/Name`` or
        ``pkg/Name``) that msgs does not know is asked of the bridge
        (``/rosapi/interface_definition``, the definition text installed on the
        robot) and built with :func:`msgs.dynamic.load`; names msgs knows cost
        nothing. Afterwards the classes work everywhere a generated one does:
        typed publishers and subscriptions, checks at the call, ``cbor-raw``.

        Raises:
            ServiceError: the bridge does not have the type (or is not ours).
            msgs.parser.DefinitionError: the robot's definition does not parse.
        """
        from msgs.dynamic import load
        from msgs.runtime import UnknownTypeError, lookup

        found: list[type[Message] | type[Service] | type[Action]] = []
        for name in type_names:
            try:
                found.append(lookup(name))
                continue
            except UnknownTypeError:
                pass
            answer = await self.call_service(
                "/rosapi/interface_definition", "rosapi_msgs/srv/InterfaceDefinition",
                {"type": name}, timeout=timeout)
            found.append(load(answer["type"], answer["definition"]))
        return found

    # -- services ------------------------------------------------------------------------------

    @overload
    def call_service(
        self,
        service: str,
        type: str,
        args: Mapping[str, Any] | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
        wait_connected: bool = False,
        strict: bool | None = None,
    ) -> ServiceCall[dict[str, Any]]: ...

    @overload
    def call_service(
        self,
        service: str,
        type: type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
        wait_connected: bool = False,
        strict: bool | None = None,
    ) -> ServiceCall[Any]: ...

    def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
        wait_connected: bool = False,
        strict: bool | None = None,
    ) -> ServiceCall[Any]:
        """Call ``service``; ``await`` the result for its response.

        ``args`` is a dict (or a ``Request`` instance for a typed service);
        the response is a dict, or a ``Response`` instance for a typed
        service. ``timeout`` is in seconds (None: wait for ever). While the link
        is down (reconnecting) the call fails at once with
        :class:`~roslibpy_lite.exceptions.NotConnected`, naming the state;
        ``wait_connected=True`` waits for the connection instead, within
        ``timeout``. The arguments are checked here, at the call; the
        request is sent when the result is awaited. A dict that leaves fields
        out is sent with the bridge's defaults and a
        :class:`~roslibpy_lite.exceptions.PartialMessageWarning` naming them
        (once per type and field set), or refused with ``strict=True`` (None:
        the client's ``strict``).

        Raises:
            ServiceError: the service answered ``result: false`` (it failed,
                does not exist, or the bridge could not call it); the text says why.
            StatusError: the bridge refused the request itself.
            RosTimeoutError: no answer within ``timeout``.
            NotConnected: the link is down (unless ``wait_connected``).
            Disconnected: the connection dropped while waiting.
            ConnectionClosed: the client is closed.
            UsageError / InvalidMessageError: bad arguments (raised at the call).
        """
        return self._services.call(service, type, args, timeout, wait_connected, strict)

    def advertise_service(
        self, service: str, type: str | type[Service], handler: ServiceHandler
    ) -> ServiceServer:
        """Serve ``service`` to ROS callers with ``handler`` (sync or async).

        The handler gets the request (dict, or ``Request`` instance for a
        typed service) and returns the response (dict, ``Response``, or
        None). If it raises, the caller is answered ``result: false`` with
        the error's text. Use as ``await`` or ``async with``.

        Raises:
            UsageError: a bad name or type, or the service is already served here.
            StatusError: the bridge refused (raised at ``await``; else see :meth:`on_error`).
            ConnectionClosed: the client is closed.
        """
        return self._services.advertise(service, type, handler)

    # -- actions -------------------------------------------------------------------------------

    async def send_goal(
        self,
        action: str,
        type: str | type[Action],
        goal: Mapping[str, Any] | Message | None = None,
        *,
        feedback: bool = True,
        on_feedback: FeedbackCallback | None = None,
        buffer_size: int = 100,
    ) -> GoalHandle:
        """Send a goal to the action server of ``action``; returns its :class:`GoalHandle`.

        ``type`` is an action type string (``pkg/action/Name`` or ``pkg/Name``)
        or a msgs action class; ``goal`` a dict or its ``Goal`` instance
        (checked here against the type). ``feedback``: ask for feedback
        (iterate the handle, or pass ``on_feedback``, sync or async);
        ``buffer_size``: feedback kept for iteration (the oldest is dropped).
        Waits for the connection when it is down (at most 10 s). A goal dict that
        leaves fields out is warned about once (or refused: the client's ``strict``).

        Raises:
            UsageError / InvalidMessageError: a bad name, type or goal.
            RosTimeoutError: the connection did not come back in time.
            ConnectionClosed: the client is closed.
        """
        return await self._actions.send_goal(action, type, goal, feedback=feedback,
                                             on_feedback=on_feedback, buffer_size=buffer_size)

    def advertise_action(
        self, action: str, type: str | type[Action], handler: ActionHandler
    ) -> ActionServer:
        """Serve ``action`` to ROS callers with ``handler`` (module doc); ``await`` it.

        Raises:
            UsageError: a bad name or type, or the action is already served here.
            StatusError: the bridge refused (raised at ``await``, which waits for the
                verdict of a confirming bridge; else see
                :meth:`~roslibpy_lite.ros.RosBase.on_error`).
            ConnectionClosed: the client is closed.
        """
        return self._actions.advertise(action, type, handler)

    # -- closing -------------------------------------------------------------------------------

    async def close(self) -> None:
        """Close the connection; the state becomes ``CLOSED``. Closing twice is harmless."""
        host = self._host
        host.shut_down(ConnectionClosed(f"the connection to {self._transport.url} was closed"))
        await self._transport.close()
        tasks = self._topics.consumers() + list(host.tasks)
        if tasks:
            # Let tasks made just now start, so the handlers they hold are awaited (and
            # cancelled) rather than dropped unawaited.
            await asyncio.sleep(0)
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()


RosFront = RosBase
"""The old name of :class:`RosBase` (kept so that existing imports still work)."""
