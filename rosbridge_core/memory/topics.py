"""Topics of the in-memory graph: :class:`MemoryPublisher` (a node's publisher),
:class:`MemoryFeed` (a node's subscription, shared by its listeners) and :class:`MemoryMessage`
(one message published, an :class:`~rosbridge_core.codec.encodings.EncodedMessage`).

A message reaches each subscription of its topic and type synchronously, in the publisher's
call; a latched publisher keeps its last message for subscriptions made later.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any, Protocol

from msgs import cdr
from msgs.runtime import Message
from rosbridge_core.codec.encodings import EncodedMessage
from rosbridge_core.codec.msgs_types import MsgsConverter
from rosbridge_core.graph import Listener

__all__ = ["MemoryFeed", "MemoryMessage", "MemoryPublisher"]

log = logging.getLogger("bridge_server.memory.graph")


class _Bus(Protocol):
    """What a publisher needs of the whole graph (:class:`~.graph.MemoryRos`)."""

    @property
    def taps(self) -> list[Callable[[MemoryPublisher, MemoryMessage], None]]: ...

    def feeds(self, topic: str, cls: type[Message]) -> list[MemoryFeed]: ...


class _TopicNode(Protocol):
    """What a publisher or a subscription needs of its node (:class:`~.graph.MemoryGraph`)."""

    @property
    def ros(self) -> _Bus: ...

    def converter(self, cls: Any) -> MsgsConverter: ...


class MemoryMessage(EncodedMessage):
    """One message published in memory, encoded for clients lazily and once per encoding."""

    __slots__ = ("conv", "msg")

    def __init__(self, topic: str, msg: Message, conv: MsgsConverter) -> None:
        super().__init__(topic, cdr.encode(msg), time.time_ns())
        self.msg = msg
        self.conv = conv

    def message_json(self) -> str:
        """The message as JSON text."""
        return self.conv.to_json(self.msg)

    def cbor_obj(self) -> Any:
        """The message as a CBOR-ready object."""
        return self.conv.to_cbor_obj(self.msg)


class MemoryFeed:
    """A node's one subscription to a topic, shared by its listeners."""

    def __init__(self, graph: _TopicNode, topic: str, msg_cls: type[Message] | None) -> None:
        self.graph = graph
        self.topic = topic
        self.msg_cls = msg_cls
        self.received = 0
        self.listeners: list[Listener] = []
        self._latched: MemoryMessage | None = None

    @property
    def latched(self) -> MemoryMessage | None:
        """The last message of a latched topic, for a late subscriber."""
        return self._latched

    @property
    def type_name(self) -> str | None:
        """Canonical type of the topic, once known."""
        return self.msg_cls._type if self.msg_cls is not None else None

    def deliver(self, msg: MemoryMessage, latched: bool) -> None:
        """Hand ``msg`` to every listener, in order; one that raises is logged and the others
        still get it (as the rclpy Graph's executor goes on)."""
        self.received += 1
        if latched:
            self._latched = msg
        for listener in list(self.listeners):
            try:
                listener(msg)
            except Exception:
                log.exception("a listener of %s failed on a message", self.topic)


class MemoryPublisher:
    """A node's publisher of (topic, type, latch), shared by reference count."""

    def __init__(self, graph: _TopicNode, topic: str, msg_cls: type[Message], latch: bool,
                 depth: int) -> None:
        self.graph = graph
        self.topic = topic
        self.latch = latch
        self.depth = depth
        self.refs = 0
        self.conv = graph.converter(msg_cls)
        self.last: MemoryMessage | None = None
        """The last message, kept for late subscribers when latched."""

    @property
    def type_name(self) -> str:
        """Canonical message type."""
        return self.conv.type_name

    def publish(self, msg: Any) -> None:
        """Publish one message (a ``msgs`` instance, or its CDR bytes) to every subscription
        of the topic and type in the graph, before returning."""
        if isinstance(msg, bytes | bytearray):
            msg = self.conv.cls.from_json(cdr.decode(bytes(msg), self.conv.cls))
        sent = MemoryMessage(self.topic, msg, self.conv)
        if self.latch:
            self.last = sent
        for tap in self.graph.ros.taps:
            tap(self, sent)
        for feed in self.graph.ros.feeds(self.topic, self.conv.cls):
            feed.deliver(sent, self.latch)
