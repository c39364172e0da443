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

Actions: :meth:`Client.send_goal` returns a blocking
:class:`~roslibpy_lite.sync.actions.GoalHandle` (iterate its feedback, wait
for its ``result(timeout)``, ``cancel()``); :meth:`Client.advertise_action`
serves an action with ``handler(goal, ctx)``: a plain function runs in a
worker thread (it may block, check ``ctx.cancel_requested`` and call the
client), an ``async def`` on the loop thread. ``on_feedback`` callbacks run on
the loop thread, like subscription callbacks.
"""

from __future__ import annotations

import contextlib
import threading
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Self, Unpack, overload

from rosbridge_core.protocol.constants import ADVERTISE_QUEUE_SIZE

from .. import MockRos as _AioMockRos
from .. import connect as _aio_connect
from .._aio import is_async_callable
from ..api import DEFAULT_CALL_TIMEOUT, ConnectionState, StateCallback
from ..exceptions import ReplacedClientWarning, UsageError
from ..jupyter import Cell, current_cell, from_cell, in_cell
from ..messages import held_warnings
from .actions import ActionServer, GoalHandle
from .handles import PUBLISH_WINDOW, Publisher, ServiceServer, StateChanges, Subscription
from .introspection import Graph
from .loop import HANDLER_THREADS, LoopThread

if TYPE_CHECKING:
    from types import TracebackType

    from msgs.runtime import Action, Message, Service

    from .. import handles
    from .._api_types import M
    from ..actions import ActionHandler, FeedbackCallback
    from ..api import Ros
    from ..client import ClientOptions

__all__ = [
    "HANDLER_THREADS",
    "PUBLISH_WINDOW",
    "ActionServer",
    "Client",
    "GoalHandle",
    "Graph",
    "LoopThread",
    "MockRos",
    "Publisher",
    "ServiceServer",
    "StateChanges",
    "Subscription",
    "connect",
]


class _Front:
    """The blocking API over an asyncio :class:`~roslibpy_lite.api.Ros` on a :class:`LoopThread`."""

    def __init__(self, loop: LoopThread, ros: Ros) -> None:
        self._loop = loop
        self.aio = ros
        """The asyncio client underneath (use it from the loop thread only)."""
        self.graph = Graph(loop, ros.graph)
        """The ROS graph and parameters, blocking (:class:`~roslibpy_lite.sync.Graph`)."""

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
            if self._loop.closing:
                return  # closed: the callback is gone with the client
            with contextlib.suppress(RuntimeError):  # the loop closed just now
                self._loop.loop.call_soon_threadsafe(remove)

        return remover

    def state_changes(self) -> StateChanges:
        """The state changes from now on: ``next(timeout)`` or iterate (ends after ``CLOSED``)."""
        watcher = self._loop.call("state_changes", self.aio.state_changes)
        return StateChanges(self._loop, watcher)

    # -- topics ------------------------------------------------------------------------------

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
        """Announce a publisher on ``topic`` (see :meth:`roslibpy_lite.api.Ros.advertise`)."""
        handle = self._loop.call(f"advertise {topic}", self.aio.advertise, topic, type,
                                 latch=latch, queue_size=queue_size, strict=strict)
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
        if callback is not None:  # in Jupyter: its output under this cell, not the loop's
            callback = in_cell(callback)
        handle, held = self._loop.call(f"subscribe {topic}", self._subscribe, topic, type,
                                       callback, options, current_cell())
        for warning in held:  # given here, on the caller's thread (a notebook's cell)
            warnings.warn(warning, stacklevel=2)
        return Subscription(self._loop, handle)

    def subscriptions(self) -> list[Subscription[Any]]:
        """The open subscriptions of this client, oldest first (``sub.close()`` ends one)."""
        found: list[handles.Subscription[Any]] = self._loop.call(
            "subscriptions", self.aio.subscriptions)
        return [Subscription(self._loop, h) for h in found]

    async def _subscribe(
        self, topic: str, type: Any, callback: Any, options: dict[str, Any], cell: Cell | None
    ) -> tuple[handles.Subscription[Any], list[Warning]]:
        with held_warnings() as held, from_cell(cell):  # the caller's cell, on this thread
            sub = self.aio.subscribe(topic, type, callback, **options)
        return await sub, held

    # -- services ----------------------------------------------------------------------------

    def call_service(
        self,
        service: str,
        type: str | type[Service],
        args: Mapping[str, Any] | Message | None = None,
        *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
        wait_connected: bool = False,
        strict: bool | None = None,
    ) -> Any:
        """Call ``service``; returns its response (see :meth:`roslibpy_lite.api.Ros.call_service`).

        Raises ServiceError, RosTimeoutError, NotConnected (at once while the link is
        down, unless ``wait_connected``), Disconnected, ConnectionClosed, UsageError as
        the asyncio client does.
        """
        call = self.aio.call_service(service, type, args, timeout=timeout,  # type: ignore[arg-type]
                                     wait_connected=wait_connected, strict=strict)
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
        serve = handler if is_async_callable(handler) else self._loop.off_loop(handler)
        handle = self._loop.call(f"advertise_service {service}", self.aio.advertise_service,
                                 service, type, serve)
        return ServiceServer(self._loop, handle)

    # -- actions -----------------------------------------------------------------------------

    def send_goal(
        self,
        action: str,
        type: str | type[Action],
        goal: Mapping[str, Any] | Message | None = None,
        *,
        feedback: bool = True,
        on_feedback: FeedbackCallback | None = None,
        buffer_size: int = 100,
    ) -> GoalHandle:
        """Send a goal; returns its blocking handle (see :meth:`roslibpy_lite.api.Ros.send_goal`).

        ``on_feedback(fb)`` runs ON THE LOOP THREAD.
        """
        handle = self._loop.run(
            self.aio.send_goal(action, type, goal, feedback=feedback, on_feedback=on_feedback,
                               buffer_size=buffer_size), f"send_goal {action}")
        return GoalHandle(self._loop, handle)

    def advertise_action(
        self, action: str, type: str | type[Action], handler: ActionHandler
    ) -> ActionServer:
        """Serve ``action`` with ``handler(goal, ctx) -> result`` (a plain function runs in a
        worker thread; see :mod:`roslibpy_lite.actions` for the rules)."""
        handle = self._loop.call(f"advertise_action {action}", self.aio.advertise_action,
                                 action, type, handler)
        return ActionServer(self._loop, handle)

    # -- closing -----------------------------------------------------------------------------

    def close(self) -> None:
        """Close the connection and stop the loop thread. Closing twice is harmless."""
        if self._loop.closing:
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


class Client(_Front):
    """A blocking rosbridge client (made by :func:`connect`); see the module docstring."""

    def close(self) -> None:
        """Close the connection and stop the loop thread. Closing twice is harmless."""
        key = self._replace_key
        with _OPEN_LOCK:
            if key is not None and _OPEN.get(key) is self:
                del _OPEN[key]
        super().close()

    _replace_key: str | tuple[str, ...] | None = None  # set by connect(..., replace=True)

    @property
    def url(self) -> str:
        """The bridge's URL."""
        url: str = self.aio.url  # type: ignore[attr-defined]
        return url


_OPEN: dict[str | tuple[str, ...], Client] = {}
"""The latest open client :func:`connect` made for each URL (or list of URLs; ``replace``
closes it)."""
_OPEN_LOCK = threading.Lock()


def connect(url: str | Sequence[str], *, replace: bool = True,
            **options: Unpack[ClientOptions]) -> Client:
    """Connect to the rosbridge server at ``url`` and return a blocking :class:`Client`.

    Takes every keyword option of :func:`roslibpy_lite.connect` (``reconnect``,
    ``backoff``, ``open_timeout``, ``offline_buffer``, ``max_pending``,
    ``token``, ``ssl``, ...), passed through unchanged, and several URLs as it does (tried
    in turn; the next when a connection is lost). Returns once the
    first connection is open; use as ``with sync.connect(url) as ros:`` or
    call ``ros.close()``.

    Connecting again to a URL this process still has an open client for (a
    notebook's ``ros = sync.connect(URL)`` cell run again) CLOSES the earlier
    client first, its thread, socket and subscriptions with it, and says so with a
    :class:`~roslibpy_lite.exceptions.ReplacedClientWarning` naming the URL; so a
    re-run leaves one client on the bridge. ``replace=False`` keeps both (a program
    that wants two connections to one bridge).

    Raises:
        ConnectError: no connection within ``open_timeout`` seconds (also its
            subclasses NotAuthenticated and TLSError, as :func:`roslibpy_lite.connect`).
        UsageError: a malformed URL or option.
    """
    key = url if isinstance(url, str) else tuple(url)
    if replace:
        with _OPEN_LOCK:
            earlier = _OPEN.pop(key, None)
        if earlier is not None and not earlier._loop.closing:
            warnings.warn(ReplacedClientWarning(
                f"sync.connect({url!r}): this process already had an open client for "
                f"{url}; it was closed with its {len(earlier.aio.subscriptions())} "
                "subscription(s) (replace=False keeps both)"), stacklevel=2)
            earlier.close()
    loop = LoopThread(f"roslibpy_lite.sync {url}")
    try:
        ros = loop.run(_open(url, options), f"connect {url}")
    except BaseException:
        loop.stop()
        raise
    client = Client(loop, ros)
    if replace:
        client._replace_key = key
        with _OPEN_LOCK:
            _OPEN[key] = client
    return client


async def _open(url: str | Sequence[str], options: ClientOptions) -> Ros:
    ros: Ros = await _aio_connect(url, replace=False, **options)  # connect above decides
    return ros


class MockRos(_Front):
    """The blocking client in memory: :class:`roslibpy_lite.MockRos` on a loop thread.

    The same API as :class:`Client`, plus the test conveniences of the
    asyncio mock: :meth:`inject`, :meth:`published`, :meth:`subscribers`,
    :meth:`served`, :meth:`drain`, :meth:`disconnect`, :meth:`reconnect`.
    Close it (or use ``with``) to stop its thread.
    """

    def __init__(self, *, offline_buffer: int = 100, validate: bool = True,
                 strict: bool = False) -> None:
        loop = LoopThread("roslibpy_lite.sync mock")
        mock: _AioMockRos = loop.call(
            "MockRos", _AioMockRos, offline_buffer=offline_buffer, validate=validate,
            strict=strict)
        super().__init__(loop, mock)
        self._mock = mock

    def inject(self, topic: str, msg: Mapping[str, Any] | Message,
               type: str | type[Message] | None = None, *, latch: bool = False) -> None:
        """Deliver ``msg`` to the subscribers of ``topic`` as if the robot published it."""
        self._loop.call(f"inject {topic}", self._mock.inject, topic, msg, type, latch=latch)

    def add_node(self, name: str, parameters: Mapping[str, Any] | None = None) -> None:
        """Play another ROS node, ``name``, serving ``parameters``
        (:meth:`roslibpy_lite.MockRos.add_node`)."""
        self._loop.call(f"add_node {name}", self._mock.add_node, name, parameters)

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
