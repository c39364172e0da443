"""How much an MCAP chunk may unpack to, checked before it is decompressed.

A chunk says how many bytes its records take once decompressed (``uncompressed_size``),
and readers size their buffer from it: an 8,880-byte file whose one chunk said 256 MiB
took a reader to 587 MiB. Every chunk read here is held to :func:`chunk_limit` (a
compression-ratio bound on the file's size, :data:`CHUNK_FLOOR` at least, never above
:data:`MAX_CHUNK_BYTES`) before a byte of it is decompressed, and is decompressed with
its output bounded by what it said (:func:`decompress`), so that a header that lies
cannot make it bigger: zstd's own frame header, which ``zstandard`` trusts over any
bound it is given, must agree with the chunk's, and lz4 stops at the size said.

The numbers are module attributes read at each call: a program that reads files of
stranger shape may raise them (``roslibpy_lite.bag._bounds.MAX_CHUNK_RATIO = 1000``).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import IO

MAX_CHUNK_BYTES = 1 << 30
"""No chunk unpacks to more than this (1 GiB), whatever the file's size."""

CHUNK_FLOOR = 64 << 20
"""A chunk may always unpack to this much (64 MiB: a 4 MiB point cloud or a 1080p
image of one colour, which zstd shrinks to a few hundred bytes, fits many times over)."""

MAX_CHUNK_RATIO = 100
"""Past :data:`CHUNK_FLOOR`, a chunk unpacks to at most this many times the file's size."""

_CHUNK_OP = 0x06
_MAGIC = 8
_RECORD = struct.Struct("<BQ")  # opcode, length
_HEAD = struct.Struct("<BQQQQII")  # opcode, length, start, end, uncompressed size, crc, len
_LZ4_HEAD = 19  # the longest lz4 frame header: magic, flags, block, size, dictionary, check
_ZSTD_HEAD = 18  # the longest zstd frame header


class ChunkBoundError(ValueError):
    """A chunk that says (or unpacks to) more than it may; the text names where and why."""


@dataclass(frozen=True)
class ChunkHead:
    """What a chunk record says of itself, before its data is read."""

    at: int
    uncompressed_size: int
    compression: str
    compressed_size: int
    data_at: int


def chunk_limit(file_size: int) -> int:
    """The most one chunk of a file of ``file_size`` bytes may unpack to."""
    return min(MAX_CHUNK_BYTES, max(CHUNK_FLOOR, MAX_CHUNK_RATIO * file_size))


def check_size(at: int, uncompressed_size: int, compressed_size: int, file_size: int) -> None:
    """Refuse a chunk at byte ``at`` whose size said is past :func:`chunk_limit`."""
    limit = chunk_limit(file_size)
    if uncompressed_size > limit:
        raise ChunkBoundError(
            f"the chunk at byte {at} says it unpacks to {uncompressed_size} bytes from "
            f"{compressed_size}, past the limit of {limit} bytes for a {file_size}-byte file "
            f"(roslibpy_lite.bag._bounds: {MAX_CHUNK_RATIO}x the file's size, at least "
            f"{CHUNK_FLOOR}, at most {MAX_CHUNK_BYTES})")


def read_head(stream: IO[bytes], at: int, file_size: int) -> ChunkHead:
    """The chunk record at byte ``at`` of ``stream``, its sizes checked (:func:`check_size`)
    and, for zstd and lz4, the size its frame header states checked against them."""
    stream.seek(at)
    raw = stream.read(_HEAD.size)
    if len(raw) < _HEAD.size:
        raise ChunkBoundError(f"the chunk at byte {at} is cut short in its head")
    op, _length, _start, _end, size, _crc, name_len = _HEAD.unpack(raw)
    if op != _CHUNK_OP or name_len > 32:
        raise ChunkBoundError(f"no chunk record at byte {at}")
    compression = stream.read(name_len).decode("utf-8", "replace")
    tail = stream.read(8)
    if len(tail) < 8:
        raise ChunkBoundError(f"the chunk at byte {at} is cut short in its head")
    (compressed,) = struct.unpack("<Q", tail)
    if compressed > file_size - stream.tell():
        raise ChunkBoundError(f"the chunk at byte {at} says it holds {compressed} bytes, "
                              f"past the end of the {file_size}-byte file")
    data_at = stream.tell()
    check_size(at, size, compressed, file_size)
    _check_frame(at, compression, stream.read(min(compressed, _LZ4_HEAD)), size)
    return ChunkHead(at, size, compression, compressed, data_at)


def _stated(stream: IO[bytes], head: ChunkHead) -> int:
    """The size the chunk's frame header states (-1: none; stored chunks state theirs)."""
    stream.seek(head.data_at)
    return _frame_size(head.at, head.compression, stream.read(min(head.compressed_size,
                                                                  _LZ4_HEAD)))


def _check_frame(at: int, compression: str, head: bytes, size: int) -> None:
    """Refuse a frame whose own header states a size other than the chunk's."""
    stated = _frame_size(at, compression, head)
    if stated not in (-1, size):
        raise ChunkBoundError(f"the chunk at byte {at} says it unpacks to {size} bytes, "
                              f"its {compression} frame says {stated}")


def _frame_size(at: int, compression: str, head: bytes) -> int:
    """The size a frame header states (-1: none), ``size`` for a stored chunk."""
    if compression == "zstd":
        import zstandard

        try:
            return int(zstandard.frame_content_size(head[:_ZSTD_HEAD]))
        except zstandard.ZstdError:
            raise ChunkBoundError(f"the chunk at byte {at} has no zstd frame header") from None
    if compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]

        try:
            return int(lz4.frame.get_frame_info(head)["content_size"]) or -1
        except RuntimeError:
            raise ChunkBoundError(f"the chunk at byte {at} has no lz4 frame header") from None
    if compression:
        raise ChunkBoundError(f"the chunk at byte {at} is compressed with {compression!r}, "
                              "which is not zstd or lz4")
    return -1


def decompress(at: int, compression: str, data: bytes, size: int) -> bytes:
    """A chunk's records, never more than the ``size`` it says (already bounded by
    :func:`check_size`); a chunk whose data unpacks to more or less is refused."""
    _check_frame(at, compression, data[:_LZ4_HEAD], size)  # states ``size`` or nothing
    if compression == "zstd":
        import zstandard

        try:  # ``size`` bounds the buffer when the frame states nothing
            out: bytes = zstandard.decompress(data, max_output_size=size)
        except zstandard.ZstdError as exc:
            raise ChunkBoundError(f"the chunk at byte {at} cannot be read: it does not "
                                  f"unpack to the {size} bytes it says: {exc}") from None
    elif compression == "lz4":
        import lz4.frame

        unpack = lz4.frame.LZ4FrameDecompressor()
        out = unpack.decompress(data, max_length=size)
        if not unpack.eof:
            raise ChunkBoundError(f"the chunk at byte {at} cannot be read: it unpacks to "
                                  f"more than the {size} bytes it says")
    else:
        out = data
    if len(out) != size:
        raise ChunkBoundError(f"the chunk at byte {at} cannot be read: it unpacks to "
                              f"{len(out)} bytes, it says {size}")
    return out


def check_chunks(stream: IO[bytes], file_size: int, offsets: Iterable[int] | None) -> None:
    """Hold each chunk of a file to its bounds before a reader that trusts chunk heads
    (mcap's) unpacks it: those at ``offsets`` (the summary's chunk index), or, with None,
    every chunk met walking the file's records up to where it is cut short. A compressed
    chunk whose frame states no size (rare: mcap's writers state it) is unpacked here,
    bounded, to learn it."""
    walk = offsets is None
    todo = iter(offsets or ())
    at = _MAGIC
    while True:
        if not walk:
            at = next(todo, -1)
            if at < 0:
                return
        stream.seek(at)
        raw = stream.read(_RECORD.size)
        if len(raw) < _RECORD.size:
            return
        op, length = _RECORD.unpack(raw)
        if walk and length > file_size - at - _RECORD.size:
            return  # cut short here: the reader stops here too
        if op == _CHUNK_OP:
            head = read_head(stream, at, file_size)
            if head.compression and _stated(stream, head) < 0:
                stream.seek(head.data_at)
                decompress(at, head.compression, stream.read(head.compressed_size),
                           head.uncompressed_size)
        at += _RECORD.size + length


def decompress_message(data: bytes, file_size: int) -> bytes:
    """One message of a recording compressed per message (rosbag2's ``message`` mode, zstd),
    held to the bound of a chunk of a file of ``file_size`` bytes."""
    import zstandard

    limit = chunk_limit(file_size)
    try:
        stated = zstandard.frame_content_size(data)
    except zstandard.ZstdError:
        raise ChunkBoundError("a compressed message has no zstd frame header") from None
    if stated > limit:
        raise ChunkBoundError(f"a compressed message says it unpacks to {stated} bytes from "
                              f"{len(data)}, past the limit of {limit} bytes for a "
                              f"{file_size}-byte recording")
    try:
        if stated >= 0:
            return bytes(zstandard.decompress(data, max_output_size=stated))
        parts, got = [], 0
        for part in zstandard.ZstdDecompressor().read_to_iter(data):
            got += len(part)
            if got > limit:
                raise ChunkBoundError(f"a compressed message unpacks to more than the limit "
                                      f"of {limit} bytes for a {file_size}-byte recording")
            parts.append(part)
        return b"".join(parts)
    except zstandard.ZstdError as exc:
        raise ChunkBoundError(f"a compressed message does not unpack: {exc}") from None


def check_whole_file(path: Path) -> None:
    """Refuse a zstd-compressed storage file (rosbag2's ``file`` compression mode) that
    unpacks to more than :data:`MAX_CHUNK_RATIO` times its size (:data:`CHUNK_FLOOR` at
    least), learnt by unpacking it as a stream, a MiB at a time, before anything writes
    it out whole."""
    import zstandard

    size = path.stat().st_size
    limit = max(CHUNK_FLOOR, MAX_CHUNK_RATIO * size)
    got = 0
    with path.open("rb") as raw, zstandard.ZstdDecompressor().stream_reader(raw) as stream:
        try:
            while part := stream.read(1 << 20):
                got += len(part)
                if got > limit:
                    raise ChunkBoundError(
                        f"{path} unpacks to more than {limit} bytes from {size}, past the "
                        f"limit ({MAX_CHUNK_RATIO}x its size, at least {CHUNK_FLOOR})")
        except zstandard.ZstdError as exc:
            raise ChunkBoundError(f"{path} does not unpack as zstd: {exc}") from None
