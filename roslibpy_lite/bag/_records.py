"""The values the bag readers hand out: one recorded message, a file's topics and summary,
a topic's payloads chunk by chunk. Shared by the MCAP and the rosbag2 readers, so neither
imports the other for them."""

from __future__ import annotations

import functools
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..exceptions import UsageError
from ..messages import RawMessage

if TYPE_CHECKING:
    from msgs.runtime import Message


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


@dataclass(frozen=True)
class TopicChunks:
    """A topic's schema and its payloads, one list per chunk, in file order."""

    type_name: str
    definition: str
    batches: Iterator[list[tuple[int, memoryview | bytes]]]
