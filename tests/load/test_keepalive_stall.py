"""The bridge's keepalive after a stall of its own: a client is asked (pinged) before it is
judged, so clients that answer survive the stall, and one that answers nothing is dropped."""

from __future__ import annotations

import asyncio
import os
import re
import signal
import time
from typing import Any, cast

from websockets.asyncio.client import connect as ws_connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.typing import Subprotocol

import roslibpy_lite
from bench.linkproxy import LinkProxy
from rosbridge_core.protocol import keepalive
from roslibpy_lite.api import ConnectionState
from tests.helpers import BridgeProcess, open_wire, roundtrip

STALL = 8.0
"""Seconds the bridge is stopped: longer than its keepalive's interval + timeout."""
KEEPALIVE = ("--keepalive-interval", "1", "--keepalive-timeout", "5")
"""The stalled bridge's keepalive: a silence of 6 s (1 + 5) drops a client without a ping
first, which the STALL exceeds; 5 s for the pong leave room for a test process busy with
what earlier tests left running (its pong once came later than 3 s in a full run)."""


async def _sid(bridge: BridgeProcess, start: int) -> int:
    """The id of the next client the bridge logs as connected (from line ``start`` on)."""
    line = await asyncio.to_thread(bridge.wait_for_line, r"client \d+ connected from", 10, start)
    match = re.search(r"client (\d+) connected", line)
    assert match is not None
    return int(match[1])


async def test_a_stall_of_the_bridge_drops_only_the_client_that_does_not_answer(
    make_bridge: Any,
) -> None:
    """The bridge process stopped (SIGSTOP) for 8 s, longer than its keepalive's interval
    and timeout together, then continued: an idle roslibpy-lite
    client and an idle raw websockets client, which send nothing but answer pings, stay
    connected and served; a client behind a blackholed link is pinged and dropped."""
    bridge = make_bridge(*KEEPALIVE)
    assert bridge.proc is not None
    pid = bridge.proc.pid
    with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
        start = len(bridge.lines)
        raw = await open_wire(bridge.url, ping_interval=None, max_size=2**20)
        raw_sid = await _sid(bridge, start)
        start = len(bridge.lines)
        async with roslibpy_lite.connect(bridge.url, ping_interval=None) as ros:
            ros_sid = await _sid(bridge, start)
            start = len(bridge.lines)
            gone = await ws_connect(f"ws://127.0.0.1:{proxy.port}", ping_interval=None,
                                    open_timeout=10)
            gone_sid = await _sid(bridge, start)
            await roundtrip(raw)
            start = len(bridge.lines)
            proxy.blackhole()
            os.kill(pid, signal.SIGSTOP)
            try:
                await asyncio.sleep(STALL)  # the stall under test, not a wait for an event
            finally:
                os.kill(pid, signal.SIGCONT)
            continued = time.monotonic()
            line = await asyncio.to_thread(bridge.wait_for_line, "no sign of it", 20, start)
            print(f"the blackholed client was dropped {time.monotonic() - continued:.1f} s "
                  "after the bridge continued")
            assert f"client {gone_sid}:" in line
            await roundtrip(raw)  # both idle clients are still served, on the same connection
            assert ros.state is ConnectionState.CONNECTED
            version = await ros.call_service("/rosapi/get_ros_version", "rosapi_msgs/srv/GetROSVersion")
            assert version["version"] == 2
            later = bridge.lines[start:]
            dropped = [x for x in later if "no sign of it" in x or "disconnected" in x]
            assert not [x for x in dropped if re.search(rf"client ({raw_sid}|{ros_sid})\b", x)], \
                dropped
            assert not [x for x in later if "connected from" in x], "a client reconnected"
            await raw.close()
            gone.transport.abort()


async def test_the_bridge_drops_a_foxglove_client_behind_a_silent_link(
    make_bridge: Any,
) -> None:
    """A Foxglove client (foxglove.websocket.v1 on the same port) behind a blackholed link is
    pinged and dropped by the bridge's keepalive like a rosbridge client."""
    bridge = make_bridge()
    with LinkProxy(("127.0.0.1", bridge.port)) as proxy:
        start = len(bridge.lines)
        ws = await ws_connect(f"ws://127.0.0.1:{proxy.port}", ping_interval=None,
                              subprotocols=[Subprotocol("foxglove.websocket.v1")],
                              open_timeout=10)
        assert '"serverInfo"' in str(await asyncio.wait_for(ws.recv(), 10))
        sid = await _sid(bridge, start)
        start = len(bridge.lines)
        proxy.blackhole()
        await asyncio.to_thread(bridge.wait_for_line, rf"client {sid}: no sign of it", 20, start)
        await asyncio.to_thread(bridge.wait_for_line, rf"client {sid} .*disconnected", 10, start)
        ws.transport.abort()


async def test_a_ping_held_up_by_a_stall_of_ours_gets_its_whole_timeout() -> None:
    """keepalive.watch over a real link with 0.2 s latency each way: a ping asked for just
    before our event loop stalls 2.5 s leaves only when the stall ends, and the peer's answer,
    0.4 s later, keeps it (the timeout, 2 s, counts again from the stall's end)."""
    accepted: asyncio.Queue[ServerConnection] = asyncio.Queue()

    async def handler(ws: ServerConnection) -> None:
        await accepted.put(ws)
        await ws.wait_closed()

    async with serve(handler, "127.0.0.1", 0, ping_interval=None) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        with LinkProxy(("127.0.0.1", port)) as proxy:
            proxy.set_latency(0.2)
            client = await ws_connect(f"ws://127.0.0.1:{proxy.port}", ping_interval=None,
                                      open_timeout=10)
            ws = await asyncio.wait_for(accepted.get(), 10)
            pings = 0
            judged = asyncio.Event()  # a second ping (the first was answered) or a drop
            dead: list[float] = []

            async def ping() -> Any:
                nonlocal pings
                pings += 1
                if pings == 1:
                    time.sleep(2.5)  # the loop held up between the ping's asking and sending
                elif pings == 2:
                    judged.set()
                return await ws.ping()

            def on_dead(silence: float) -> None:
                dead.append(silence)
                judged.set()

            watcher = asyncio.create_task(keepalive.watch(ws.transport, ping, on_dead, 0.4, 2.0))
            try:
                async with asyncio.timeout(10):
                    await judged.wait()
            finally:
                watcher.cancel()
            assert not dead, f"dropped after {dead[0]:.1f} s of silence"
            assert pings == 2
            await client.close()


class _Transport:
    """Just enough of an asyncio transport for :func:`keepalive.watch` (its socket is read
    through the patched ``tcp_state``)."""

    def __init__(self) -> None:
        self.aborted = False

    def get_extra_info(self, name: str) -> object:
        return object() if name == "socket" else None

    def is_closing(self) -> bool:
        return self.aborted

    def abort(self) -> None:
        self.aborted = True


async def test_a_pong_within_a_clock_tick_of_its_ping_counts_as_an_answer(
    monkeypatch: Any,
) -> None:
    """The kernel tells when data last came in whole clock ticks (4 ms at HZ=250), so a pong
    on loopback can read as a little older than its ping: that it came is read from the
    count of bytes received, and a peer that answers every ping is never dropped, even when
    websockets' own answer to the ping never reaches the watch."""
    loop = asyncio.get_running_loop()
    pings: list[float] = []

    def tcp_state(sock: object) -> tuple[float, int, int]:
        last = pings[-1] - 0.004 if pings else started  # the tick puts it before the ping
        return loop.time() - last, 0, 6 * len(pings)  # each pong's 6 bytes came in

    judged = asyncio.Event()  # the fifth ping (four were answered), or a drop

    def ping() -> asyncio.Future[float]:
        pings.append(loop.time())
        if len(pings) == 5:
            judged.set()
        return loop.create_future()  # never resolved: only the kernel's evidence counts

    dead: list[float] = []

    def on_dead(silence: float) -> None:
        dead.append(silence)
        judged.set()

    started = loop.time()
    monkeypatch.setattr(keepalive, "tcp_state", tcp_state)
    watcher = asyncio.create_task(keepalive.watch(cast(asyncio.Transport, _Transport()), ping,
                                                  on_dead, 0.2, 0.3))
    try:
        async with asyncio.timeout(10):
            await judged.wait()
    finally:
        watcher.cancel()
    assert not dead, f"dropped after {dead[0]:.2f} s of silence, though every ping was answered"
