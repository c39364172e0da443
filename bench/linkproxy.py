"""A fault-injecting TCP proxy on 127.0.0.1: the bad links of Wi-Fi and cellular, in user space.

This kernel has no traffic shaping (no netem), so tests and benchmarks put this proxy
between a client and the bridge and break the link on purpose::

    with LinkProxy(("127.0.0.1", bridge_port)) as link:
        url = f"ws://127.0.0.1:{link.port}"
        ...
        link.blackhole()            # silence both ways: no FIN, no RST, bytes wait in kernel buffers
        link.restore()              # the link comes back; TCP delivers what waited
        link.set_latency(0.1)       # 100 ms each way
        link.set_bandwidth(250_000) # bytes per second, each way (2 Mbit/s)
        link.cut()                  # RST on both sides of every connection

The proxy runs its own event loop on a thread of its own, so blocking tests, asyncio tests
and benchmark processes all drive it the same way; every control is thread-safe.

What each fault does to the two TCP connections it joins:

- **blackhole**: the proxy stops reading. The sender's kernel keeps accepting bytes until its
  send buffer and the proxy's small receive buffer are full, then its writes block, exactly
  as when a robot drives out of range and TCP retransmits into the void. Nothing is lost or
  reordered: after :meth:`restore` the bytes flow on, as TCP would deliver them if the link
  came back before either side gave up.
- **latency**: each chunk is forwarded ``latency`` seconds after it was read.
- **bandwidth**: each direction is paced by a token bucket; the proxy's receive buffers are
  kept small (``rcvbuf``, 64 KiB by default, about a 2 Mbit/s link's bandwidth-delay product
  at 250 ms) so the sender, not the proxy, holds what the link cannot carry yet.
- **cut**: every open connection is reset (``SO_LINGER`` 0), both sides see ECONNRESET.
- **refuse**: new connections are accepted and reset at once while set (a bridge that is down).

Given several targets, the proxy is also a round-robin TCP load balancer (what stands in
front of several relays): each new connection goes to the next target in turn, and a target
that refuses the connection is skipped for the next one, as a balancer's health check takes a
dead backend out. :attr:`carried` counts the connections each target got.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import socket
import struct
import threading
import time
from collections.abc import Coroutine, Sequence
from typing import Any, Self

__all__ = ["LinkProxy"]

_CHUNK = 16384


class _Pipe:
    """One direction of one proxied connection: read, hold for the faults, write."""

    def __init__(self, link: LinkProxy, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        self.link = link
        self.reader = reader
        self.writer = writer
        self.tokens = 0.0
        self.stamp = time.monotonic()
        self.bytes = 0

    async def run(self) -> None:
        link = self.link
        delayed: asyncio.Queue[tuple[float, bytes] | None] = asyncio.Queue()
        sender = asyncio.create_task(self._send(delayed))
        try:
            while True:
                await link._open.wait()  # a blackhole stops reading here
                data = await self.reader.read(_CHUNK)
                if not data:
                    break
                await link._open.wait()  # read just before the hole opened: hold it
                await self._pace(len(data))
                delayed.put_nowait((time.monotonic() + link.latency, data))
        except (ConnectionError, OSError):
            pass
        finally:
            delayed.put_nowait(None)
            with contextlib.suppress(Exception):
                await sender

    async def _pace(self, size: int) -> None:
        """Wait until the token bucket allows ``size`` bytes (no-op without a bandwidth cap)."""
        rate = self.link.bandwidth
        if rate is None:
            return
        burst = max(float(_CHUNK), rate / 20)
        while True:
            now = time.monotonic()
            self.tokens = min(burst, self.tokens + (now - self.stamp) * rate)
            self.stamp = now
            if self.tokens >= size or self.tokens >= burst:
                self.tokens -= size
                return
            await asyncio.sleep((min(size, burst) - self.tokens) / rate)

    async def _send(self, delayed: asyncio.Queue[tuple[float, bytes] | None]) -> None:
        try:
            while (item := await delayed.get()) is not None:
                due, data = item
                wait = due - time.monotonic()
                if wait > 0:
                    await asyncio.sleep(wait)
                await self.link._open.wait()
                self.writer.write(data)
                self.bytes += len(data)
                await self.writer.drain()
            if self.writer.can_write_eof():
                self.writer.write_eof()
        except (ConnectionError, OSError):
            pass


class LinkProxy:
    """Forward 127.0.0.1:``port`` to ``target`` with faults switched on and off at will.

    Use as a context manager (or :meth:`start` / :meth:`close`). ``port`` 0 picks a free port;
    :attr:`port` tells which. ``rcvbuf`` bounds what the proxy itself accepts ahead of the
    link (see the module docstring). ``target`` may be a list of addresses: connections are
    then spread over them round-robin, skipping those that refuse.
    """

    def __init__(self, target: tuple[str, int] | Sequence[tuple[str, int]], port: int = 0,
                 rcvbuf: int = 65536) -> None:
        targets = [target] if isinstance(target[0], str) else list(target)
        self.targets: list[tuple[str, int]] = targets  # type: ignore[assignment]
        self.carried: dict[tuple[str, int], int] = {t: 0 for t in self.targets}
        """Connections carried to each target so far."""
        self._turn = itertools.cycle(range(len(self.targets)))
        self.port = port
        self.rcvbuf = rcvbuf
        self.latency = 0.0
        self.bandwidth: float | None = None
        self.refusing = False
        self.connections = 0
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="linkproxy", daemon=True)
        self._open = asyncio.Event()
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._pipes: list[_Pipe] = []

    # -- life cycle ------------------------------------------------------------------------
    def start(self) -> Self:
        """Listen and return self; :attr:`port` is then the proxy's port."""
        self._thread.start()
        self._call(self._start())
        return self

    async def _start(self) -> None:
        self._open.set()
        # Buffer sizes must be set before listen/connect: TCP fixes its window scale in the SYN.
        sock = _socket(self.rcvbuf)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(("127.0.0.1", self.port))
        sock.listen(64)
        sock.setblocking(False)
        self._server = await asyncio.start_server(self._accept, sock=sock, limit=_CHUNK)
        self.port = sock.getsockname()[1]

    def close(self) -> None:
        """Reset every connection, stop listening and end the proxy's thread."""
        if not self._thread.is_alive():
            return
        self._call(self._close())
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5)
        self._loop.close()

    async def _close(self) -> None:
        self._open.set()
        self._reset_all()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
        # the pipes of reset connections: let them finish before the loop stops
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self._reset_all()  # connections that got their upstream half while the server closed

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- faults ----------------------------------------------------------------------------
    def blackhole(self) -> None:
        """Stop carrying bytes both ways, silently: no FIN, no RST (a link out of range)."""
        self._loop.call_soon_threadsafe(self._open.clear)

    def restore(self) -> None:
        """End a blackhole or a refusal: bytes flow again, new connections are carried."""
        self.refusing = False
        self._loop.call_soon_threadsafe(self._open.set)

    def set_latency(self, seconds: float) -> None:
        """Delay every chunk by ``seconds`` in each direction."""
        self.latency = seconds

    def set_bandwidth(self, bytes_per_second: float | None) -> None:
        """Cap each direction at ``bytes_per_second`` (None: no cap)."""
        self.bandwidth = bytes_per_second

    def cut(self) -> None:
        """Reset every open connection (both sides see a RST); new ones are still accepted."""
        self._call(self._cut())

    async def _cut(self) -> None:
        self._reset_all()

    def refuse(self) -> None:
        """Reset new connections at once until :meth:`restore` (the far end is down)."""
        self.refusing = True

    @property
    def bytes_forwarded(self) -> int:
        """Bytes written onwards, both directions, all connections so far."""
        return sum(p.bytes for p in self._pipes)

    # -- internals -------------------------------------------------------------------------
    def _call(self, coro: Coroutine[Any, Any, None]) -> None:
        asyncio.run_coroutine_threadsafe(coro, self._loop).result(10)

    def _reset_all(self) -> None:
        for w in list(self._writers):
            _reset(w)
        self._writers.clear()

    def _accept(
        self, c_reader: asyncio.StreamReader, c_writer: asyncio.StreamWriter
    ) -> Coroutine[Any, Any, None]:
        # Counted as open from the start: a stop or a cut before its task first runs resets it
        # too (a task cancelled before it starts never reaches its own clean-up).
        self._writers.add(c_writer)
        return self._serve(c_reader, c_writer)

    async def _serve(self, c_reader: asyncio.StreamReader, c_writer: asyncio.StreamWriter) -> None:
        try:
            await self._carry(c_reader, c_writer)
        except asyncio.CancelledError:  # the proxy stops: asyncio would log this task's end
            _reset(c_writer)

    async def _carry(self, c_reader: asyncio.StreamReader, c_writer: asyncio.StreamWriter) -> None:
        if self.refusing:
            self._writers.discard(c_writer)
            _reset(c_writer)
            return
        try:
            s_reader, s_writer = await self._connect()
        except BaseException as exc:  # refused, or the proxy stops while connecting
            self._writers.discard(c_writer)
            _reset(c_writer)
            if isinstance(exc, OSError):
                return
            raise
        self.connections += 1
        self._writers.add(s_writer)
        up, down = _Pipe(self, c_reader, s_writer), _Pipe(self, s_reader, c_writer)
        self._pipes += [up, down]
        await asyncio.gather(up.run(), down.run(), return_exceptions=True)
        for w in (c_writer, s_writer):
            if w in self._writers:
                self._writers.discard(w)
                w.close()


    async def _connect(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        """A connection to the next target in turn that takes one (OSError: none does)."""
        first = next(self._turn)
        order = self.targets[first:] + self.targets[:first]
        for i, target in enumerate(order):
            upstream = _socket(self.rcvbuf)
            upstream.setblocking(False)
            try:
                await asyncio.get_running_loop().sock_connect(upstream, target)
                pair = await asyncio.open_connection(sock=upstream, limit=_CHUNK)
            except BaseException as exc:
                upstream.close()
                if isinstance(exc, OSError) and i + 1 < len(order):
                    continue  # a dead backend: the next one
                raise
            self.carried[target] += 1
            return pair
        raise AssertionError("unreachable: the loop returns or raises")


def _socket(rcvbuf: int) -> socket.socket:
    """A TCP socket whose receive buffer (and so its advertised window) stays at ``rcvbuf``."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def _reset(writer: asyncio.StreamWriter) -> None:
    sock = writer.get_extra_info("socket")
    if sock is not None:
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    writer.transport.abort()
