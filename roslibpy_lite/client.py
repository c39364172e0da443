"""The asyncio websocket client: connect, pump frames, reconnect, restore.

Usage::

    import roslibpy_lite

    async with roslibpy_lite.connect("ws://robot:9090") as ros:
        pub = await ros.advertise("/chatter", "std_msgs/msg/String")
        await pub.publish({"data": "hello"})
        async with ros.subscribe("/imu", "sensor_msgs/msg/Imu") as sub:
            async for msg in sub:
                ...
        reply = await ros.call_service("/mult", "mult_msgs/srv/MultFloats", {"x": 2.0, "y": 3.0})

``connect()`` may also be awaited (``ros = await connect(url)``; then
``await ros.close()``).

How it works
------------
One task reads frames and dispatches them (no task per message): a publish
goes by dict lookup to the subscriptions of its topic; a service response
completes the waiting call's future; a ``status`` error naming one of our
requests fails that request. One writer task drains a send queue, so the
order of our ops is kept; ``publish`` waits only when more than
``max_pending`` frames are waiting (backpressure). All parsing and
serialising goes through :mod:`roslibpy_lite.ops` / :mod:`roslibpy_lite.protocol`
(JSON, CBOR with RFC 8746 typed arrays, fragments).

The client never waits for acknowledgements the stock rosbridge server does
not send: ``advertise``/``subscribe``/``advertise_service`` return once the
op is handed to the connection. When our bridge answers one with a ``status``
error, that handle's ``error`` is set: the next ``publish`` raises it, an
``async for`` over the subscription raises it.

Reconnects
----------
With ``reconnect=True`` (the default), a dropped connection is reopened at
once, then with exponential backoff and jitter while attempts fail
(:class:`~roslibpy_lite._backoff.Backoff`, 0.1 s doubling to 5 s by default),
for as long as the client is open. A connection that drops within
``stable_after`` (1 s) of opening counts as a failed attempt, so a peer that
accepts and drops at once is not hammered. The
state goes ``CONNECTED → RECONNECTING → CONNECTED``. After each reconnect,
in this order: every open publisher is advertised again, every open
subscription is subscribed again with the same options, every served service
is advertised again, and then the messages buffered while offline are sent.

While the connection is down:

- service calls in flight fail at once with
  :class:`~roslibpy_lite.exceptions.Disconnected`; a call started while
  reconnecting waits for the connection within its own timeout;
- ``publish`` keeps the latest ``offline_buffer`` messages PER PUBLISHER
  (default 100; older ones are dropped and counted in ``pub.dropped``) and
  sends them after the publisher is re-advertised. With ``offline_buffer=0``
  it raises :class:`~roslibpy_lite.exceptions.Disconnected` instead.
  Messages already queued to a socket that then died are lost: delivery is
  at most once;
- subscriptions keep their buffered messages and resume when the bridge
  sends again; an ``async for`` simply waits;
- requests from ROS callers to our services that were being handled are
  answered into the void (the bridge has already failed them).

Threads: a client belongs to the event loop that connected it; from other
threads use ``asyncio.run_coroutine_threadsafe``.

After ``close()`` (or a drop with ``reconnect=False``) the state is
``CLOSED``: calls raise :class:`~roslibpy_lite.exceptions.ConnectionClosed`,
``async for`` over subscriptions ends.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
from collections import deque
from collections.abc import Awaitable, Callable, Generator, Mapping
from typing import TYPE_CHECKING, Any, Self, overload

from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import ConnectionClosed as WsConnectionClosed
from websockets.exceptions import InvalidHandshake, InvalidURI

from . import ops
from ._backoff import Backoff
from .api import (
    DEFAULT_CALL_TIMEOUT,
    ConnectionState,
    MessageCallback,
    ServiceHandler,
    StateCallback,
)
from .exceptions import (
    ConnectError,
    ConnectionClosed,
    Disconnected,
    ProtocolError,
    RosTimeoutError,
    ServiceError,
    StatusError,
    UsageError,
)
from .handles import (
    Publisher,
    ServiceServer,
    StateHub,
    StateWatcher,
    Subscription,
    from_wire,
    message_type,
    service_type,
    to_wire,
)
from .protocol import Protocol

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Message, Service

    from .api import M

__all__ = ["Client", "Connector", "connect"]

log = logging.getLogger("roslibpy_lite.client")

_Values = Mapping[str, Any] | str


class _Call:
    __slots__ = ("future", "service")

    def __init__(self, service: str, future: asyncio.Future[_Values]) -> None:
        self.service = service
        self.future = future


class Client:
    """A rosbridge v2 connection with everything built on it (see the module docstring).

    Make one with :func:`connect`. Args (all keyword-only, all optional):

    Args:
        reconnect: reopen a dropped connection (and restore everything).
        backoff: the reconnect delays (default 0.1 s doubling to 5 s, 50% jitter).
        open_timeout: seconds to wait for the first connection (retrying with
            backoff while ``reconnect`` is on) before :func:`connect` raises
            :class:`~roslibpy_lite.exceptions.ConnectError`.
        offline_buffer: messages kept per publisher while disconnected (0: raise).
        max_pending: frames queued for sending before ``publish`` waits.
        max_size: largest incoming frame in bytes (None: no limit).
        ping_interval: seconds between websocket pings that detect a dead
            peer (None: off); the connection is dropped after ``ping_timeout``.
        ws_compression: websocket per-message compression (``"deflate"`` or
            None, the default: off, cheaper on a LAN).
        proxy: passed to websockets (None: connect directly).
    """

    def __init__(
        self,
        url: str,
        *,
        reconnect: bool = True,
        backoff: Backoff | None = None,
        open_timeout: float = 10.0,
        offline_buffer: int = 100,
        max_pending: int = 1024,
        max_size: int | None = 256 * 1024 * 1024,
        ping_interval: float | None = 20.0,
        ping_timeout: float | None = 20.0,
        ws_compression: str | None = None,
        proxy: str | None = None,
    ) -> None:
        if offline_buffer < 0:
            raise UsageError(f"offline_buffer must be >= 0, got {offline_buffer}")
        if max_pending < 1:
            raise UsageError(f"max_pending must be >= 1, got {max_pending}")
        self.url = url
        self.reconnect = reconnect
        self.stable_after = 1.0
        """A connection that lived this long (seconds) resets the backoff when it drops."""
        self.backoff = backoff or Backoff()
        self.open_timeout = open_timeout
        self.offline_buffer = offline_buffer
        self.max_pending = max_pending
        self._ws_options: dict[str, Any] = {
            "max_size": max_size,
            "ping_interval": ping_interval,
            "ping_timeout": ping_timeout,
            "compression": ws_compression,
            "proxy": proxy,
            "open_timeout": open_timeout,
        }
        self._hub = StateHub(ConnectionState.CONNECTING)
        self._protocol = Protocol()
        self._ids = itertools.count(1)
        # Handles, in creation order (dicts keep it) for restoring after a reconnect.
        self._publishers: dict[str, list[Publisher[Any]]] = {}
        self._subs: dict[str, Subscription[Any]] = {}
        self._topic_subs: dict[str, tuple[Subscription[Any], ...]] = {}
        self._servers: dict[str, ServiceServer] = {}
        self._requests: dict[str, Publisher[Any] | Subscription[Any] | ServiceServer] = {}
        self._calls: dict[str, _Call] = {}
        self._handler_tasks: set[asyncio.Task[None]] = set()
        self._status_callbacks: list[Callable[[ops.Status], None]] = []
        # Sending.
        self._ws: ClientConnection | None = None
        self._outbox: deque[str] = deque()
        self._out_wake: asyncio.Future[None] | None = None
        self._queued = 0
        self._sent = 0
        self._flush_waiters: list[tuple[int, asyncio.Future[None]]] = []
        self._runner: asyncio.Task[None] | None = None
        self._first: asyncio.Future[None] | None = None
        self._closing = False
        self.connects = 0
        """How many times a connection was opened (1 + reconnects)."""
        self.status_errors = 0
        """``status`` errors from the bridge that named none of our pending requests."""

    def __repr__(self) -> str:
        return f"<Client {self.url} {self._hub.state.value}>"

    # -- connection ----------------------------------------------------------------------------

    async def _start(self) -> None:
        """Open the first connection (called by :func:`connect`)."""
        if self._runner is not None:
            raise UsageError("the client is already started")
        loop = asyncio.get_running_loop()
        self._first = loop.create_future()
        self._runner = loop.create_task(self._run(), name=f"roslibpy_lite {self.url}")
        try:
            await self._first
        except BaseException:
            await self.close()
            raise

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.open_timeout
        try:
            while not self._closing:
                try:
                    ws = await ws_connect(self.url, **self._ws_options)
                except (OSError, InvalidHandshake, TimeoutError) as exc:
                    if self._first is not None and not self._first.done() and (
                        not self.reconnect or loop.time() >= deadline
                    ):
                        self._first.set_exception(
                            ConnectError(f"cannot connect to {self.url}: {_why(exc)}")
                        )
                        self._hub.set(ConnectionState.CLOSED)
                        return
                    delay = self.backoff.next()
                    if log.isEnabledFor(logging.DEBUG):
                        log.debug("connect to %s failed (%s); retry in %.2f s",
                                  self.url, _why(exc), delay)
                    await asyncio.sleep(delay)
                    continue
                except InvalidURI as exc:
                    if self._first is not None and not self._first.done():
                        self._first.set_exception(UsageError(f"bad URL {self.url!r}: {exc}"))
                    self._hub.set(ConnectionState.CLOSED)
                    return
                except Exception as exc:  # anything else websockets may raise: a failed attempt
                    if self._first is not None and not self._first.done():
                        self._first.set_exception(
                            ConnectError(f"cannot connect to {self.url}: {_why(exc)}")
                        )
                        self._hub.set(ConnectionState.CLOSED)
                        return
                    log.warning("connect to %s failed: %s", self.url, _why(exc))
                    await asyncio.sleep(self.backoff.next())
                    continue
                self.connects += 1
                opened = loop.time()
                await self._session(ws)
                if self._closing:
                    return
                if not self.reconnect:
                    log.warning("connection to %s lost; reconnect is off", self.url)
                    self._shutdown(Disconnected(f"connection to {self.url} lost"))
                    return
                log.warning("connection to %s lost; reconnecting", self.url)
                self._hub.set(ConnectionState.RECONNECTING)
                self._lost()
                if loop.time() - opened >= self.stable_after:
                    self.backoff.reset()  # it was a good connection: try again at once
                else:  # a peer that accepts and drops at once: back off, do not hammer it
                    await asyncio.sleep(self.backoff.next())
        finally:
            if self._first is not None and not self._first.done():
                self._first.set_exception(ConnectionClosed("the client was closed"))

    async def _session(self, ws: ClientConnection) -> None:
        """Serve one open connection until it closes."""
        self._ws = ws
        self._protocol = Protocol()
        self._restore()
        self._hub.set(ConnectionState.CONNECTED)
        if self._first is not None and not self._first.done():
            self._first.set_result(None)
        writer = asyncio.get_running_loop().create_task(self._write(ws))
        try:
            receive = self._receive
            async for frame in ws:
                receive(frame)
        except WsConnectionClosed:
            pass
        finally:
            self._ws = None
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, WsConnectionClosed):
                await writer
            with contextlib.suppress(Exception):
                await ws.close()

    def _lost(self) -> None:
        """The connection is gone: drop unsent frames, fail calls in flight."""
        self._outbox.clear()
        self._sent = self._queued
        self._wake_flushers()
        if self._calls:
            calls, self._calls = self._calls, {}
            for call_id, call in calls.items():
                if not call.future.done():
                    call.future.set_exception(Disconnected(
                        f"connection to {self.url} dropped while calling {call.service} "
                        f"(request {call_id})"
                    ))

    def _restore(self) -> None:
        """Send every open handle's request again (on each new connection)."""
        for pubs in self._publishers.values():
            self._send_advertise(pubs[0])
        for sub in self._subs.values():
            sub.error = None
            self._send_subscribe(sub)
        for server in self._servers.values():
            server.error = None
            self._send(ops.AdvertiseService(server.service, server.type_name, id=server.id))
        for pubs in self._publishers.values():
            for pub in pubs:
                pub.error = None
                while pub._offline:
                    self._send_text(pub._offline.popleft())

    # -- sending -------------------------------------------------------------------------------

    def _send(self, op: ops.Op) -> None:
        if self._ws is None:
            return  # restored from the handles on the next connection
        self._send_text(ops.encode(op))

    def _send_text(self, text: str) -> None:
        self._outbox.append(text)
        self._queued += 1
        wake = self._out_wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    async def _write(self, ws: ClientConnection) -> None:
        outbox = self._outbox
        loop = asyncio.get_running_loop()
        while True:
            while outbox:
                frame = outbox.popleft()
                await ws.send(frame)
                self._sent += 1
                if self._flush_waiters:
                    self._wake_flushers()
            self._out_wake = loop.create_future()
            try:
                await self._out_wake
            finally:
                self._out_wake = None

    def _wake_flushers(self) -> None:
        sent = self._sent
        keep: list[tuple[int, asyncio.Future[None]]] = []
        for target, fut in self._flush_waiters:
            if target <= sent:
                if not fut.done():
                    fut.set_result(None)
            else:
                keep.append((target, fut))
        self._flush_waiters = keep

    async def _flush(self) -> None:
        """Return once every frame queued so far was written (or the connection dropped)."""
        if self._sent >= self._queued or self._ws is None:
            return
        fut = asyncio.get_running_loop().create_future()
        self._flush_waiters.append((self._queued, fut))
        await fut

    def _send_advertise(self, pub: Publisher[Any]) -> None:
        self._send(ops.Advertise(pub.topic, pub.type_name, id=pub.id, latch=pub.latch,
                                 queue_size=pub.queue_size))

    def _send_subscribe(self, sub: Subscription[Any]) -> None:
        self._send(ops.Subscribe(
            sub.topic, sub.type_name, id=sub.id, throttle_rate=sub.throttle_rate,
            queue_length=sub.queue_length, compression=sub.compression,
            fragment_size=sub.fragment_size,
        ))

    # -- the receive path ----------------------------------------------------------------------

    def _receive(self, frame: str | bytes) -> None:
        """Decode one frame and dispatch what it completes (never raises)."""
        try:
            op = self._protocol.receive(frame)
        except ProtocolError as exc:
            log.warning("ignoring a bad frame from %s: %s", self.url, exc.message)
            return
        if op is None:
            return
        if type(op) is ops.Publish:
            subs = self._topic_subs.get(op.topic)
            if subs is not None:
                msg = op.msg
                for sub in subs:
                    sub._deliver(msg)
            return
        try:
            self._dispatch(op)
        except Exception:  # a bug here must not kill the connection
            log.exception("failed to handle a %s op", op.OP)

    def _dispatch(self, op: ops.Op) -> None:
        if isinstance(op, ops.ServiceResponse):
            call = self._calls.pop(str(op.id), None) if op.id is not None else None
            if call is None:
                log.debug("service_response for an unknown call %r", op.id)
                return
            if call.future.done():
                return
            if op.result:
                call.future.set_result(op.values if isinstance(op.values, Mapping) else {})
            else:
                reason = op.values if isinstance(op.values, str) else _reason(op.values)
                call.future.set_exception(ServiceError(call.service, reason))
        elif isinstance(op, ops.CallService):
            self._serve_request(op)
        elif isinstance(op, ops.Status):
            self._status(op)
        else:
            log.debug("ignoring a %s op", op.OP)

    def _status(self, op: ops.Status) -> None:
        for cb in list(self._status_callbacks):
            try:
                cb(op)
            except Exception:
                log.exception("status callback raised")
        if op.level != "error":
            log.info("bridge status %s: %s", op.level, op.msg)
            return
        key = str(op.id) if op.id is not None else None
        if key is not None:
            call = self._calls.pop(key, None)
            if call is not None:
                if not call.future.done():
                    call.future.set_exception(StatusError(op.msg, level=op.level, id=op.id))
                return
            handle = self._requests.get(key)
            if handle is not None:
                log.warning("bridge refused %s: %s", key, op.msg)
                error = StatusError(op.msg, level=op.level, id=op.id)
                if isinstance(handle, Publisher):  # every handle sharing the advertise
                    for pub in self._publishers.get(handle.topic, [handle]):
                        pub._fail(error)
                else:
                    handle._fail(error)
                return
        self.status_errors += 1
        log.warning("bridge error: %s", op.msg)

    def _serve_request(self, op: ops.CallService) -> None:
        server = self._servers.get(op.service)
        if server is None or op.id is None:
            self._send(ops.ServiceResponse(op.service, False, f"{op.service} is not served here",
                                           id=op.id))
            return
        outcome = server.invoke(op.args)
        if isinstance(outcome, tuple):
            self._answer(op, outcome)
            return

        async def finish() -> None:
            self._answer(op, await outcome)

        task = asyncio.get_running_loop().create_task(finish())
        self._handler_tasks.add(task)
        task.add_done_callback(self._handler_tasks.discard)

    def _answer(self, op: ops.CallService, outcome: tuple[bool, _Values]) -> None:
        result, values = outcome
        try:
            text = ops.encode(ops.ServiceResponse(op.service, result, values, id=op.id))
        except ProtocolError as exc:
            text = ops.encode(ops.ServiceResponse(op.service, False, exc.message, id=op.id))
        if self._ws is not None:
            self._send_text(text)

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
        self._status_callbacks.append(callback)

        def remove() -> None:
            with contextlib.suppress(ValueError):
                self._status_callbacks.remove(callback)

        return remove

    def _check_open(self) -> None:
        if self._hub.state is ConnectionState.CLOSED:
            raise ConnectionClosed(f"the connection to {self.url} is closed")

    def _new_id(self, kind: str, name: str) -> str:
        return f"{kind}:{name}:{next(self._ids)}"

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
        Use as ``pub = await ros.advertise(...)`` or ``async with ros.advertise(...) as pub``.

        Raises:
            UsageError: a bad topic or type.
            ConnectionClosed: the client is closed.
        """
        self._check_open()
        _check_name(topic, "topic")
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
        )
        if pubs:
            pubs.append(pub)
        else:
            self._publishers[topic] = [pub]
            self._requests[pub.id] = pub
            self._send_advertise(pub)
        return pub

    def _publish(self, pub: Publisher[Any], wire: Mapping[str, Any]) -> Awaitable[None] | None:
        if self._ws is not None:
            self._send_text(ops.encode(ops.Publish(pub.topic, wire)))
            if self._queued - self._sent > self.max_pending:
                return self._flush()
            return None
        self._check_open()
        if self.offline_buffer == 0:
            raise Disconnected(f"publish to {pub.topic}: the connection to {self.url} is down")
        text = ops.encode(ops.Publish(pub.topic, wire))  # a copy, checked now
        if len(pub._offline) >= self.offline_buffer:
            pub._offline.popleft()
            pub.dropped += 1
        pub._offline.append(text)
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
        ``callback`` (sync or async). Use as ``async with`` or ``await``.

        Raises:
            UsageError: a bad topic, type or option (or cbor2 missing).
            ConnectionClosed: the client is closed.
        """
        self._check_open()
        _check_name(topic, "topic")
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
        self._requests[sub.id] = sub
        self._topic_subs[topic] = (*self._topic_subs.get(topic, ()), sub)
        self._send_subscribe(sub)
        return sub

    def _unsubscribe(self, sub: Subscription[Any]) -> None:
        if self._subs.pop(sub.id, None) is None:
            return
        self._requests.pop(sub.id, None)
        left = tuple(s for s in self._topic_subs.get(sub.topic, ()) if s is not sub)
        if left:
            self._topic_subs[sub.topic] = left
        else:
            self._topic_subs.pop(sub.topic, None)
        if self._hub.state is not ConnectionState.CLOSED:
            self._send(ops.Unsubscribe(sub.topic, id=sub.id))

    # -- services ------------------------------------------------------------------------------

    @overload
    async def call_service(
        self,
        service: str,
        type: str,
        args: Mapping[str, Any] | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> dict[str, Any]: ...

    @overload
    async def call_service(
        self,
        service: str,
        type: type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> Any: ...

    async def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> Any:
        """Call ``service`` and return its response.

        ``args`` is a dict (or a ``Request`` instance for a typed service);
        the response is a dict, or a ``Response`` instance for a typed
        service. ``timeout`` (seconds, None: wait for ever) covers waiting for
        the connection too.

        Raises:
            ServiceError: the service answered ``result: false`` (it failed,
                does not exist, or the bridge could not call it); the text says why.
            StatusError: the bridge refused the request itself.
            RosTimeoutError: no answer within ``timeout``.
            Disconnected: the connection dropped while waiting.
            ConnectionClosed: the client is closed.
            UsageError / InvalidMessageError: bad arguments.
        """
        self._check_open()
        _check_name(service, "service")
        type_name, srv_cls = service_type(type)
        if args is None:
            args = {}
        wire = to_wire(args, f"{type_name}_Request", srv_cls.Request if srv_cls else None,
                       f"call {service}")
        if timeout is not None and not timeout > 0:
            raise UsageError(f"call {service}: timeout must be > 0 or None, got {timeout!r}")
        call_id = self._new_id("call_service", service)
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(timeout):
                if self._ws is None:
                    await self._hub.wait_connected()
                future: asyncio.Future[_Values] = loop.create_future()
                self._calls[call_id] = _Call(service, future)
                # The bridge gets a little longer, so our own timeout decides.
                server_timeout = timeout + 1.0 if timeout is not None else None
                self._send(ops.CallService(service, wire, type_name, id=call_id,
                                           timeout=server_timeout))
                values = await future
        except TimeoutError:
            raise RosTimeoutError(
                f"call {service}: no answer within {timeout} s"
                + ("" if self.is_connected else f" (state {self.state.value})")
            ) from None
        finally:
            self._calls.pop(call_id, None)
        if not isinstance(values, Mapping):  # pragma: no cover - failures are exceptions
            values = {}
        if srv_cls is not None:
            return from_wire(values, srv_cls.Response, f"response of {service}")
        return dict(values)

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
            ConnectionClosed: the client is closed.
        """
        self._check_open()
        _check_name(service, "service")
        type_name, srv_cls = service_type(type)
        if service in self._servers:
            raise UsageError(f"advertise_service {service}: already served by this client")
        server = ServiceServer(self, service, type_name, srv_cls, handler,
                               id=self._new_id("advertise_service", service))
        self._servers[service] = server
        self._requests[server.id] = server
        self._send(ops.AdvertiseService(service, type_name, id=server.id))
        return server

    def _unadvertise_service(self, server: ServiceServer) -> None:
        if self._servers.get(server.service) is not server:
            return
        del self._servers[server.service]
        self._requests.pop(server.id, None)
        if self._hub.state is not ConnectionState.CLOSED:
            self._send(ops.UnadvertiseService(server.service, id=server.id))

    # -- closing -------------------------------------------------------------------------------

    def _shutdown(self, error: ConnectionClosed) -> None:
        """Enter CLOSED: fail calls, end subscriptions (no messages to the server)."""
        self._hub.set(ConnectionState.CLOSED)
        calls, self._calls = self._calls, {}
        for call in calls.values():
            if not call.future.done():
                call.future.set_exception(error)
        self._lost()
        for sub in list(self._subs.values()):
            sub._end()
        for pubs in self._publishers.values():
            for pub in pubs:
                pub._offline.clear()

    async def close(self) -> None:
        """Close the connection; the state becomes ``CLOSED``. Closing twice is harmless."""
        self._closing = True
        self._shutdown(ConnectionClosed(f"the client of {self.url} was closed"))
        ws = self._ws
        if ws is not None:
            with contextlib.suppress(Exception):
                await ws.close()
        runner = self._runner
        if runner is not None and runner is not asyncio.current_task():
            if not runner.done():
                runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await runner
        tasks = [t for s in self._subs.values() if (t := s._consumer) is not None]
        tasks += list(self._handler_tasks)
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


class Connector:
    """What :func:`connect` returns: ``await`` it for a :class:`Client`, or use ``async with``."""

    def __init__(self, client: Client) -> None:
        self._client = client

    async def _open(self) -> Client:
        await self._client._start()
        return self._client

    def __await__(self) -> Generator[Any, None, Client]:
        return self._open().__await__()

    async def __aenter__(self) -> Client:
        return await self._open()

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self._client.close()


def connect(
    url: str,
    *,
    reconnect: bool = True,
    backoff: Backoff | None = None,
    open_timeout: float = 10.0,
    offline_buffer: int = 100,
    max_pending: int = 1024,
    max_size: int | None = 256 * 1024 * 1024,
    ping_interval: float | None = 20.0,
    ping_timeout: float | None = 20.0,
    ws_compression: str | None = None,
    proxy: str | None = None,
) -> Connector:
    """Connect to a rosbridge server at ``url`` (``ws://host:9090``).

    ``async with connect(url) as ros:`` or ``ros = await connect(url)``. See
    :class:`Client` for the options. Returns once the first connection is
    open.

    Raises (when awaited):
        ConnectError: no connection within ``open_timeout`` seconds (with
            ``reconnect`` on, attempts are retried with backoff until then).
        UsageError: a malformed URL or option.
    """
    return Connector(Client(
        url, reconnect=reconnect, backoff=backoff, open_timeout=open_timeout,
        offline_buffer=offline_buffer, max_pending=max_pending, max_size=max_size,
        ping_interval=ping_interval, ping_timeout=ping_timeout, ws_compression=ws_compression,
        proxy=proxy,
    ))


def _check_name(name: str, what: str) -> None:
    if not isinstance(name, str) or not name:
        raise UsageError(f"a {what} name must be a non-empty string, got {name!r}")


def _need_cbor() -> None:
    try:
        import cbor2  # noqa: F401
    except ImportError:
        raise UsageError(
            "compression='cbor' needs cbor2: install roslibpy-lite[cbor]"
        ) from None


def _why(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _reason(values: Any) -> str:
    if values is None:
        return "no reason given"
    return str(values)
