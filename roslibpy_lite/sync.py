"""The blocking client: roslibpy_lite without ``async``/``await``.

For plain scripts, notebooks and threaded programs. It runs the asyncio
client on an event loop of its own, in a background thread, in the spirit of
``websockets.sync`` and ``httpx.Client``::

    from roslibpy_lite import sync

    with sync.connect("ws://robot:9090") as ros:
        pub = ros.advertise("/chatter", "std_msgs/msg/String")
        pub.publish({"data": "hello"})
        with ros.subscribe("/imu", "sensor_msgs/msg/Imu") as sub:
            msg = sub.get(timeout=2.0)
        reply = ros.call_service("/mult", "mult_msgs/srv/MultFloats", {"x": 2.0, "y": 3.0})

:func:`connect` takes the same options as :func:`roslibpy_lite.connect`; the
methods, exceptions and reconnect behaviour are those of the asyncio client
(see :mod:`roslibpy_lite.client`). :class:`MockRos` is the same in memory.

Threads
-------
- Every client owns one **loop thread** (named ``roslibpy_lite.sync ...``)
  that runs its event loop. ``close()`` (or leaving the ``with`` block)
  stops it and its socket; nothing is left behind.
- Any number of your threads may call one client at once: each call is
  handed to the loop thread and waits for its result there.
- **Subscription callbacks** and **state callbacks** run ON THE LOOP
  THREAD, in order, never on your thread. Keep them short. They may
  ``publish`` (it is then queued without waiting), but any other blocking
  call from a callback raises :class:`~roslibpy_lite.exceptions.UsageError`
  (it would wait for the very thread it blocks).
- **Service handlers** given to :meth:`Client.advertise_service` run on a
  small worker pool of the client (``roslibpy_lite.sync ... handler``), one
  thread per request being handled, so a handler may block and may call the
  client itself (call another service, publish).
- **Ctrl+C** during a blocking call raises ``KeyboardInterrupt`` on your
  thread and cancels the pending operation on the loop thread; the client
  stays usable.

Jupyter notebooks already run an event loop on their main thread; this
client never touches it, so it works there unchanged.

Actions: the blocking front of actions goes into :class:`_Front` next to
:meth:`_Front.call_service` once the asyncio client has them.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import inspect
import logging
import threading
from collections import deque
from collections.abc import Callable, Coroutine, Iterator, Mapping
from typing import TYPE_CHECKING, Any, Generic, Self, TypeVar, overload

from . import MockRos as _AioMockRos
from . import connect as _aio_connect
from .api import DEFAULT_CALL_TIMEOUT, ConnectionState, StateCallback
from .exceptions import ConnectionClosed, RosTimeoutError, UsageError

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Message, Service

    from . import handles
    from .api import M, Ros

__all__ = [
    "Client",
    "LoopThread",
    "MockRos",
    "Publisher",
    "ServiceServer",
    "StateChanges",
    "Subscription",
    "connect",
]

T = TypeVar("T")
H = TypeVar("H", bound="handles.Publisher[Any] | handles.Subscription[Any] | handles.ServiceServer")
log = logging.getLogger("roslibpy_lite.sync")

HANDLER_THREADS = 8
"""Service requests a blocking client handles at once (one worker thread each)."""

PUBLISH_WINDOW = 64
"""Messages a blocking publisher has in flight before ``publish`` waits."""


async def _tracked(coro: Coroutine[Any, Any, T], done: threading.Event) -> T:
    try:
        return await coro
    finally:
        done.set()


async def _call_async(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    result = fn(*args, **kwargs)
    if inspect.isawaitable(result):
        result = await result
    return result


class LoopThread:
    """An asyncio event loop on a daemon thread of its own, plus a worker pool.

    :meth:`run` hands a coroutine to the loop and blocks the calling thread
    until it finishes; if the wait is interrupted (Ctrl+C), the coroutine is
    cancelled on the loop before the interruption propagates.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.loop = asyncio.new_event_loop()
        self.handlers = concurrent.futures.ThreadPoolExecutor(
            max_workers=HANDLER_THREADS, thread_name_prefix=f"{name} handler"
        )
        self.closed = False
        self._stopping = False
        self._thread = threading.Thread(target=self._main, name=name, daemon=True)
        self._thread.start()

    def _main(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_forever()

    def in_loop(self) -> bool:
        """True when called from the loop thread itself (from a callback)."""
        return threading.get_ident() == self._thread.ident

    def run(self, coro: Coroutine[Any, Any, T], what: str) -> T:
        """Run ``coro`` on the loop and return its result (``what`` names it in errors).

        Raises:
            UsageError: called from the loop thread (it would wait for ever).
            ConnectionClosed: the loop was stopped.
            KeyboardInterrupt: the wait was interrupted; ``coro`` was cancelled.
        """
        if self.in_loop():
            coro.close()
            raise UsageError(
                f"{what}: a blocking call from a callback (on the client's loop thread) "
                "would wait for ever; publish from callbacks, or hand the work to another thread"
            )
        if self.closed:
            coro.close()
            raise ConnectionClosed(f"{what}: the client is closed")
        done = threading.Event()
        future = asyncio.run_coroutine_threadsafe(_tracked(coro, done), self.loop)
        return self.wait(future, what, done)

    def wait(
        self, future: concurrent.futures.Future[T], what: str,
        done: threading.Event | None = None,
    ) -> T:
        """The result of ``future`` (running on the loop); cancels it if the wait is interrupted.

        ``done`` is set once the cancelled work has really ended there.
        """
        try:
            return future.result()
        except concurrent.futures.CancelledError:
            if self._stopping:  # cancelled by close(), not by this caller
                raise ConnectionClosed(f"{what}: the client was closed") from None
            raise
        except BaseException:
            if not future.done():  # interrupted while waiting (Ctrl+C): cancel it there
                future.cancel()
                if done is not None:
                    done.wait(5.0)
            raise

    def call(self, what: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        """Run ``fn(*args, **kwargs)`` on the loop (awaiting its result if it is awaitable).

        ``what`` names the operation in errors.
        """
        return self.run(_call_async(fn, args, kwargs), what)

    def off_loop(self, fn: Callable[[Any], T]) -> Callable[[Any], Coroutine[Any, Any, T]]:
        """An ``async`` function that runs the plain ``fn(arg)`` on the worker pool."""
        pool, loop = self.handlers, self.loop

        async def run(arg: Any) -> T:
            return await loop.run_in_executor(pool, fn, arg)

        return run

    def stop(self) -> None:
        """Cancel what is left on the loop, stop the worker pool and the thread. Idempotent."""
        if self.closed:
            return
        if self.in_loop():
            raise UsageError("close: cannot close the client from one of its own callbacks")
        self._stopping = True
        self.run(self._finish(), "close")
        self.closed = True
        # From a handler's own thread, joining the pool would wait for itself.
        self.handlers.shutdown(wait=not threading.current_thread().name.startswith(
            f"{self.name} handler"))
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join()
        self.loop.close()

    async def _finish(self) -> None:
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await self.loop.shutdown_asyncgens()
        await self.loop.shutdown_default_executor()  # getaddrinfo's threads


class _Handle(Generic[H]):
    """What the blocking handles share: the asyncio handle underneath, ``with``, ``closed``."""

    def __init__(self, loop: LoopThread, handle: H) -> None:
        self._loop = loop
        self.handle = handle
        """The asyncio handle underneath (see :mod:`roslibpy_lite.handles`)."""

    def __repr__(self) -> str:
        return f"<sync {self.handle!r}>"

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
        if not self._loop.closed:
            self.close()


class Publisher(_Handle["handles.Publisher[Any]"], Generic[T]):
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
        if self._loop.closed:
            raise ConnectionClosed(f"publish {self.topic}: the client is closed")
        future = asyncio.run_coroutine_threadsafe(handle.publish(wire), self._loop.loop)
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


class Subscription(_Handle["handles.Subscription[Any]"], Generic[T]):
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
        """The next message (waits at most ``timeout`` seconds; None: for ever).

        Raises:
            RosTimeoutError: none arrived in time.
            UsageError: the subscription is closed.
        """
        msg: T = self._loop.run(self.handle.get(timeout), f"get from {self.topic}")
        return msg

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
        self._loop.call(f"on_message {self.topic}", self.handle.on_message, callback)

    def unsubscribe(self) -> None:
        """Stop the subscription."""
        self.close()


class ServiceServer(_Handle["handles.ServiceServer"]):
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

    def __init__(self, loop: LoopThread, watcher: handles.StateWatcher) -> None:
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
        if not self._loop.closed:
            self._loop.call("state_changes", self._watcher.close)


class _Front:
    """The blocking API over an asyncio :class:`~roslibpy_lite.api.Ros` on a :class:`LoopThread`."""

    def __init__(self, loop: LoopThread, ros: Ros) -> None:
        self._loop = loop
        self.aio = ros
        """The asyncio client underneath (use it from the loop thread only)."""

    def __repr__(self) -> str:
        return f"<sync {self.aio!r}>"

    # -- state -------------------------------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        """The current connection state."""
        return self.aio.state

    @property
    def is_connected(self) -> bool:
        """True while the state is ``CONNECTED``."""
        return self.aio.is_connected

    def wait_connected(self, timeout: float | None = None) -> None:
        """Return once connected (RosTimeoutError after ``timeout``; ConnectionClosed if closed)."""
        self._loop.run(self.aio.wait_connected(timeout), "wait_connected")

    def on_state_change(self, callback: StateCallback) -> Callable[[], None]:
        """Call ``callback(state)`` on each change, ON THE LOOP THREAD; returns its remover."""
        remove: Callable[[], None] = self._loop.call(
            "on_state_change", self.aio.on_state_change, callback)

        def remover() -> None:
            self._loop.loop.call_soon_threadsafe(remove)

        return remover

    def state_changes(self) -> StateChanges:
        """The state changes from now on: ``next(timeout)`` or iterate (ends after ``CLOSED``)."""
        watcher = self._loop.call("state_changes", self.aio.state_changes)
        return StateChanges(self._loop, watcher)

    # -- topics ------------------------------------------------------------------------------

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
        """Announce a publisher on ``topic`` (see :meth:`roslibpy_lite.api.Ros.advertise`)."""
        handle = self._loop.call(f"advertise {topic}", self.aio.advertise, topic, type,
                                 latch=latch, queue_size=queue_size)
        return Publisher(self._loop, handle)

    @overload
    def subscribe(
        self, topic: str, type: str, callback: Callable[[Any], Any] | None = None, **options: Any
    ) -> Subscription[dict[str, Any]]: ...

    @overload
    def subscribe(
        self, topic: str, type: type[M], callback: Callable[[Any], Any] | None = None,
        **options: Any,
    ) -> Subscription[M]: ...

    def subscribe(
        self, topic: str, type: str | type[Message], callback: Callable[[Any], Any] | None = None,
        **options: Any,
    ) -> Subscription[Any]:
        """Subscribe to ``topic``; iterate the handle, ``get(timeout)``, or pass ``callback``.

        ``callback(msg)`` runs ON THE LOOP THREAD. ``options`` are those of
        :meth:`roslibpy_lite.api.Ros.subscribe` (``throttle_rate``,
        ``queue_length``, ``compression``, ``fragment_size``, ``buffer_size``).
        """
        handle = self._loop.call(f"subscribe {topic}", self._subscribe, topic, type,
                                 callback, options)
        return Subscription(self._loop, handle)

    async def _subscribe(
        self, topic: str, type: Any, callback: Any, options: dict[str, Any]
    ) -> handles.Subscription[Any]:
        return await self.aio.subscribe(topic, type, callback, **options)

    # -- services ----------------------------------------------------------------------------

    def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> Any:
        """Call ``service``; returns its response (see :meth:`roslibpy_lite.api.Ros.call_service`).

        Raises ServiceError, RosTimeoutError, Disconnected, ConnectionClosed,
        UsageError as the asyncio client does.
        """
        call = self.aio.call_service(service, type, args, timeout=timeout)  # type: ignore[arg-type]
        return self._loop.run(call, f"call {service}")

    def advertise_service(
        self, service: str, type: str | type[Service], handler: Callable[[Any], Any]
    ) -> ServiceServer:
        """Serve ``service`` with ``handler(request) -> response``.

        A plain function runs on the client's worker pool (it may block and
        call the client); an ``async def`` runs on the loop thread. Raising
        answers the caller ``result: false`` with the error's text.
        """
        if not callable(handler):
            raise UsageError(f"advertise_service {service}: handler must be callable")
        serve = handler if _is_async(handler) else self._loop.off_loop(handler)
        handle = self._loop.call(f"advertise_service {service}", self.aio.advertise_service,
                                 service, type, serve)
        return ServiceServer(self._loop, handle)

    # Actions: add send_goal / action servers here once the asyncio client has them.

    # -- closing -----------------------------------------------------------------------------

    def close(self) -> None:
        """Close the connection and stop the loop thread. Closing twice is harmless."""
        if self._loop.closed:
            return
        try:
            self._loop.run(self.aio.close(), "close")
        finally:
            self._loop.stop()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _is_async(fn: Callable[..., Any]) -> bool:
    call = getattr(fn, "__call__", None)  # noqa: B004 - an object with an async __call__
    return inspect.iscoroutinefunction(fn) or inspect.iscoroutinefunction(call)


class Client(_Front):
    """A blocking rosbridge client (made by :func:`connect`); see the module docstring."""


def connect(url: str, **options: Any) -> Client:
    """Connect to the rosbridge server at ``url`` and return a blocking :class:`Client`.

    Takes every keyword option of :func:`roslibpy_lite.connect` (``reconnect``,
    ``backoff``, ``open_timeout``, ``offline_buffer``, ``max_pending``,
    ``token``, ``ssl``, ...), passed through unchanged. Returns once the
    first connection is open; use as ``with sync.connect(url) as ros:`` or
    call ``ros.close()``.

    Raises:
        ConnectError: no connection within ``open_timeout`` seconds (also its
            subclasses NotAuthenticated and TLSError, as :func:`roslibpy_lite.connect`).
        UsageError: a malformed URL or option.
    """
    loop = LoopThread(f"roslibpy_lite.sync {url}")
    try:
        ros = loop.run(_open(url, options), f"connect {url}")
    except BaseException:
        loop.stop()
        raise
    return Client(loop, ros)


async def _open(url: str, options: dict[str, Any]) -> Ros:
    ros: Ros = await _aio_connect(url, **options)
    return ros


class MockRos(_Front):
    """The blocking client in memory: :class:`roslibpy_lite.MockRos` on a loop thread.

    The same API as :class:`Client`, plus the test conveniences of the
    asyncio mock: :meth:`inject`, :meth:`published`, :meth:`subscribers`,
    :meth:`served`, :meth:`drain`, :meth:`disconnect`, :meth:`reconnect`.
    Close it (or use ``with``) to stop its thread.
    """

    def __init__(self, *, offline_buffer: int = 100, validate: bool = True) -> None:
        loop = LoopThread("roslibpy_lite.sync mock")
        mock: _AioMockRos = loop.call(
            "MockRos", _AioMockRos, offline_buffer=offline_buffer, validate=validate)
        super().__init__(loop, mock)
        self._mock = mock

    def inject(self, topic: str, msg: Mapping[str, Any] | Message,
               type: str | type[Message] | None = None, *, latch: bool = False) -> None:
        """Deliver ``msg`` to the subscribers of ``topic`` as if the robot published it."""
        self._loop.call(f"inject {topic}", self._mock.inject, topic, msg, type, latch=latch)

    def published(self, topic: str) -> list[dict[str, Any]]:
        """Every message published on ``topic`` through this mock, oldest first."""
        return self._loop.call("published", self._mock.published, topic)  # type: ignore[no-any-return]

    def subscribers(self, topic: str) -> int:
        """How many open subscriptions ``topic`` has."""
        count: int = self._loop.call("subscribers", self._mock.subscribers, topic)
        return count

    def served(self) -> list[str]:
        """The names of the services served through this mock."""
        names: list[str] = self._loop.call("served", self._mock.served)
        return names

    def drain(self) -> None:
        """Return once every async callback has taken every message delivered so far."""
        self._loop.run(self._mock.drain(), "drain")

    def disconnect(self) -> None:
        """Play a dropped connection (state ``RECONNECTING``)."""
        self._loop.call("disconnect", self._mock.disconnect)

    def reconnect(self) -> None:
        """Play a reconnect (state ``CONNECTED``; buffered publishes are delivered)."""
        self._loop.call("reconnect", self._mock.reconnect)
