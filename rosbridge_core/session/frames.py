"""Websocket frames as a server writes them (RFC 6455 5.2): what the outbox hands its link.

A frame is text, binary, binary in two parts, or one framed already (:class:`Wire`, shared by
every client that gets a message in one encoding and spelling); :func:`frame_parts` makes the
bytes of frames a link writes as they are (no extension, no frame logging).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

__all__ = ["JOINED_BYTES", "Frame", "Wire", "frame_bytes", "frame_parts", "header", "joined"]

JOINED_BYTES = 64 * 1024
"""Largest payload whose shared frame (:class:`Wire`) is one ``bytes`` of header and payload;
a bigger one is its header and the encoding's own bytes (written one after the other: a
copy of a camera frame per client costs more than a second piece in one write)."""


class Wire:
    """A whole websocket frame as it goes on the socket: its header and payload joined, or
    for a big frame the header and then the payload, the encoding's own bytes (not copied).
    Shared by every client that gets the message in one encoding and spelling
    (:func:`~rosbridge_core.session.outbox.shared_frame`).
    """

    __slots__ = ("parts", "size")

    def __init__(self, parts: tuple[bytes, ...]) -> None:
        self.parts = parts
        self.size = sum(map(len, parts))


Frame = str | bytes | tuple[bytes, bytes] | Wire
"""One websocket frame to write: text (``str``), binary (``bytes``), binary in two parts
(a header and a payload shared with other clients, joined only into the socket write), or
one framed already (:class:`Wire`)."""


def frame_bytes(frames: Sequence[Frame]) -> bytes:
    """Unmasked, unfragmented websocket frames (RFC 6455 5.2, as a server sends them): text
    for ``str``, binary for ``bytes`` (or a pair of ``bytes``: one frame of both), one after
    the other.

    What websockets' ``send_text``/``send_binary`` would write for the same frames on a
    connection without extensions (``tests/bridge/test_outbox.py`` compares them), in a
    few operations instead of a frame object and a buffer each: on the way from ROS to a
    client, framing was a sixth of the bridge's time for a small message.
    """
    return b"".join(frame_parts(frames))


def frame_parts(frames: Sequence[Frame]) -> list[bytes]:
    """:func:`frame_bytes`, not joined: the pieces to write one after the other."""
    parts: list[bytes] = []
    add = parts.append
    for frame in frames:
        if isinstance(frame, Wire):
            parts.extend(frame.parts)
        elif isinstance(frame, str):
            data = frame.encode()
            add(header(0x81, len(data)))  # FIN, text
            add(data)
        elif isinstance(frame, tuple):  # a binary frame in two parts, not joined before
            add(header(0x82, len(frame[0]) + len(frame[1])))
            add(frame[0])
            add(frame[1])
        else:
            add(header(0x82, len(frame)))  # FIN, binary
            add(frame)
    return parts


def header(first: int, size: int) -> bytes:
    """A server frame's header: its first byte (FIN and opcode), the payload's length."""
    if size < 126:
        return bytes((first, size))
    if size < 0x10000:
        return _HEAD16(first, 126, size)
    return _HEAD64(first, 127, size)


_HEAD16 = struct.Struct("!BBH").pack
_HEAD64 = struct.Struct("!BBQ").pack


def joined(frame: Frame) -> str | bytes:
    """The frame as one ``str`` or ``bytes`` (a two-part frame joined; never a :class:`Wire`,
    which only a connection that frames its own writes gets)."""
    assert not isinstance(frame, Wire), "a framed frame where a payload was expected"
    return b"".join(frame) if isinstance(frame, tuple) else frame
