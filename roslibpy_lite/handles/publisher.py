"""A publisher on one topic (:class:`Publisher`, made by ``ros.advertise``)."""

from __future__ import annotations

from collections import deque
from collections.abc import Coroutine, Mapping
from typing import Any, Generic, Protocol, TypeVar

from msgs.runtime import Message
from rosbridge_core.protocol import ops

from .._aio import running_loop
from ..exceptions import RosLibError, UsageError
from ..messages import Completeness, check_dict, to_wire
from .awaitables import _DONE, _Deferred
from .base import Backend, _BridgeHandle

T = TypeVar("T")


class PublisherBackend(Backend, Protocol):
    """What a publisher needs (:class:`~roslibpy_lite.capabilities.topics.Topics`)."""

    def publish_message(
        self, pub: Publisher[Any], wire: Mapping[str, Any]
    ) -> Coroutine[Any, Any, None] | None:
        """Send (or buffer) one message; may return a coroutine to await for backpressure."""
        ...

    def forget_publisher(self, pub: Publisher[Any]) -> None:
        """Forget a publisher."""
        ...


class Publisher(_BridgeHandle, Generic[T]):
    """A publisher on one topic (made by ``ros.advertise``)."""

    _backend: PublisherBackend

    def __init__(
        self,
        backend: PublisherBackend,
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
