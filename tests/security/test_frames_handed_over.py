"""Frames handed to the session as they are read (BridgeConnection.hand_frames_to), over real
websocket connections to a server with the bridge's connection class.

A whole message with nothing queued before it skips websockets' queue and the turn of the
loop that wakes the reader; anything else keeps websockets' path, so messages stay in the
order they were sent and invalid UTF-8 still closes the connection (1007). At a frame
boundary the bridge reads whole data frames itself (BridgeConnection.data_received): the
bytes it reads are the frames websockets would have made, and what it does not take
(control frames, a frame cut off by the read, what websockets refuses) is websockets' again.
"""

from __future__ import annotations

import asyncio
import struct
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from bridge_server.front.handshake import Security
from rosbridge_core.security import SecurityConfig


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
async def _server(seen: Seen, handed: bool = True,
                  max_size: int = 2**20) -> AsyncIterator[tuple[str, asyncio.Event]]:
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
                     compression=None, max_size=max_size) as server:
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


def _client_frame(payload: bytes, head: int = 0x81, mask: bytes = b"\x00\x00\x00\x00") -> bytes:
    """One frame as a client sends it (``head``: FIN, reserved bits, opcode), masked with
    ``mask`` (all zeros: the payload shows as it is), or unmasked with ``mask=b""``."""
    size = len(payload)
    bit = 0x80 if mask else 0
    if size < 126:
        length = bytes((bit | size,))
    elif size < 0x10000:
        length = bytes((bit | 126,)) + struct.pack("!H", size)
    else:
        length = bytes((bit | 127,)) + struct.pack("!Q", size)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload)) if mask else payload
    return bytes((head,)) + length + mask + masked


async def test_several_whole_messages_read_at_once_are_each_handed_over() -> None:
    """Messages of every length encoding (7, 16 and 64 bits), text and binary, written at once,
    each reach the handler whole and in order."""
    seen = Seen()
    long_text = "é" * 100 + "x" * 20
    big = bytes(range(256)) * 300
    async with _server(seen) as (url, _), connect(url, compression=None) as ws:
        def frames() -> None:
            ws.protocol.send_text(b'{"op": "short"}')
            ws.protocol.send_text(long_text.encode())
            ws.protocol.send_binary(big)
            ws.protocol.send_text(b"")
        _write_at_once(ws, frames)
        await seen.until(4)
    assert seen == [("direct", '{"op": "short"}'), ("direct", long_text), ("direct", big),
                    ("direct", "")]


async def test_bytes_in_the_middle_of_a_frame_are_never_read_as_a_frame() -> None:
    """A frame cut off by a read is finished by websockets: the rest of it, even when it looks
    like a whole frame of its own, is that frame's payload; the next frame is read at once."""
    seen = Seen()
    inner = _client_frame(b"inner")
    payload = b"0123456789" + inner
    outer = _client_frame(payload, head=0x82)
    cut = len(outer) - len(inner)  # the second read starts with the inner frame's bytes
    async with _server(seen) as (url, _), connect(url, compression=None) as ws:
        ws.transport.write(_client_frame(b"first") + outer[:cut])
        await seen.until(1)
        ws.transport.write(outer[cut:])
        await seen.until(2)
        await ws.send("last")
        await seen.until(3)
    assert seen == [("direct", "first"), ("direct", payload), ("direct", "last")]


async def test_a_read_ending_after_a_frames_header_leaves_its_payload_to_websockets() -> None:
    """A read that ends right after a frame's header and mask leaves websockets' parser
    inside that frame with nothing buffered: the next read, a whole frame to look at, is still
    that frame's payload (the parser seen waiting for a frame before that read is not taken
    to wait there still)."""
    seen = Seen()
    inner = _client_frame(b"inner")
    outer = _client_frame(inner, head=0x82)
    cut = len(outer) - len(inner)  # the header and mask
    async with _server(seen) as (url, _), connect(url, compression=None) as ws:
        ws.transport.write(_client_frame(b"first") + outer[:cut])
        await seen.until(1)
        await asyncio.sleep(0.1)  # the two reads apart
        ws.transport.write(outer[cut:])
        await seen.until(2)
        await ws.send("last")
        await seen.until(3)
    assert seen == [("direct", "first"), ("direct", inner), ("direct", "last")]


async def test_a_ping_between_messages_is_answered_and_keeps_them_in_order() -> None:
    """A ping read between two messages goes to websockets, which answers it; the messages
    around it arrive in order, the one after it too."""
    seen = Seen()
    async with _server(seen) as (url, _), connect(url, compression=None) as ws:
        ws.transport.write(_client_frame(b"before") + _client_frame(b"", head=0x89)
                           + _client_frame(b"after"))
        await seen.until(2)
        async with asyncio.timeout(10):
            await (await ws.ping())
        await ws.send("again")
        await seen.until(3)
    assert seen == [("direct", "before"), ("direct", "after"), ("direct", "again")]


@pytest.mark.parametrize(("frame", "code"), [
    (_client_frame(b"x" * 2000), 1009),  # over max_size
    (_client_frame(b"x", mask=b""), 1002),  # not masked
    (_client_frame(b"x", head=0xC1), 1002),  # a reserved bit without an extension
], ids=["too-big", "unmasked", "reserved-bit"])
async def test_frames_websockets_refuses_still_close_the_connection(frame: bytes,
                                                                    code: int) -> None:
    """A frame websockets would refuse is never handed over, and it closes the connection
    with the code it always did."""
    seen = Seen()
    async with _server(seen, max_size=1000) as (url, ended), connect(url, compression=None) as ws:
        ws.transport.write(frame)
        async with asyncio.timeout(10):
            await ended.wait()
            await ws.wait_closed()
    assert seen == []
    assert ws.close_code == code


async def test_a_new_message_inside_a_fragmented_one_closes_the_connection_with_1002() -> None:
    """A text frame that is not final, then (read apart from it) a new whole text frame
    instead of its continuation: websockets' protocol error (1002), and neither frame is
    handed to the session, though the second looks like a whole message at a frame start."""
    seen = Seen()
    async with _server(seen) as (url, ended), connect(url, compression=None) as ws:
        ws.transport.write(_client_frame(b'{"op": "first', head=0x01))  # text, FIN not set
        async with asyncio.timeout(10):
            await (await ws.ping())  # the fragment has been read: the new frame is read apart
        ws.transport.write(_client_frame(b'{"op": "second"}'))
        closed = asyncio.ensure_future(ended.wait())
        handed = asyncio.ensure_future(seen.until(1))
        await asyncio.wait([closed, handed], timeout=10, return_when=asyncio.FIRST_COMPLETED)
        handed.cancel()
        assert seen == []
        async with asyncio.timeout(10):
            await closed
            await ws.wait_closed()
    assert ws.close_code == 1002
