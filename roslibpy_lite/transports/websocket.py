"""Frames over a real websocket: connect, pump, write with backpressure, reconnect.

One task reads frames and hands each completed op to the client (no task per
message). One writer task drains a send queue, so the order of our ops is
kept. A dropped connection is reopened at once, then with exponential backoff
and jitter while attempts fail (:class:`~roslibpy_lite._backoff.Backoff`); a
connection that drops within ``stable_after`` of opening counts as a failed
attempt, so a peer that accepts and drops at once is not hammered.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any
from urllib.parse import unquote, urlsplit

from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import ConnectionClosed as WsConnectionClosed
from websockets.exceptions import InvalidHandshake, InvalidURI

from rosbridge_core.protocol import keepalive, ops
from rosbridge_core.protocol.constants import DEFAULT_PORT, MAX_CLIENT_FRAME
from rosbridge_core.protocol.frames import Conversation
from rosbridge_core.protocol.ops import ACKS_HEADER, AUTH_HEADER, SESSION_HEADER

from .._backoff import Backoff
from ..exceptions import (
    ConnectError,
    ConnectionClosed,
    Disconnected,
    NotAuthenticated,
    ProtocolError,
    RemoteProtocolError,
    UsageError,
)
from .refusals import (
    _closed_by_policy,
    _hint,
    _not_found,
    _plain_to_tls,
    _refusal,
    _relay_of,
    _tls_mismatch,
    _why,
)
from .resumable import ACK_INTERVAL, ClientSession

if TYPE_CHECKING:
    from .base import Link

__all__ = ["WebSocketTransport"]

log = logging.getLogger("roslibpy_lite.client")


class WebSocketTransport:
    """A :class:`~roslibpy_lite.transports.base.Transport` over websockets (see the module doc)."""

    def __init__(
        self,
        url: str | Sequence[str],
        *,
        reconnect: bool = True,
        backoff: Backoff | None = None,
        open_timeout: float = 10.0,
        max_size: int | None = MAX_CLIENT_FRAME,
        ping_interval: float | None = keepalive.DEFAULT_INTERVAL,
        ping_timeout: float | None = keepalive.DEFAULT_TIMEOUT,
        ws_compression: str | None = None,
        proxy: str | None = None,
        token: str | None = None,
        ssl_context: ssl.SSLContext | None = None,
        resume: bool = True,
        resume_frames: int = 1000,
        wait_for_robot: bool = False,
    ) -> None:
        self._dial = tuple(with_default_port(u) for u in ([url] if isinstance(url, str) else url))
        self.urls = tuple(shown_url(u) for u in self._dial)
        """The URLs as logs and error texts show them: a ``token`` in a query is ``***``."""
        if not self.urls:
            raise UsageError("no URL to connect to")
        self._at = 0  # the URL connected to, or tried next
        self.reconnect = reconnect
        self.backoff = backoff or Backoff()
        self.open_timeout = open_timeout
        self.wait_for_robot = wait_for_robot
        self.stable_after = 1.0
        self.acks = False
        self.connects = 0
        # Where the kernel can tell (Linux), keepalive.watch judges the link by TCP's own
        # evidence, so a pong late behind a big frame never drops a busy link; elsewhere
        # websockets' ping/pong does the job with the same figures.
        self._keepalive = (ping_interval, ping_timeout) if (
            ping_interval is not None and ping_timeout is not None and keepalive.supported_here()
        ) else None
        own_pings = self._keepalive is None
        self._ws_options: dict[str, Any] = {
            "max_size": max_size,
            "ping_interval": ping_interval if own_pings else None,
            "ping_timeout": ping_timeout if own_pings else None,
            "compression": ws_compression,
            "proxy": proxy,
            "additional_headers": {ACKS_HEADER: "1"},
            "logger": _WS_LOG,
        }
        self._has_token = token is not None
        if token is not None:  # never logged: it is only ever in this header
            self._ws_options["additional_headers"]["Authorization"] = f"Bearer {token}"
        if ssl_context is not None:
            self._ws_options["ssl"] = ssl_context
        self._link: Link | None = None
        self._deliver_op: Callable[[ops.Op], None] = _unbound
        # A session that outlives a dropped link, when the bridge keeps them (resumable.py).
        self.session: ClientSession | None = ClientSession(resume_frames) if resume else None
        self._ack_timer: asyncio.TimerHandle | None = None
        self._ack_frame: str | None = None
        self._protocol = Conversation()
        self._ws: ClientConnection | None = None
        self._outbox: deque[str] = deque()
        self._out_wake: asyncio.Future[None] | None = None
        self._queued = 0
        self._sent = 0
        self._flush_waiters: list[tuple[int, asyncio.Future[None]]] = []
        self._runner: asyncio.Task[None] | None = None
        self._first: asyncio.Future[None] | None = None
        self._closing = False

    @property
    def url(self) -> str:
        """The URL connected to (or tried next)."""
        return self.urls[self._at]

    def _move_on(self) -> bool:
        """Take the next URL (several: each in turn); True when a round of them is done."""
        self._at = (self._at + 1) % len(self.urls)
        return self._at == 0

    def bind(self, link: Link) -> None:
        """Attach the client."""
        self._link = link
        self._deliver_op = link.receive_op

    @property
    def connected(self) -> bool:
        """True while a socket is open."""
        return self._ws is not None

    # -- connecting ----------------------------------------------------------------------------

    async def start(self) -> None:
        """Open the first connection."""
        if self._runner is not None:
            raise UsageError("the client is already started")
        loop = asyncio.get_running_loop()
        self._first = loop.create_future()
        self._runner = loop.create_task(self._run(), name=f"roslibpy_lite {self.url}")
        await self._first

    def _fail_first(self, error: Exception) -> bool:
        """Fail :meth:`start` with ``error``; False once the first connection was made."""
        if self._first is None or self._first.done():
            return False
        self._first.set_exception(error)
        assert self._link is not None
        self._link.shut_down(ConnectionClosed(str(error)))
        return True

    def _attempt_timeout(self, deadline: float) -> float:
        """How long the next attempt may take: the first connection keeps to ``open_timeout``."""
        if self._first is not None and not self._first.done():
            return max(0.05, deadline - asyncio.get_running_loop().time())
        return self.open_timeout

    def _failed_attempt(self, exc: BaseException, attempts: int, started: float) -> str:
        """The text of a failed first connection: what was tried, what went wrong, what to check."""
        took = asyncio.get_running_loop().time() - started
        tried = f"{attempts} attempt{'s' if attempts != 1 else ''} in {took:.1f} s"
        where = self.url if len(self.urls) == 1 else f"any of {', '.join(self.urls)}"
        return f"cannot connect to {where} ({tried}): {_why(exc)}; {_hint(self.url, exc)}"

    async def _run(self) -> None:
        assert self._link is not None
        link = self._link
        loop = asyncio.get_running_loop()
        started = loop.time()
        deadline = started + self.open_timeout
        attempts = 0
        next_note = started
        try:
            while not self._closing:
                attempts += 1
                try:
                    options = self._ws_options
                    if self.session is not None:
                        options = {**options, "additional_headers": {
                            **options["additional_headers"], **self.session.headers()}}
                    ws = await ws_connect(self._dial[self._at],
                                          open_timeout=self._attempt_timeout(deadline),
                                          **options)
                except (OSError, InvalidHandshake, TimeoutError) as exc:
                    refused = _refusal(self.url, exc) or await _plain_to_tls(self.url, exc)
                    if refused is not None:  # a refused token or certificate: retrying cannot help
                        if not self._fail_first(refused):
                            log.error("%s", refused)
                            link.shut_down(refused)
                        return
                    missing = _not_found(self.url, exc)  # a first connection only: not there
                    if (missing is not None and len(self.urls) == 1
                            and not (self.wait_for_robot and _relay_of(exc) is not None)
                            and self._fail_first(missing)):
                        return
                    now = loop.time()
                    give_up = not self.reconnect or now >= deadline or _tls_mismatch(self.url, exc)
                    first = self._first is not None and not self._first.done()
                    if len(self.urls) > 1 and not (first and now >= deadline) \
                            and not self._move_on():
                        log.info("cannot connect to %s (%s); trying %s", self.urls[self._at - 1],
                                 _why(exc), self.url)
                        continue  # the next one at once; a full round failed backs off
                    if give_up and self._fail_first(
                        ConnectError(self._failed_attempt(exc, attempts, started))
                    ):
                        return
                    delay = self.backoff.next()
                    first = self._first is not None and not self._first.done()
                    if first:  # never sleep past the deadline: one last attempt at it
                        delay = min(delay, max(0.0, deadline - now))
                    if now >= next_note:  # not silent, not noisy: a line every 5 s or so
                        next_note = now + 5.0
                        log.log(logging.INFO if first else logging.WARNING,
                                "cannot connect to %s yet (%s); retrying%s",
                                self.url, _why(exc),
                                f" until {self.open_timeout} s are up" if first else "")
                    await asyncio.sleep(delay)
                    continue
                except InvalidURI as exc:
                    if not self._fail_first(UsageError(f"bad URL {self.url!r}: {exc}")):
                        link.shut_down(ConnectionClosed(f"bad URL {self.url!r}"))
                    return
                except Exception as exc:  # anything else websockets may raise: a failed attempt
                    if self._fail_first(ConnectError(self._failed_attempt(exc, attempts, started))):
                        return
                    log.warning("connect to %s failed: %s", self.url, _why(exc))
                    await asyncio.sleep(self.backoff.next())
                    continue
                if (not self._has_token and ws.response is not None
                        and ws.response.headers.get(AUTH_HEADER) == "required"):
                    await ws.close()
                    refused = NotAuthenticated(
                        f"the bridge at {self.url} requires a token: give one (token=... in "
                        "Python, --token or $ROSLIBPY_LITE_TOKEN on the command line)")
                    if not self._fail_first(refused):
                        log.error("%s", refused)
                        link.shut_down(refused)
                    return
                self.connects += 1
                self.acks = ws.response is not None and ws.response.headers.get(ACKS_HEADER) == "1"
                try:
                    self._opened(ws)
                except RemoteProtocolError as exc:  # a resume answered with a bad count
                    await ws.close(1002, "bad resume count")
                    failed = ConnectError(f"the bridge at {self.url} resumed this client's "
                                          f"session wrongly: {exc}")
                    if not self._fail_first(failed):
                        log.error("%s", failed)
                        link.shut_down(failed)
                    return
                opened = loop.time()
                await self._session(ws)
                if self._closing:
                    return
                closed = _closed_by_policy(self.url, ws)
                if closed is not None:  # the bridge refused us (our token, our op rate)
                    log.error("%s", closed)
                    link.shut_down(closed)
                    return
                if not self.reconnect:
                    log.warning("connection to %s lost; reconnect is off", self.url)
                    link.shut_down(Disconnected(f"connection to {self.url} lost"))
                    return
                lost_url = self.url
                if len(self.urls) > 1:
                    self._move_on()  # a server that died: the next one, not the same again
                log.warning("connection to %s lost; reconnecting%s", lost_url,
                            f" to {self.url}" if self.url != lost_url else "")
                self._lost()
                link.link_down()
                if loop.time() - opened >= self.stable_after:
                    self.backoff.reset()  # it was a good connection: try again at once
                else:  # a peer that accepts and drops at once: back off, do not hammer it
                    await asyncio.sleep(self.backoff.next())
        finally:
            if self._first is not None and not self._first.done():
                self._first.set_exception(ConnectionClosed("the client was closed"))

    def _link_dead(self, silence: float) -> None:
        log.warning("no sign of %s for %.1f s (a silent link: out of range, or the network "
                    "dropped it): closing it%s", self.url, silence,
                    "; reconnecting" if self.reconnect else "")

    async def _session(self, ws: ClientConnection) -> None:
        """Serve one open connection until it closes."""
        assert self._link is not None
        self._ws = ws
        self._protocol = Conversation()
        self._link.link_up()
        if self._first is not None and not self._first.done():
            self._first.set_result(None)
        writer = asyncio.get_running_loop().create_task(self._write(ws))
        watcher = None
        if self._keepalive is not None:
            interval, timeout = self._keepalive
            watcher = asyncio.get_running_loop().create_task(keepalive.watch(
                ws.transport, ws.ping, self._link_dead, interval, timeout))
        try:
            receive = self.receive
            async for frame in ws:
                receive(frame)
        except WsConnectionClosed:
            pass
        finally:
            self._ws = None
            if watcher is not None:
                watcher.cancel()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, WsConnectionClosed):
                await writer
            with contextlib.suppress(Exception):
                await ws.close()

    def _opened(self, ws: ClientConnection) -> None:
        """A handshake succeeded: resume the session (what the bridge missed goes first), or
        start anew (frames kept from the old connection are dropped, as without sessions)."""
        session = self.session
        if session is None:
            return
        lost = session.lost
        resumed, again = session.opened(ws.response.headers if ws.response is not None else {})
        if resumed:
            log.info("resumed the session with %s: %d frames sent again", self.url, len(again))
            self._outbox.extendleft(reversed(again))
            self._queued += len(self._outbox)  # kept at the drop (see _lost), and again
            return
        unsent = len(self._outbox)
        self._outbox.clear()
        self._sent = self._queued
        if session.lost > lost or unsent:
            log.warning("the bridge at %s did not keep this client's session: %d frames "
                        "written before the link dropped may not have reached it",
                        self.url, session.lost - lost + unsent)

    def _lost(self) -> None:
        """The connection is gone: release flush waiters; unsent frames are dropped, or kept
        for a resume when the bridge keeps sessions."""
        if self._ack_timer is not None:
            self._ack_timer.cancel()
            self._ack_timer = None
        self._ack_frame = None
        if self.session is None or self.session.token is None or self._closing:
            self._outbox.clear()
        else:  # kept for a resume, and no longer counted as queued (so no flush waits)
            self._queued -= len(self._outbox)
        self._sent = self._queued
        self._wake_flushers()

    # -- receiving -----------------------------------------------------------------------------

    def receive(self, frame: str | bytes) -> None:
        """Decode one frame and hand what it completes to the client (never raises)."""
        try:
            op = self._protocol.receive(frame)
        except ProtocolError as exc:
            log.warning("ignoring a bad frame from %s: %s", self.url, exc.message)
            self._count_received()
            return
        if type(op) is ops.SessionAck:
            if self.session is not None:
                self.session.acked(op.count)
            return
        if self.session is not None and self.session.token is not None:
            self._count_received()
        if op is not None:
            self._deliver_op(op)

    def _count_received(self) -> None:
        session = self.session
        if session is None or session.token is None:
            return
        session.received += 1
        if self._ack_timer is None:
            self._ack_timer = asyncio.get_running_loop().call_later(ACK_INTERVAL, self._ack)

    def _ack(self) -> None:
        """Confirm what arrived (written ahead of the queue, and neither counted nor kept)."""
        self._ack_timer = None
        session = self.session
        if session is None or self._ws is None or session.received == session.confirmed:
            return
        session.confirmed = session.received
        self._ack_frame = ops.encode(ops.SessionAck(session.received))
        wake = self._out_wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    # -- sending -------------------------------------------------------------------------------

    def encode(self, op: ops.Op) -> str:
        """The JSON text of ``op`` (a snapshot: later changes to its message do not matter)."""
        return ops.encode(op)

    def write(self, frame: str) -> None:
        """Queue one text frame for the writer task."""
        self._outbox.append(frame)
        self._queued += 1
        wake = self._out_wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    @property
    def backlog(self) -> int:
        """Frames queued but not yet written."""
        return self._queued - self._sent

    async def _write(self, ws: ClientConnection) -> None:
        outbox = self._outbox
        loop = asyncio.get_running_loop()
        session = self.session
        while True:
            if self._ack_frame is not None:
                ack, self._ack_frame = self._ack_frame, None
                await ws.send(ack)
            while outbox:
                frame = outbox.popleft()
                if session is not None and session.token is not None:
                    session.wrote(frame)  # kept until the bridge confirms it
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

    async def flush(self) -> None:
        """Return once every frame queued so far was written (or the connection dropped)."""
        if self._sent >= self._queued or self._ws is None:
            return
        fut = asyncio.get_running_loop().create_future()
        self._flush_waiters.append((self._queued, fut))
        await fut

    # -- closing -------------------------------------------------------------------------------

    async def close(self) -> None:
        """Close the socket and stop reconnecting."""
        self._closing = True
        self._lost()
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


def _unbound(op: ops.Op) -> None:
    raise RuntimeError("the transport has no client yet")


_SECRET_HEADERS = frozenset({"authorization", "proxy-authorization", SESSION_HEADER.lower()})


class _Redact(logging.Filter):
    """websockets' DEBUG lines of our connections without secrets: the request line's
    ``token`` (:func:`shown_url`) and the values of ``Authorization`` and the session
    header, both ways."""

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if isinstance(args, tuple) and isinstance(record.msg, str):
            if record.msg.startswith("> GET %s") and args:
                record.args = (shown_url(str(args[0])), *args[1:])
            elif record.msg in ("> %s: %s", "< %s: %s") and len(args) == 2 \
                    and str(args[0]).lower() in _SECRET_HEADERS:
                record.args = (args[0], "***")
        return True


_WS_LOG = logging.getLogger("roslibpy_lite.websockets")
"""The logger websockets writes our connections' lines to (DEBUG: the handshake, frames)."""
_WS_LOG.addFilter(_Redact())


def shown_url(url: str) -> str:
    """``url`` as logs and error texts may show it: the value of a ``token`` query parameter
    (its name matched as servers read it: percent-decoded, any case) is ``***``. A browser
    client must put its token there; ours takes ``token=`` but a URL may still carry one."""
    base, mark, query = url.partition("?")
    if not mark:
        return url
    query, hash_mark, fragment = query.partition("#")
    pairs = []
    for pair in query.split("&"):
        name, eq, _ = pair.partition("=")
        pairs.append(f"{name}{eq}***" if eq and unquote(name).strip().lower() == "token"
                     else pair)
    return f"{base}?{'&'.join(pairs)}{hash_mark}{fragment}"


ROSBRIDGE_PORT = DEFAULT_PORT
"""The port rosbridge servers listen on unless told otherwise."""


def with_default_port(url: str) -> str:
    """``url`` with the rosbridge port when a ``ws://`` URL names none (``ws://robot`` means
    ``ws://robot:9090``, not port 80). A ``wss://`` URL keeps TLS's 443: that is where a TLS
    proxy in front of a bridge listens."""
    try:
        parts = urlsplit(url)
        port = parts.port
    except ValueError:
        return url  # malformed: websockets names the problem at connect
    if parts.scheme != "ws" or port is not None or not parts.hostname:
        return url
    user, at, hostport = parts.netloc.rpartition("@")
    return parts._replace(netloc=f"{user}{at}{hostport}:{ROSBRIDGE_PORT}").geturl()
