"""``Ros``: roslibpy's connection manager over roslibpy_lite's loop thread.

Like roslibpy, constructing a :class:`Ros` starts connecting in the
background; :meth:`Ros.run` waits for the connection, :meth:`Ros.run_forever`
blocks until :meth:`Ros.terminate`. Once connected, roslibpy_lite's client
reconnects by itself and restores topics and services; ``"close"`` and
``"ready"`` are emitted on every drop and every (re)connection.

Threads: the connection lives on one loop thread. Every user callback
(topic callbacks, events, ``on_ready(..., run_in_thread=False)``, call
callbacks and errbacks, ``call_later``) runs in order on ONE callback
thread (``roslibpy_lite.compat callbacks``), as roslibpy runs them on its
reactor thread; unlike roslibpy, a callback may also make blocking calls.
Service handlers run on the loop thread's worker pool.
"""

from __future__ import annotations

import asyncio
import base64
import concurrent.futures
import contextlib
import inspect
import logging
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import roslibpy_lite

from .._backoff import Backoff
from ..api import ConnectionState
from ..capabilities.introspection import rosapi_type
from ..exceptions import (
    ConnectError,
    ConnectionClosed,
    NotAuthenticated,
    ServiceError,
    TLSError,
)
from ..sync import LoopThread
from .core import (
    Param,
    RosTimeoutError,
    ServiceException,
    ServiceResponse,
    Time,
)

if TYPE_CHECKING:
    from ..api import Ros as AioRos

__all__ = ["Ros", "set_rosapi_timeout"]

log = logging.getLogger("roslibpy_lite.compat")

CONNECTION_TIMEOUT = 10
ROSAPI_TIMEOUT = 3.0

Callback = Callable[..., Any]


def set_rosapi_timeout(timeout: float) -> None:
    """Set the seconds a blocking introspection call (``get_topics`` ...) waits."""
    global ROSAPI_TIMEOUT
    ROSAPI_TIMEOUT = timeout


def _options(headers: dict[str, str] | None) -> dict[str, Any]:
    """The client options for roslibpy's ``headers``: only ``Authorization: Bearer`` is known."""
    options: dict[str, Any] = {}
    for name, value in (headers or {}).items():
        if name.lower() == "authorization" and value.startswith("Bearer "):
            options["token"] = value.removeprefix("Bearer ")
        else:  # the value may be a secret: never in the text
            raise NotImplementedError(
                f"roslibpy_lite.compat.Ros sends no websocket header {name!r}; "
                "only 'Authorization: Bearer <token>' is supported"
            )
    return options


def _url(host: str, port: int | None, is_secure: bool) -> str:
    if port is None:
        return host
    scheme = "wss" if is_secure else "ws"
    return f"{scheme}://{host}:{port}"


class Ros:
    """Connection manager to a rosbridge server, as ``roslibpy.Ros``.

    Args:
        host: the bridge's host name or address, or a whole ``ws://`` URL
            (then leave ``port`` out).
        port: the bridge's port, e.g. 9090.
        is_secure: use ``wss://``.
        headers: ``{"Authorization": "Bearer <token>"}`` sends the token to a
            bridge that requires one; other headers raise NotImplementedError.
        transport: accepted and ignored (roslibpy_lite has one transport).
    """

    def __init__(
        self,
        host: str,
        port: int | None = None,
        is_secure: bool = False,
        headers: dict[str, str] | None = None,
        transport: str | None = None,
    ) -> None:
        self._options = _options(headers)
        self.url = _url(host, port, is_secure)
        self._last_failure: ConnectError | None = None
        self._loop = LoopThread(f"roslibpy_lite.compat {self.url}")
        self._callbacks = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix="roslibpy_lite.compat callbacks")
        self._events: dict[str, list[Callback]] = {}
        self._lock = threading.Lock()
        self._client: AioRos | None = None
        self._ready: asyncio.Future[AioRos] | None = None
        self._opener: concurrent.futures.Future[None] | None = None
        self._terminated = threading.Event()
        self._closed = False
        self.is_connecting = False

    def __repr__(self) -> str:
        return f"<compat Ros {self.url} {'connected' if self.is_connected else 'not connected'}>"

    # -- connection ----------------------------------------------------------------------------

    @property
    def is_connected(self) -> bool:
        """True while the connection is open."""
        return self._client is not None and self._client.is_connected

    def connect(self) -> None:
        """Start connecting in the background (``run``, ``run_forever`` and the first
        operation do it; call it again to reopen after :meth:`close`)."""
        self._closed = False
        if not self._loop.closed:
            self._loop.loop.call_soon_threadsafe(self._start)

    def _start(self) -> asyncio.Future[AioRos]:
        """The future of the connection, opening it if nobody has yet (on the loop)."""
        if self._ready is None:
            self._ready = self._loop.loop.create_future()
            self.is_connecting = True
            self._opener = asyncio.run_coroutine_threadsafe(self._open(), self._loop.loop)
        return self._ready

    async def _open(self) -> None:
        """Try until connected (roslibpy retries for ever too); then the client reconnects."""
        backoff = Backoff()
        while True:
            try:
                client = await roslibpy_lite.connect(self.url, open_timeout=CONNECTION_TIMEOUT,
                                                     **self._options)
            except (NotAuthenticated, TLSError) as exc:  # another attempt would only repeat it
                log.error("%s", exc)
                self.emit("error", exc)
                self.is_connecting = False
                if self._ready is not None and not self._ready.done():
                    self._ready.set_exception(exc)  # run() and every operation raise it
                return
            except ConnectError as exc:
                log.warning("%s", exc)
                self._last_failure = exc
                self.emit("error", exc)
                await asyncio.sleep(backoff.next())
                continue
            break
        self.is_connecting = False
        self._client = client
        client.on_state_change(self._state_changed)
        self._state_changed(client.state)
        if self._ready is not None and not self._ready.done():
            self._ready.set_result(client)

    def _state_changed(self, state: ConnectionState) -> None:
        if state is ConnectionState.CONNECTED:
            self.emit("ready", self)
        elif state in (ConnectionState.RECONNECTING, ConnectionState.CLOSED):
            self.emit("close", self)

    async def _connected(self) -> AioRos:
        if self._closed:
            raise ConnectionClosed("the Ros connection is closed; call connect() to reopen it")
        return await asyncio.shield(self._start())

    def run(self, timeout: float = CONNECTION_TIMEOUT) -> None:
        """Connect and wait until the connection is ready.

        Raises:
            RosTimeoutError: not connected within ``timeout`` seconds.
        """
        self._closed = False
        self._loop.run(self._wait_ready(timeout), "run")

    async def _wait_ready(self, timeout: float) -> None:
        try:
            await asyncio.wait_for(self._connected(), timeout)
        except TimeoutError:
            why = self._last_failure
            raise RosTimeoutError(
                f"Failed to connect to ROS at {self.url} within {timeout:g} s: "
                + (str(why) if why is not None else "no answer yet; check that a rosbridge "
                   "server is running there and the host and port are right")
            ) from None

    def run_forever(self) -> None:
        """Connect, then block until :meth:`terminate` is called (from a callback or a thread)."""
        self.connect()
        self._terminated.wait()

    def run_event_loop(self) -> None:
        """Deprecated roslibpy name of :meth:`run_forever`."""
        self.run_forever()

    def close(self, timeout: float = CONNECTION_TIMEOUT) -> None:
        """Disconnect (emits ``"closing"``, then ``"close"``); :meth:`connect` opens again."""
        if self._loop.closing:
            return
        if self.is_connected:
            self.emit("closing")
        self._loop.run(self._close(), "close")

    async def _close(self) -> None:
        self._closed = True
        if self._opener is not None:
            self._opener.cancel()
        if self._ready is not None and not self._ready.done():
            self._ready.set_exception(ConnectionClosed("the Ros connection was closed"))
            self._ready.exception()  # retrieved: nobody may be waiting
        self._ready = None
        self.is_connecting = False
        client, self._client = self._client, None
        if client is not None:
            await client.close()

    def terminate(self) -> None:
        """Close the connection and stop every thread of this Ros; ``run_forever`` returns."""
        if self._terminated.is_set():
            return
        try:
            self.close()
        finally:
            self._loop.stop()
            on_callback_thread = threading.current_thread().name.startswith(
                "roslibpy_lite.compat callbacks")
            self._callbacks.shutdown(wait=not on_callback_thread)
            self._terminated.set()

    # -- events and callbacks ------------------------------------------------------------------

    def on(self, event_name: str, callback: Callback) -> None:
        """Call ``callback(*args)`` whenever ``event_name`` is emitted.

        Events: ``"ready"`` (connected, again after each reconnect), ``"close"``
        (the connection dropped or was closed), ``"closing"`` (``close()`` was
        called), ``"error"`` (a connection attempt failed).
        """
        with self._lock:
            self._events.setdefault(event_name, []).append(callback)

    def off(self, event_name: str, callback: Callback | None = None) -> None:
        """Remove ``callback`` from ``event_name`` (every callback when None)."""
        with self._lock:
            if callback is None:
                self._events.pop(event_name, None)
            elif callback in self._events.get(event_name, []):
                self._events[event_name].remove(callback)

    def emit(self, event_name: str, *args: Any) -> None:
        """Trigger ``event_name``: its callbacks run on the callback thread."""
        with self._lock:
            callbacks = list(self._events.get(event_name, []))
        for callback in callbacks:
            self.run_on_callback_thread(callback, *args)

    def run_on_callback_thread(
        self, callback: Callback, *args: Any
    ) -> concurrent.futures.Future[Any] | None:
        """Run ``callback(*args)`` on the callback thread (as roslibpy runs callbacks);
        None once this Ros was terminated. Failures are logged."""
        try:
            future = self._callbacks.submit(callback, *args)
        except RuntimeError:  # terminated
            return None
        future.add_done_callback(_log_raised)
        return future

    async def run_on_callback_thread_and_wait(self, callback: Callback, *args: Any) -> None:
        """Run ``callback(*args)`` on the callback thread; return (on the loop) once it ran."""
        future = self.run_on_callback_thread(callback, *args)
        if future is None:
            return
        loop = asyncio.get_running_loop()
        waiter: asyncio.Future[None] = loop.create_future()

        def wake(_: concurrent.futures.Future[Any]) -> None:
            with contextlib.suppress(RuntimeError):  # the loop was stopped meanwhile
                loop.call_soon_threadsafe(_finish, waiter)

        future.add_done_callback(wake)
        await waiter

    def on_ready(self, callback: Callable[[], Any], run_in_thread: bool = True) -> None:
        """Call ``callback()`` once connected (at once if connected already).

        ``run_in_thread``: in a thread of its own (roslibpy's default), else
        on the callback thread.
        """

        def fire(*_: Any) -> None:
            self.off("ready", fire)
            if run_in_thread:
                self.call_in_thread(callback)
            else:
                callback()

        if self.is_connected:
            fire()
        else:
            self.on("ready", fire)

    def call_in_thread(self, callback: Callable[[], Any]) -> None:
        """Run ``callback()`` in a new daemon thread."""
        threading.Thread(target=callback, name="roslibpy_lite.compat call_in_thread",
                         daemon=True).start()

    def call_later(self, delay: float, callback: Callable[[], Any]) -> None:
        """Run ``callback()`` on the callback thread after ``delay`` seconds.

        After :meth:`terminate` it never runs (as roslibpy's stopped reactor).
        """
        if self._loop.closing:
            return
        loop = self._loop.loop
        with contextlib.suppress(RuntimeError):  # terminated just now
            loop.call_soon_threadsafe(loop.call_later, delay, self.run_on_callback_thread, callback)

    # -- operations (used by Topic, Service, Param: compat.core.Driver) ------------------------

    @property
    def loop_thread(self) -> LoopThread:
        """The thread whose asyncio loop runs the connection."""
        return self._loop

    def run_blocking(self, what: str, fn: Callable[[AioRos], Any]) -> Any:
        """Run ``fn(client)`` on the loop once connected; block for its result."""
        return self._loop.run(self._op(fn), what)

    def run_when_connected(
        self,
        fn: Callable[[AioRos], Any],
        done: Callable[[concurrent.futures.Future[Any]], None] | None = None,
    ) -> None:
        """Run ``fn(client)`` on the loop once connected, without waiting (in call order);
        the compat Topic, Service and ActionClient classes go through this.

        ``done(future)`` runs on the callback thread when it finishes; failures
        without ``done`` are logged.

        Raises:
            ConnectionClosed: this Ros was terminated.
        """
        try:
            future = self._loop.submit(self._op(fn), "roslibpy_lite.compat")
        except ConnectionClosed:
            raise ConnectionClosed(
                f"the Ros of {self.url} was terminated; make a new Ros to connect again"
            ) from None
        if done is None:
            future.add_done_callback(_log_raised)
        else:
            future.add_done_callback(lambda f: self.run_on_callback_thread(done, f))

    async def _op(self, fn: Callable[[AioRos], Any]) -> Any:
        client = await self._connected()
        result = fn(client)
        if inspect.isawaitable(result):
            result = await result
        return result

    def request_service(
        self,
        service: str,
        type_name: str,
        args: dict[str, Any],
        callback: Callback | None,
        errback: Callback | None,
        timeout: float | None,
    ) -> ServiceResponse | None:
        """Call a service blocking (returns the response) or with callback/errback."""

        def call(client: AioRos) -> Any:
            # roslibpy's calls wait for the connection while it is being reopened
            return client.call_service(service, type_name, args, timeout=timeout,
                                       wait_connected=True)

        if callback is None:
            try:
                return ServiceResponse(_as_json(self.run_blocking(f"call {service}", call)))
            except ServiceError as exc:
                raise ServiceException(exc.reason) from None

        def done(future: concurrent.futures.Future[Any]) -> None:
            exc = future.exception()
            if exc is None:
                callback(ServiceResponse(_as_json(future.result())))
            elif errback is not None:
                errback(exc.reason if isinstance(exc, ServiceError) else str(exc))
            else:
                log.error("call %s failed: %s", service, exc)

        self.run_when_connected(call, done)
        return None

    def _rosapi(
        self,
        name: str,
        args: dict[str, Any],
        key: str | None,
        callback: Callback | None,
        errback: Callback | None,
        timeout: float | None = None,
    ) -> Any:
        """Call ``/rosapi/<name>``: ``result[key]`` when blocking, else ``callback(response)``."""
        result = self.request_service(
            f"/rosapi/{name}", rosapi_type(name), args, callback, errback,
            ROSAPI_TIMEOUT if timeout is None else timeout)
        if result is None or key is None:
            return result
        return result[key]

    # -- introspection -------------------------------------------------------------------------

    def get_time(self, callback: Callback | None = None, errback: Callback | None = None) -> Any:
        """The current ROS time (a :class:`Time`; blocking unless ``callback`` is given)."""
        result = self._rosapi("get_time", {}, None, callback, errback)
        if result is None:
            return None
        stamp = result["time"]
        return Time(stamp.get("secs", stamp.get("sec", 0)),
                    stamp.get("nsecs", stamp.get("nanosec", 0)))

    def get_topics(self, callback: Callback | None = None, errback: Callback | None = None) -> Any:
        """The topic names."""
        return self._rosapi("topics", {}, "topics", callback, errback)

    def get_topic_type(
        self, topic: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The type of ``topic``."""
        return self._rosapi("topic_type", {"topic": topic}, "type", callback, errback)

    def get_topics_for_type(
        self, topic_type: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The topics of type ``topic_type``."""
        return self._rosapi("topics_for_type", {"type": topic_type}, "topics", callback, errback)

    def get_services(
        self, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The service names."""
        return self._rosapi("services", {}, "services", callback, errback)

    def get_service_type(
        self, service_name: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The type of ``service_name``."""
        return self._rosapi("service_type", {"service": service_name}, "type", callback, errback)

    def get_services_for_type(
        self, service_type: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The services of type ``service_type``."""
        return self._rosapi("services_for_type", {"type": service_type}, "services",
                            callback, errback)

    def get_service_request_details(
        self, type: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The typedefs of a service type's request."""
        return self._rosapi("service_request_details", {"type": type}, None, callback, errback)

    def get_service_response_details(
        self, type: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The typedefs of a service type's response."""
        return self._rosapi("service_response_details", {"type": type}, None, callback, errback)

    def get_message_details(
        self, message_type: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The typedefs of a message type."""
        return self._rosapi("message_details", {"type": message_type}, None, callback, errback)

    def get_nodes(self, callback: Callback | None = None, errback: Callback | None = None) -> Any:
        """The node names."""
        return self._rosapi("nodes", {}, "nodes", callback, errback)

    def get_node_details(
        self, node: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """What ``node`` subscribes, publishes and serves."""
        result = self._rosapi("node_details", {"node": node}, None, callback, errback)
        if result is None:
            return None
        return {k: result[k] for k in ("services", "subscribing", "publishing")}

    def get_action_servers(self, callback: Callback, errback: Callback | None = None) -> None:
        """Pass the action server names to ``callback`` (non-blocking only, as in roslibpy)."""
        self._rosapi("action_servers", {}, None, callback, errback)

    def get_params(self, callback: Callback | None = None, errback: Callback | None = None) -> Any:
        """The parameter names (``/node:param`` in ROS 2)."""
        return self._rosapi("get_param_names", {}, "names", callback, errback)

    def get_param(
        self, name: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> Any:
        """The value of parameter ``name``."""
        return Param(self, name).get(callback, errback, timeout=ROSAPI_TIMEOUT)

    def set_param(
        self, name: str, value: Any, callback: Callback | None = None,
        errback: Callback | None = None,
    ) -> None:
        """Set parameter ``name`` to ``value``."""
        Param(self, name).set(value, callback, errback, timeout=ROSAPI_TIMEOUT)

    def delete_param(
        self, name: str, callback: Callback | None = None, errback: Callback | None = None
    ) -> None:
        """Delete parameter ``name``."""
        Param(self, name).delete(callback, errback, timeout=ROSAPI_TIMEOUT)


def _finish(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


def _log_raised(future: concurrent.futures.Future[Any]) -> None:
    if future.cancelled():
        return
    exc = future.exception()
    if exc is not None:
        log.error("a roslibpy_lite.compat callback or operation failed: %r", exc)


def _as_json(value: Any) -> Any:
    """``value`` with ``bytes`` (the client's ``uint8[]`` fields) as base64 text, the JSON
    form roslibpy gives its users."""
    if isinstance(value, bytes):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, dict):
        return {k: _as_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_as_json(v) for v in value]
    return value
