"""The front: the whole user API once, over any transport.

:class:`RosFront` owns what a user touches: ``advertise``/``subscribe``/
``call_service``/``advertise_service`` (from
:class:`~roslibpy_lite.services_front.ServicesMixin`), ``send_goal``/``advertise_action``
(from :class:`~roslibpy_lite.actions_front.ActionsMixin`), the connection state, validation, the
handles, request ids, restoring everything after a reconnect, and the error
rules. Under it a transport (:mod:`roslibpy_lite.transports`) only moves ops:
:class:`~roslibpy_lite.client.Client` is the front over a websocket,
:class:`~roslibpy_lite.mock.MockRos` the front over an in-memory bridge. So a
rule written here holds in production and in unit tests alike.

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
  nobody awaits goes to the error hooks (:meth:`RosFront.on_error`), is
  logged, sets the handle's ``error`` (the next ``publish`` raises it, an
  ``async for`` raises it), and never only to the log.

Adding a capability (an action client or server, ...)
-----------------------------------------------------
1. Route the ops it receives: ``self._routes[ops.ActionFeedback] = self._on_feedback``
   (every op type not in ``_routes`` is ignored; ``publish`` has its own fast
   path). Replies about one request carry its id: keep the waiting requests in
   a dict keyed by id, as ``call_service`` keeps ``self._calls``
   (:mod:`roslibpy_lite.services_front`); status errors naming an id in
   ``self._calls`` fail that call's future.
2. Send with ``self._send(op)`` (dropped while disconnected) and make ids with
   ``self._new_id(kind, name)``.
3. A long-lived handle (a served action) registers with ``self._request(handle, op)``:
   it is then in ``self._requests`` (status errors with its id reach
   ``handle._fail``), its verdict is awaited by ``await handle``; and add
   a callback to ``self._restorers`` that re-sends its op after each reconnect.
4. Fail what is in flight in :meth:`_disconnected` / :meth:`_shutdown` (both
   call every function in ``self._on_drop`` with the error).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
from collections.abc import Callable, Coroutine, Mapping
from typing import TYPE_CHECKING, Any, Self, overload

from . import ops
from .actions import ActionServer, GoalHandle
from .actions_front import ActionsMixin
from .api import ConnectionState, MessageCallback, StateCallback
from .exceptions import (
    ConnectionClosed,
    Disconnected,
    RosLibError,
    StatusError,
    UsageError,
    status_error,
)
from .handles import Publisher, ServiceServer, Subscription
from .messages import check_name, lookup_message_class, message_type
from .services_front import ServicesMixin
from .state import StateHub, StateWatcher, add_callback

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Message

    from .api import M
    from .transports.base import Transport

__all__ = ["ErrorCallback", "RosFront"]

log = logging.getLogger("roslibpy_lite.client")

_Handle = Publisher[Any] | Subscription[Any] | ServiceServer | ActionServer | GoalHandle
ErrorCallback = Callable[[RosLibError], None]
"""An error hook: ``fn(error)`` for a bridge error nobody awaits (see :meth:`RosFront.on_error`)."""


class RosFront(ServicesMixin, ActionsMixin):
    """The user API over a transport (see the module docstring).

    Args:
        transport: what carries the ops.
        offline_buffer: messages kept per publisher while disconnected (0: raise).
        max_pending: frames queued for sending before ``publish`` waits.
        validate: check dict messages against the ``msgs`` class of their type
            when there is one (on by default; off saves the check's time).
        verdict_timeout: how long ``await ros.advertise(...)`` (and subscribe,
            advertise_service) waits for the bridge's verdict when it sends one.
    """

    def __init__(
        self,
        transport: Transport,
        *,
        offline_buffer: int = 100,
        max_pending: int = 1024,
        validate: bool = True,
        verdict_timeout: float = 5.0,
    ) -> None:
        if offline_buffer < 0:
            raise UsageError(f"offline_buffer must be >= 0, got {offline_buffer}")
        if max_pending < 1:
            raise UsageError(f"max_pending must be >= 1, got {max_pending}")
        self.offline_buffer = offline_buffer
        self.max_pending = max_pending
        self.validate = validate
        self.verdict_timeout = verdict_timeout
        self._transport = transport
        self._hub = StateHub(ConnectionState.CONNECTING)
        self._ids = itertools.count(1)
        # Handles, in creation order (dicts keep it) for restoring after a reconnect.
        self._publishers: dict[str, list[Publisher[Any]]] = {}
        self._subs: dict[str, Subscription[Any]] = {}
        self._topic_subs: dict[str, tuple[Subscription[Any], ...]] = {}
        self._requests: dict[str, _Handle] = {}
        self._verdicts: dict[str, asyncio.Event] = {}
        self._awaited: set[str] = set()
        self._reports: dict[str, asyncio.Handle] = {}
        self._handler_tasks: set[asyncio.Task[None]] = set()
        self._status_callbacks: list[Callable[[ops.Status], None]] = []
        self._error_callbacks: list[ErrorCallback] = []
        self._restorers: list[Callable[[], None]] = []
        self._on_drop: list[Callable[[ConnectionClosed], None]] = []
        self._routes: dict[type[Any], Callable[[Any], None]] = {ops.Status: self._on_status}
        self._init_services()  # call_service / advertise_service (roslibpy_lite.services_front)
        self._init_actions()  # send_goal / advertise_action (roslibpy_lite.actions_front)
        self.status_errors = 0
        """``status`` errors from the bridge that named none of our pending requests."""
        transport.bind(self)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self._transport.url} {self._hub.state.value}>"

    # -- the transport's hooks -----------------------------------------------------------------

    def _connected(self) -> None:
        """A connection is open: send every open handle's request again, then buffered messages."""
        for pubs in self._publishers.values():
            self._send(pubs[0].request_op())
        for sub in self._subs.values():
            sub.error = None
            self._send(sub.request_op())
        for restore in self._restorers:  # served services, then actions
            restore()
        t = self._transport
        for pubs in self._publishers.values():
            for pub in pubs:
                pub.error = None
                while pub._offline and t.connected:
                    t.write(pub._offline.popleft())
        self._hub.set(ConnectionState.CONNECTED)

    def _disconnected(self) -> None:
        """The connection dropped; a reconnect follows. Calls in flight fail at once."""
        self._hub.set(ConnectionState.RECONNECTING)
        self._fail_calls(lambda service, call_id: Disconnected(
            f"connection to {self._transport.url} dropped while calling {service} "
            f"(request {call_id})"
        ))
        self._release_verdicts()
        for fn in self._on_drop:
            fn(Disconnected(f"connection to {self._transport.url} dropped"))

    def _shutdown(self, error: ConnectionClosed) -> None:
        """Enter CLOSED: fail calls, end subscriptions (no messages to the server)."""
        self._hub.set(ConnectionState.CLOSED)
        self._fail_calls(lambda service, call_id: error)
        self._release_verdicts()
        for fn in self._on_drop:
            fn(error)
        for sub in list(self._subs.values()):
            sub._end()
        for pubs in self._publishers.values():
            for pub in pubs:
                pub._offline.clear()

    def _release_verdicts(self) -> None:
        verdicts, self._verdicts = self._verdicts, {}
        for event in verdicts.values():
            event.set()

    # -- the receive path ----------------------------------------------------------------------

    def _on_op(self, op: ops.Op) -> None:
        """Dispatch one op from the transport (never raises)."""
        if type(op) is ops.Publish:
            subs = self._topic_subs.get(op.topic)
            if subs is not None:
                msg = op.msg
                for sub in subs:
                    sub._deliver(msg)
            return
        route = self._routes.get(type(op))
        if route is None:
            log.debug("ignoring a %s op", op.OP)
            return
        try:
            route(op)
        except Exception:  # a bug here must not kill the connection
            log.exception("failed to handle a %s op", op.OP)

    def _on_status(self, op: ops.Status) -> None:
        for cb in list(self._status_callbacks):
            try:
                cb(op)
            except Exception:
                log.exception("status callback raised")
        key = str(op.id) if op.id is not None else None
        if op.level != "error":
            if key is not None and key in self._requests:
                event = self._verdicts.pop(key, None)
                if event is not None and op.level == "info":
                    event.set()  # the bridge accepted the request
                    return
                if op.level == "info":
                    return  # an acknowledgement after a reconnect
            log.info("bridge status %s: %s", op.level, op.msg)
            return
        error = status_error(op.msg, level=op.level, id=op.id)  # Forbidden when it says so
        if key is not None:
            call = self._calls.pop(key, None)
            if call is not None:
                if not call.future.done():
                    call.future.set_exception(error)
                return
            handle = self._requests.get(key)
            if handle is not None:
                self._refused(key, handle, error)
                return
        pubs = self._publishers_named_in(op.msg)
        for pub in pubs:
            pub._fail_once(error)
        self.status_errors += 1
        self._report(error, "bridge error")

    def _refused(self, key: str, handle: _Handle, error: StatusError) -> None:
        """The bridge refused a handle's request: the handle fails; awaited or reported."""
        if isinstance(handle, Publisher):  # every handle sharing the advertise
            for pub in self._publishers.get(handle.topic, [handle]):
                pub._fail(error)
        else:
            handle._fail(error)
        event = self._verdicts.pop(key, None)
        if event is not None:
            event.set()
        if key in self._awaited:
            return  # the caller awaiting the handle raises it
        # Reported a moment later unless the handle is awaited first: an in-memory bridge
        # refuses during the call itself, and ``await ros.subscribe(...)`` must raise then too.
        loop = asyncio._get_running_loop()
        if loop is None:
            self._report(error, f"bridge refused {key}")
        else:
            self._reports[key] = loop.call_soon(self._report, error, f"bridge refused {key}")

    def _publishers_named_in(self, text: str) -> list[Publisher[Any]]:
        """Publishers of the topic a bridge's ``publish to <topic> ...`` error names."""
        if not text.startswith("publish to "):
            return []
        topic = text[len("publish to "):].split(" ", 1)[0].rstrip(":")
        found = self._publishers.get(topic) or self._publishers.get(topic.lstrip("/"))
        return list(found or [])

    def _report(self, error: RosLibError, what: str) -> None:
        """Tell the error hooks (and the log) about an error nobody awaits."""
        if isinstance(error, StatusError):
            self._reports.pop(str(error.id), None)
        log.warning("%s: %s", what, error)
        for cb in list(self._error_callbacks):
            try:
                cb(error)
            except Exception:
                log.exception("error callback raised")

    # -- sending -------------------------------------------------------------------------------

    def _send(self, op: ops.Op) -> None:
        """Send ``op`` now, or drop it while disconnected (handles are restored on connect)."""
        t = self._transport
        if t.connected:
            t.write(t.encode(op))

    def _new_id(self, kind: str, name: str) -> str:
        return f"{kind}:{name}:{next(self._ids)}"

    def _request(self, handle: _Handle, op: ops.Op) -> None:
        """Send a handle's request; with a confirming bridge, expect its verdict."""
        self._requests[handle.id] = handle
        t = self._transport
        if t.connected:
            if t.acks:
                self._verdicts[handle.id] = asyncio.Event()
            t.write(t.encode(op))

    async def _settle(self, handle: _Handle) -> None:
        """``await handle``: written, and (with a confirming bridge) accepted."""
        await self._transport.flush()
        key = handle.id
        event = self._verdicts.get(key)
        if event is not None:
            self._awaited.add(key)
            try:
                async with asyncio.timeout(self.verdict_timeout):
                    await event.wait()
            except TimeoutError:
                log.debug("no verdict on %s within %s s", key, self.verdict_timeout)
            finally:
                self._awaited.discard(key)
                self._verdicts.pop(key, None)
        if handle.error is not None and self._requests.get(key) is handle:
            report = self._reports.pop(key, None)
            if report is not None:
                report.cancel()
            self._forget(handle)
            raise handle.error

    def _forget(self, handle: _Handle) -> None:
        """Drop a refused handle's registration (nothing is sent)."""
        self._requests.pop(handle.id, None)
        if isinstance(handle, Publisher):
            pubs = self._publishers.pop(handle.topic, [])
            for pub in pubs:
                self._requests.pop(pub.id, None)
        elif isinstance(handle, Subscription):
            self._drop_sub(handle)
        elif isinstance(handle, ServiceServer) and self._servers.get(handle.service) is handle:
            del self._servers[handle.service]

    async def _flush(self) -> None:
        await self._transport.flush()

    # -- state ---------------------------------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        """The current connection state."""
        return self._hub.state

    @property
    def is_connected(self) -> bool:
        """True while the state is ``CONNECTED``."""
        return self._hub.state is ConnectionState.CONNECTED

    async def wait_connected(self, timeout: float | None = None) -> None:
        """Return once connected (raises RosTimeoutError, or ConnectionClosed once closed)."""
        await self._hub.wait_connected(timeout)

    def on_state_change(self, callback: StateCallback) -> Callable[[], None]:
        """Call ``callback(state)`` on every change; returns a function that removes it."""
        return self._hub.on_change(callback)

    def state_changes(self) -> StateWatcher:
        """An async iterator of the state changes from now on (ends after ``CLOSED``)."""
        return self._hub.watch()

    def on_status(self, callback: Callable[[ops.Status], None]) -> Callable[[], None]:
        """Call ``callback(status_op)`` for every ``status`` op the bridge sends."""
        return add_callback(self._status_callbacks, callback)

    def on_error(self, callback: ErrorCallback) -> Callable[[], None]:
        """Call ``callback(error)`` for every bridge error no caller is waiting for.

        That is: a refused ``advertise``/``subscribe``/``advertise_service``
        that was not awaited (or whose verdict came after ``await`` returned),
        a message the bridge could not publish, and errors naming no request.
        Each is logged too. Returns a function that removes the callback.
        """
        return add_callback(self._error_callbacks, callback)

    def _check_open(self) -> None:
        if self._hub.state is ConnectionState.CLOSED:
            raise ConnectionClosed(f"the connection to {self._transport.url} is closed")

    # -- publishers ----------------------------------------------------------------------------

    @overload
    def advertise(
        self, topic: str, type: str, *, latch: bool = False, queue_size: int = 100
    ) -> Publisher[dict[str, Any]]: ...

    @overload
    def advertise(
        self, topic: str, type: type[M], *, latch: bool = False, queue_size: int = 100
    ) -> Publisher[M]: ...

    def advertise(
        self, topic: str, type: str | type[Message], *, latch: bool = False, queue_size: int = 100
    ) -> Publisher[Any]:
        """Announce a publisher on ``topic``.

        ``type`` is a type string (publish dicts) or a msgs class (publish
        instances or dicts). ``latch``: late subscribers get the last message.
        Use as ``pub = await ros.advertise(...)`` or ``async with ros.advertise(...) as pub``;
        awaiting waits for the bridge's verdict when it sends one.

        Raises:
            UsageError: a bad topic or type (an unknown type says "did you mean").
            StatusError: the bridge refused (raised at ``await``; else see :meth:`on_error`).
            ConnectionClosed: the client is closed.
        """
        self._check_open()
        check_name(topic, "topic")
        type_name, cls = message_type(type)
        pubs = self._publishers.get(topic)
        if pubs and pubs[0].type_name != type_name:
            raise UsageError(
                f"advertise {topic}: already advertised here as {pubs[0].type_name}, "
                f"not {type_name}"
            )
        pub: Publisher[Any] = Publisher(
            self, topic, type_name, cls, latch=latch, queue_size=queue_size,
            id=self._new_id("advertise", topic), offline_buffer=self.offline_buffer,
            check_cls=self._check_cls(type_name, cls),
        )
        if pubs:
            pubs.append(pub)
        else:
            self._publishers[topic] = [pub]
            self._request(pub, pub.request_op())
        return pub

    def _check_cls(self, type_name: str, cls: type[Message] | None) -> type[Message] | None:
        """The class dicts of ``type_name`` are checked against (None: unchecked)."""
        if cls is not None:
            return cls
        return lookup_message_class(type_name) if self.validate else None

    def _publish(
        self, pub: Publisher[Any], wire: Mapping[str, Any]
    ) -> Coroutine[Any, Any, None] | None:
        t = self._transport
        if t.connected:
            t.write(t.encode(ops.Publish(pub.topic, wire)))
            if t.backlog > self.max_pending:
                return t.flush()
            return None
        self._check_open()
        if self.offline_buffer == 0:
            raise Disconnected(
                f"publish to {pub.topic}: the connection to {t.url} is down"
            )
        frame = t.encode(ops.Publish(pub.topic, wire))  # a copy, checked now
        if len(pub._offline) >= self.offline_buffer:
            pub._offline.popleft()
            pub.dropped += 1
        pub._offline.append(frame)
        return None

    def _unadvertise(self, pub: Publisher[Any]) -> None:
        pubs = self._publishers.get(pub.topic)
        if not pubs or pub not in pubs:
            return
        first = pubs[0]
        pubs.remove(pub)
        if pubs:
            if first is pub:  # the request id lives on with the next handle
                self._requests.pop(pub.id, None)
                self._requests[pubs[0].id] = pubs[0]
            return
        del self._publishers[pub.topic]
        self._requests.pop(pub.id, None)
        if self._hub.state is not ConnectionState.CLOSED:
            self._send(ops.Unadvertise(pub.topic, id=first.id))

    # -- subscriptions -------------------------------------------------------------------------

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
    ) -> Subscription[Any]:
        """Subscribe to ``topic``.

        Messages are dicts for a type string, instances for a msgs class.
        Options: ``throttle_rate`` (ms between messages, at the bridge),
        ``queue_length`` (the bridge's queue for us; 0: its default),
        ``compression`` (``"none"`` or ``"cbor"``, which needs cbor2),
        ``fragment_size`` (the bridge splits larger messages into fragments of
        this many characters; they are reassembled here),
        ``buffer_size`` (this side's buffer; the oldest message is dropped
        when full). Iterate the handle, ``await sub.get()``, or pass
        ``callback`` (sync or async). Use as ``async with`` or ``await``
        (which waits for the bridge's verdict when it sends one).

        Raises:
            UsageError: a bad topic, type or option (or cbor2 missing).
            StatusError: the bridge refused (raised at ``await``; else see :meth:`on_error`).
            ConnectionClosed: the client is closed.
        """
        self._check_open()
        check_name(topic, "topic")
        type_name, cls = message_type(type)
        if compression == "cbor":
            _need_cbor()
        sub: Subscription[Any] = Subscription(
            self, topic, type_name, cls, throttle_rate=throttle_rate, queue_length=queue_length,
            compression=compression, fragment_size=fragment_size, buffer_size=buffer_size,
            id=self._new_id("subscribe", topic),
        )
        if callback is not None:
            sub.on_message(callback)
        self._subs[sub.id] = sub
        self._topic_subs[topic] = (*self._topic_subs.get(topic, ()), sub)
        self._request(sub, sub.request_op())
        return sub

    def _drop_sub(self, sub: Subscription[Any]) -> bool:
        if self._subs.pop(sub.id, None) is None:
            return False
        self._requests.pop(sub.id, None)
        left = tuple(s for s in self._topic_subs.get(sub.topic, ()) if s is not sub)
        if left:
            self._topic_subs[sub.topic] = left
        else:
            self._topic_subs.pop(sub.topic, None)
        return True

    def _unsubscribe(self, sub: Subscription[Any]) -> None:
        if self._drop_sub(sub) and self._hub.state is not ConnectionState.CLOSED:
            self._send(ops.Unsubscribe(sub.topic, id=sub.id))

    # -- closing -------------------------------------------------------------------------------

    async def close(self) -> None:
        """Close the connection; the state becomes ``CLOSED``. Closing twice is harmless."""
        self._shutdown(ConnectionClosed(f"the connection to {self._transport.url} was closed"))
        await self._transport.close()
        tasks = [t for s in self._subs.values() if (t := s._consumer) is not None]
        tasks += list(self._handler_tasks)
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


def _need_cbor() -> None:
    try:
        import cbor2  # noqa: F401
    except ImportError:
        raise UsageError(
            "compression='cbor' needs cbor2: install roslibpy-lite[cbor]"
        ) from None

