"""The handles a backend returns: publishers, subscriptions, service servers.

The capabilities of :mod:`roslibpy_lite.capabilities` make them and supply the
hooks of :class:`Backend` (:class:`TopicBackend`, :class:`ServiceBackend`). Every handle

- is awaitable (``pub = await ros.advertise(...)``: returns once the
  request has been handed to the connection and, when the bridge confirms
  requests, accepted; a refusal raises there) and an async context manager
  (``async with ros.subscribe(...) as sub:``; closes on exit);
- closes with ``await handle.close()`` (or its specific name:
  ``unadvertise``, ``unsubscribe``); closing twice is harmless, using a closed
  handle raises :class:`~roslibpy_lite.exceptions.UsageError`.

Subscriptions deliver to callbacks or to their own bounded buffer:

- sync callbacks run in the receive path, in order, with no task per message;
- async callbacks run one at a time, in order, in one task per subscription,
  fed from the buffer;
- with no callback, messages wait in the buffer for ``async for`` /
  :meth:`Subscription.get`.

The buffer keeps at most ``buffer_size`` messages: when full, the OLDEST is
dropped and :attr:`Subscription.dropped` counts it. Who keeps and drops what between the
robot and this buffer (the bridge's ``queue_length``, the link, this buffer) is drawn in
one place: the "Buffers" section of the Publish and subscribe guide
(``docs/guides/pubsub.md``).

Fresh values do not go through the buffer: :meth:`Subscription.latest` is the newest
message received and its age, :meth:`Subscription.next` the first one after the call,
:meth:`Subscription.collect` every one during some seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import time
import traceback
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine, Generator, Mapping
from typing import TYPE_CHECKING, Any, Generic, NamedTuple, Protocol, Self, TypeVar, cast

from msgs.runtime import Message, Service, ValidationError
from rosbridge_core.protocol import ops

from ._aio import is_async_callable, running_loop
from ._api_types import MessageCallback, ServiceHandler
from .exceptions import (
    InvalidMessageError,
    NoMessageYet,
    RosLibError,
    RosLibWarning,
    RosTimeoutError,
    UsageError,
)
from .jupyter import in_cell, write_in_cell
from .messages import Completeness, RawMessage, check_dict, from_wire, to_wire, warn_user

if TYPE_CHECKING:
    from types import TracebackType

__all__ = [
    "Backend",
    "Collected",
    "Latest",
    "Publisher",
    "ServiceBackend",
    "ServiceCall",
    "ServiceServer",
    "Subscription",
    "TopicBackend",
]

log = logging.getLogger("roslibpy_lite.client")

T = TypeVar("T")
_SKIP: Any = object()

_HINTS = {"next": "await sub.next(timeout) waits for one",
          "wait_connected": "await ros.wait_connected() first"}

REPORT_WINDOW = 10.0
"""Seconds over which a failing callback's further failures are counted into one line."""
PAUSE_AFTER = 1000
"""Failures in a row after which a subscription pauses a callback
(:meth:`Subscription.resume_callbacks` runs it again)."""


# --- the backend hooks -----------------------------------------------------------------------

class Backend(Protocol):
    """What every handle needs from the capability that made it."""

    async def settle(self, handle: Any) -> None:
        """Return once the handle's request was sent and (if the bridge says so) accepted."""
        ...


class TopicBackend(Backend, Protocol):
    """What publishers and subscriptions need
    (:class:`~roslibpy_lite.capabilities.topics.Topics`)."""

    def publish_message(
        self, pub: Publisher[Any], wire: Mapping[str, Any]
    ) -> Coroutine[Any, Any, None] | None:
        """Send (or buffer) one message; may return a coroutine to await for backpressure."""
        ...

    def forget_publisher(self, pub: Publisher[Any]) -> None:
        """Forget a publisher."""
        ...

    def forget_subscription(self, sub: Subscription[Any]) -> None:
        """Forget a subscription."""
        ...

    def require_link(self, what: str, hint: str = "pass wait_connected=True to wait for it"
                     ) -> None:
        """Raise :class:`~roslibpy_lite.exceptions.NotConnected` (naming the state) unless
        the link is up, :class:`~roslibpy_lite.exceptions.ConnectionClosed` once closed."""
        ...

    def link_note(self) -> str:
        """``""`` while connected, else `` (state reconnecting)`` for an error text."""
        ...

    async def silence_note(self, topic: str) -> str:
        """``"; nothing publishes /Imu in the graph; did you mean '/imu'?"`` or ``""``."""
        ...


class ServiceBackend(Backend, Protocol):
    """What a served service needs (:class:`~roslibpy_lite.capabilities.services.Services`)."""

    def forget_service(self, server: ServiceServer) -> None:
        """Forget a served service."""
        ...


class _BridgeHandle:
    """What every handle shares: close state, await and ``async with``."""

    _backend: Backend
    closed: bool
    error: RosLibError | None

    async def close(self) -> None:  # pragma: no cover - overridden
        """Close the handle."""
        raise NotImplementedError

    def fail(self, error: RosLibError) -> None:
        """The bridge reported that this handle's request failed."""
        self.error = error

    async def _ready(self) -> Self:
        await self._backend.settle(self)
        return self

    def __await__(self) -> Generator[Any, None, Self]:
        return self._ready().__await__()

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()


class Publisher(_BridgeHandle, Generic[T]):
    """A publisher on one topic (made by ``ros.advertise``)."""

    _backend: TopicBackend

    def __init__(
        self,
        backend: TopicBackend,
        topic: str,
        type_name: str,
        msg_cls: type[Message] | None,
        *,
        latch: bool,
        queue_size: int,
        id: str,
        offline_buffer: int,
        check_cls: type[Message] | None = None,
        strict: bool | None = None,
        completeness: Completeness | None = None,
    ) -> None:
        self._backend = backend
        self.topic = topic
        self.type_name = type_name
        self.msg_cls = msg_cls
        self.latch = latch
        self.queue_size = queue_size
        self.id = id
        self.closed = False
        self.error: RosLibError | None = None
        """Why this publisher cannot publish at all: the bridge refused its ``advertise``
        (every later :meth:`publish` raises it)."""
        self.last_error: RosLibError | None = None
        """The last message the bridge could not publish, set as soon as the bridge says so
        (the next :meth:`publish` raises it once; it stays here for inspection)."""
        self.offline_queue: deque[Any] = deque()  # backend-specific form (encoded frame, copy)
        self.offline_buffer = offline_buffer
        self.dropped = 0
        """Messages dropped because the offline buffer was full (oldest first)."""
        self.published = 0
        """Messages accepted by :meth:`publish`."""
        self._check_cls = check_cls if msg_cls is None else msg_cls
        self._error_once: RosLibError | None = None
        self.strict = strict
        """Refuse dicts that leave fields out (None: the client's ``strict``)."""
        self._completeness = completeness if completeness is not None else Completeness()

    def __repr__(self) -> str:
        return f"<Publisher {self.topic} {self.type_name}{' closed' if self.closed else ''}>"

    @property
    def offline_pending(self) -> int:
        """Messages published while the connection was down, waiting to be sent."""
        return len(self.offline_queue)

    def request_op(self) -> ops.Advertise:
        """The ``advertise`` op this publisher stands for."""
        return ops.Advertise(self.topic, self.type_name, id=self.id, latch=self.latch,
                             queue_size=self.queue_size)

    def to_wire(self, msg: T | Mapping[str, Any]) -> Mapping[str, Any]:
        """The wire form of ``msg`` after the type checks (see :func:`to_wire`).

        A dict is checked against the type's ``msgs`` class when there is one, and
        one that leaves fields out is warned about once or refused (``strict``).
        """
        what = f"publish to {self.topic}"
        wire = to_wire(msg, self.type_name, self.msg_cls, what)
        if wire is msg:
            check_dict(wire, self._check_cls, what)
            self._completeness.check(wire, self._check_cls, what, self.strict)
        return wire

    def fail_next_publish(self, error: RosLibError) -> None:
        """The bridge could not publish a message: the next :meth:`publish` raises ``error``."""
        self._error_once = self.last_error = error

    def publish(self, msg: T | Mapping[str, Any]) -> Coroutine[Any, Any, None]:
        """Publish one message (a dict, or an instance of the advertised type).

        Called on the client's event loop, the message is checked and sent
        (or buffered while offline) at the call, so a forgotten ``await``
        loses no message (a plain coroutine would send nothing, silently but
        for Python's warning); awaiting the result waits only when the send
        queue is full (backpressure), and a result that needed waiting but
        was never awaited logs "did you forget await?". Called from another
        thread (no running loop), the work happens when the result is run on
        the client's loop (``asyncio.run_coroutine_threadsafe``).
        See the client module for what happens while the connection is down.

        Raises (at the call):
            UsageError: the publisher is closed, or the message has another type.
            InvalidMessageError: a field the type lacks or a value that does not fit.
            StatusError: the bridge refused this publisher's ``advertise``, or
                could not publish an earlier message (raised once).
            ConnectionClosed: the client is closed (``Disconnected`` while the
                connection is down and buffering is off).
        """
        if running_loop() is None:  # another thread: run it later, on the client's loop
            return _Deferred(self._publish_later(msg), f"publish to {self.topic}")
        if self.error is not None:
            raise self.error
        if self._error_once is not None:
            error, self._error_once = self._error_once, None
            raise error
        if self.closed:
            raise UsageError(f"publisher of {self.topic} is closed")
        wire = self.to_wire(msg)
        waiting = self._backend.publish_message(self, wire)
        self.published += 1
        if waiting is None:
            return _DONE
        return _Deferred(waiting, f"publish to {self.topic} (waiting for queue space)")

    async def _publish_later(self, msg: T | Mapping[str, Any]) -> None:
        await self.publish(msg)

    async def unadvertise(self) -> None:
        """Stop publishing (the bridge drops its ROS publisher once no handle uses it)."""
        if self.closed:
            return
        self.closed = True
        self.offline_queue.clear()
        self._backend.forget_publisher(self)

    async def close(self) -> None:
        """Same as :meth:`unadvertise`."""
        await self.unadvertise()


class Latest(NamedTuple, Generic[T]):
    """The newest message of a subscription and how old it is (:meth:`Subscription.latest`).

    Unpacks as ``msg, age = sub.latest()``.
    """

    msg: T
    """The message, as the subscription gives it (dict, typed instance or RawMessage)."""
    age: float
    """Seconds since this client received it (when :meth:`Subscription.latest` was called)."""

    @property
    def stamp_age(self) -> float | None:
        """Seconds from the message's ``header.stamp`` to now, by this machine's clock (so
        it includes any offset between the robot's clock and this one, and a simulated
        clock's stamps give nonsense); None for a message without a header stamp."""
        stamp = _header_stamp(self.msg)
        return None if stamp is None else time.time() - stamp


def _header_stamp(msg: Any) -> float | None:
    """``header.stamp`` in seconds since the epoch, of a dict or typed message (None: none)."""
    if isinstance(msg, Mapping):
        stamp = (msg.get("header") or {}).get("stamp")
        sec, nanosec = (stamp.get("sec"), stamp.get("nanosec")) if isinstance(
            stamp, Mapping) else (None, None)
    else:
        stamp = getattr(getattr(msg, "header", None), "stamp", None)
        sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
    if not isinstance(sec, int) or not isinstance(nanosec, int):
        return None
    return sec + nanosec / 1e9


class Collected(list[T]):
    """The messages :meth:`Subscription.collect` received, oldest first: a list, with
    :attr:`times` beside it (``roslibpy_lite.data.to_dataframe`` indexes by them when the
    messages have no header stamp)."""

    def __init__(self, messages: list[T], times: list[float]) -> None:
        super().__init__(messages)
        self.times = times
        """When each message was received (seconds since the epoch)."""


class _Tap:
    """A reader of fresh messages (``next`` or ``collect``): sees each message delivered
    from its start on, apart from the buffer."""

    __slots__ = ("future", "messages", "times", "wait_connected")

    def __init__(self, future: asyncio.Future[None] | None, wait_connected: bool) -> None:
        self.future = future
        self.wait_connected = wait_connected
        self.messages: list[Any] = []
        self.times: list[float] = []


class _Failures:
    """One callback's failures on one subscription: the first of a burst is reported in
    full, the others counted into one line per :data:`REPORT_WINDOW` seconds."""

    __slots__ = ("callback", "in_row", "last", "more", "since", "timer")

    def __init__(self, callback: Callable[[Any], Any]) -> None:
        self.callback = callback
        self.in_row = 0  # failures since its last success
        self.more = 0  # failures of this burst not reported yet
        self.since = 0.0  # when this window of the burst began (0: no burst)
        self.last = ""  # the last failure, "Type: text"
        self.timer: asyncio.TimerHandle | None = None


def _callback_name(callback: Any) -> str:
    name = getattr(callback, "__qualname__", None)
    return name if isinstance(name, str) else repr(callback)


class Subscription(_BridgeHandle, Generic[T]):
    """A subscription to one topic (made by ``ros.subscribe``).

    Iterate it (``async for msg in sub``), await :meth:`get` (the OLDEST buffered message:
    it can be seconds old), or register callbacks (:meth:`on_message`); for fresh values
    read :meth:`latest` (the newest and its age), await :meth:`next` (the first after the
    call) or :meth:`collect` (every message during some seconds). What the buffers keep and
    drop: the "Buffers" section of the Publish and subscribe guide. Counters: :attr:`received`,
    :attr:`dropped` (buffer overflow), :attr:`decode_errors` (typed messages
    that did not fit their class; skipped), :attr:`callback_errors`.

    A callback that raises is reported once per burst: the first traceback (in Jupyter under
    the cell that subscribed, elsewhere on the ``roslibpy_lite.client`` log), then one line
    per :data:`REPORT_WINDOW` seconds with the count of further failures; after
    :data:`PAUSE_AFTER` failures in a row it is paused (:attr:`paused`;
    :meth:`resume_callbacks` runs it again).
    """

    _backend: TopicBackend

    def __init__(
        self,
        backend: TopicBackend,
        topic: str,
        type_name: str,
        msg_cls: type[Message] | None,
        *,
        throttle_rate: int,
        queue_length: int,
        compression: str,
        fragment_size: int | None = None,
        buffer_size: int,
        id: str,
        raw: bool = False,
    ) -> None:
        if buffer_size < 1:
            raise UsageError(f"subscribe {topic}: buffer_size must be >= 1, got {buffer_size}")
        if throttle_rate < 0 or queue_length < 0:
            raise UsageError(f"subscribe {topic}: throttle_rate and queue_length must be >= 0")
        if fragment_size is not None and fragment_size < 1:
            raise UsageError(f"subscribe {topic}: fragment_size must be >= 1, got {fragment_size}")
        if compression not in ops.ENCODINGS:
            *most, last = map(repr, ops.ENCODINGS)
            raise UsageError(f"subscribe {topic}: compression must be {', '.join(most)} or "
                             f"{last}, got {compression!r}")
        self._backend = backend
        self.topic = topic
        self.type_name = type_name
        self.msg_cls = msg_cls
        self.throttle_rate = throttle_rate
        self.queue_length = queue_length
        self.compression = compression
        self.raw = raw  # messages are RawMessage (CDR bytes, the bridge's stamp)
        self.uint8_as_sent = False
        """False (the default): ``uint8[]``/``char[]`` fields of dict messages are
        ``bytes`` whatever the compression, where msgs knows the type. True: as the
        bridge sent them (base64 text under JSON), as roslibpy gives them (the
        roslibpy drop-in sets it)."""
        self.fragment_size = fragment_size
        self.buffer_size = buffer_size
        self.id = id
        self.closed = False
        self.error: RosLibError | None = None
        self.received = 0
        self.dropped = 0
        self.decode_errors = 0
        self.callback_errors = 0
        self._queue: deque[Mapping[str, Any] | RawMessage] = deque()
        self._sync_cbs: list[Callable[[Any], Any]] = []
        self._async_cbs: list[Callable[[Any], Awaitable[Any]]] = []
        self._buffering = True
        self._waiter: asyncio.Future[None] | None = None
        self.consumer: asyncio.Task[None] | None = None
        self._idle = asyncio.Event()
        self._idle.set()
        self._latest: Mapping[str, Any] | RawMessage | None = None
        self._latest_at = 0.0  # time.monotonic() of receipt
        self._since = time.monotonic()
        self._taps: list[_Tap] = []
        self._failing: dict[int, _Failures] = {}  # by id() of the callback
        self.paused: list[Callable[[Any], Any]] = []
        """Callbacks paused after :data:`PAUSE_AFTER` failures in a row."""
        self.blocking = False
        """Made for the blocking client: its error texts give that client's calls."""
        self.held_warnings: list[Warning] = []
        """Warnings of a blocking client's call, for it to give on the caller's thread."""
        self.collected: Collected[T] = Collected([], [])
        """What the last :meth:`collect` collected, also when it was interrupted."""

    def __repr__(self) -> str:
        return f"<Subscription {self.topic} {self.type_name}{' closed' if self.closed else ''}>"

    def request_op(self) -> ops.Subscribe:
        """The ``subscribe`` op this subscription stands for."""
        return ops.Subscribe(
            self.topic, self.type_name, id=self.id, throttle_rate=self.throttle_rate,
            queue_length=self.queue_length, compression=self.compression,
            fragment_size=self.fragment_size,
        )

    # -- callbacks -------------------------------------------------------------------------

    def on_message(self, callback: MessageCallback) -> None:
        """Also deliver every message to ``callback`` (sync or async).

        Once a callback is registered, messages no longer wait for ``async
        for``; sync callbacks run at once in the receive path, async ones in
        order in this subscription's own task.
        """
        if self.closed:
            raise UsageError(f"subscription to {self.topic} is closed")
        if not callable(callback):
            raise UsageError(f"subscribe {self.topic}: callback must be callable")
        callback = in_cell(callback)  # its output under the cell that subscribed, in Jupyter
        if is_async_callable(callback):
            if self._waiter is not None:
                raise UsageError(
                    f"subscription to {self.topic} is being iterated; "
                    "iterate it or give it async callbacks, not both"
                )
            self._async_cbs.append(cast("Callable[[Any], Awaitable[Any]]", callback))
            if self.consumer is None:
                self.consumer = asyncio.get_running_loop().create_task(
                    self._consume(), name=f"roslibpy_lite subscription {self.topic}"
                )
        else:
            self._sync_cbs.append(callback)
        self._buffering = bool(self._async_cbs)

    def remove_callback(self, callback: Any, same: Callable[[Any, Any], bool]) -> Any:
        """Stop calling the registered callback that ``same(it, callback)`` finds; returns
        it (None: there is none). For the topics capability's duplicate rule."""
        for cbs in (self._sync_cbs, self._async_cbs):
            for cb in cbs:
                if same(cb, callback):
                    cbs.remove(cb)
                    self._buffering = bool(self._async_cbs)
                    return cb
        return None

    def has_callbacks(self) -> bool:
        """Whether any callback is registered."""
        return bool(self._sync_cbs or self._async_cbs)

    # -- the receive path ------------------------------------------------------------------

    def deliver(self, raw: Mapping[str, Any] | RawMessage) -> None:
        """Take one message in its wire form, or a RawMessage for a raw subscription
        (called by the backend, never blocks)."""
        self.received += 1
        self._latest = raw
        self._latest_at = time.monotonic()
        if self._taps:
            self._feed_taps(raw)
        if self._sync_cbs:
            msg = self._decode(raw)
            if msg is not _SKIP:
                for cb in self._sync_cbs:
                    try:
                        result = cb(msg)
                    except Exception as exc:
                        self._callback_failed(cb, exc)
                        continue
                    if inspect.isawaitable(result):
                        # A sync-looking callable returned an awaitable: run it anyway.
                        self._run_stray(cb, result)
                    elif self._failing:
                        self._callback_ok(cb)
            if not self._buffering:
                return
        queue = self._queue
        if len(queue) >= self.buffer_size:
            queue.popleft()
            self.dropped += 1
        queue.append(raw)
        self._idle.clear()
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _feed_taps(self, raw: Mapping[str, Any] | RawMessage) -> None:
        now = time.time()
        for tap in self._taps:
            tap.messages.append(raw)
            tap.times.append(now)
            if tap.future is not None and not tap.future.done():
                tap.future.set_result(None)

    def link_lost(self, error: RosLibError) -> None:
        """The link dropped (a reconnect follows): readers of fresh messages that do not wait
        for the connection fail with ``error`` (for the topics capability)."""
        for tap in self._taps:
            if not tap.wait_connected and tap.future is not None and not tap.future.done():
                tap.future.set_exception(error)

    def _run_stray(self, cb: Callable[[Any], Any], awaitable: Awaitable[Any]) -> None:
        async def run() -> None:
            try:
                await awaitable
            except Exception as exc:
                self._callback_failed(cb, exc)
            else:
                if self._failing:
                    self._callback_ok(cb)

        task = asyncio.get_running_loop().create_task(run())
        _STRAY.add(task)
        task.add_done_callback(_STRAY.discard)

    # -- callbacks that raise ------------------------------------------------------------------

    def _callback_failed(self, cb: Callable[[Any], Any], exc: Exception) -> None:
        """``cb`` raised ``exc``: count it, report the first of a burst in full and the rest
        as one line per window, pause it after PAUSE_AFTER in a row."""
        self.callback_errors += 1
        failures = self._failing.get(id(cb))
        if failures is None:
            failures = self._failing[id(cb)] = _Failures(cb)
        failures.in_row += 1
        failures.last = f"{type(exc).__name__}: {exc}"
        now = time.monotonic()
        if failures.since == 0.0 or (failures.more == 0 and now - failures.since >= REPORT_WINDOW):
            failures.since = now  # a new burst: this one in full
            self._report(cb, f"callback {_callback_name(cb)} for {self.topic} raised (further "
                             f"failures within {REPORT_WINDOW:g} s are counted, not shown):",
                         exc)
            loop = running_loop()
            if loop is not None and failures.timer is None:
                failures.timer = loop.call_later(REPORT_WINDOW, self._window_ended, failures)
        else:
            failures.more += 1
            if now - failures.since >= REPORT_WINDOW:  # no timer (no loop): count here
                self._summarise(failures)
        if failures.in_row >= PAUSE_AFTER:
            self._pause(failures)

    def _callback_ok(self, cb: Callable[[Any], Any]) -> None:
        failures = self._failing.get(id(cb))
        if failures is not None:
            failures.in_row = 0

    def _window_ended(self, failures: _Failures) -> None:
        failures.timer = None
        if failures.more:
            self._summarise(failures)
            loop = running_loop()
            if loop is not None and not self.closed:
                failures.timer = loop.call_later(REPORT_WINDOW, self._window_ended, failures)
        elif self._failing.get(id(failures.callback)) is failures:
            del self._failing[id(failures.callback)]  # the burst is over

    def _summarise(self, failures: _Failures) -> None:
        """Report the failures counted since the last report, as one line."""
        now = time.monotonic()
        if failures.more:
            n = failures.more
            self._report(failures.callback, (
                f"callback {_callback_name(failures.callback)} for {self.topic} raised {n} more "
                f"time{'s' * (n != 1)} in the last {now - failures.since:.1f} s "
                f"(the last: {failures.last})"))
        failures.more = 0
        failures.since = now

    def _pause(self, failures: _Failures) -> None:
        cb = failures.callback
        self._summarise(failures)
        if failures.timer is not None:
            failures.timer.cancel()
        del self._failing[id(cb)]
        self._sync_cbs = [c for c in self._sync_cbs if c is not cb]  # a new list: the
        self._async_cbs = [c for c in self._async_cbs if c is not cb]  # loop goes on
        self._buffering = bool(self._async_cbs)
        self.paused.append(cb)
        self._report(cb, f"callback {_callback_name(cb)} for {self.topic} raised "
                         f"{failures.in_row} times in a row: paused (sub.resume_callbacks() "
                         "runs it again)")

    def resume_callbacks(self) -> int:
        """Run the callbacks paused after failing :data:`PAUSE_AFTER` times in a row again;
        returns how many."""
        paused, self.paused = self.paused, []
        for cb in paused:
            self.on_message(cb)
        return len(paused)

    def _report(self, cb: Callable[[Any], Any], text: str, exc: Exception | None = None) -> None:
        """Under the cell that subscribed ``cb`` in Jupyter, else on the log."""
        if exc is not None:
            shown = text + "\n" + "".join(traceback.format_exception(exc))
            if not write_in_cell(cb, shown):
                log.error("%s", text, exc_info=exc)
        elif not write_in_cell(cb, text):
            log.warning("%s", text)

    def _end_failures(self) -> None:
        """Closing: say what was counted and not yet reported."""
        for failures in list(self._failing.values()):
            if failures.timer is not None:
                failures.timer.cancel()
            self._summarise(failures)
        self._failing.clear()

    def _decode(self, raw: Mapping[str, Any] | RawMessage) -> Any:
        cls = self.msg_cls
        if cls is None or isinstance(raw, RawMessage):
            return raw
        try:
            return cls.from_json(raw)
        except ValidationError as exc:
            self.decode_errors += 1
            # The field path and expected type only: no payload in the log.
            log.warning("a message on %s does not fit %s: field %s: expected %s",
                        self.topic, cls._type, exc.path or "<message>", exc.expected)
            return _SKIP

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def fail(self, error: RosLibError) -> None:
        """The bridge refused the subscription, or it ended: iteration raises ``error``
        (for the topics capability)."""
        self.error = error
        self._wake()
        for tap in self._taps:
            if tap.future is not None and not tap.future.done():
                tap.future.set_exception(error)

    async def _wait(self) -> None:
        if self._waiter is not None:
            raise UsageError(f"subscription to {self.topic} is already awaited by another task")
        self._waiter = asyncio.get_running_loop().create_future()
        try:
            await self._waiter
        finally:
            self._waiter = None

    async def _consume(self) -> None:
        queue = self._queue
        while True:
            while queue:
                msg = self._decode(queue.popleft())
                if msg is _SKIP:
                    continue
                for cb in self._async_cbs:
                    try:
                        await cb(msg)
                    except Exception as exc:
                        self._callback_failed(cb, exc)
                    else:
                        if self._failing:
                            self._callback_ok(cb)
            self._idle.set()
            if self.closed:
                return
            await self._wait()

    async def _drained(self) -> None:
        """Return once async callbacks have taken every buffered message (for MockRos.drain)."""
        if self.consumer is not None and not self.consumer.done():
            await self._idle.wait()

    # -- reading ---------------------------------------------------------------------------

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> T:
        queue = self._queue
        while True:
            if queue:
                msg = self._decode(queue.popleft())
                if msg is _SKIP:
                    continue
                result: T = msg
                return result
            if self.error is not None:
                raise self.error
            if self.closed:
                raise StopAsyncIteration
            if self._async_cbs:
                raise UsageError(
                    f"subscription to {self.topic} delivers to async callbacks; "
                    "iterate it or give it callbacks, not both"
                )
            await self._wait()

    async def get(self, timeout: float | None = None) -> T:
        """The OLDEST message waiting in this subscription's buffer, or, when it is empty,
        the next one to arrive: what ``async for`` gives next.

        Nothing is skipped, so a message read a while after subscribing may be seconds old
        (up to ``buffer_size`` messages wait; see the "Buffers" section of the Publish and
        subscribe guide). For the newest message use :meth:`latest`, for one that arrives
        after the call :meth:`next`.

        Raises:
            RosTimeoutError: none arrived within ``timeout`` seconds (the text names the
                connection state when the link is down).
            UsageError: the subscription is closed.
            StatusError: the bridge refused this subscription.
        """
        try:
            async with asyncio.timeout(timeout):
                return await self.__anext__()
        except StopAsyncIteration:
            raise UsageError(f"subscription to {self.topic} is closed") from None
        except TimeoutError:
            raise await self._silence(timeout) from None

    def latest(self, *, allow_stale: bool = False) -> Latest[T]:
        """The newest message received (whatever the buffer holds) and its age in seconds
        since this client received it (``.stamp_age``: since its header stamp).

        Reads without waiting and takes nothing from the buffer. ``allow_stale=True`` also
        answers while the link is down (the age then says how stale it is).

        Raises:
            NotConnected: the link is down (the text names the state); the message would
                be from before the outage.
            NoMessageYet: nothing has arrived yet (``await sub.next(timeout)`` waits).
            UsageError: the subscription is closed.
            StatusError: the bridge refused this subscription.
        """
        self._check_readable()
        if not allow_stale:
            self._backend.require_link(f"latest message on {self.topic}",
                                       "latest(allow_stale=True) reads it anyway")
        raw = self._latest
        if raw is None:
            raise NoMessageYet(
                f"no message on {self.topic} yet (subscribed "
                f"{time.monotonic() - self._since:.1f} s ago); {self._hint('next')}"
            )
        msg = self._decode(raw)
        if msg is _SKIP:
            raise NoMessageYet(f"the latest message on {self.topic} did not fit "
                               f"{self.type_name} (see the log)")
        return Latest(msg, time.monotonic() - self._latest_at)

    async def next(self, timeout: float | None = None, *, wait_connected: bool = False) -> T:
        """The first message to arrive after this call (the buffer is left as it is).

        ``wait_connected=True``: while the link is down, wait for it (within ``timeout``)
        instead of raising.

        Raises:
            NotConnected: the link is down, or drops while waiting (unless ``wait_connected``).
            RosTimeoutError: none arrived within ``timeout`` seconds.
            UsageError: the subscription is closed.
            StatusError: the bridge refused this subscription.
        """
        self._check_readable()
        if not wait_connected:
            self._backend.require_link(f"next message on {self.topic}")
        tap = _Tap(asyncio.get_running_loop().create_future(), wait_connected)
        self._taps.append(tap)
        try:
            async with asyncio.timeout(timeout):
                while True:
                    assert tap.future is not None
                    await tap.future
                    while tap.messages:
                        msg = self._decode(tap.messages.pop(0))
                        if msg is not _SKIP:
                            result: T = msg
                            return result
                    tap.future = asyncio.get_running_loop().create_future()
        except TimeoutError:
            self._taps.remove(tap)
            raise await self._silence(timeout) from None
        finally:
            if tap in self._taps:
                self._taps.remove(tap)

    async def collect(self, seconds: float) -> Collected[T]:
        """Every message that arrives during the next ``seconds`` seconds, oldest first,
        with when each arrived (:class:`Collected`; the buffer is left as it is).

        Interrupted (cancelled, Ctrl+C, a notebook's stop button), it keeps what it had
        collected in :attr:`collected`.

        Raises:
            NotConnected: the link is down when it starts.
            UsageError: ``seconds`` is negative, or the subscription is closed.
        """
        if not seconds >= 0:
            raise UsageError(f"collect from {self.topic}: seconds must be >= 0, got {seconds!r}")
        self._check_readable()
        self._backend.require_link(f"collect from {self.topic}", self._hint("wait_connected"))
        tap = _Tap(None, True)
        self._taps.append(tap)
        try:
            await asyncio.sleep(seconds)  # a window of time is what was asked for
        except asyncio.CancelledError as exc:  # a notebook's stop button, a task's cancel
            exc.add_note(f"collect from {self.topic} was interrupted: the "
                         f"{len(tap.messages)} messages it had are in sub.collected")
            raise
        finally:
            self._taps.remove(tap)
            messages: list[T] = []
            times: list[float] = []
            for raw, when in zip(tap.messages, tap.times, strict=True):
                msg = self._decode(raw)
                if msg is not _SKIP:
                    messages.append(msg)
                    times.append(when)
            self.collected = Collected(messages, times)
        if not self.collected and (note := await self._backend.silence_note(self.topic)):
            warning = RosLibWarning(f"collect from {self.topic}: no message in {seconds} s{note}")
            if self.blocking:
                self.held_warnings.append(warning)  # given on the caller's thread
            else:
                warn_user(warning)
        return self.collected

    async def _silence(self, timeout: float | None) -> RosTimeoutError:
        """The error of a wait that ended empty, naming a misspelt topic."""
        note = self._backend.link_note() or await self._backend.silence_note(self.topic)
        return RosTimeoutError(f"no message on {self.topic} within {timeout} s{note}")

    def _hint(self, kind: str) -> str:
        """The call that helps (``next``, ``wait_connected``), spelt for this handle's client."""
        text = _HINTS[kind]
        return text.removeprefix("await ") if self.blocking else text

    def _check_readable(self) -> None:
        if self.error is not None:
            raise self.error
        if self.closed:
            raise UsageError(f"subscription to {self.topic} is closed")

    @property
    def pending(self) -> int:
        """How many messages wait in the buffer."""
        return len(self._queue)

    # -- closing ---------------------------------------------------------------------------

    async def unsubscribe(self) -> None:
        """Stop the subscription; an ``async for`` over it ends after the buffered messages."""
        if self.closed:
            return
        self.mark_closed()
        self._backend.forget_subscription(self)
        consumer = self.consumer
        if consumer is not None and consumer is not asyncio.current_task():
            consumer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await consumer

    def mark_closed(self) -> None:
        """Mark closed and wake readers (the backend closes too; no message to the server)."""
        self.closed = True
        if self._failing:
            self._end_failures()
        self._wake()
        for tap in self._taps:
            if tap.future is not None and not tap.future.done():
                tap.future.set_exception(UsageError(f"subscription to {self.topic} is closed"))

    async def close(self) -> None:
        """Same as :meth:`unsubscribe`."""
        await self.unsubscribe()


_STRAY: set[asyncio.Task[None]] = set()
_Outcome = tuple[bool, Mapping[str, Any] | str]


class ServiceServer(_BridgeHandle):
    """A service served by this client (made by ``ros.advertise_service``)."""

    _backend: ServiceBackend

    def __init__(
        self,
        backend: ServiceBackend,
        service: str,
        type_name: str,
        srv_cls: type[Service] | None,
        handler: ServiceHandler,
        *,
        id: str,
    ) -> None:
        if not callable(handler):
            raise UsageError(f"advertise_service {service}: handler must be callable")
        self._backend = backend
        self.service = service
        self.type_name = type_name
        self.srv_cls = srv_cls
        self.handler = handler
        self.id = id
        self.closed = False
        self.error: RosLibError | None = None
        self.calls = 0
        """Requests handled."""
        self.failures = 0
        """Requests whose handler raised (answered ``result: false``)."""

    def __repr__(self) -> str:
        return f"<ServiceServer {self.service} {self.type_name}{' closed' if self.closed else ''}>"

    def request_op(self) -> ops.AdvertiseService:
        """The ``advertise_service`` op this server stands for."""
        return ops.AdvertiseService(self.service, self.type_name, id=self.id)

    def invoke(self, args: Any) -> _Outcome | Coroutine[Any, Any, _Outcome]:
        """Run the handler on a request's wire form.

        Returns ``(result, values)`` at once for a sync handler, or a
        coroutine that produces it for an async one. A handler that raises,
        a request that does not fit the type, or a response that does not fit,
        gives ``(False, "<text>")``; ``(True, values)`` otherwise.
        """
        self.calls += 1
        try:
            request = self._request(args)
            result = self.handler(request)
        except Exception as exc:
            return self._failed(exc)
        if inspect.isawaitable(result):
            return self._finish(result)
        return self._response(result)

    async def _finish(self, awaitable: Awaitable[Any]) -> tuple[bool, Mapping[str, Any] | str]:
        try:
            result = await awaitable
        except Exception as exc:
            return self._failed(exc)
        return self._response(result)

    def _request(self, args: Any) -> Any:
        if args is None:
            args = {}
        if not isinstance(args, Mapping):
            raise InvalidMessageError(f"request to {self.service} is not an object")
        if self.srv_cls is None:
            return args
        return from_wire(args, self.srv_cls.Request, f"request to {self.service}")

    def _response(self, result: Any) -> tuple[bool, Mapping[str, Any] | str]:
        try:
            if result is None:
                result = self.srv_cls.Response() if self.srv_cls is not None else {}
            cls = self.srv_cls.Response if self.srv_cls is not None else None
            type_name = cls._type if cls is not None else f"{self.type_name}_Response"
            what = f"response of {self.service}"
            wire = to_wire(result, type_name, cls, what)
            if cls is not None and not isinstance(result, Message):
                from_wire(wire, cls, what)  # a dict answer to a typed service must fit too
            return True, wire
        except Exception as exc:
            return self._failed(exc)

    def _failed(self, exc: Exception) -> tuple[bool, str]:
        self.failures += 1
        # The class and text say what went wrong; the request itself is not logged.
        log.warning("handler of %s raised %s: %s", self.service, type(exc).__name__, exc)
        return False, str(exc) or type(exc).__name__

    async def unadvertise(self) -> None:
        """Stop serving."""
        if self.closed:
            return
        self.closed = True
        self._backend.forget_service(self)

    async def close(self) -> None:
        """Same as :meth:`unadvertise`."""
        await self.unadvertise()


# --- awaitables that refuse to be used un-awaited ----------------------------------------------

class _Done(Coroutine[Any, None, None]):
    """The result of a publish that needs no waiting: a finished coroutine (stateless)."""

    __slots__ = ()

    def __await__(self) -> Generator[Any, None, None]:
        return
        yield  # pragma: no cover - makes this a generator

    def send(self, value: Any) -> Any:
        """Finish at once."""
        raise StopIteration

    def throw(self, *args: Any) -> Any:
        """Raise the given exception."""
        exc = args[1] if len(args) > 1 and args[1] is not None else args[0]
        raise exc

    def close(self) -> None:
        """Nothing to close."""


_DONE = _Done()


class _Deferred(Coroutine[Any, Any, T]):
    """A coroutine wrapper that says "did you forget await?" if it is dropped unstarted.

    It is a real :class:`collections.abc.Coroutine`, so ``asyncio.create_task``
    and ``gather`` take it like the coroutine it wraps.
    """

    __slots__ = ("_coro", "_started", "_what")

    def __init__(self, coro: Coroutine[Any, Any, T], what: str) -> None:
        self._coro = coro
        self._what = what
        self._started = False

    def __await__(self) -> Generator[Any, None, T]:
        self._started = True
        return self._coro.__await__()

    def send(self, value: Any) -> Any:
        """Advance the wrapped coroutine (what a Task does)."""
        self._started = True
        return self._coro.send(value)

    def throw(self, *args: Any) -> Any:
        """Raise inside the wrapped coroutine."""
        self._started = True
        return self._coro.throw(*args)

    def close(self) -> None:
        """Close the wrapped coroutine."""
        self._started = True
        self._coro.close()

    def __del__(self) -> None:
        if not self._started:
            self._coro.close()
            log.error("%s was never awaited: did you forget await?", self._what)


class _NotAwaited(UsageError, AttributeError):
    """An awaitable used as its result (an AttributeError too, so ``getattr(x, n, d)`` works)."""


class ServiceCall(_Deferred[T]):
    """What ``ros.call_service(...)`` returns: ``await`` it for the response.

    Used without ``await`` (indexed, its attributes read, iterated, or
    dropped) it raises (or logs) :class:`~roslibpy_lite.exceptions.UsageError`
    saying "did you forget await?".
    """

    __slots__ = ()

    def __init__(self, coro: Coroutine[Any, Any, T], service: str) -> None:
        super().__init__(coro, f"call_service({service!r})")

    def _unawaited(self) -> UsageError:
        return _NotAwaited(
            f"{self._what} returns an awaitable, not the response: did you forget await? "
            f"(reply = await ros.call_service(...))"
        )

    def __getattr__(self, name: str) -> Any:
        raise self._unawaited()

    def __getitem__(self, key: Any) -> Any:
        raise self._unawaited()

    def __iter__(self) -> Any:
        raise self._unawaited()

    def __bool__(self) -> bool:
        raise self._unawaited()
