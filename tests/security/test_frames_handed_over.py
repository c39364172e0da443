"""Frames handed to the session as they are read (BridgeConnection.hand_frames_to), over real
websocket connections to a server with the bridge's connection class.

A whole message with nothing queued before it skips websockets' queue and the turn of the
loop that wakes the reader; anything else keeps websockets' path, so messages stay in the
order they were sent and invalid UTF-8 still closes the connection (1007).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from bridge_server.security import Security, SecurityConfig


class Seen(list[tuple[str, str | bytes]]):
    """The messages a server connection got, each with how it came; awaitable by count."""

    def __init__(self) -> None:
        super().__init__()
        self.grew = asyncio.Event()

    def add(self, how: str, data: str | bytes) -> None:
        self.append((how, data))
        self.grew.set()

    async def until(self, count: int) -> None:
        async with asyncio.timeout(10):
            while len(self) < count:
                self.grew.clear()
                await self.grew.wait()


@asynccontextmanager
async def _server(seen: Seen, handed: bool = True) -> AsyncIterator[tuple[str, asyncio.Event]]:
    """A server whose connections record each message and how it came: ``direct`` (handed
    over as read) or ``loop`` (through ``recv``); the event is set when a connection ends."""
    ended = asyncio.Event()

    async def handler(ws: ServerConnection) -> None:
        hand_over: Callable[[Any], None] = ws.hand_frames_to  # type: ignore[attr-defined]
        if handed:
            hand_over(lambda data: seen.add("direct", data))
        try:
            async for data in ws:
                seen.add("loop", data)
        except ConnectionClosed:
            pass
        finally:
            hand_over(None)
            ended.set()

    security = Security(SecurityConfig())
    async with serve(handler, "127.0.0.1", 0, create_connection=security.connection_class,
                     compression=None) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        yield f"ws://127.0.0.1:{port}", ended


def _write_at_once(ws: ClientConnection, frames: Callable[[], None]) -> None:
    """Make the frames ``frames`` sends with the client's protocol and write them with one
    socket write, so the server reads them in one go."""
    frames()
    ws.transport.write(b"".join(ws.protocol.data_to_send()))


async def test_a_whole_message_is_handed_over_as_it_is_read() -> None:
    """Text and binary messages in one frame each reach the handler, not the reading loop."""
    seen = Seen()
    async with _server(seen) as (url, _), connect(url, compression=None) as ws:
        await ws.send('{"op": "a"}')
        await ws.send(b"\x01\x02")
        await seen.until(2)
    assert seen == [("direct", '{"op": "a"}'), ("direct", b"\x01\x02")]


async def test_without_a_handler_messages_come_through_the_loop() -> None:
    """No handler set: websockets' own path, unchanged."""
    seen = Seen()
    async with _server(seen, handed=False) as (url, _), connect(url, compression=None) as ws:
        await ws.send('{"op": "a"}')
        await seen.until(1)
    assert seen == [("loop", '{"op": "a"}')]


async def test_a_message_behind_a_fragmented_one_keeps_its_place() -> None:
    """A message in several frames goes through the loop, and a whole one read right behind
    it waits for it instead of overtaking it."""
    seen = Seen()
    async with _server(seen) as (url, _), connect(url, compression=None) as ws:
        def frames() -> None:
            ws.protocol.send_text(b'{"op": ', fin=False)
            ws.protocol.send_continuation(b'"first"}', fin=True)
            ws.protocol.send_text(b'{"op": "second"}')
        _write_at_once(ws, frames)
        await seen.until(2)
        await ws.send('{"op": "third"}')
        await seen.until(3)
    assert [data for _, data in seen] == ['{"op": "first"}', '{"op": "second"}',
                                          '{"op": "third"}']
    assert seen[0][0] == "loop" and seen[2][0] == "direct"


async def test_invalid_utf8_still_closes_the_connection_with_1007() -> None:
    """A text frame that is not UTF-8 is not handed over: websockets closes (1007) as before."""
    seen = Seen()
    async with _server(seen) as (url, ended), connect(url, compression=None) as ws:
        _write_at_once(ws, lambda: ws.protocol.send_text(b'{"op": "\xff"}'))
        async with asyncio.timeout(10):
            await ended.wait()
            await ws.wait_closed()
    assert seen == []
    assert ws.close_code == 1007


async def test_a_handler_that_raises_closes_the_connection_with_1011() -> None:
    """What the handler raises is logged and ends the connection (internal error)."""
    ended = asyncio.Event()

    def fail(data: Any) -> None:
        raise RuntimeError("boom")

    async def handler(ws: ServerConnection) -> None:
        ws.hand_frames_to(fail)  # type: ignore[attr-defined]
        try:
            async for _ in ws:
                pass
        except ConnectionClosed:
            pass
        ended.set()

    security = Security(SecurityConfig())
    async with serve(handler, "127.0.0.1", 0, create_connection=security.connection_class,
                     compression=None) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        async with connect(f"ws://127.0.0.1:{port}", compression=None) as ws:
            await ws.send("x")
            async with asyncio.timeout(10):
                await ws.wait_closed()
                await ended.wait()
    assert ws.close_code == 1011
