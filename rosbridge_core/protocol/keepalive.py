"""Noticing a dead link in seconds, without being fooled by a busy one (both ends use this).

A link that goes silent without a FIN or RST (a robot driving out of Wi-Fi range) looks
like an idle one to TCP. websockets' keepalive waits for a pong; but a pong queued behind a
large frame on a slow link can take longer than any sensible timeout, so a pong timeout
alone either notices dead links late or drops busy ones.

The evidence used here is the kernel's (``TCP_INFO``): data received from the peer, or our
own data being acknowledged by it in bulk (at least :data:`PROGRESS_BYTES` per check). Whether
the peer sent anything *after* a ping is read from the kernel's count of bytes received, not
from the time of the last data it reports, which counts in whole clock ticks (4 ms at
``HZ=250``): a pong on loopback comes back within a tick and could read as older than the
ping.

A peer that is slowly receiving a large frame acknowledges it as it arrives, and a peer that
sends to us is evidently there; the few bytes of a ping being acknowledged are not counted,
since whatever sits between us (a NAT box, a proxy, the far kernel of a hung link) may
acknowledge those. Only when the peer has shown nothing for ``interval`` seconds is it
pinged (its pong is data); when it has then shown nothing for ``timeout`` seconds *since the
ping was sent*, the link is declared dead and the connection aborted, which the usual
disconnect path handles (reconnect on the client, cleanup on the bridge). So a dead link is
noticed within about ``interval + timeout`` seconds, plus one check period (``interval / 2``).

A silence is never judged before the peer has been asked: when our own side stalled (the
event loop blocked, the process stopped) every peer looks silent for as long as the stall
lasted, though none of them was asked anything. After such a stall each silent peer is
pinged first, and dropped only if it then answers nothing for ``timeout`` seconds (a ping
that was waiting to be sent when the stall came has its ``timeout`` counted again from the
stall's end, once).

Where ``TCP_INFO`` is not available (not Linux, not TCP), :func:`watch` returns ``False``
and the caller keeps websockets' own ping/pong keepalive with the same figures.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import weakref
from collections.abc import Callable
from typing import Any

__all__ = [
    "DEFAULT_INTERVAL",
    "DEFAULT_TIMEOUT",
    "PROGRESS_BYTES",
    "SLICES",
    "supported_here",
    "tcp_state",
    "watch",
]

SLICES = 8
"""Slots the watched links of one loop are dealt into, one slot looked at a time (see
:class:`_Ticker`)."""
DEFAULT_INTERVAL = 2.0
"""Seconds without a sign of the peer before it is pinged."""
DEFAULT_TIMEOUT = 3.0
"""Further seconds without a sign of it after which the link is dead (so about 5 s in all)."""
PROGRESS_BYTES = 1024
"""Bytes of ours the peer must acknowledge between two checks to count as a sign of it."""

_TCP_INFO = getattr(socket, "TCP_INFO", None)
_INFO_SIZE = 136
_LAST_DATA_RECV = struct.Struct("=I")  # tcpi_last_data_recv, in milliseconds
_LAST_DATA_RECV_OFFSET = 52  # after 8 one-byte fields and 11 u32 fields of struct tcp_info
_BYTES_ACKED = struct.Struct("=Q")  # tcpi_bytes_acked
_BYTES_ACKED_OFFSET = 120
_BYTES_RECEIVED = struct.Struct("=Q")  # tcpi_bytes_received
_BYTES_RECEIVED_OFFSET = 128


def supported_here() -> bool:
    """Whether this platform's TCP tells when the peer was last heard (``TCP_INFO``)."""
    return _TCP_INFO is not None


def tcp_state(sock: socket.socket) -> tuple[float, int, int] | None:
    """(seconds since the peer last sent us data, bytes of ours it acknowledged in all, bytes
    of its we received in all), or ``None`` where the kernel does not tell."""
    if _TCP_INFO is None:
        return None
    try:
        info = sock.getsockopt(socket.IPPROTO_TCP, _TCP_INFO, _INFO_SIZE)
    except OSError:
        return None
    if len(info) < _INFO_SIZE:
        return None
    (data_ms,) = _LAST_DATA_RECV.unpack_from(info, _LAST_DATA_RECV_OFFSET)
    (acked,) = _BYTES_ACKED.unpack_from(info, _BYTES_ACKED_OFFSET)
    (received,) = _BYTES_RECEIVED.unpack_from(info, _BYTES_RECEIVED_OFFSET)
    return float(data_ms) / 1000.0, int(acked), int(received)


async def watch(
    transport: asyncio.Transport,
    ping: Callable[[], Any],
    on_dead: Callable[[float], None],
    interval: float = DEFAULT_INTERVAL,
    timeout: float = DEFAULT_TIMEOUT,
) -> bool:
    """Watch one connection until it dies (``on_dead(silence)`` is called and the transport
    aborted) or this task is cancelled. ``ping`` sends a websocket ping (websockets' ``ping``:
    what it returns, or the future that gives, is resolved by the pong); its answer, or any
    data the kernel saw arrive after it, shows the peer is there.

    The link is looked at every ``interval / 2`` s by its loop's one :class:`_Ticker` of that
    period, with every other link watched so: this task only waits for the verdict.

    Returns ``False`` at once if the transport cannot be judged (see the module docstring).
    """
    sock = transport.get_extra_info("socket")
    probe = _borrow(sock)
    try:
        state = tcp_state(probe) if probe is not None else None
        if state is None:
            return False
        loop = asyncio.get_running_loop()
        link = _Watched(loop, transport, probe, ping, on_dead, interval, timeout, state[1])
        ticker = _Ticker.of(loop, link.period)
        ticker.add(link)
        try:
            return await link.verdict
        finally:
            ticker.discard(link)
    finally:
        if probe is not None and probe is not sock:
            probe.detach()  # the transport's descriptor, never closed here


def _borrow(sock: Any) -> Any:
    """What ``tcp_state`` reads for the transport's socket ``sock``: a socket object of the
    transport's own descriptor, made once (uvloop's stand-in makes one at every
    ``getsockopt``: a seventh of a relay's keepalive with 5,000 connections), to be detached,
    never closed; ``sock`` itself where it has no descriptor to lend."""
    if sock is None or isinstance(sock, socket.socket):
        return sock
    try:
        return socket.socket(sock.family, sock.type, sock.proto, sock.fileno())
    except (AttributeError, OSError, ValueError):
        return sock


class _Watched:
    """One watched link: what :func:`watch` knows of its peer between two looks."""

    __slots__ = ("acked", "answered", "checked", "heard", "interval", "loop", "on_dead",
                 "period", "ping", "pinged", "probe", "received_then", "restarted", "slot",
                 "timeout", "transport", "verdict")

    def __init__(self, loop: asyncio.AbstractEventLoop, transport: asyncio.Transport,
                 probe: Any, ping: Callable[[], Any], on_dead: Callable[[float], None],
                 interval: float, timeout: float, acked: int) -> None:
        self.loop, self.transport, self.probe = loop, transport, probe
        self.ping, self.on_dead = ping, on_dead
        self.interval, self.timeout = interval, timeout
        self.period = max(0.05, interval / 2)
        now = loop.time()
        self.heard = now
        self.acked = acked
        self.pinged: float | None = None  # when the ping not answered yet was sent
        self.received_then = 0  # the bytes received from the peer in all when it was sent
        self.restarted = False  # whether its clock was restarted after a stall of ours
        self.answered = now  # when a pong last came
        self.checked = now
        self.slot = 0
        self.verdict: asyncio.Future[bool] = loop.create_future()

    def _pong(self) -> None:
        self.answered = self.loop.time()

    def look(self, now: float) -> bool:
        """One look at the link (its ticker's, every :attr:`period`): whether the watch is
        over (its :attr:`verdict` then set)."""
        if self.transport.is_closing():  # before reading: the descriptor is still its own
            return self._end(True)
        state = tcp_state(self.probe)
        if state is None:
            return self._end(True)  # the socket is gone: the connection is ending anyway
        period = self.period
        stalled = now - self.checked >= 2 * period  # our side was late: the loop was held up
        self.checked = now
        data_age, now_acked, received = state
        heard = max(self.heard, now - data_age, self.answered)
        if now_acked - self.acked >= PROGRESS_BYTES:  # the peer is taking our data: alive
            heard = now
        self.acked = now_acked
        pinged = self.pinged
        if pinged is not None and (heard > pinged or received > self.received_then):
            heard = max(heard, pinged)
            pinged = self.pinged = None  # heard of since the ping: it answered
        self.heard = heard
        silence = now - heard
        if pinged is not None:
            if stalled and not self.restarted:
                # The ping may have left only now (it was queued behind the stall): its
                # clock starts again, once, so a stall that goes on does not hide a dead peer.
                self.pinged, self.restarted = now, True
            elif now - pinged >= self.timeout:
                self.on_dead(silence)
                self.transport.abort()
                return self._end(True)
        elif silence >= self.interval:
            self.pinged, self.restarted, self.received_then = now, False, received
            with contextlib.suppress(Exception):
                _retrieve(self.ping(), self._pong)
        return False

    def _end(self, result: bool) -> bool:
        if not self.verdict.done():
            self.verdict.set_result(result)
        return True


class _Ticker:
    """The looks at every link one loop watches with one period: one timer for them all, not
    a sleeping task each (5,000 connections woke 5,000 tasks a second: a sixth of a relay's
    CPU). The links are dealt round into :data:`SLICES` slots, one slot looked at every
    ``period / SLICES`` s, so each link is looked at once a period and no turn of the loop
    looks at them all."""

    _of: weakref.WeakValueDictionary[tuple[int, float], _Ticker] = (
        weakref.WeakValueDictionary())
    """The tickers by loop and period, weakly: a ticker lives while its loop runs its task or
    a watch waits on it, so a loop dropped with watches still pending (a cycle with its
    tasks) is collected with its ticker."""

    def __init__(self, loop: asyncio.AbstractEventLoop, period: float) -> None:
        self.loop = weakref.ref(loop)
        self.period = period
        self.slots: list[dict[_Watched, None]] = [{} for _ in range(SLICES)]
        self.count = 0
        self.dealt = 0
        self.running = False
        """Its task runs (kept by its loop's timer: a ticker never holds its loop)."""

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop, period: float) -> _Ticker:
        """``loop``'s ticker of ``period`` (made when first asked for)."""
        key = (id(loop), period)
        ticker = cls._of.get(key)
        if ticker is None or ticker.loop() is not loop:  # none, or a dead loop's of that id
            ticker = cls._of[key] = cls(loop, period)
        return ticker

    def add(self, link: _Watched) -> None:
        """Look at ``link`` from now on (in the next slot dealt)."""
        link.slot = self.dealt % SLICES
        self.dealt += 1
        self.slots[link.slot][link] = None
        self.count += 1
        if not self.running:  # it ends once it watches nothing
            self.running = True
            asyncio.get_running_loop().create_task(self._run(), name=f"keepalive-{self.period:g}s")

    def discard(self, link: _Watched) -> None:
        """Look at ``link`` no more."""
        if self.slots[link.slot].pop(link, False) is None:
            self.count -= 1

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        step = self.period / SLICES
        slot = 0
        try:
            while self.count:
                await asyncio.sleep(step)
                now = loop.time()
                for link in list(self.slots[slot]):
                    try:
                        over = link.look(now)
                    except Exception as exc:  # one link's fault ends its watch, not the others'
                        if not link.verdict.done():
                            link.verdict.set_exception(exc)
                        over = True
                    if over:
                        self.discard(link)
                slot = (slot + 1) % SLICES
        finally:
            self.running = False


def _retrieve(waiter: Any, pong: Callable[[], None]) -> None:
    """Call ``pong`` when the answer to the ping ``waiter`` stands for comes (a future the
    pong resolves, or a coroutine giving one, as websockets' ``ping``), and collect the
    outcomes so that a connection closing meanwhile warns nobody."""
    def answer(g: asyncio.Future[Any]) -> None:
        if not g.cancelled() and g.exception() is None:
            pong()

    def sent(f: asyncio.Future[Any]) -> None:
        if f.cancelled() or f.exception() is not None:
            return
        inner = f.result()
        if asyncio.isfuture(inner):
            inner.add_done_callback(answer)

    if asyncio.isfuture(waiter):
        waiter.add_done_callback(answer)
    elif asyncio.iscoroutine(waiter):
        asyncio.ensure_future(waiter).add_done_callback(sent)
