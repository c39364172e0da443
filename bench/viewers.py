"""Many websocket viewers in one process that count frames without decoding them.

A benchmark's viewers must cost less than the server they measure: a websockets client
decodes and parses every frame, about as much Python per frame as the server spends on it,
so 100-200 of them in the harness's own process measured the harness. Here each viewer is
an asyncio protocol that reads the frame headers off the byte stream and skips the payloads
(a 1 MiB camera frame costs a header parse), and :class:`ViewerPool` runs them in
``processes`` child processes of their own. Only the first viewer of each process decodes
what it gets, to check the content (a ``publish`` op of the topic, numbered in order) and
to time it when the message carries a stamp.

Run as a program (``python bench/viewers.py URL COUNT SUBSCRIBE_JSON``), it opens COUNT
viewers, sends each the subscribe op, waits until the server has read it (an op it answers
with an error status, read after the subscribe), prints ``{"event": "ready"}``, then prints
the counts each time a line arrives on stdin and ends when stdin closes.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import re
import struct
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from websockets.frames import Frame, Opcode

__all__ = ["Viewer", "ViewerPool", "cpu_seconds", "open_viewer"]

_SYNC = json.dumps({"op": "publish", "msg": {}})  # no topic: an error status comes back
PREFIX = 24
"""Bytes of each frame a counting viewer looks at: the op's name is in them (JSON or CBOR)."""
WARM_UP = 20
"""Messages numbered below this are not timed (the publisher's and the server's start)."""
_STAMP = re.compile(rb"(\d+) (\d{6,})")  # "<seq> <monotonic ns>" of the bench publishers


def _client_frame(text: str) -> bytes:
    """One masked client text frame."""
    return Frame(Opcode.TEXT, text.encode()).serialize(mask=True, extensions=[])


class Viewer(asyncio.Protocol):
    """One raw websocket connection that counts the data frames it receives."""

    def __init__(self, request: bytes, decode: bool, prefix: int = PREFIX,
                 on_frame: Callable[[bytes, int], None] | None = None) -> None:
        """``prefix``: bytes of each frame looked at; ``on_frame(prefix, size)``, if given, is
        called with them and the payload's size for every data frame after the sync (a
        status too)."""
        self.request = request
        self.decode = decode
        self.prefix_len = prefix
        self.on_frame = on_frame
        self.size = 0  # the current frame's payload size
        self.transport: asyncio.Transport | None = None
        self.opened: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.synced: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self.closed = asyncio.get_running_loop().create_future()
        self.handshake = b""
        self.head = bytearray()  # the bytes of a frame header read so far
        self.left = 0  # payload bytes of the current frame still to come
        self.opcode = 0
        self.payload: bytearray | None = None  # kept when decoding (or for control frames)
        self.prefix = bytearray()  # a frame's first bytes: what it is, without decoding it
        self.frames = 0  # data frames since the server read the subscribe
        self.published = 0  # of those, publish ops (checked on the decoding viewer only)
        self.last_seq = -1
        self.seqs: list[int] = []  # the numbers the decoding viewer got
        self.out_of_order = 0
        self.latencies: list[float] = []

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        transport.write(self.request)

    def connection_lost(self, exc: Exception | None) -> None:
        for fut in (self.opened, self.synced, self.closed):
            if not fut.done():
                fut.set_result(None)

    def close(self) -> None:
        """Send a close frame and close the connection."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(Frame(Opcode.CLOSE, b"\x03\xe8").serialize(  # 1000
                mask=True, extensions=[]))
            self.transport.close()

    def send(self, text: str) -> None:
        """Send one text frame."""
        assert self.transport is not None
        self.transport.write(_client_frame(text))

    def data_received(self, data: bytes) -> None:
        if not self.opened.done():
            self.handshake += data
            end = self.handshake.find(b"\r\n\r\n")
            if end < 0:
                return
            if not self.handshake.startswith(b"HTTP/1.1 101"):
                assert self.transport is not None
                self.transport.close()
                self.opened.set_exception(
                    ConnectionError(self.handshake[:end].decode(errors="replace")))
                return
            data = self.handshake[end + 4:]
            self.handshake = b""
            self.opened.set_result(None)
        pos, n = 0, len(data)
        while pos < n:
            if self.left:  # inside a payload: skip it (or keep it when decoding)
                take = min(self.left, n - pos)
                if self.payload is not None:
                    self.payload += data[pos:pos + take]
                elif len(self.prefix) < self.prefix_len:
                    self.prefix += data[pos:pos + min(take, self.prefix_len - len(self.prefix))]
                pos += take
                self.left -= take
                if not self.left:
                    self._frame_done()
                continue
            head = self.head
            need = 2
            while pos < n and len(head) < need:
                head.append(data[pos])
                pos += 1
                if len(head) == 2:
                    size = head[1] & 0x7F
                    need = 2 + (2 if size == 126 else 8 if size == 127 else 0)
            if len(head) < need:
                return
            size = head[1] & 0x7F
            if size == 126:
                size = struct.unpack_from("!H", head, 2)[0]
            elif size == 127:
                size = struct.unpack_from("!Q", head, 2)[0]
            self.opcode = head[0] & 0x0F
            head.clear()
            keep = self.decode or self.opcode >= 0x8 or not self.synced.done()
            self.payload = bytearray() if keep else None
            self.prefix.clear()
            self.left = self.size = size
            if not size:
                self._frame_done()

    def _frame_done(self) -> None:
        opcode, payload = self.opcode, self.payload
        self.payload = None
        if opcode == 0x9:  # ping: answer it, or the server's keepalive drops us
            assert self.transport is not None and payload is not None
            self.transport.write(Frame(Opcode.PONG, bytes(payload)).serialize(
                mask=True, extensions=[]))
            return
        if opcode >= 0x8 or opcode == 0x0:  # close, pong; continuations count with their first
            return
        if not self.synced.done():
            assert payload is not None
            if b'"status"' in payload[:64]:
                self.synced.set_result(None)
            return
        if self.on_frame is not None:
            self.on_frame(bytes(payload if payload is not None else self.prefix), self.size)
        if payload is not None:
            self.frames += 1
            self._check(bytes(payload), time.monotonic_ns())
        elif b"publish" in self.prefix:  # not a status (a drop report)
            self.frames += 1

    def _check(self, payload: bytes, now: int) -> None:
        if payload[:64].find(b"publish") < 0:
            self.frames -= 1  # a status or another op: not a message
            return
        self.published += 1
        m = _STAMP.search(payload[:512])
        if m is None:
            return
        seq, stamp = int(m.group(1)), int(m.group(2))
        if seq <= self.last_seq:
            self.out_of_order += 1
        self.last_seq = seq
        self.seqs.append(seq)
        if seq >= WARM_UP:
            self.latencies.append((now - stamp) / 1e6)


async def open_viewer(url: str, subscribe: str, prefix: int = PREFIX,
                      on_frame: Callable[[bytes, int], None] | None = None) -> Viewer:
    """One counting viewer in this process (see :class:`Viewer`), once the server has read
    its ``subscribe`` (JSON text)."""
    return await _open(url, subscribe, False, prefix, on_frame)


async def _open(url: str, subscribe: str, decode: bool, prefix: int = PREFIX,
                on_frame: Callable[[bytes, int], None] | None = None) -> Viewer:
    parts = urlsplit(url)
    key = base64.b64encode(os.urandom(16)).decode()
    path = parts.path or "/"
    request = (f"GET {path} HTTP/1.1\r\nHost: {parts.netloc}\r\nUpgrade: websocket\r\n"
               f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
               "Sec-WebSocket-Version: 13\r\n\r\n").encode()
    loop = asyncio.get_running_loop()
    assert parts.hostname is not None and parts.port is not None, url
    _, viewer = await loop.create_connection(lambda: Viewer(request, decode, prefix, on_frame),
                                             parts.hostname, parts.port)
    await asyncio.wait_for(viewer.opened, 30)
    viewer.send(subscribe)
    viewer.send(_SYNC)
    await asyncio.wait_for(viewer.synced, 30)
    return viewer


async def _serve(url: str, count: int, subscribe: str) -> None:
    viewers: list[Viewer] = []
    deadline = time.monotonic() + 30
    while len(viewers) < count:  # a relay answers 404 until the robot is there: try again
        try:
            viewers.append(await _open(url, subscribe, decode=not viewers))
        except (ConnectionError, OSError):
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.2)
    print(json.dumps({"event": "ready"}), flush=True)
    reader = asyncio.StreamReader()
    loop = asyncio.get_running_loop()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    while await reader.readline():
        first = viewers[0]
        print(json.dumps({"event": "counts", "frames": [v.frames for v in viewers],
                          "checked": first.published, "out_of_order": first.out_of_order,
                          "seqs": first.seqs,
                          "latencies_ms": first.latencies}), flush=True)
    for v in viewers:
        v.close()


class ViewerPool:
    """``count`` viewers of one subscription spread over ``processes`` processes."""

    def __init__(self, url: str, count: int, subscribe: dict[str, Any], processes: int = 4
                 ) -> None:
        self.url = url
        self.subscribe = json.dumps(subscribe)
        sizes = [count // processes + (i < count % processes) for i in range(processes)]
        self.sizes = [s for s in sizes if s]
        self.procs: list[asyncio.subprocess.Process] = []

    @property
    def pids(self) -> list[int]:
        """The viewer processes' ids."""
        return [p.pid for p in self.procs]

    async def start(self, timeout: float = 60.0) -> ViewerPool:
        """Start the processes and wait until every viewer's subscribe was read."""
        for size in self.sizes:
            self.procs.append(await asyncio.create_subprocess_exec(
                sys.executable, str(Path(__file__).resolve()), self.url, str(size),
                self.subscribe, stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE))
        for p in self.procs:
            await self._event(p, "ready", timeout)
        return self

    @staticmethod
    async def _event(p: asyncio.subprocess.Process, name: str, timeout: float) -> dict[str, Any]:
        assert p.stdout is not None
        while True:
            line = await asyncio.wait_for(p.stdout.readline(), timeout)
            if not line:
                raise RuntimeError(f"a viewer process ended before {name!r}")
            with contextlib.suppress(ValueError):
                ev: dict[str, Any] = json.loads(line)
                if ev.get("event") == name:
                    return ev

    async def counts(self) -> dict[str, Any]:
        """Frames per viewer, and what the decoding viewers checked."""
        frames: list[int] = []
        checked = out_of_order = 0
        lat: list[float] = []
        seqs: list[int] = []
        for p in self.procs:
            assert p.stdin is not None
            p.stdin.write(b"count\n")
        for p in self.procs:
            ev = await self._event(p, "counts", 30)
            frames += ev["frames"]
            checked += ev["checked"]
            out_of_order += ev["out_of_order"]
            lat += ev["latencies_ms"]
            seqs = seqs or ev["seqs"]
        return {"frames": frames, "checked": checked, "out_of_order": out_of_order,
                "latencies_ms": lat, "seqs": seqs}

    async def close(self) -> None:
        """Close the viewers and end the processes."""
        for p in self.procs:
            if p.stdin is not None:
                with contextlib.suppress(Exception):
                    p.stdin.close()
        for p in self.procs:
            try:
                await asyncio.wait_for(p.wait(), 10)
            except TimeoutError:
                p.kill()
                await p.wait()


if __name__ == "__main__":
    asyncio.run(_serve(sys.argv[1], int(sys.argv[2]), sys.argv[3]))


def cpu_seconds(pids: list[int], system: bool = False) -> float:
    """CPU seconds of the processes so far (``system``: the kernel's share only)."""
    import psutil

    total = 0.0
    for pid in pids:
        t = psutil.Process(pid).cpu_times()
        total += t.system if system else t.user + t.system
    return total
