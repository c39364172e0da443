"""Many watched links cost their loop one timer, not a sleeping task each (issue 49: with
5,000 connections a relay spent a sixth of its CPU waking its keepalives), the socket the
keepalive borrows from uvloop's transport is the transport's still when the watch ends, and
the bridge's keepalive pings without a task a ping."""

from __future__ import annotations

import asyncio
import gc
import math
import weakref
from collections import Counter
from typing import Any, cast

import uvloop
from websockets.asyncio.client import connect as ws_connect
from websockets.asyncio.server import ServerConnection, serve

from bridge_server.front.websocket import WebSocketLink
from rosbridge_core.protocol import keepalive

LINKS = 200
INTERVAL = 0.4
"""A look every 0.2 s."""


class _Transport:
    """Just enough of a transport: its socket stands for itself in the patched ``tcp_state``."""

    def get_extra_info(self, name: str) -> object:
        return self if name == "socket" else None

    def is_closing(self) -> bool:
        return False

    def abort(self) -> None:
        raise AssertionError("a link that keeps answering was dropped")


async def test_many_links_share_one_timer_and_are_looked_at_in_turn(monkeypatch: Any) -> None:
    """200 links watched for a second: each is looked at once a period (at most 6 times, all
    alike within one), by a few
    dozen timers in all (one a slot of :data:`keepalive.SLICES`), where a task a link made
    1,000; and no turn of the loop looks at more than one slot's share of them."""
    loop = asyncio.get_running_loop()
    looks: Counter[int] = Counter()
    when: Counter[float] = Counter()

    def tcp_state(sock: object) -> tuple[float, int, int]:
        looks[id(sock)] += 1
        when[loop.time()] += 1
        return 0.0, 0, 0  # heard just now: never pinged

    timers = 0
    call_later = loop.call_later

    def counting(delay: float, *args: Any, **kwargs: Any) -> asyncio.TimerHandle:
        nonlocal timers
        timers += 1
        return call_later(delay, *args, **kwargs)

    monkeypatch.setattr(keepalive, "tcp_state", tcp_state)
    watches = [asyncio.create_task(keepalive.watch(cast(asyncio.Transport, _Transport()),
                                                   loop.create_future, lambda s: None,
                                                   INTERVAL, 1.0))
               for _ in range(LINKS)]
    await asyncio.sleep(0)  # each has taken its first look at the socket (not a ticker's)
    first = sum(looks.values())
    looks.clear()
    when.clear()
    monkeypatch.setattr(loop, "call_later", counting)
    await asyncio.sleep(1.0)
    monkeypatch.setattr(loop, "call_later", call_later)
    for w in watches:
        w.cancel()
    await asyncio.gather(*watches, return_exceptions=True)
    assert first == LINKS
    assert len(looks) == LINKS, f"{LINKS - len(looks)} links never looked at"
    fewest, most = min(looks.values()), max(looks.values())  # fewer on a loaded machine
    assert most <= 6 and most - fewest <= 1, sorted(set(looks.values()))
    assert timers <= 3 * keepalive.SLICES * 1.0 / (INTERVAL / 2), (
        f"{timers} timers for {LINKS} links in a second")
    assert max(when.values()) <= math.ceil(LINKS / keepalive.SLICES), (
        f"{max(when.values())} links looked at in one turn of the loop")


def test_the_borrowed_socket_stays_the_transports() -> None:
    """Under uvloop the keepalive reads TCP's state through a socket object of the
    transport's own descriptor: when the watch ends the connection still carries messages
    both ways (a closed descriptor would end it)."""
    async def main() -> None:
        async def echo(ws: ServerConnection) -> None:
            async for m in ws:
                await ws.send(m)

        async with serve(echo, "127.0.0.1", 0) as server:
            port = next(iter(server.sockets)).getsockname()[1]
            async with ws_connect(f"ws://127.0.0.1:{port}") as ws:
                assert type(ws.transport.get_extra_info("socket")).__name__ == "PseudoSocket"
                watch = asyncio.create_task(keepalive.watch(ws.transport, ws.ping,
                                                            lambda s: None, 0.2, 1.0))
                await asyncio.sleep(0.5)  # a few looks through the borrowed socket
                assert not watch.done()
                watch.cancel()
                await asyncio.gather(watch, return_exceptions=True)
                for i in range(3):
                    await ws.send(f"still here {i}")
                    assert await asyncio.wait_for(ws.recv(), 5) == f"still here {i}"

    uvloop.run(main())


async def test_the_bridge_s_ping_is_written_at_once_and_its_pong_resolves_it() -> None:
    """The bridge's keepalive pings with :meth:`WebSocketLink.ping_now`: a future its pong
    resolves (websockets' ``ping`` is a coroutine, a task a ping), which the client's pong
    resolves with the round trip; a second ping waits for none of the first."""
    got: asyncio.Queue[tuple[bool, float, float]] = asyncio.Queue()

    async def handler(conn: ServerConnection) -> None:
        ws = cast(WebSocketLink, conn)
        first, second = ws.ping_now(), ws.ping_now()
        if not (asyncio.isfuture(first) and asyncio.isfuture(second)):
            await got.put((False, -1.0, -1.0))
            return
        rtt1, rtt2 = await asyncio.wait_for(asyncio.gather(first, second), 5)
        await got.put((True, rtt1, rtt2))
        await ws.wait_closed()

    async with serve(handler, "127.0.0.1", 0, create_connection=WebSocketLink) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        async with ws_connect(f"ws://127.0.0.1:{port}", ping_interval=None) as client:
            reader = asyncio.create_task(client.wait_closed())  # reads, so it answers pings
            written_at_once, rtt1, rtt2 = await asyncio.wait_for(got.get(), 10)
            reader.cancel()
    assert written_at_once, "a ping went through a coroutine (a task a ping)"
    assert 0 <= rtt1 < 5 and 0 <= rtt2 < 5


def test_a_finished_loop_is_not_kept_by_its_ticker(monkeypatch: Any) -> None:
    """The tickers are kept per loop, weakly: a loop that watched a link and was closed,
    however it ended (its tasks cancelled, or left pending), can be collected."""
    monkeypatch.setattr(keepalive, "tcp_state", lambda sock: (0.0, 0, 0))

    async def watched_a_while() -> None:
        loop = asyncio.get_running_loop()
        watching.append(asyncio.create_task(keepalive.watch(
            cast(asyncio.Transport, _Transport()), loop.create_future, lambda s: None,
            INTERVAL, 1.0)))
        await asyncio.sleep(0.3)  # the ticker looked at it

    refs = []
    watching: list[asyncio.Task[bool]] = []
    for cancel_pending in (True, False):
        loop = asyncio.new_event_loop()
        refs.append(weakref.ref(loop))
        loop.run_until_complete(watched_a_while())
        if cancel_pending:  # as asyncio.run ends
            pending = asyncio.all_tasks(loop)
            for task in pending:
                task.cancel()
            loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            del pending, task
        loop.close()
        del loop
        watching.clear()
    gc.collect()
    assert [r() is None for r in refs] == [True, True]
