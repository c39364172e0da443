"""The blocking handles: publishers, subscriptions, service servers, state changes.

Each wraps an asyncio handle of :mod:`roslibpy_lite.handles` (its
``handle`` attribute) and runs its operations on the client's
:class:`~roslibpy_lite.sync.loop.LoopThread`.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
import warnings
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any, Generic, Protocol, Self, TypeVar

from ..api import ConnectionState
from ..exceptions import ConnectionClosed, RosTimeoutError, UsageError
from ..jupyter import in_cell
from .loop import LoopThread

if TYPE_CHECKING:
    from .. import handles
    from ..state import StateWatcher

__all__ = ["PUBLISH_WINDOW", "Publisher", "ServiceServer", "StateChanges", "Subscription"]

T = TypeVar("T")
H = TypeVar("H")
C = TypeVar("C", bound="_Closable")
log = logging.getLogger("roslibpy_lite.sync")

class _Closable(Protocol):
    @property
    def closed(self) -> bool: ...

    async def close(self) -> None: ...


PUBLISH_WINDOW = 64
"""Messages a blocking publisher has in flight before ``publish`` waits."""


class _Wrapper(Generic[H]):
    """A blocking object over an asyncio one (``handle``), run on the client's loop thread."""

    def __init__(self, loop: LoopThread, handle: H) -> None:
        self._loop = loop
        self.handle = handle
        """The asyncio handle underneath (see :mod:`roslibpy_lite.handles`)."""

    def __repr__(self) -> str:
        return f"<sync {self.handle!r}>"

    def __eq__(self, other: object) -> bool:
        """Two wrappers of one asyncio handle are equal (``sub in ros.subscriptions()``)."""
        return type(other) is type(self) and other.handle is self.handle

    def __hash__(self) -> int:
        return id(self.handle)


class _BlockingHandle(_Wrapper[C]):
    """What the closable blocking handles share: ``with``, ``closed``, ``close``."""

    @property
    def closed(self) -> bool:
        """True once closed (or the client closed)."""
        return bool(self.handle.closed)

    def close(self) -> None:
        """Close the handle."""
        self._loop.run(self.handle.close(), f"close {self.handle!r}")

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        if not self._loop.closing:
            self.close()


class Publisher(_BlockingHandle["handles.Publisher[Any]"], Generic[T]):
    """A blocking publisher (made by :meth:`Client.advertise`); a context manager.

    ``publish`` checks the message on your thread (a bad one raises at once)
    and hands it to the loop thread without waiting for each one: at most
    :data:`PUBLISH_WINDOW` messages are in flight per publisher, then it waits
    (backpressure). Order is kept. A failure found on the loop thread (the
    connection closed meanwhile) is raised by the next ``publish`` or
    :meth:`flush`.
    """

    def __init__(self, loop: LoopThread, handle: handles.Publisher[Any]) -> None:
        super().__init__(loop, handle)
        self._pending: deque[concurrent.futures.Future[None]] = deque()
        self._lock = threading.Lock()

    @property
    def topic(self) -> str:
        """The topic name."""
        return self.handle.topic

    def publish(self, msg: T | Mapping[str, Any]) -> None:
        """Publish ``msg``.

        From a callback on the loop thread it is queued too; a failure is
        then logged. Raises what :meth:`roslibpy_lite.handles.Publisher.publish`
        raises (UsageError, InvalidMessageError, StatusError, ConnectionClosed).
        """
        handle = self.handle
        if handle.closed:
            raise UsageError(f"publisher of {self.topic} is closed")
        if handle.error is not None:
            raise handle.error
        wire = handle.to_wire(msg)
        if self._loop.in_loop():
            task = self._loop.loop.create_task(handle.publish(wire))
            task.add_done_callback(_log_failure)
            return
        future = self._loop.submit(handle.publish(wire), f"publish {self.topic}")
        with self._lock:
            self._pending.append(future)
            finished = []
            while self._pending and self._pending[0].done():
                finished.append(self._pending.popleft())
            oldest = self._pending.popleft() if len(self._pending) > PUBLISH_WINDOW else None
        for done in finished:
            self._loop.wait(done, f"publish {self.topic}")
        if oldest is not None:
            self._loop.wait(oldest, f"publish {self.topic}")

    def flush(self) -> None:
        """Return once every message published so far is handed to the connection."""
        while True:
            with self._lock:
                if not self._pending:
                    return
                future = self._pending.popleft()
            self._loop.wait(future, f"publish {self.topic}")

    def unadvertise(self) -> None:
        """Stop publishing (after the messages published so far)."""
        self.close()

    def close(self) -> None:
        """Same as :meth:`unadvertise`."""
        try:
            self.flush()
        finally:
            super().close()


def _log_failure(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("publish from a callback failed: %s", task.exception())


class Subscription(_BlockingHandle["handles.Subscription[Any]"], Generic[T]):
    """A blocking subscription (made by :meth:`Client.subscribe`).

    ``for msg in sub`` iterates until it is closed; :meth:`get` and
    :meth:`messages` take a timeout. A context manager (unsubscribes on exit).
    """

    @property
    def topic(self) -> str:
        """The topic name."""
        return self.handle.topic

    @property
    def received(self) -> int:
        """Messages received so far."""
        return self.handle.received

    @property
    def dropped(self) -> int:
        """Messages dropped because the buffer was full."""
        return self.handle.dropped

    def get(self, timeout: float | None = None) -> T:
        """The OLDEST buffered message, or the next to arrive when none waits (at most
        ``timeout`` seconds; None: for ever). It can be seconds old: see
        :meth:`roslibpy_lite.handles.Subscription.get`; :meth:`latest` and :meth:`next`
        give fresh ones.

        Raises:
            RosTimeoutError: none arrived in time (naming the state when the link is down).
            UsageError: the subscription is closed.
        """
        msg: T = self._loop.run(self.handle.get(timeout), f"get from {self.topic}")
        return msg

    def latest(self, *, allow_stale: bool = False) -> handles.Latest[T]:
        """The newest message received and its age: ``msg, age = sub.latest()``
        (see :meth:`roslibpy_lite.handles.Subscription.latest`; raises NotConnected while
        the link is down unless ``allow_stale``, NoMessageYet before the first message)."""
        found: handles.Latest[T] = self._loop.call(
            f"latest on {self.topic}", self.handle.latest, allow_stale=allow_stale)
        return found

    def next(self, timeout: float | None = None, *, wait_connected: bool = False) -> T:
        """The first message to arrive after the call (see
        :meth:`roslibpy_lite.handles.Subscription.next`: NotConnected at once while the link
        is down unless ``wait_connected``; RosTimeoutError after ``timeout`` seconds)."""
        msg: T = self._loop.run(self.handle.next(timeout, wait_connected=wait_connected),
                                f"next on {self.topic}")
        return msg

    def __init__(self, loop: LoopThread, handle: handles.Subscription[Any]) -> None:
        super().__init__(loop, handle)
        handle.blocking = True  # its errors name this client's calls

    def collect(self, seconds: float) -> handles.Collected[T]:
        """Every message that arrives during the next ``seconds`` seconds, with when each
        arrived (see :meth:`roslibpy_lite.handles.Subscription.collect`). Interrupted
        (Ctrl+C, a notebook's stop button), it keeps what it had in :attr:`collected`."""
        try:
            found: handles.Collected[T] = self._loop.run(self.handle.collect(seconds),
                                                          f"collect from {self.topic}")
        except KeyboardInterrupt as exc:
            exc.add_note(f"collect from {self.topic} was interrupted: the "
                         f"{len(self.handle.collected)} messages it had are in sub.collected")
            raise
        held, self.handle.held_warnings = self.handle.held_warnings, []
        for warning in held:
            warnings.warn(warning, stacklevel=2)
        return found

    @property
    def collected(self) -> handles.Collected[T]:
        """What the last :meth:`collect` collected, also when it was interrupted."""
        return self.handle.collected

    def messages(self, timeout: float | None = None) -> Iterator[T]:
        """Iterate the messages until the subscription closes.

        Raises:
            RosTimeoutError: no message within ``timeout`` seconds of the previous one.
        """
        while True:
            try:
                yield self._loop.run(self._next(timeout), f"iterate {self.topic}")
            except StopAsyncIteration:
                return

    async def _next(self, timeout: float | None) -> T:
        try:
            async with asyncio.timeout(timeout):
                msg: T = await self.handle.__anext__()
                return msg
        except TimeoutError:
            raise RosTimeoutError(f"no message on {self.topic} within {timeout} s") from None

    def __iter__(self) -> Iterator[T]:
        return self.messages()

    def on_message(self, callback: Callable[[T], Any]) -> None:
        """Also deliver every message to ``callback`` (it runs on the loop thread)."""
        self._loop.call(f"on_message {self.topic}", self.handle.on_message, in_cell(callback))

    @property
    def paused(self) -> list[Callable[[Any], Any]]:
        """Callbacks paused after failing many times in a row (see
        :class:`roslibpy_lite.handles.Subscription`)."""
        return list(self.handle.paused)

    def resume_callbacks(self) -> int:
        """Run the paused callbacks again; returns how many."""
        count: int = self._loop.call(f"resume_callbacks {self.topic}",
                                     self.handle.resume_callbacks)
        return count

    def unsubscribe(self) -> None:
        """Stop the subscription."""
        self.close()


class ServiceServer(_BlockingHandle["handles.ServiceServer"]):
    """A blocking service server (made by :meth:`Client.advertise_service`)."""

    @property
    def service(self) -> str:
        """The service name."""
        return self.handle.service

    def unadvertise(self) -> None:
        """Stop serving."""
        self.close()


class StateChanges:
    """The connection state changes from its creation on (made by :meth:`Client.state_changes`)."""

    def __init__(self, loop: LoopThread, watcher: StateWatcher) -> None:
        self._loop = loop
        self._watcher = watcher

    def next(self, timeout: float | None = None) -> ConnectionState:
        """The next state (raises RosTimeoutError, or ConnectionClosed after ``CLOSED``)."""
        return self._loop.run(self._watcher.next(timeout), "state_changes")

    def __iter__(self) -> Iterator[ConnectionState]:
        while True:
            try:
                yield self.next()
            except ConnectionClosed:
                return

    def close(self) -> None:
        """Stop watching."""
        if not self._loop.closing:
            self._loop.call("state_changes", self._watcher.close)
