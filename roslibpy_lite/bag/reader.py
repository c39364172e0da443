"""Reading ROS 2 MCAP files: ours, rosbag2's and other tools' (see the package docstring)."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from ._mcap import need_mcap
from ._mcapread import open_reader, read_mcap, records
from ._records import BagInfo, BagMessage, TopicChunks, TopicInfo

__all__ = ["BagInfo", "BagMessage", "TopicInfo", "info", "read", "topic_chunks"]

log = logging.getLogger("roslibpy_lite.bag")


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
    yield from read_mcap(Path(path), topics, start_ns, end_ns)


def topic_chunks(path: Path, topic: str) -> TopicChunks | None:
    """A topic's payloads chunk by chunk for the tables' speed path, from an MCAP file or a
    rosbag2 recording, or None where the layout does not allow it (the caller reads the
    messages one by one then)."""
    from . import _chunks, _rosbag2

    if _rosbag2.is_rosbag2(path):
        return _rosbag2.topic_chunks(path, topic)
    return _chunks.topic_chunks(path, topic)


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
        reader = open_reader(stream)
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
    for schema, channel, message in records(path, None, None, None):
        entry = counts.setdefault(channel.topic, [schema.name if schema else "", 0,
                                                  channel.metadata.get("offered_qos_profiles",
                                                                       "")])
        entry[1] += 1
        first = message.log_time if n == 0 else min(first, message.log_time)
        last = max(last, message.log_time)
        n += 1
    topics = [TopicInfo(t, v[0], v[1], v[2]) for t, v in sorted(counts.items())]
    return BagInfo(path, size, n, first, last, topics, False)
