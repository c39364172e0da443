"""One topic's CDR payloads straight from an indexed MCAP file's chunks (for tables).

:func:`topic_chunks` reads the chunks that hold the topic (the summary's chunk index says
which), decompresses each once and walks its records with one ``unpack_from`` per record,
keeping ``(log time, payload)`` of the topic's messages as views of the chunk's bytes: no
record objects, no copies. A zstd chunk is decompressed only up to the end of the topic's
last message in it, which the chunk's message index places: in a recording of an IMU
beside a camera, each chunk's IMU messages come before the frame that filled it, and a
table of the IMU decompresses none of the frames. A chunk's payloads are handed over as
one batch, so that only one chunk's bytes are held at a time. The order is the file's
(chunks by offset, records as written); :func:`roslibpy_lite.bag.read` gives log-time
order, which a stable sort by log time of this order reproduces (the mcap reader breaks
ties by chunk offset, then by place in the chunk).

It answers None when the file is not one it reads this way (no summary or no chunk index,
as a recording cut short; the topic's channels of more than one schema), and the caller
reads the file with :func:`roslibpy_lite.bag.read`.
"""

from __future__ import annotations

import array
import io
import struct
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..exceptions import UsageError
from ._bounds import ChunkBoundError, decompress, read_head
from ._mcap import MESSAGE_ENCODING
from ._records import TopicChunks

_RECORD = struct.Struct("<BQ")  # opcode, length
_MESSAGE = struct.Struct("<H4xQ")  # channel id, (sequence), log time
_MESSAGE_OP = 0x05
_MESSAGE_INDEX_OP = 0x07
_MESSAGE_HEAD = 2 + 4 + 8 + 8


def topic_chunks(path: Path, topic: str) -> TopicChunks | None:
    """The topic's messages of an MCAP file chunk by chunk, or None (see the module
    docstring); :func:`.reader.topic_chunks` also takes rosbag2 recordings."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    with path.open("rb") as stream:
        try:
            summary = make_reader(stream).get_summary()
        except McapError:
            summary = None
    if summary is None or not summary.chunk_indexes:
        return None
    mine = {cid for cid, ch in summary.channels.items() if ch.topic == topic
            and ch.message_encoding == MESSAGE_ENCODING and ch.schema_id in summary.schemas}
    schemas = {(summary.schemas[summary.channels[cid].schema_id].name,
                bytes(summary.schemas[summary.channels[cid].schema_id].data)) for cid in mine}
    if len(schemas) != 1:
        return None
    (name, text), = schemas
    chunks = sorted((ci.chunk_start_offset,
                     [at for cid, at in ci.message_index_offsets.items() if cid in mine])
                    for ci in summary.chunk_indexes
                    if not ci.message_index_offsets
                    or not mine.isdisjoint(ci.message_index_offsets))
    return TopicChunks(name, text.decode("utf-8", "replace"),
                       _batches(path, chunks, frozenset(mine)))


def _batches(path: Path, chunks: list[tuple[int, list[int]]], channels: frozenset[int]
             ) -> Iterator[list[tuple[int, memoryview | bytes]]]:
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk

    with path.open("rb") as stream:
        size = stream.seek(0, io.SEEK_END)
        for at, indexes in chunks:
            try:
                read_head(stream, at, size)  # its sizes bounded before anything is unpacked
                end = _last_record(stream, indexes) if indexes else None
                stream.seek(at + 1 + 8, io.SEEK_SET)  # past the record's opcode and length
                data = _decompress(at, Chunk.read(ReadDataStream(stream)), end)
            except ChunkBoundError as exc:
                raise UsageError(f"{path}: {exc}") from None
            except Exception as exc:
                raise UsageError(f"{path}: the chunk at byte {at} cannot be read: "
                                 f"{type(exc).__name__}: {exc}") from None
            yield _messages(path, at, memoryview(data), channels)


def _last_record(stream: Any, indexes: list[int]) -> int:
    """Where the last of the topic's records starts in the chunk's records, from the
    chunk's message indexes of the topic's channels (-1: it holds none)."""
    last = -1
    for at in indexes:
        size = stream.seek(0, io.SEEK_END)
        stream.seek(at, io.SEEK_SET)
        op, length = _RECORD.unpack(stream.read(_RECORD.size))
        if op != _MESSAGE_INDEX_OP or not 6 <= length <= size - at:  # read no more than is there
            raise ValueError(f"no message index at byte {at}")
        body = stream.read(length)
        offsets = array.array("Q", body[6:6 + (len(body) - 6) // 8 * 8])
        if sys.byteorder != "little":
            offsets.byteswap()
        if len(offsets) > 1:
            last = max(last, max(offsets[1::2]))  # (log time, offset) pairs
    return last


def _decompress(at: int, chunk: Any, end: int | None = None) -> bytes:
    """A chunk's records (never more than it says: :func:`._bounds.decompress`); with
    ``end`` (where the last record wanted starts), a zstd chunk only up to the end of that
    record: what follows it is never decompressed."""
    if chunk.compression == "zstd" and end is not None and end <= chunk.uncompressed_size // 2:
        import zstandard

        if end < 0:
            return b""
        reader = zstandard.ZstdDecompressor().stream_reader(chunk.data)
        head = _read(reader, end + _RECORD.size)
        length = _RECORD.unpack_from(head, end)[1]
        if end + _RECORD.size + length > chunk.uncompressed_size:
            raise ValueError(f"a record at {end} claims {length} bytes, past the chunk's "
                             f"{chunk.uncompressed_size}")
        return head + _read(reader, length)
    return decompress(at, chunk.compression, chunk.data, chunk.uncompressed_size)


def _read(reader: Any, n: int) -> bytes:
    """``n`` bytes of a decompressing reader (less only where the data ends)."""
    parts, got = [], 0
    while got < n:
        part = reader.read(n - got)
        if not part:
            raise ValueError(f"the records end {n - got} bytes short of the message index")
        parts.append(part)
        got += len(part)
    return b"".join(parts)


def _messages(path: Path, at: int, data: memoryview, channels: frozenset[int]
              ) -> list[tuple[int, memoryview | bytes]]:
    """``(log time, payload)`` of the messages of ``channels`` in one chunk's records."""
    out: list[tuple[int, memoryview | bytes]] = []
    append = out.append
    record, message = _RECORD.unpack_from, _MESSAGE.unpack_from
    end = len(data)
    pos = 0
    while pos < end:
        if pos + 9 > end:
            raise UsageError(f"{path}: the chunk at byte {at} ends inside a record")
        op, length = record(data, pos)
        start = pos + 9
        pos = start + length
        if pos > end:
            raise UsageError(f"{path}: a record in the chunk at byte {at} claims {length} "
                             f"bytes, {end - start} are left")
        if op == _MESSAGE_OP:
            if length < _MESSAGE_HEAD:
                raise UsageError(f"{path}: a message record in the chunk at byte {at} is "
                                 f"{length} bytes long, under its {_MESSAGE_HEAD}-byte head")
            channel, log_time = message(data, start)
            if channel in channels:
                append((log_time, data[start + _MESSAGE_HEAD:pos]))
    return out
