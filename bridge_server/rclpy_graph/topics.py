"""The bridge's shared topic entities: one ROS subscription per topic for every session
(:class:`SharedSubscription`), one publisher per (topic, type, latch) (:class:`SharedPublisher`),
and the message they hand out (:class:`Incoming`).

Sharing
-------
* :class:`SharedSubscription`: one ROS subscription per topic for every
  client, taking messages serialized. Each message becomes one
  :class:`Incoming`: ``cbor-raw`` subscribers get its CDR bytes as they came; it
  is deserialized only to build its JSON or CBOR encoding, each at most once;
  every subscribed session is handed the same ``str``/``bytes``.
* :class:`SharedPublisher`: one rclpy publisher per (topic, type, latch),
  reference counted across sessions.

QoS
---
A shared subscription follows the publishers it sees
(``get_publishers_info_by_topic``): best effort if any publisher is best
effort (a reliable reader would not match it), transient local if every
publisher is transient local (a transient-local reader does not match a
volatile writer). :meth:`~.node.RosNode.refresh` re-checks this periodically and
replaces a subscription whose profile no longer fits, and resolves the type of
subscriptions made before any publisher existed ("late publishers"). The last
message of a transient-local topic is kept and handed to each client that
subscribes later.
"""

from __future__ import annotations

import importlib
import logging
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.qos import qos_profile
from bridge_server.rclpy_graph.reader import Reader
from bridge_server.rclpy_graph.types import resolve_message
from rosbridge_core.codec.encodings import EncodedMessage

__all__ = [
    "BULK_SUBSCRIPTION_DEPTH",
    "REPLAY_MEMORY",
    "SUBSCRIPTION_DEPTH",
    "Incoming",
    "Listener",
    "SharedPublisher",
    "SharedSubscription",
    "TopicNode",
]

log = logging.getLogger("bridge_server.rclpy_graph.node")  # the name it always logged under

Listener = Callable[["Incoming"], None]

SUBSCRIPTION_DEPTH = 1000
"""History depth of the bridge's shared ROS subscriptions for ordinary messages.

History holds only samples the executor has not taken yet, so a deep one costs
nothing while the bridge keeps up; it bridges the moments when Fast DDS holds a
reliable stream back to repair a lost sample (under load, a depth of 100 lost
messages that way)."""

BULK_SUBSCRIPTION_DEPTH = 50
"""History depth for bulk types (a numeric or byte sequence: images, point clouds,
maps), where a deep history could hold gigabytes while the bridge lags."""

REPLAY_MEMORY = 1000
"""Source timestamps a subscription remembers of the messages it took, so that one made
to replace it (its publishers turned out transient local) skips the history it already
handed out when the writers replay it."""



class TopicNode(Protocol):
    """What the shared topic entities use of the bridge's node (:class:`~.node.RosNode`)."""

    @property
    def node(self) -> Any:
        """The rclpy node."""

    @property
    def reader(self) -> Reader | None:
        """What takes the topics' messages (``None`` before start)."""

    @property
    def subscriptions(self) -> dict[str, SharedSubscription]:
        """The shared subscription of each topic."""

    def topic_types(self, topic: str) -> list[str]:
        """Types the ROS graph lists for ``topic``."""


class Incoming(EncodedMessage):
    """One ROS message received on a topic, encoded lazily and once per encoding.

    It arrives serialized (CDR, ``data``): ``cbor-raw`` subscribers get those bytes as they
    came, and the message is deserialized only to build the JSON or the CBOR encoding, each
    at most once (a topic with only cbor-raw subscribers is never deserialized). The JSON
    text is made from the bytes directly where it can be (:mod:`rosbridge_core.codec.cdr_json`).
    """

    __slots__ = ("_msg_json", "conv")

    def __init__(self, topic: str, data: bytes, conv: convert.Converter, stamp_ns: int) -> None:
        super().__init__(topic, data, stamp_ns)
        self.conv = conv
        self._msg_json: str | None = None

    @property
    def msg(self) -> Any:
        """The rclpy message, deserialized from :attr:`data` (anew on each use: the JSON and
        CBOR encodings are each built once and kept, the object is not, so a queued
        message costs its bytes and its encodings, not a third copy)."""
        return deserialize_message(self.data, self.conv.msg_cls)

    def message_json(self) -> str:
        """The message as JSON text, straight from its CDR bytes where it can be."""
        msg_json = self._msg_json
        if msg_json is None:
            fast = self.conv.json_from_cdr
            if fast is not None:
                msg_json = fast(self.data)  # None: a NaN, or bytes it cannot decode
            if msg_json is None:
                msg_json = self.conv.to_json(self.msg)
            self._msg_json = msg_json
        return msg_json

    def cbor_obj(self) -> Any:
        """The message as a CBOR-ready object."""
        return self.conv.to_cbor_obj(self.msg)



def _is_bulky(msg_cls: type[Any], depth: int = 0) -> bool:
    """Whether a message type carries a numeric/byte sequence (or array of > 1024 items)."""
    from rosidl_parser.definition import AbstractSequence, Array, BasicType, NamespacedType

    if depth > 8:
        return False
    for slot in getattr(msg_cls, "SLOT_TYPES", ()):
        if isinstance(slot, AbstractSequence | Array):
            if isinstance(slot.value_type, BasicType) and (
                not isinstance(slot, Array) or slot.size > 1024
            ):
                return True
        elif isinstance(slot, NamespacedType):
            module = importlib.import_module(".".join(slot.namespaces))
            if _is_bulky(getattr(module, slot.name), depth + 1):
                return True
    return False


class SharedSubscription:
    """The bridge's one ROS subscription to a topic, shared by every listening session.

    ``msg_cls`` is ``None`` while the type is not known yet (subscribed without
    a type before any publisher appeared); :meth:`~.node.RosNode.refresh` fills it in.
    """

    def __init__(self, ros: TopicNode, topic: str, msg_cls: type[Any] | None) -> None:
        self.ros = ros
        self.topic = topic
        self.msg_cls = msg_cls
        self.conv: convert.Converter | None = None
        self.listeners: list[Listener] = []
        self.latched: Incoming | None = None
        self.reliable = True
        self.transient_local = False
        self._sub: Any = None
        self._warned = False
        self.received = 0
        # source timestamps of the latest messages taken (on the reader's thread), for a
        # re-subscription that replays the writers' history
        self._taken: deque[int] = deque(maxlen=REPLAY_MEMORY)

    @property
    def type_name(self) -> str | None:
        """Canonical type of the topic, once known."""
        return self.conv.type_name if self.conv is not None else None

    def _wanted_qos(self) -> tuple[bool, bool]:
        infos = self.ros.node.get_publishers_info_by_topic(self.topic)
        if not infos:
            return self.reliable, self.transient_local
        reliable = all(i.qos_profile.reliability != ReliabilityPolicy.BEST_EFFORT for i in infos)
        transient = all(
            i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos
        )
        return reliable, transient

    def _create(self) -> None:
        assert self.msg_cls is not None
        self.conv = convert.converter_for(self.msg_cls)
        self.reliable, self.transient_local = self._wanted_qos()
        depth = BULK_SUBSCRIPTION_DEPTH if _is_bulky(self.msg_cls) else SUBSCRIPTION_DEPTH
        qos = qos_profile(self.reliable, self.transient_local, depth)
        topic = self.topic
        msg_cls = self.msg_cls
        # a subscription made to replace another (the publishers' QoS changed) and that is
        # transient local gets the writers' history again: what the old one took already is
        # not handed out twice (known by source timestamp); what it never saw still is
        taken_before = frozenset(self._taken) if self.transient_local else frozenset()
        remember = self._taken.append

        def take(handle: Any, limit: int) -> tuple[list[bytes], int]:
            # up to ``limit`` of what is queued (delivered at once, in one hand-off), and
            # how many were taken (replays skipped included)
            batch: list[bytes] = []
            take_message = handle.take_message
            for took in range(limit):
                taken = take_message(msg_cls, True)  # raw: Incoming deserializes when needed
                if taken is None:
                    return batch, took
                source = taken[1]["source_timestamp"]
                remember(source)
                if source not in taken_before:
                    batch.append(taken[0])
            return batch, limit

        reader = self.ros.reader
        assert reader is not None, "the ROS side is not started"
        self._sub = reader.subscribe(msg_cls, topic, qos, take, self._deliver_batch)
        log.debug(
            "subscribed to %s (%s, %s, %s)",
            topic,
            self.conv.type_name,
            "reliable" if self.reliable else "best effort",
            "transient local" if self.transient_local else "volatile",
        )

    def _destroy(self) -> None:
        if self._sub is not None:
            sub, self._sub = self._sub, None
            if self.ros.reader is not None:
                self.ros.reader.unsubscribe(sub)

    def _deliver_batch(self, msgs: list[bytes], stamp_ns: int) -> None:
        conv = self.conv
        if conv is None or self.ros.subscriptions.get(self.topic) is not self:
            return  # the subscription was removed meanwhile
        topic = self.topic
        listeners = self.listeners
        for msg in msgs:
            self.received += 1
            inc = Incoming(topic, msg, conv, stamp_ns)
            if self.transient_local:
                self.latched = inc
            for listener in listeners:
                try:
                    listener(inc)
                except Exception:
                    log.exception("listener failed on %s", topic)

    def refresh(self) -> None:
        """Resolve a pending type, or replace the subscription if the publishers' QoS changed."""
        if self.msg_cls is None:
            types = self.ros.topic_types(self.topic)
            if not types:
                return
            try:
                self.msg_cls = resolve_message(types[0])
            except Exception as exc:
                if not self._warned:
                    self._warned = True
                    log.warning("cannot subscribe to %s: %s", self.topic, exc)
                return
            self._create()
            return
        if self._sub is None:
            return
        reliable, transient = self._wanted_qos()
        if (reliable, transient) != (self.reliable, self.transient_local):
            log.info("QoS of %s changed: re-subscribing", self.topic)
            self._destroy()
            self._create()


class SharedPublisher:
    """A ROS publisher shared (reference counted) by the sessions that advertised it.

    A latched one keeps only its last message (transient local, depth 1), whatever queue
    size the client asked for: a late subscriber, ROS node or bridge client, gets the
    last value, not the writer's history (``queue_size`` of the rosbridge op is the depth
    of an ordinary publisher).
    """

    def __init__(self, ros: TopicNode, topic: str, msg_cls: type[Any], latch: bool, depth: int):
        self.ros = ros
        self.topic = topic
        self.msg_cls = msg_cls
        self.conv = convert.converter_for(msg_cls)
        self.latch = latch
        self.refs = 0
        depth = 1 if latch else max(depth, 1)
        self.pub = ros.node.create_publisher(msg_cls, topic, qos_profile(True, latch, depth))

    @property
    def type_name(self) -> str:
        """Canonical message type."""
        return self.conv.type_name

    def publish(self, msg: Any) -> None:
        """Publish one message (callable from the loop thread; rcl publish is thread safe)."""
        self.pub.publish(msg)

