"""An MCAP file's records and messages, read with the mcap library (chunk heads bounded
first): the part of reading that rosbag2 directories of MCAP files share with plain files."""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from ..exceptions import UsageError
from ._bounds import ChunkBoundError, check_chunks
from ._mcap import MESSAGE_ENCODING, need_mcap
from ._records import BagMessage

log = logging.getLogger("roslibpy_lite.bag")


def open_reader(stream: Any) -> Any:
    from mcap.reader import make_reader

    return make_reader(stream)


def records(path: Path, topics: Iterable[str] | None, start_ns: int | None,
             end_ns: int | None) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) in log-time order; a file without summary is read
    front to back up to its last readable chunk."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    wanted = None if topics is None else set(topics)
    with path.open("rb") as stream:
        reader = open_reader(stream)
        try:
            summary = reader.get_summary()
        except McapError:
            summary = None
        indexed = summary.chunk_indexes if summary is not None else []
        try:  # mcap's reader sizes its buffers from the chunks' heads: bound them first
            check_chunks(stream, stream.seek(0, 2),
                         [ci.chunk_start_offset for ci in indexed] if indexed else None)
        except ChunkBoundError as exc:
            raise UsageError(f"{path}: {exc}") from None
        if summary is not None and indexed:
            # the time bounds are filtered here: their keyword names differ by mcap version
            for schema, channel, message in reader.iter_messages(topics=wanted,
                                                                 log_time_order=True):
                if start_ns is not None and message.log_time < start_ns:
                    continue
                if end_ns is not None and message.log_time >= end_ns:
                    continue
                yield schema, channel, message
            return
        stream.seek(0)
        count = 0
        try:
            # in file order (log-time order would hold everything back until the end)
            messages = NonSeekingReader(stream).iter_messages(log_time_order=False)
            for schema, channel, message in messages:
                if wanted is not None and channel.topic not in wanted:
                    continue
                if start_ns is not None and message.log_time < start_ns:
                    continue
                if end_ns is not None and message.log_time >= end_ns:
                    continue
                count += 1
                yield schema, channel, message
        except (McapError, EOFError, ValueError, struct.error) as exc:  # cut mid-record
            log.warning("%s ends early (%s): %d messages read up to there", path,
                        type(exc).__name__, count)


def read_mcap(path: Path, topics: Iterable[str] | None, start_ns: int | None,
              end_ns: int | None) -> Iterator[BagMessage]:
    """:func:`roslibpy_lite.bag.read` of one MCAP file."""
    need_mcap()
    texts: dict[int, str] = {}
    for schema, channel, message in records(Path(path), topics, start_ns, end_ns):
        if schema is None or channel.message_encoding != MESSAGE_ENCODING:
            continue
        text = texts.get(schema.id)
        if text is None:
            text = texts[schema.id] = bytes(schema.data).decode("utf-8", "replace")
        yield BagMessage(channel.topic, schema.name, message.log_time, message.publish_time,
                         bytes(message.data), text)
