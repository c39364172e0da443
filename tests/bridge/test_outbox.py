"""The outbox's writer over a real websocket connection: an idle writer's first message is
written before ``push`` returns, what follows in the same turn goes in one write after it."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import cbor2
import pytest
from hypothesis import given
from hypothesis import strategies as st
from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.frames import Frame, Opcode

from bridge_server.front.websocket import WebSocketLink
from rosbridge_core.codec.encodings import EncodedMessage
from rosbridge_core.protocol import ops
from rosbridge_core.session.outbox import Frame as OutFrame
from rosbridge_core.session.outbox import Outbox, TopicQueue, frame_bytes
from tests.helpers import async_wait_until


class _Text:
    """Stands for an Incoming: the outbox only asks it for its JSON text (``encoded("none")``,
    and keeps its frame on it)."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.framed: dict[tuple[str, str | None], object] | None = None

    def encoded(self, encoding: str, _name: str | None = None) -> str | bytes:
        assert encoding == "none", encoding
        return self.text


@asynccontextmanager
async def _parked_outbox(
    compression: str | None,
) -> AsyncIterator[tuple[Outbox, ClientConnection, ServerConnection, asyncio.Task[None]]]:
    """An outbox on the server side of a real connection, its writer parked (idle); the
    client end reads what it writes."""
    conns: asyncio.Queue[ServerConnection] = asyncio.Queue()

    async def handler(ws: ServerConnection) -> None:
        await conns.put(ws)
        await ws.wait_closed()

    async with serve(handler, "127.0.0.1", 0, compression=compression,
                     create_connection=WebSocketLink) as server:
        port = next(iter(server.sockets)).getsockname()[1]
        async with connect(f"ws://127.0.0.1:{port}", compression=compression) as client:
            ws = await conns.get()
            assert isinstance(ws, WebSocketLink)
            box = Outbox(ws, 1, 100, 0, 5.0, warn=lambda _msg: None)
            writer = asyncio.create_task(box.writer())
            await async_wait_until(lambda: box.idle, 5.0, "the writer idle")
            yield box, client, ws, writer


@pytest.mark.parametrize("compression", [None, "deflate"])
async def test_an_idle_writer_writes_at_once_and_batches_what_follows(
    compression: str | None,
) -> None:
    """Without an extension the outbox frames what it writes; with permessage-deflate
    websockets does."""
    async with _parked_outbox(compression) as (box, client, ws, writer):
        assert bool(ws.protocol.extensions) == (compression is not None)
        writes: list[bytes] = []
        transport: Any = ws.transport
        real_write = transport.write

        def counting_write(data: bytes) -> None:
            writes.append(data)
            real_write(data)

        transport.write = counting_write
        sub = TopicQueue(box, "/t", "/t")
        box.push(sub, _Text("first"))  # type: ignore[arg-type]
        assert len(writes) == 1, "an idle writer's first message waits for no turn"
        box.push(sub, _Text("second"))  # type: ignore[arg-type]
        box.send_text("a reply")
        box.push(sub, _Text("third"))  # type: ignore[arg-type]
        assert len(writes) == 1, "what follows in the same turn waits for the writer"
        got = [await asyncio.wait_for(client.recv(), 5.0) for _ in range(4)]
        assert got == ["first", "a reply", "second", "third"]  # replies go first
        assert len(writes) == 2, "the writer wrote the three that followed at once"
        await async_wait_until(lambda: box.idle, 5.0, "the writer idle again")
        box.close()
        box.push(sub, _Text("after close"))  # type: ignore[arg-type]
        assert len(writes) == 2, "a closed outbox writes nothing"
        await asyncio.wait_for(writer, 5.0)


def _websockets_frames(frames: list[str | bytes]) -> bytes:
    return b"".join(
        Frame(Opcode.TEXT, f.encode()).serialize(mask=False, extensions=[])
        if isinstance(f, str)
        else Frame(Opcode.BINARY, f).serialize(mask=False, extensions=[])
        for f in frames
    )


@given(st.lists(st.one_of(st.text(max_size=300), st.binary(max_size=300)), max_size=5))
def test_frames_are_what_websockets_would_write(frames: list[str | bytes]) -> None:
    """The outbox's own framing gives websockets' bytes for text and binary frames."""
    assert frame_bytes(frames) == _websockets_frames(frames)


def test_frames_of_every_length_form_are_what_websockets_would_write() -> None:
    """Each payload length encoding (7-bit, 16-bit, 64-bit) at its edges, text and binary."""
    for size in (0, 1, 125, 126, 127, 65535, 65536, 70000):
        frames: list[str | bytes] = ["é" * (size // 2) + "x" * (size % 2), b"\x00" * size]
        assert frame_bytes(frames) == _websockets_frames(frames), size


def test_two_part_frames_are_one_binary_frame() -> None:
    """A (header, payload) pair is written as the one binary frame of both, at each length
    form (the Foxglove path shares the payload among clients instead of joining it)."""
    for size in (0, 1, 112, 113, 65522, 65523, 70000):
        head, payload = b"\x01" * 13, bytes(range(256)) * (size // 256) + b"\x07" * (size % 256)
        pair: list[OutFrame] = [(head, payload), "after"]
        assert frame_bytes(pair) == _websockets_frames([head + payload, "after"]), size


async def test_a_lone_message_written_at_once_leaves_the_writer_parked() -> None:
    """After a direct write with nothing following in its turn the writer is not woken (no
    task wake-up and empty round per lone reply); a message in a later turn is again written
    at once, and one that follows a direct write in its turn still waits for the writer."""
    async with _parked_outbox(None) as (box, client, _ws, writer):
        rounds = [0]
        real_take = box._take

        def counting_take() -> list[OutFrame]:
            rounds[0] += 1
            return real_take()

        box._take = counting_take  # type: ignore[method-assign]
        for i in range(3):
            box.send_text(f"reply {i}")
            assert await asyncio.wait_for(client.recv(), 5.0) == f"reply {i}"
            await async_wait_until(lambda: box.idle, 5.0, "parked again")
        assert rounds[0] == 3, "each lone reply: one take (the direct write), no writer round"
        box.send_text("a")
        box.send_text("b")  # follows a direct write in its turn: the writer sends it
        assert [await asyncio.wait_for(client.recv(), 5.0) for _ in range(2)] == ["a", "b"]
        await async_wait_until(lambda: box.idle, 5.0, "parked after the burst")
        box.close()
        await asyncio.wait_for(writer, 5.0)


async def test_replies_alone_ask_the_link_once_whether_to_frame() -> None:
    """Whether frames may be written framed (``raw_ok``) matters to a topic message's shared
    frame: a reply written at once asks once (the link's write); a message queued behind one
    twice more (taken framed by the writer, then written)."""
    async with _parked_outbox(None) as (box, client, ws, writer):
        assert isinstance(ws, WebSocketLink)
        asked = [0]
        real_raw_ok = ws.raw_ok

        def counting_raw_ok() -> bool:
            asked[0] += 1
            return real_raw_ok()

        ws.raw_ok = counting_raw_ok  # type: ignore[method-assign]
        box.send_text("a reply")
        assert await asyncio.wait_for(client.recv(), 5.0) == "a reply"
        assert asked[0] == 1, "a reply alone: only the write asks"
        await async_wait_until(lambda: box.idle, 5.0, "parked again")
        box.send_text("another reply")
        box.push(TopicQueue(box, "/t", "/t"), _Text("a message"))  # type: ignore[arg-type]
        got = [await asyncio.wait_for(client.recv(), 5.0) for _ in range(2)]
        assert got == ["another reply", "a message"]
        assert asked[0] == 4, "the reply's write, then the message's take and write"
        box.close()
        await asyncio.wait_for(writer, 5.0)


class _Raw(_Text):
    """Stands for an Incoming with a cbor-raw encoding too (the bytes it hands out are kept,
    as an Incoming keeps its encodings)."""

    def __init__(self, text: str, raw: bytes) -> None:
        super().__init__(text)
        self.raw = raw

    def encoded(self, encoding: str, _name: str | None = None) -> str | bytes:
        return self.raw if encoding == "cbor-raw" else super().encoded(encoding)


def _record_writes(ws: ServerConnection) -> list[tuple[bytes, ...]]:
    """What the outbox hands the connection's transport, one tuple of pieces per call."""
    calls: list[tuple[bytes, ...]] = []
    transport: Any = ws.transport
    real_write, real_writelines = transport.write, transport.writelines

    def write(data: bytes) -> None:
        calls.append((data,))
        real_write(data)

    def writelines(parts: Any) -> None:
        parts = tuple(parts)
        calls.append(parts)
        transport.write = real_write  # asyncio's writelines writes them joined: not a call
        try:
            real_writelines(parts)
        finally:
            transport.write = write

    transport.write, transport.writelines = write, writelines
    return calls


async def test_a_message_is_framed_once_and_its_bytes_written_to_every_viewer() -> None:
    """Two clients' idle outboxes write the very same frame bytes of a message (made once,
    kept on the message); a big cbor-raw payload goes out as the encoding's own bytes after
    its header, not copied into a frame per client."""
    async with _parked_outbox(None) as (box1, client1, ws1, w1), \
            _parked_outbox(None) as (box2, client2, ws2, w2):
        calls1, calls2 = _record_writes(ws1), _record_writes(ws2)
        small = _Text("a small message")
        box1.push(TopicQueue(box1, "/t", "/t"), small)  # type: ignore[arg-type]
        box2.push(TopicQueue(box2, "/t", "/t"), small)  # type: ignore[arg-type]
        assert len(calls1) == len(calls2) == 1
        assert calls1[0][0] is calls2[0][0], "one frame's bytes for both clients"
        assert small.framed is not None and len(small.framed) == 1
        assert [await client1.recv(), await client2.recv()] == ["a small message"] * 2
        await async_wait_until(lambda: box1.idle and box2.idle, 5.0, "both parked")

        payload = bytes(range(256)) * 1024  # 256 KiB, a frame of the 64-bit length form
        big = _Raw("unused", payload)
        for box in (box1, box2):
            sub = TopicQueue(box, "/img", "/img")
            sub.ids["i"] = ops.Subscribe(topic="/img", compression="cbor-raw")
            sub.configure(10)
            box.push(sub, big)  # type: ignore[arg-type]  # written at once: both parked
        assert calls1[-1][-1] is payload and calls2[-1][-1] is payload, "the payload not copied"
        assert [await client1.recv(), await client2.recv()] == [payload] * 2
        for box, writer in ((box1, w1), (box2, w2)):
            box.close()
            await asyncio.wait_for(writer, 5.0)


class _Received(EncodedMessage):
    """A received message as both ROS sides give it: its CDR bytes, encoded by the bridge's
    own encodings (its CBOR object: the bytes under ``data``)."""

    __slots__ = ()

    def cbor_obj(self) -> Any:
        return {"data": self.data}


async def test_a_cbor_raw_camera_frame_is_written_without_copying_its_bytes() -> None:
    """A cbor-raw camera frame goes to the socket as the frame's and the op's heads and then
    the very bytes the ROS side received (neither CBOR nor websocket framing copies them),
    and the client reads the op cbor2 makes of it."""
    async with _parked_outbox(None) as (box, client, ws, writer):
        calls = _record_writes(ws)
        data = bytes(range(256)) * 3600  # a 640x480 rgb8 frame's size
        frame = _Received("/camera", data, 1_700_000_000_123_456_789)
        sub = TopicQueue(box, "/camera", "/camera")
        sub.ids["i"] = ops.Subscribe(topic="/camera", compression="cbor-raw")
        sub.configure(10)
        box.push(sub, frame)  # written at once: parked
        assert len(calls) == 1 and calls[0][-1] is data, "the payload not copied"
        assert len(calls[0]) == 2, "the websocket and CBOR heads in one piece before it"
        got = await asyncio.wait_for(client.recv(), 5.0)
        assert got == cbor2.dumps({"op": "publish", "topic": "/camera", "msg": {
            "secs": 1_700_000_000, "nsecs": 123_456_789, "bytes": data}})
        box.close()
        await asyncio.wait_for(writer, 5.0)


async def test_a_cbor_camera_frame_is_written_without_joining_its_envelope() -> None:
    """A big message over cbor goes to the socket as the frame's and the op's heads and then
    the message's CBOR as the encoding made it (not copied into one buffer with the
    envelope), and the client reads the op cbor2 makes of it."""
    async with _parked_outbox(None) as (box, client, ws, writer):
        calls = _record_writes(ws)
        frame = _Received("/camera", bytes(range(256)) * 3600, 1_700_000_000_123_456_789)
        sub = TopicQueue(box, "/camera", "/camera")
        sub.ids["i"] = ops.Subscribe(topic="/camera", compression="cbor")
        sub.configure(10)
        box.push(sub, frame)  # written at once: parked
        encoded = frame.encoded("cbor")
        assert isinstance(encoded, tuple) and calls == [(calls[0][0], encoded[1])]
        assert calls[0][-1] is encoded[1], "the message's CBOR not copied"
        got = await asyncio.wait_for(client.recv(), 5.0)
        assert got == cbor2.dumps({"op": "publish", "topic": "/camera",
                                   "msg": {"data": frame.data}})
        box.close()
        await asyncio.wait_for(writer, 5.0)
