"""Topic ops of one client: advertise, unadvertise, publish, subscribe, unsubscribe.

Several subscribe ops of one client to one topic (different ids) are merged
into one :class:`~rosbridge_core.session.outbox.TopicQueue` (see
:mod:`rosbridge_core.session.outbox` for the merged options and the queues);
``compression: png`` (legacy) falls back to plain JSON with a warning.
Publishers are shared between clients per topic, type and latching
(:meth:`rosbridge_core.graph.Graph.acquire_publisher`); a client's are released
``publisher_grace`` seconds after it leaves.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, ClassVar

from rosbridge_core.interfaces import ConversionError, canonical_name
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.session.limits import over_cap
from rosbridge_core.session.outbox import TopicQueue

if TYPE_CHECKING:
    from rosbridge_core.graph import Publisher
    from rosbridge_core.security import Gate
    from rosbridge_core.session.host import SessionView

__all__ = ["SessionTopics"]


class SessionTopics:
    """One client's publishers and subscriptions, and the ops that change them."""

    OPS: ClassVar[dict[type[ops.Op], str]] = {
        ops.Publish: "publish",
        ops.Subscribe: "subscribe",
        ops.Unsubscribe: "unsubscribe",
        ops.Advertise: "advertise",
        ops.Unadvertise: "unadvertise",
    }
    """The ops this capability carries out, and the method for each."""
    LIMITS: ClassVar[dict[type[ops.Op], str]] = {
        ops.Subscribe: "subscribe_limit",
        ops.Advertise: "publisher_limit",
        ops.Publish: "publisher_limit",
    }
    """The ops that add to what the connection holds, and the method that checks each."""

    def subscribe_limit(self, op: ops.Subscribe) -> str | None:
        """Why this subscription would pass the connection's limits (``None``: it would not)."""
        limits = self.session.limits
        topic = absolute_name(op.topic)
        sub = self.subs.get(topic)
        ids = limits.max_subscription_ids
        if sub is not None and ids and op.id not in sub.ids and len(sub.ids) >= ids:
            # ids of one topic merge into one subscription, but each is work to merge
            return f"too many subscription ids for {topic} on this connection (at most {ids})"
        return over_cap(self.subs, topic, limits.max_subscriptions, "subscriptions")

    def publisher_limit(self, op: ops.Advertise | ops.Publish) -> str | None:
        """Why a publisher for this op would pass the connection's limits."""
        return over_cap(self.publishers, absolute_name(op.topic),
                        self.session.limits.max_publishers, "publishers")

    def __init__(self, session: SessionView) -> None:
        self.session = session
        self.graph = session.graph
        self.publishers: dict[str, Publisher] = {}
        self.subs: dict[str, TopicQueue] = {}

    # -- publishing ----------------------------------------------------------------------------

    def advertise(self, op: ops.Advertise) -> None:
        """Create (or share) a ROS publisher for the topic."""
        topic = absolute_name(op.topic)
        cls = self.graph.resolve_message(op.type)
        type_name = canonical_name(op.type, "msg")
        current = self.publishers.get(topic)
        if current is not None:
            if current.type_name == type_name:
                return
            self.session.error(
                f"advertise: topic {topic} is already advertised by this client with type "
                f"{current.type_name}, not {type_name}",
                op.id,
            )
            return
        existing = [t for t in self.graph.topic_types(topic) if t != type_name]
        existing += [t for t in self.graph.publisher_types(topic) if t != type_name]
        if existing:
            self.session.error(
                f"advertise: topic {topic} already has type {existing[0]}; "
                f"cannot advertise it as {type_name}",
                op.id,
            )
            return
        self.publishers[topic] = self.graph.acquire_publisher(
            topic, cls, bool(op.latch), op.queue_size or 1
        )

    def unadvertise(self, op: ops.Unadvertise) -> None:
        """Release this client's publisher for the topic."""
        topic = absolute_name(op.topic)
        pub = self.publishers.pop(topic, None)
        if pub is None:
            self.session.error(
                f"unadvertise: topic {topic} is not advertised by this client", op.id
            )
            return
        self.graph.release_publisher(pub)

    def publish(self, op: ops.Publish) -> None:
        """Convert the message and publish it (auto-advertising a topic the graph knows)."""
        topic = absolute_name(op.topic)
        pub = self.publishers.get(topic)
        if pub is None:
            types = self.graph.topic_types(topic)
            if not types:
                self.session.error(
                    f"publish: topic {topic} is not advertised and the ROS graph has no type "
                    "for it; send advertise first",
                    op.id,
                )
                return
            cls = self.graph.resolve_message(types[0])
            pub = self.publishers[topic] = self.graph.acquire_publisher(
                topic, cls, bool(op.latch), op.queue_size or 10
            )
        try:
            msg = pub.conv.from_obj(op.msg, "msg")
        except ConversionError as exc:
            self.session.error(f"publish to {topic} ({pub.type_name}): {exc}", op.id)
            return
        pub.publish(msg)
        self.session.shared.metrics.published(topic, self.session.frame_len)

    # -- subscribing ---------------------------------------------------------------------------

    def subscribe(self, op: ops.Subscribe) -> None:
        """Add this id to the client's subscription of the topic."""
        session = self.session
        topic = absolute_name(op.topic)
        if op.compression == "png":
            # Stock clients still offer png; they all read plain JSON publish ops too.
            session.status(
                "warning",
                f"subscribe to {topic}: compression 'png' is not supported; "
                "sending plain JSON instead (use cbor or cbor-raw for compact messages)",
                op.id,
            )
            op = dataclasses.replace(op, compression="none")
        self._warn_limits(op, topic)
        cls: type[Any] | None = None
        if op.type is None:
            graph = self.graph.topic_types(topic)
            if graph:  # known now: an uninstalled type is an error the client should hear
                cls = self.graph.resolve_message(graph[0])
        else:
            cls = self.graph.resolve_message(op.type)
            type_name = canonical_name(op.type, "msg")
            graph = self.graph.topic_types(topic)
            if graph and type_name not in graph:
                session.error(
                    f"subscribe: topic {topic} has type {graph[0]} in the ROS graph, "
                    f"not {type_name}",
                    op.id,
                )
                return
        sub = self.subs.get(topic)
        if sub is None:
            sub = TopicQueue(session.outbox, topic, op.topic)
            sub.ids[op.id] = op
            self._configure(sub)
            try:
                sub.shared = self.graph.subscribe(topic, cls, sub.on_message)
            except ValueError as exc:
                session.error(f"subscribe: {exc}", op.id)
                return
            self.subs[topic] = sub
            session.shared.graph_changed()
            latched = sub.shared.latched
            if latched is not None:
                session.outbox.push(sub, latched)
            return
        shared = sub.shared
        if cls is not None and shared is not None:
            if shared.msg_cls is None:
                try:
                    self.graph.subscribe(topic, cls, sub.on_message)
                finally:
                    self.graph.unsubscribe(shared, sub.on_message)
            elif shared.msg_cls is not cls:
                session.error(
                    f"subscribe: topic {topic} is already subscribed with type "
                    f"{shared.type_name}",
                    op.id,
                )
                return
        sub.ids[op.id] = op
        self._configure(sub)

    def unsubscribe(self, op: ops.Unsubscribe) -> None:
        """Remove one id (or, without id, every id) of the client's subscription."""
        topic = absolute_name(op.topic)
        sub = self.subs.get(topic)
        if sub is None:
            self.session.status("warning", f"unsubscribe: not subscribed to {topic}", op.id)
            return
        if op.id is not None and op.id in sub.ids:
            del sub.ids[op.id]
        elif op.id is not None:
            self.session.status(
                "warning", f"unsubscribe: no subscription {op.id!r} on {topic}", op.id
            )
            return
        else:
            sub.ids.clear()
        if sub.ids:
            self._configure(sub)
            return
        del self.subs[topic]
        self._drop_sub(sub)

    def _configure(self, sub: TopicQueue) -> None:
        """Apply the merged options of a subscription's ids, within the bridge's limits."""
        limits = self.session.limits
        sub.configure(self.session.config.default_queue_length, limits.max_queue_length,
                      limits.min_fragment_size)

    def _warn_limits(self, op: ops.Subscribe, topic: str) -> None:
        """Say which of a subscribe's options the bridge's limits lower or raise."""
        limits = self.session.limits
        if limits.max_queue_length and op.queue_length > limits.max_queue_length:
            self.session.status(
                "warning", f"subscribe to {topic}: queue_length {op.queue_length} is over "
                f"this bridge's limit; using {limits.max_queue_length}", op.id)
        size = op.fragment_size
        if size is not None and 0 < size < limits.min_fragment_size:
            self.session.status(
                "warning", f"subscribe to {topic}: fragment_size {size} is under this "
                f"bridge's floor; using {limits.min_fragment_size} bytes", op.id)

    def _drop_sub(self, sub: TopicQueue) -> None:
        sub.close()
        metrics = self.session.shared.metrics
        metrics.retire_subscription(sub.topic, sub.sent, sub.sent_bytes, sub.dropped_total)
        if sub.shared is not None:
            shared, sub.shared = sub.shared, None
            self.graph.unsubscribe(shared, sub.on_message)
            if self.graph.subscriptions.get(shared.topic) is not shared:  # it went: keep its count
                metrics.retire_ros_subscription(shared.topic, shared.received)

    # -- the session's hooks -------------------------------------------------------------------

    async def close(self) -> None:
        """The client left: drop its subscriptions at once, its publishers after the grace."""
        for sub in list(self.subs.values()):
            self._drop_sub(sub)
        self.subs.clear()
        grace = self.session.shared.publisher_grace
        for pub in self.publishers.values():
            if grace > 0:
                self.session.loop.call_later(grace, self.graph.release_publisher, pub)
            else:
                self.graph.release_publisher(pub)
        self.publishers.clear()

    def recheck(self, gate: Gate) -> int:
        """End the subscriptions and publishers the role no longer allows; how many ended."""
        ended = 0
        for topic, sub in list(self.subs.items()):
            why = gate.forbids("subscribe", topic)
            if why is not None:
                for op_id in list(sub.ids) or [None]:
                    self.session.error(f"subscribe: subscription to {topic} ended: {why}", op_id)
                del self.subs[topic]
                self._drop_sub(sub)
                ended += 1
        for topic in list(self.publishers):
            why = gate.forbids("publish", topic)
            if why is not None:
                self.graph.release_publisher(self.publishers.pop(topic))
                self.session.error(f"advertise: publisher of {topic} ended: {why}")
                ended += 1
        return ended
