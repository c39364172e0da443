"""Frames over a real websocket: connect, pump, write with backpressure, reconnect.

One task reads frames and hands each completed op to the front (no task per
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
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import ConnectionClosed as WsConnectionClosed
from websockets.exceptions import InvalidHandshake, InvalidURI

from .. import ops
from .._backoff import Backoff
from ..exceptions import ConnectError, ConnectionClosed, Disconnected, ProtocolError, UsageError
from ..protocol import Protocol

if TYPE_CHECKING:
    from .base import Link

__all__ = ["WebSocketTransport"]

log = logging.getLogger("roslibpy_lite.client")


class WebSocketTransport:
    """A :class:`~roslibpy_lite.transports.base.Transport` over websockets (see the module doc)."""

    def __init__(
        self,
        url: str,
        *,
        reconnect: bool = True,
        backoff: Backoff | None = None,
        open_timeout: float = 10.0,
        max_size: int | None = 256 * 1024 * 1024,
        ping_interval: float | None = 20.0,
        ping_timeout: float | None = 20.0,
        ws_compression: str | None = None,
        proxy: str | None = None,
    ) -> None:
        self.url = url
        self.reconnect = reconnect
        self.backoff = backoff or Backoff()
        self.open_timeout = open_timeout
        self.stable_after = 1.0
        self.acks = False
        self.connects = 0
        self._ws_options: dict[str, Any] = {
            "max_size": max_size,
            "ping_interval": ping_interval,
            "ping_timeout": ping_timeout,
            "compression": ws_compression,
            "proxy": proxy,
            "open_timeout": open_timeout,
        }
        self._link: Link | None = None
        self._on_op: Callable[[ops.Op], None] = _unbound
        self._protocol = Protocol()
        self._ws: ClientConnection | None = None
        self._outbox: deque[str] = deque()
        self._out_wake: asyncio.Future[None] | None = None
        self._queued = 0
        self._sent = 0
        self._flush_waiters: list[tuple[int, asyncio.Future[None]]] = []
        self._runner: asyncio.Task[None] | None = None
        self._first: asyncio.Future[None] | None = None
        self._closing = False

    def bind(self, link: Link) -> None:
        """Attach the front."""
        self._link = link
        self._on_op = link._on_op

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
        self._link._shutdown(ConnectionClosed(str(error)))
        return True

    async def _run(self) -> None:
        assert self._link is not None
        link = self._link
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.open_timeout
        try:
            while not self._closing:
                try:
                    ws = await ws_connect(self.url, **self._ws_options)
                except (OSError, InvalidHandshake, TimeoutError) as exc:
                    if (not self.reconnect or loop.time() >= deadline) and self._fail_first(
                        ConnectError(f"cannot connect to {self.url}: {_why(exc)}")
                    ):
                        return
                    delay = self.backoff.next()
                    if log.isEnabledFor(logging.DEBUG):
                        log.debug("connect to %s failed (%s); retry in %.2f s",
                                  self.url, _why(exc), delay)
                    await asyncio.sleep(delay)
                    continue
                except InvalidURI as exc:
                    if not self._fail_first(UsageError(f"bad URL {self.url!r}: {exc}")):
                        link._shutdown(ConnectionClosed(f"bad URL {self.url!r}"))
                    return
                except Exception as exc:  # anything else websockets may raise: a failed attempt
                    if self._fail_first(ConnectError(f"cannot connect to {self.url}: {_why(exc)}")):
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
                    link._shutdown(Disconnected(f"connection to {self.url} lost"))
                    return
                log.warning("connection to %s lost; reconnecting", self.url)
                self._lost()
                link._disconnected()
                if loop.time() - opened >= self.stable_after:
                    self.backoff.reset()  # it was a good connection: try again at once
                else:  # a peer that accepts and drops at once: back off, do not hammer it
                    await asyncio.sleep(self.backoff.next())
        finally:
            if self._first is not None and not self._first.done():
                self._first.set_exception(ConnectionClosed("the client was closed"))

    async def _session(self, ws: ClientConnection) -> None:
        """Serve one open connection until it closes."""
        assert self._link is not None
        self._ws = ws
        self._protocol = Protocol()
        self._link._connected()
        if self._first is not None and not self._first.done():
            self._first.set_result(None)
        writer = asyncio.get_running_loop().create_task(self._write(ws))
        try:
            receive = self.receive
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
        """The connection is gone: drop unsent frames, release flush waiters."""
        self._outbox.clear()
        self._sent = self._queued
        self._wake_flushers()

    # -- receiving -----------------------------------------------------------------------------

    def receive(self, frame: str | bytes) -> None:
        """Decode one frame and hand what it completes to the front (never raises)."""
        try:
            op = self._protocol.receive(frame)
        except ProtocolError as exc:
            log.warning("ignoring a bad frame from %s: %s", self.url, exc.message)
            return
        if op is not None:
            self._on_op(op)

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
    raise RuntimeError("the transport has no front yet")


def _why(exc: BaseException) -> str:
    text = str(exc)
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
