"""Reading ROS 2 MCAP files: ours, rosbag2's and other tools' (see the package docstring)."""

from __future__ import annotations

import functools
import logging
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..exceptions import UsageError
from ..messages import RawMessage
from ._bounds import ChunkBoundError, check_chunks
from ._mcap import MESSAGE_ENCODING, need_mcap

if TYPE_CHECKING:
    from msgs.runtime import Message

__all__ = ["BagInfo", "BagMessage", "TopicInfo", "info", "read"]

log = logging.getLogger("roslibpy_lite.bag")


@functools.lru_cache(maxsize=256)
def _message_class(type_name: str, definition: str) -> type[Message]:
    """The class of a file's schema, built once per (name, text), not once per message."""
    from msgs.dynamic import load
    from msgs.runtime import Message

    cls = load(type_name, definition)
    if not (isinstance(cls, type) and issubclass(cls, Message)):
        raise UsageError(f"{type_name} is not a message type")
    return cls


@dataclass(frozen=True, slots=True)
class BagMessage:
    """One recorded message: CDR bytes, times, and its type's definition from the file."""

    topic: str
    type_name: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    definition: str

    def decode(self) -> Message:
        """The typed message, its class built from the file's schema when msgs lacks it.

        Raises:
            msgs.parser.DefinitionError: the schema does not parse.
            msgs.cdr.CdrError: the bytes do not decode as the schema says.
        """
        from msgs.cdr import decode

        cls = _message_class(self.type_name, self.definition)
        return cls.from_json(decode(self.data, cls))

    def raw(self) -> RawMessage:
        """The same message as a :class:`~roslibpy_lite.RawMessage` (publish time as stamp)."""
        return RawMessage(self.topic, self.type_name, self.data, self.publish_time_ns)

    def __repr__(self) -> str:
        return (f"BagMessage(topic={self.topic!r}, type_name={self.type_name!r}, "
                f"log_time_ns={self.log_time_ns}, data=<{len(self.data)} bytes>)")


@dataclass
class TopicInfo:
    """One topic of a file."""

    topic: str
    type_name: str
    messages: int
    qos: str = ""  # rosbag2's offered_qos_profiles, when the writer gave them


@dataclass
class BagInfo:
    """What :func:`info` tells about a file. ``complete``: it has its summary (a file
    from a recorder that was killed has not, and is read up to its last whole chunk)."""

    path: Path
    size: int
    messages: int
    start_ns: int
    end_ns: int
    topics: list[TopicInfo] = field(default_factory=list)
    complete: bool = True
    library: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Seconds from the first message to the last."""
        return (self.end_ns - self.start_ns) / 1e9 if self.messages else 0.0


def _reader(stream: Any) -> Any:
    from mcap.reader import make_reader

    return make_reader(stream)


def _records(path: Path, topics: Iterable[str] | None, start_ns: int | None,
             end_ns: int | None) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) in log-time order; a file without summary is read
    front to back up to its last readable chunk."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    wanted = None if topics is None else set(topics)
    with path.open("rb") as stream:
        reader = _reader(stream)
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


def read(path: str | Path, topics: Iterable[str] | None = None, *,
         start_ns: int | None = None, end_ns: int | None = None) -> Iterator[BagMessage]:
    """The messages of a ROS 2 MCAP file in log-time order (only ``topics``, if given;
    ``start_ns``/``end_ns`` bound the log time). ``msg.decode()`` gives typed messages.

    A rosbag2 recording (its directory, or a bare ``.db3`` file) is read as well, with the
    rosbag2 extra (publish time = log time, which is all a .db3 keeps)."""
    from . import _rosbag2

    if _rosbag2.is_rosbag2(Path(path)):
        yield from _rosbag2.read(Path(path), topics, start_ns, end_ns)
        return
    need_mcap()
    texts: dict[int, str] = {}
    for schema, channel, message in _records(Path(path), topics, start_ns, end_ns):
        if schema is None or channel.message_encoding != MESSAGE_ENCODING:
            continue
        text = texts.get(schema.id)
        if text is None:
            text = texts[schema.id] = bytes(schema.data).decode("utf-8", "replace")
        yield BagMessage(channel.topic, schema.name, message.log_time, message.publish_time,
                         bytes(message.data), text)


def info(path: str | Path) -> BagInfo:
    """Topics, types, counts, times and size of a file (from its summary, else by reading),
    or of a rosbag2 recording (from its metadata; the rosbag2 extra)."""
    from . import _rosbag2

    if _rosbag2.is_rosbag2(Path(path)):
        return _rosbag2.info(Path(path))
    need_mcap()
    from mcap.exceptions import McapError

    path = Path(path)
    size = path.stat().st_size
    with path.open("rb") as stream:
        reader = _reader(stream)
        try:
            summary = reader.get_summary()
            header = reader.get_header()
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        except McapError:
            summary, header, metadata = None, None, {}
    if summary is not None and summary.statistics is not None:
        stats = summary.statistics
        topics = [
            TopicInfo(ch.topic, summary.schemas[ch.schema_id].name if ch.schema_id in
                      summary.schemas else "", stats.channel_message_counts.get(ch.id, 0),
                      ch.metadata.get("offered_qos_profiles", ""))
            for ch in sorted(summary.channels.values(), key=lambda c: c.topic)
        ]
        return BagInfo(path, size, stats.message_count, stats.message_start_time,
                       stats.message_end_time, topics, True,
                       header.library if header is not None else "", metadata)
    counts: dict[str, list[Any]] = {}
    first = last = 0
    n = 0
    for schema, channel, message in _records(path, None, None, None):
        entry = counts.setdefault(channel.topic, [schema.name if schema else "", 0,
                                                  channel.metadata.get("offered_qos_profiles",
                                                                       "")])
        entry[1] += 1
        first = message.log_time if n == 0 else min(first, message.log_time)
        last = max(last, message.log_time)
        n += 1
    topics = [TopicInfo(t, v[0], v[1], v[2]) for t, v in sorted(counts.items())]
    return BagInfo(path, size, n, first, last, topics, False)
