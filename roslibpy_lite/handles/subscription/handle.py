"""The :class:`Subscription` handle, made of its parts (:mod:`.callbacks`, :mod:`.reading`):
its request, the receive path (:meth:`Subscription.deliver`, never blocking) and closing."""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import time
from collections import deque
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, Protocol, TypeVar

from msgs.runtime import Message
from rosbridge_core.protocol import ops

from ...exceptions import RosLibError, UsageError
from ...messages import RawMessage
from .callbacks import _Callbacks, _Failures
from .fields import _SKIP, LinkBackend
from .reading import Collected, _Reading, _Tap

T = TypeVar("T")


class SubscriptionBackend(LinkBackend, Protocol):
    """What a subscription needs (:class:`~roslibpy_lite.capabilities.topics.Topics`)."""

    def forget_subscription(self, sub: Subscription[Any]) -> None:
        """Forget a subscription."""
        ...


class Subscription(_Callbacks[T], _Reading[T]):
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

    _backend: SubscriptionBackend

    def __init__(
        self,
        backend: SubscriptionBackend,
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
                    if result is not None and inspect.isawaitable(result):
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

    def fail(self, error: RosLibError) -> None:
        """The bridge refused the subscription, or it ended: iteration raises ``error``
        (for the topics capability)."""
        self.error = error
        self._wake()
        for tap in self._taps:
            if tap.future is not None and not tap.future.done():
                tap.future.set_exception(error)

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
