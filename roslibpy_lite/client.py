"""The websocket client: the client (:mod:`roslibpy_lite.ros`) over a real connection.

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
serialising goes through :mod:`rosbridge_core.protocol.ops` /
:mod:`rosbridge_core.protocol.frames` (JSON, CBOR with RFC 8746 typed arrays,
fragments). The socket side lives in :mod:`roslibpy_lite.transports.websocket`, the API in
:mod:`roslibpy_lite.ros`.

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
and served action is advertised again, and then the messages buffered while
offline are sent.

While the connection is down:

- service calls and action goals in flight fail at once with
  :class:`~roslibpy_lite.exceptions.Disconnected` (the bridge cancels such
  goals on the ROS side); a call started while reconnecting waits for the
  connection within its own timeout;
- ``publish`` keeps the latest ``offline_buffer`` messages PER PUBLISHER
  (default 100; older ones are dropped and counted in ``pub.dropped``) and
  sends them after the publisher is re-advertised. With ``offline_buffer=0``
  it raises :class:`~roslibpy_lite.exceptions.Disconnected` instead.
  Messages already queued to a socket that then died are lost: delivery is
  at most once;
- subscriptions keep their buffered messages and resume when the bridge
  sends again; an ``async for`` simply waits;
- requests from ROS callers to our services that were being handled are
  answered into the void (the bridge has already failed them); handlers of
  goals we were serving are cancelled (async) or see ``cancel_requested``
  (sync), since the bridge has aborted those goals.

Threads: a client belongs to the event loop that connected it; from other
threads use ``asyncio.run_coroutine_threadsafe``.

After ``close()`` (or a drop with ``reconnect=False``) the state is
``CLOSED``: calls raise :class:`~roslibpy_lite.exceptions.ConnectionClosed`,
``async for`` over subscriptions ends.
"""

from __future__ import annotations

import asyncio
import ssl as _ssl
import warnings
import weakref
from collections.abc import Callable, Coroutine, Generator, Sequence
from typing import TYPE_CHECKING, Any, TypedDict, TypeVar, Unpack

from rosbridge_core.protocol.constants import MAX_CLIENT_FRAME

from . import jupyter
from ._aio import running_loop
from ._api_types import ConnectionState
from ._backoff import Backoff
from .exceptions import ReplacedClientWarning, UsageError
from .ros import RosBase
from .transports.websocket import WebSocketTransport

if TYPE_CHECKING:
    from types import TracebackType

__all__ = ["Client", "ClientOptions", "Connector", "connect", "run"]

T = TypeVar("T")
EXIT_INTERRUPTED = 130
"""The exit status of a script stopped with Ctrl+C (128 + SIGINT), as shells report it."""


class ClientOptions(TypedDict, total=False):
    """The keyword options :func:`connect` (and ``sync.connect``) pass on to :class:`Client`.

    Their meanings and defaults are :class:`Client`'s (a test keeps the two lists equal).
    """

    reconnect: bool
    backoff: Backoff | None
    open_timeout: float
    offline_buffer: int
    max_pending: int
    max_size: int | None
    ping_interval: float | None
    ping_timeout: float | None
    ws_compression: str | None
    proxy: str | None
    validate: bool
    strict: bool
    token: str | None
    ssl: _ssl.SSLContext | str | None
    resume: bool
    wait_for_robot: bool


class Client(RosBase):
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
        ping_interval: seconds the bridge may be silent before it is pinged
            (None: no keepalive); after ``ping_timeout`` more seconds without any
            sign of it the link counts as dead: the connection is closed, the
            state goes to RECONNECTING and the client reconnects and restores
            (default 2 + 3: a silent link is noticed in about 5-6 s). On Linux
            the sign is TCP's own (data or acknowledgements from the bridge), so
            a pong stuck behind a large frame on a slow link never drops a busy
            connection; elsewhere it is websockets' ping/pong.
        ws_compression: websocket per-message compression (``"deflate"`` or
            None, the default: off, cheaper on a LAN).
        proxy: passed to websockets (None: connect directly).
        token: sent as ``Authorization: Bearer <token>`` to a bridge that requires
            one (``--auth-file``); a refused token raises
            :class:`~roslibpy_lite.exceptions.NotAuthenticated` and is never retried.
        ssl: for ``wss://`` URLs, an :class:`ssl.SSLContext` or the path of a CA
            file (PEM) that signed the bridge's certificate (default: the system's
            trusted CAs). A certificate problem raises
            :class:`~roslibpy_lite.exceptions.TLSError` in one line.
        validate: check dict messages against their ``msgs`` class (see
            :class:`~roslibpy_lite.ros.RosBase`).
        strict: refuse message and request dicts that leave fields out (see
            :class:`~roslibpy_lite.ros.RosBase`).
        resume: ask the bridge to keep this client's session across a dropped link
            (our bridge does, for ``--session-keep`` seconds; stock servers ignore the
            request): after a reconnect nothing this client sent is lost or published
            twice, and messages that arrived meanwhile are delivered
            (:mod:`roslibpy_lite.transports.resumable`).
        wait_for_robot: through a relay (``roslibpy-lite-relay``), keep trying while the
            relay answers that the robot is not connected, until ``open_timeout`` (a robot
            still starting). By default that answer fails :func:`connect` at once with
            the relay's words: a misspelt or offline robot is not worth waiting for.
    """

    _receive: Callable[[str | bytes], None]

    def __init__(
        self,
        url: str | Sequence[str],
        *,
        reconnect: bool = True,
        backoff: Backoff | None = None,
        open_timeout: float = 10.0,
        offline_buffer: int = 100,
        max_pending: int = 1024,
        max_size: int | None = MAX_CLIENT_FRAME,
        ping_interval: float | None = 2.0,
        ping_timeout: float | None = 3.0,
        ws_compression: str | None = None,
        proxy: str | None = None,
        validate: bool = True,
        strict: bool = False,
        token: str | None = None,
        ssl: _ssl.SSLContext | str | None = None,
        resume: bool = True,
        wait_for_robot: bool = False,
    ) -> None:
        self._ws = WebSocketTransport(
            url, reconnect=reconnect, backoff=backoff, open_timeout=open_timeout,
            max_size=max_size, ping_interval=ping_interval, ping_timeout=ping_timeout,
            ws_compression=ws_compression, proxy=proxy, token=token,
            ssl_context=_ssl_context([url] if isinstance(url, str) else url, ssl),
            resume=resume, wait_for_robot=wait_for_robot,
        )
        super().__init__(self._ws, offline_buffer=offline_buffer, max_pending=max_pending,
                         validate=validate, strict=strict)
        self._receive = self._ws.receive  # the receive path, for tests and benchmarks
        self._started = False

    @property
    def url(self) -> str:
        """The bridge's URL (of several: the one connected to, or tried next)."""
        return self._ws.url

    @property
    def urls(self) -> tuple[str, ...]:
        """Every URL this client may connect to, in the order it tries them."""
        return self._ws.urls

    @property
    def reconnect(self) -> bool:
        """Whether a dropped connection is reopened."""
        return self._ws.reconnect

    @property
    def backoff(self) -> Backoff:
        """The reconnect delays."""
        return self._ws.backoff

    @property
    def open_timeout(self) -> float:
        """Seconds the first connection may take."""
        return self._ws.open_timeout

    @property
    def stable_after(self) -> float:
        """A connection that lived this long (seconds) resets the backoff when it drops."""
        return self._ws.stable_after

    @stable_after.setter
    def stable_after(self, value: float) -> None:
        self._ws.stable_after = value

    @property
    def connects(self) -> int:
        """How many times a connection was opened (1 + reconnects)."""
        return self._ws.connects

    async def _start(self) -> None:
        """Open the first connection (called by :func:`connect`)."""
        if self._started:
            raise UsageError("the client is already started")
        self._started = True
        try:
            await self._ws.start()
        except BaseException:
            await self.close()
            raise


class Connector:
    """What :func:`connect` returns: ``await`` it for a :class:`Client`, or use ``async with``.

    Using it as a client without ``await`` raises
    :class:`~roslibpy_lite.exceptions.UsageError` saying "did you forget await?".
    """

    def __init__(self, client: Client, replace: str | tuple[str, ...] | None = None) -> None:
        self._client = client
        self._replace = replace

    async def _open(self) -> Client:
        key = self._replace
        if key is not None:
            ref = _OPEN.pop(key, None)
            earlier = ref() if ref is not None else None
            if earlier is not None and earlier.state is not ConnectionState.CLOSED:
                warnings.warn(ReplacedClientWarning(
                    f"connect({key!r}): this process already had an open client for it; it "
                    f"was closed with its {len(earlier.subscriptions())} subscription(s) "
                    "(replace=False keeps both)"), stacklevel=2)
                await earlier.close()
        await self._client._start()
        if key is not None:
            _OPEN[key] = weakref.ref(self._client)
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

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or not hasattr(Client, name):
            raise AttributeError(name)
        raise _ConnectNotAwaited(
            f"connect() returns a Connector, not a client, so it has no {name!r}: "
            "did you forget await? Use 'ros = await roslibpy_lite.connect(url)' or "
            "'async with roslibpy_lite.connect(url) as ros:'"
        )


class _ConnectNotAwaited(UsageError, AttributeError):
    """A Connector used as the client it opens."""


_OPEN: dict[str | tuple[str, ...], weakref.ref[Client]] = {}
"""The latest client :func:`connect` opened with ``replace`` for each URL (or list)."""


def connect(url: str | Sequence[str], *, replace: bool | None = None,
            **options: Unpack[ClientOptions]) -> Connector:
    """Connect to a rosbridge server at ``url`` (``ws://host:9090``).

    Several URLs (a list: relays serving the same robot, or bridges on the same ROS graph)
    are tried in turn: the first that answers is used, and when its connection is lost the
    client moves to the next and restores its subscriptions, publishers and services there.

    ``async with connect(url) as ros:`` or ``ros = await connect(url)``. See
    :class:`Client` for the ``options`` (:class:`ClientOptions`). Returns once
    the first connection is open.

    ``replace``: close an open client this process made for the same URL (or list) first,
    with a :class:`~roslibpy_lite.exceptions.ReplacedClientWarning` naming it. ``None``
    (the default) replaces inside a Jupyter kernel, where a cell run again
    (``ros = await connect(URL)``) would otherwise leave the earlier client connected with
    its subscriptions, and not elsewhere, where a program may want two clients of one
    bridge.

    Raises (when awaited):
        ConnectError: no connection within ``open_timeout`` seconds (with
            ``reconnect`` on, attempts are retried with backoff until then).
        NotAuthenticated: the bridge refused ``token`` (not retried).
        TLSError: the bridge's certificate could not be verified, or it wants a
            client certificate (not retried).
        UsageError: a malformed URL or option (``ssl=`` with ``ws://``, an
            unreadable CA file).
    """
    if replace is None:
        replace = jupyter.in_kernel()
    key = (url if isinstance(url, str) else tuple(url)) if replace else None
    return Connector(Client(url, **options), key)


def _ssl_context(urls: Sequence[str], ssl: _ssl.SSLContext | str | None
                 ) -> _ssl.SSLContext | None:
    """The TLS context for ``urls``: as given, or one trusting the CA file ``ssl`` names."""
    if ssl is None:
        return None
    for url in urls:
        if not url.startswith("wss://"):
            raise UsageError(f"ssl= is for wss:// URLs, not {url!r}")
    if isinstance(ssl, _ssl.SSLContext):
        return ssl
    try:
        return _ssl.create_default_context(cafile=ssl)
    except (OSError, _ssl.SSLError) as exc:
        raise UsageError(f"ssl={ssl!r}: cannot load it as a CA file: {exc}") from None


class _RunInALoop(UsageError, RuntimeError):
    """run() inside a running loop (a RuntimeError too, as asyncio.run's own refusal is)."""


def run(main: Coroutine[Any, Any, T], *, debug: bool | None = None) -> T:
    """Run a script's ``main()`` coroutine; Ctrl+C ends it cleanly, with no traceback.

    Like :func:`asyncio.run` (which it calls): on Ctrl+C the ``main`` task is
    cancelled, so ``async with connect(...)`` blocks close their connection,
    and then the program exits with status 130 instead of printing
    asyncio's traceback::

        async def main() -> None:
            async with roslibpy_lite.connect("ws://robot:9090") as ros:
                ...

        if __name__ == "__main__":
            roslibpy_lite.run(main())

    Returns what ``main`` returns.

    Raises:
        SystemExit: with status 130 after Ctrl+C (KeyboardInterrupt).
        UsageError: called inside a running event loop (a Jupyter cell's): ``await main()``
            there instead.
    """
    if running_loop() is not None:
        main.close()  # never started: no "never awaited" warning on top
        raise _RunInALoop(
            "roslibpy_lite.run() cannot start an event loop inside a running one (a Jupyter "
            "notebook's cell runs in one): write `await main()` at the top level of the cell "
            "instead")
    try:
        return asyncio.run(main, debug=debug)
    except KeyboardInterrupt:
        raise SystemExit(EXIT_INTERRUPTED) from None
