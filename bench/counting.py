"""Counting the numbered frames a viewer gets without decoding them: small std_msgs/String
publish frames (:class:`Sink`), a numbered image stream in order (:class:`InOrder`), and the
wait for a step's last frames (:func:`drain_until`)."""

from __future__ import annotations

import asyncio
import re
import time
from typing import Any

SINK_PREFIX = 128
"""Bytes of a frame :class:`Sink` reads: the op's start and the String's number are in them."""
_JSON_SEQ = re.compile(rb'\{"op":"publish",.*?"msg":\{"data":"(\d+)')
# cbor-raw: the op's "bytes" key, its byte string's head, then the CDR of the String:
# encapsulation (4), the string's length (4), the decimal sequence number
_CDR_SEQ = re.compile(rb"\x65bytes(?:[\x40-\x57]|\x58.|\x59..)\x00\x01\x00\x00....(\d+)",
                      re.DOTALL)


class Sink:
    """Counts numbered std_msgs/String publish frames of one step from their first
    :data:`SINK_PREFIX` bytes (a counting viewer's, :mod:`bench.viewers`): the harness reads
    40,000 messages a second without decoding them."""

    def __init__(self, size: int) -> None:
        self.seen = bytearray(size)
        self.unique = 0
        self.frames = 0
        self.t_last = time.monotonic()

    def feed(self, prefix: bytes, _size: int = 0) -> None:
        """Count one frame from its first bytes (JSON text, or a cbor-raw binary frame: the
        CDR of a String); a frame that is not a numbered publish op counts as none."""
        m = _JSON_SEQ.match(prefix) if prefix[:1] == b"{" else _CDR_SEQ.search(prefix)
        if m is None:
            return
        self.frames += 1
        self.t_last = time.monotonic()
        seq = int(m.group(1))
        if 0 <= seq < len(self.seen) and not self.seen[seq]:
            self.seen[seq] = 1
            self.unique += 1


async def drain_until(
    sink: Any, want: int, idle: float = 1.0, limit: float = 15.0
) -> None:
    """Wait until ``sink.unique`` reaches ``want`` or nothing arrived for ``idle`` seconds
    (counted from the later of the last arrival and this call), ``limit`` seconds at most."""
    start = time.monotonic()
    deadline = start + limit
    while sink.unique < want and time.monotonic() < deadline:
        if time.monotonic() - max(sink.t_last, start) > idle:
            return
        await asyncio.sleep(0.02)


class InOrder:
    """Counts the frames of a numbered stream and those that came in order (numbered above
    every frame before them: a late or repeated frame is not); frames without a number
    (a status op) are counted apart, as ``other``."""

    def __init__(self) -> None:
        self.frames = 0
        self.other = 0
        self.last = -1
        self.t_last = time.monotonic()
        self.in_order_at: list[float] = []
        """When each frame in order came (``time.monotonic()``)."""

    @property
    def unique(self) -> int:
        """Frames in order so far (what :func:`drain_until` waits on)."""
        return len(self.in_order_at)

    def in_order_by(self, t: float) -> int:
        """Frames in order that came by ``t`` (``time.monotonic()``)."""
        return sum(at <= t for at in self.in_order_at)

    def feed(self, seq: int | None) -> None:
        """Count one frame numbered ``seq`` (``None``: not a frame of the stream)."""
        if seq is None:
            self.other += 1
            return
        self.frames += 1
        self.t_last = time.monotonic()
        if seq > self.last:
            self.in_order_at.append(self.t_last)
            self.last = seq
