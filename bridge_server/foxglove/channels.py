"""A Foxglove client's channels: what it subscribes to (the bridge's topics, advertised to it
as channels) and what it publishes on (its own client channels), as :class:`ChannelOps`,
a part of :class:`~bridge_server.foxglove.session.FoxgloveSession`.

Messages go out as the ROS side received them (:data:`QUEUE_BYTES` per subscription, newest
kept); what a client publishes is decoded and converted in order on its channel's
:class:`~bridge_server.foxglove.inbound.Inbound` before it reaches ROS.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from bridge_server.foxglove import ops
from bridge_server.foxglove.base import ENCODINGS, ClientChannel, SessionBase, log
from bridge_server.foxglove.hub import message_class
from bridge_server.foxglove.inbound import Inbound
from msgs import cdr
from rosbridge_core.codec.budget import explain
from rosbridge_core.interfaces import BridgeError, ConversionError, canonical_name
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.security.names import InvalidNameError, check_name
from rosbridge_core.session.limits import over_cap
from rosbridge_core.session.outbox import TopicQueue

if TYPE_CHECKING:
    from rosbridge_core.graph import Message as RosMessage

__all__ = ["QUEUE_BYTES", "ChannelOps"]

QUEUE_BYTES = 8 * 1024 * 1024
"""Bytes of messages a subscription holds for a slow client (at most the bridge's default
queue length of them; nine 640x480 rgb8 frames, about foxglove_bridge's 10 MB send buffer
limit per connection); when full, the oldest goes first."""


class ChannelOps(SessionBase):
    """The subscribe, unsubscribe, advertise, unadvertise and message-data ops of a Foxglove
    client."""

    # -- subscriptions -------------------------------------------------------------------------

    def _subscribe(self, op: ops.Subscribe) -> None:
        for sub_id, channel_id in op.subscriptions:
            channel = self.hub.by_id.get(channel_id)
            if sub_id in self.subscriptions:
                self.error(f"subscribe: subscription id {sub_id} is in use on this connection")
            elif channel is None:
                self.error(f"subscribe: no channel {channel_id} (unknown, or no longer "
                           "advertised)")
            elif channel.topic in self.topics.subs:
                self.error(f"subscribe: channel {channel_id} ({channel.topic}) is subscribed "
                           "on this connection already")
            elif (why := self.gate.forbids("subscribe", channel.topic)) is not None:
                self.error(f"subscribe: {channel.topic}: forbidden: {why}")
            elif (why := over_cap(self.topics.subs, channel.topic,
                                  self.limits.max_subscriptions, "subscriptions")) is not None:
                self.error(f"subscribe: {channel.topic}: {why}")
            else:
                self._add_subscription(sub_id, channel)

    def _add_subscription(self, sub_id: int, channel: ops.Channel) -> None:
        topic = channel.topic
        cls = self.graph.resolve_message(channel.schema_name)
        sub = TopicQueue(self.outbox, topic, topic)
        header = ops.message_data_header
        hub = self.hub
        cap = min(self.config.default_queue_length, self.limits.max_queue_length or 1 << 30)

        def frame(inc: RosMessage) -> tuple[bytes, bytes]:
            stamp = hub.clock_ns if self.uses_time and hub.clock_ns is not None else inc.stamp_ns
            return header(sub_id, stamp), inc.data  # the payload is not copied per client

        def on_message(inc: RosMessage) -> None:
            # newest wins within QUEUE_BYTES: 9 camera frames, or the default count of small ones
            sub.maxlen = max(1, min(cap, QUEUE_BYTES // (len(inc.data) + 1)))
            sub.on_message(inc)

        sub.encode = frame
        self._listeners[sub] = on_message
        try:
            sub.shared = self.graph.subscribe(topic, cls, on_message)
        except ValueError as exc:
            del self._listeners[sub]
            self.error(f"subscribe: {exc}")
            return
        self.subscriptions[sub_id] = (sub, channel)
        self.topics.subs[topic] = sub
        self.shared.graph_changed()
        latched = sub.shared.latched
        if latched is not None:
            self.outbox.push(sub, latched)

    def _unsubscribe(self, op: ops.Unsubscribe) -> None:
        for sub_id in op.subscription_ids:
            found = self.subscriptions.pop(sub_id, None)
            if found is None:
                self.error(f"unsubscribe: no subscription {sub_id} on this connection")
                continue
            self._drop(found[0])

    def _drop(self, sub: TopicQueue) -> None:
        self.topics.subs.pop(sub.topic, None)
        sub.close()
        metrics = self.shared.metrics
        metrics.retire_subscription(sub.topic, sub.sent, sub.sent_bytes, sub.dropped_total)
        if sub.shared is not None:
            shared, sub.shared = sub.shared, None
            self.graph.unsubscribe(shared, self._listeners.pop(sub))
            if self.graph.subscriptions.get(shared.topic) is not shared:
                metrics.retire_ros_subscription(shared.topic, shared.received)

    # -- client publishing ---------------------------------------------------------------------

    def _advertise(self, op: ops.ClientAdvertise) -> None:
        for ch in op.channels:
            try:
                self._add_client_channel(ch)
            except BridgeError as exc:
                self.error(f"advertise: channel {ch.id} ({ch.topic}): {exc}")

    def _add_client_channel(self, ch: ops.ClientChannel) -> None:
        topic = absolute_name(ch.topic)
        if ch.id in self.client_channels:
            raise BridgeError(f"channel id {ch.id} is advertised on this connection already")
        if ch.encoding not in ENCODINGS:
            raise BridgeError(f"encoding {ch.encoding!r} is not one of "
                              f"{', '.join(ENCODINGS)}")
        try:
            check_name(topic, "topic")
        except InvalidNameError as exc:
            raise BridgeError(str(exc)) from None
        why = self.gate.forbids("publish", topic)
        if why is not None:
            raise BridgeError(f"forbidden: {why}")
        why = over_cap(self.topics.publishers, topic, self.limits.max_publishers, "publishers")
        if why is not None:
            raise BridgeError(why)
        type_name = canonical_name(ch.schema_name, "msg")
        cls = self.graph.resolve_message(type_name)
        others = [t for t in [*self.graph.topic_types(topic), *self.graph.publisher_types(topic)]
                  if t != type_name]
        if others:
            raise BridgeError(f"topic {topic} has type {others[0]}, not {type_name}")
        if ch.encoding == "cdr":
            decode: Callable[[bytes], Any] = cdr.decoder_for(message_class(self.graph, type_name))
        else:
            decode = ops.parse_json
        pub = self.topics.publishers.get(topic)
        if pub is None:
            pub = self.topics.publishers[topic] = self.graph.acquire_publisher(topic, cls, False,
                                                                               10)
        self._publisher_refs[topic] = self._publisher_refs.get(topic, 0) + 1
        conv = pub.conv

        def convert(payload: bytes) -> Any:
            return conv.from_obj(decode(payload), "msg")

        self.client_channels[ch.id] = ClientChannel(ch.id, topic, ch.encoding, pub,
                                                     Inbound(convert))

    def _unadvertise(self, op: ops.ClientUnadvertise) -> None:
        for channel_id in op.channel_ids:
            ch = self.client_channels.pop(channel_id, None)
            if ch is None:
                self.error(f"unadvertise: no client channel {channel_id} on this connection")
                continue
            ch.inbound.close()
            refs = self._publisher_refs[ch.topic] - 1
            self._publisher_refs[ch.topic] = refs
            if refs == 0:
                del self._publisher_refs[ch.topic]
                self.graph.release_publisher(self.topics.publishers.pop(ch.topic))

    def _publish(self, op: ops.ClientMessage) -> None:
        ch = self.client_channels.get(op.channel_id)
        if ch is None:
            self.error(f"message data: no client channel {op.channel_id} on this connection "
                       "(advertise it first)")
            return
        size = len(op.payload)

        def done(msg: Any, exc: BaseException | None) -> None:
            if exc is not None:
                self._not_published(ch, exc)
            elif self.client_channels.get(ch.id) is ch:  # not unadvertised meanwhile
                ch.publisher.publish(msg)
                self.shared.metrics.published(ch.topic, size + 5)

        why = ch.inbound.submit(op.payload, done)
        if why is not None:
            self._not_published(ch, why)

    def _not_published(self, ch: ClientChannel, why: BaseException | str) -> None:
        """Tell the client one of its messages on ``ch`` was not published, and why (a
        message over the decode budget names its field and the budget)."""
        if not isinstance(why, str | cdr.CdrError | ValueError | ConversionError):
            log.error("session %d: converting a message of %s failed", self.sid, ch.topic,
                      exc_info=why)
            why = f"internal error ({type(why).__name__})"
        elif not isinstance(why, str):
            why = explain(why)
        self.error(f"message data on {ch.topic} ({ch.publisher.type_name}, {ch.encoding}): "
                   f"not published: {why}")
