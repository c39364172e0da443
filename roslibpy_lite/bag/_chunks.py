"""One topic's CDR payloads straight from an indexed MCAP file's chunks (for tables).

:func:`topic_chunks` reads the chunks that hold the topic (the summary's chunk index says
which), decompresses each once and walks its records with one ``unpack_from`` per record,
keeping ``(log time, payload)`` of the topic's messages as views of the chunk's bytes: no
record objects, no copies. A chunk's payloads are handed over as one batch, so that only
one chunk's bytes are held at a time. The order is the file's (chunks by offset, records
as written); :func:`roslibpy_lite.bag.read` gives log-time order, which a stable sort by
log time of this order reproduces (the mcap reader breaks ties by chunk offset, then by
place in the chunk).

It answers None when the file is not one it reads this way (no summary or no chunk index,
as a recording cut short; the topic's channels of more than one schema), and the caller
reads the file with :func:`roslibpy_lite.bag.read`.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..exceptions import UsageError
from ._mcap import MESSAGE_ENCODING

_RECORD = struct.Struct("<BQ")  # opcode, length
_MESSAGE = struct.Struct("<H4xQ")  # channel id, (sequence), log time
_MESSAGE_OP = 0x05
_MESSAGE_HEAD = 2 + 4 + 8 + 8


@dataclass(frozen=True)
class TopicChunks:
    """A topic's schema and its payloads, one list per chunk, in file order."""

    type_name: str
    definition: str
    batches: Iterator[list[tuple[int, memoryview]]]


def topic_chunks(path: Path, topic: str) -> TopicChunks | None:
    """The topic's messages chunk by chunk, or None (see the module docstring)."""
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
    chunks = sorted(ci.chunk_start_offset for ci in summary.chunk_indexes
                     if not ci.message_index_offsets
                     or not mine.isdisjoint(ci.message_index_offsets))
    return TopicChunks(name, text.decode("utf-8", "replace"),
                       _batches(path, chunks, frozenset(mine)))


def _batches(path: Path, chunks: list[int], channels: frozenset[int]
             ) -> Iterator[list[tuple[int, memoryview]]]:
    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk

    with path.open("rb") as stream:
        for at in chunks:
            stream.seek(at + 1 + 8, io.SEEK_SET)  # past the record's opcode and length
            try:
                data = _decompress(Chunk.read(ReadDataStream(stream)))
            except Exception as exc:
                raise UsageError(f"{path}: the chunk at byte {at} cannot be read: "
                                 f"{type(exc).__name__}: {exc}") from None
            yield _messages(path, at, memoryview(data), channels)


def _decompress(chunk: Any) -> bytes:
    if chunk.compression == "zstd":
        import zstandard

        data: bytes = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]

        data = lz4.frame.decompress(chunk.data)
    else:  # as mcap's reader takes it: stored as it is
        data = chunk.data
    return data


def _messages(path: Path, at: int, data: memoryview, channels: frozenset[int]
              ) -> list[tuple[int, memoryview]]:
    """``(log time, payload)`` of the messages of ``channels`` in one chunk's records."""
    out: list[tuple[int, memoryview]] = []
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
