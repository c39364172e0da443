"""One Foxglove client of the bridge: its frame loop and what it owns.

A :class:`FoxgloveSession` is what :class:`~rosbridge_core.session.session.Session` is
for rosbridge clients, for clients that offered ``foxglove.websocket.v1`` in the
handshake, on the same port. It goes through the same parts: the bridge's
:class:`~rosbridge_core.graph.Graph` (never rclpy), an
:class:`~rosbridge_core.session.outbox.Outbox` (a queue per subscription bounded by
:data:`QUEUE_BYTES` that drops the oldest, so a slow client gets the newest frames, not a
backlog), the
per-connection limits, and the :class:`~rosbridge_core.security.Gate` (token from the
handshake, op rate, and the role's say on each name). Every refusal or bad frame is
answered with a ``status`` error naming what was wrong; the connection stays up.

Messages go out as the ROS side received them: the CDR bytes of each message behind
the 13-byte message-data header, no decoding, and no copy per client (the header and the
shared payload are joined only into the socket write). What a client publishes or sends as a
service request is decoded from CDR (or JSON) with the pure-Python classes of
:mod:`msgs` (:func:`~bridge_server.foxglove.hub.message_class`), checked by the same
converter as rosbridge's publishes, and only then reaches ROS.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import contextlib
import json
import logging
import math
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from bridge_server.foxglove import wire
from bridge_server.foxglove.hub import CLOCK, GraphState, message_class
from bridge_server.foxglove.inbound import Inbound
from msgs import cdr
from msgs.runtime import ValidationError
from rosbridge_core.codec.budget import explain
from rosbridge_core.interfaces import BridgeError, ConversionError, canonical_name
from rosbridge_core.security.gate import POLICY_VIOLATION
from rosbridge_core.security.names import InvalidNameError, check_name, full_name
from rosbridge_core.security.permissions import LISTING, PARAMETER_LISTING
from rosbridge_core.session.calls import Calls
from rosbridge_core.session.client_status import ClientStatus, client_status
from rosbridge_core.session.limits import over_cap
from rosbridge_core.session.liveness import watch_link
from rosbridge_core.session.outbox import Outbox, Subscription

if TYPE_CHECKING:
    from bridge_server.foxglove.hub import Hub, ServiceEntry
    from rosbridge_core.graph import Message as RosMessage
    from rosbridge_core.graph import Publisher
    from rosbridge_core.security.options import SecurityConfig
    from rosbridge_core.session.host import Shared
    from rosbridge_core.session.link import ClientLink

__all__ = ["ENCODINGS", "OVERSIZE_GRACE", "QUEUE_BYTES", "FoxgloveSession"]

log = logging.getLogger("bridge_server.foxglove")

QUEUE_BYTES = 8 * 1024 * 1024
"""Bytes of messages a subscription holds for a slow client (at most the bridge's default
queue length of them; nine 640x480 rgb8 frames, about foxglove_bridge's 10 MB send buffer
limit per connection); when full, the oldest goes first."""

ENCODINGS = ("cdr", "json")
"""Encodings a client may publish and call services in."""

OVERSIZE_GRACE = 1024 * 1024
"""Bytes past ``--max-message-size`` a Foxglove frame may have and still be answered
with a ``status`` error (and dropped) rather than a close (1009)."""

_LEVELS = {"info": wire.STATUS_INFO, "warning": wire.STATUS_WARNING, "error": wire.STATUS_ERROR}


@dataclass
class _ClientChannel:
    """A channel the client publishes on."""

    id: int
    topic: str
    encoding: str
    publisher: Publisher
    inbound: Inbound  # decodes and converts its messages, in order (large ones off the loop)


class _Topics:
    """A client's subscriptions and publishers by topic (what the bridge's per-topic
    counts read of every session kind)."""

    def __init__(self) -> None:
        self.subs: dict[str, Subscription] = {}
        self.publishers: dict[str, Publisher] = {}


class FoxgloveSession:
    """One Foxglove client (see the module's text)."""

    protocol_name = "foxglove"

    def __init__(self, shared: Shared, hub: Hub[FoxgloveSession], link: ClientLink, sid: int
                 ) -> None:
        """Client ``sid``'s session over ``link``, sharing ``shared`` with the other sessions
        of its server and ``hub`` with the other Foxglove ones."""
        self.shared = shared
        self.hub = hub
        self.graph = shared.graph
        self.link = link
        self.sid = sid
        self.loop = asyncio.get_running_loop()
        self.config = shared.session_config
        self.peer = link.address
        self.connected_at = time.time()
        self.calls = Calls(self.loop)
        self.outbox = Outbox(
            link, sid, self.config.control_limit, shared.security.config.max_queued_messages,
            self.config.drop_report_interval, lambda text: self.status("warning", text),
        )
        self.topics = _Topics()
        self.subscriptions: dict[int, tuple[Subscription, wire.Channel]] = {}
        self.client_channels: dict[int, _ClientChannel] = {}
        self._publisher_refs: dict[str, int] = {}
        self._listeners: dict[Subscription, Callable[[RosMessage], None]] = {}
        self.parameter_names: set[str] | None = None  # None: not following; empty: all
        self.graph_seen: GraphState | None = None  # what it was told; None: not following
        self.shown_channels: set[int] = set()  # the ids of the channels it was told of
        self.shown_services: set[int] = set()
        self.uses_time = False
        self.gate = shared.security.gate(self)

    @property
    def limits(self) -> SecurityConfig:
        """The bridge's per-connection limits (as configured now)."""
        return self.shared.security.config

    @property
    def wants_graph(self) -> bool:
        """Whether the client follows the connection graph."""
        return self.graph_seen is not None

    @property
    def closed(self) -> bool:
        """Whether the connection has ended."""
        return self.outbox.closed

    # -- running -------------------------------------------------------------------------------

    async def run(self) -> None:
        """Serve the client until it leaves, then release what it owned."""
        if not self.gate.authenticated:  # a Foxglove client has no auth op: token or nothing
            self.gate.end()
            await self.link.close(POLICY_VIOLATION, "authentication required: give the token "
                                "in the URL (?token=...) or an Authorization header")
            return
        link = self.link
        # frames a little over the limit get a status, not a close
        link.limit_frames(self.shared.link_config.max_message_size + OVERSIZE_GRACE)
        writer = asyncio.create_task(self.outbox.writer(), name=f"foxglove-{self.sid}-writer")
        watcher = watch_link(link, self.sid, self.shared.link_config)
        try:
            self._hello()
            async for frame in link:
                self.handle_frame(frame)
        except link.closed_errors:
            pass
        finally:
            if watcher is not None:
                watcher.cancel()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, *link.closed_errors):
                await writer
            self.outbox.close()
            await self.cleanup()

    def _hello(self) -> None:
        """``serverInfo``, then the channels and services the client may use."""
        hub = self.hub
        hub.attach(self)  # the first client's look at the graph happens now
        capabilities = ["clientPublish", "services"]
        if self.gate.forbids(*PARAMETER_LISTING) is None:  # as for rosapi's get_param_names
            capabilities += ["parameters", "parametersSubscribe"]
        if self.gate.forbids(*LISTING) is None:  # as for rosbridge's rosapi lists
            capabilities.append("connectionGraph")
        if CLOCK in hub.channels and self.gate.forbids("subscribe", CLOCK) is None:
            self.uses_time = True
            capabilities.append("time")
        self.send_text(wire.json_frame(
            "serverInfo", name=f"roslibpy-lite bridge ({self.graph.name})",
            capabilities=capabilities, supportedEncodings=list(ENCODINGS),
            metadata={"ROS_DISTRO": "jazzy", "protocols": "rosbridge v2, foxglove.websocket.v1"},
            sessionId=f"{self.shared.metrics.started:.0f}",
        ))
        self.show_lists()

    async def cleanup(self) -> None:
        """Release subscriptions at once, publishers after the bridge's grace."""
        self.gate.end()
        self.hub.detach(self)
        for sub, _ in list(self.subscriptions.values()):
            self._drop(sub)
        self.subscriptions.clear()
        for ch in self.client_channels.values():
            ch.inbound.close()
        grace = self.shared.publisher_grace
        for pub in self.topics.publishers.values():
            if grace > 0:
                self.loop.call_later(grace, self.graph.release_publisher, pub)
            else:
                self.graph.release_publisher(pub)
        self.topics.publishers.clear()
        await self.calls.cancel_all()

    def describe(self, worker: int) -> ClientStatus:
        """This client's typed status (its entry in ``/status.json``) in worker ``worker``: a
        Foxglove client serves nothing and is never kept to resume."""
        return client_status(
            sid=self.sid, worker=worker, protocol=self.protocol_name, address=self.peer,
            connected_at=self.connected_at, subs=self.topics.subs.values(), outbox=self.outbox,
            publishes=self.topics.publishers, serves=(), calls_in_flight=len(self.calls),
            parked=False)

    def spawn(self, coro: Coroutine[Any, Any, None]) -> None:
        """Run ``coro`` as a task of this client's, cancelled when it leaves."""
        self.calls.spawn(coro)

    # -- sending -------------------------------------------------------------------------------

    def send_text(self, frame: str | bytes) -> None:
        """Queue one control frame (JSON text or a binary op)."""
        self.outbox.send_text(frame)

    def status(self, level: str, msg: str, id: Any = None, *, always: bool = True) -> None:
        """A ``status`` op (``level``: info, warning or error, as the gate says them)."""
        self.send_text(wire.json_frame("status", level=_LEVELS.get(level, wire.STATUS_ERROR),
                                       message=msg))

    def error(self, msg: str, kind: str = "request") -> None:
        """Tell the client of a refused or failed request; count it by kind."""
        log.info("foxglove client %d: %s", self.sid, msg)
        self.shared.metrics.error(kind)
        self.status("error", msg)

    def refuse(self, op: Any, why: str) -> None:
        """The gate's refusal of ``op`` (see :meth:`Gate.deny`)."""
        self.error(f"{getattr(op, 'OP', type(op).__name__)}: {why}")

    def send_time(self, stamp_ns: int) -> None:
        """The ``time`` op, to a client told of the ``time`` capability."""
        if self.uses_time:
            self.send_text(wire.time_frame(stamp_ns))

    def graph_changed(self, added: list[wire.Channel], removed: list[wire.Channel],
                      s_added: list[ServiceEntry], s_removed: list[ServiceEntry]) -> None:
        """Channels and services came or went: subscriptions to those gone end, and the
        client's lists follow (:meth:`show_lists`)."""
        for sub_id, (sub, channel) in list(self.subscriptions.items()):
            if channel in removed:
                del self.subscriptions[sub_id]
                self._drop(sub)
        self.show_lists()

    def show_lists(self) -> None:
        """Bring the client's channels and services to those of the hub its role lets it
        see now (``subscribe`` on the topic, ``call_service`` on the service): withdraw what
        it was told of that went or that it may no longer see, advertise the rest."""
        gate = self.gate
        channels = {c.id: c for c in self.hub.channels.values()
                    if gate.forbids("subscribe", c.topic) is None}
        services = {e.id: e for e in self.hub.services.values()
                    if gate.forbids("call_service", e.name) is None}
        if gone := sorted(self.shown_channels - channels.keys()):
            self.send_text(wire.json_frame("unadvertise", channelIds=gone))
        if gone := sorted(self.shown_services - services.keys()):
            self.send_text(wire.json_frame("unadvertiseServices", serviceIds=gone))
        if new := [c.to_json() for i, c in channels.items() if i not in self.shown_channels]:
            self.send_text(wire.json_frame("advertise", channels=new))
        if new := [e.to_json() for i, e in services.items() if i not in self.shown_services]:
            self.send_text(wire.json_frame("advertiseServices", services=new))
        self.shown_channels, self.shown_services = set(channels), set(services)

    def show_graph(self, state: GraphState) -> None:
        """The connection graph is now ``state``: if the client follows it, a
        ``connectionGraphUpdate`` with what changed of what its role lets it see (the names
        rosbridge's rosapi lists would give it)."""
        if self.graph_seen is None:
            return
        seen = state.seen_by(self.gate.sees)
        update = seen.update_since(self.graph_seen)
        self.graph_seen = seen
        if update is not None:
            self.send_text(wire.json_frame("connectionGraphUpdate", **update))

    def parameters_changed(self, changed: list[tuple[str, Any]]) -> None:
        """Parameters changed in ROS: tell the client of those it follows."""
        names = self.parameter_names
        if names is None:
            return
        shown = [(n, v) for n, v in changed if (not names or n in names)
                 and self.gate.forbids("params", ":".join(_split(n))) is None]
        if shown:
            self.send_text(wire.json_frame("parameterValues",
                                           parameters=[_parameter(n, v) for n, v in shown]))

    # -- receiving -----------------------------------------------------------------------------

    def handle_frame(self, frame: str | bytes) -> None:
        """Parse one frame and carry out its op; whatever is wrong goes back as ``status``."""
        if not self.gate.admit_frame(len(frame)):
            return
        cap = self.shared.link_config.max_message_size
        if len(frame) > cap:
            self.error(f"a frame of {len(frame)} bytes is over this bridge's limit of {cap} "
                       "bytes (--max-message-size); it was dropped", "protocol")
            return
        try:
            op = wire.parse_text(frame) if isinstance(frame, str) else wire.parse_binary(frame)
        except wire.WireError as exc:
            self.error(str(exc), "protocol")
            return
        handler = self._HANDLERS[type(op)]
        try:
            handler(self, op)
        except BridgeError as exc:
            self.error(str(exc))
        except Exception:
            log.exception("foxglove client %d: %s failed", self.sid, type(op).__name__)
            self.error(f"{type(op).__name__}: internal error (the bridge log has the details)",
                       "internal")

    # -- subscriptions -------------------------------------------------------------------------

    def _subscribe(self, op: wire.Subscribe) -> None:
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

    def _add_subscription(self, sub_id: int, channel: wire.Channel) -> None:
        topic = channel.topic
        cls = self.graph.resolve_message(channel.schema_name)
        sub = Subscription(self.outbox, topic, topic)
        header = wire.message_data_header
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

    def _unsubscribe(self, op: wire.Unsubscribe) -> None:
        for sub_id in op.subscription_ids:
            found = self.subscriptions.pop(sub_id, None)
            if found is None:
                self.error(f"unsubscribe: no subscription {sub_id} on this connection")
                continue
            self._drop(found[0])

    def _drop(self, sub: Subscription) -> None:
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

    def _advertise(self, op: wire.ClientAdvertise) -> None:
        for ch in op.channels:
            try:
                self._add_client_channel(ch)
            except BridgeError as exc:
                self.error(f"advertise: channel {ch.id} ({ch.topic}): {exc}")

    def _add_client_channel(self, ch: wire.ClientChannel) -> None:
        topic = full_name(ch.topic)
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
            decode = wire.parse_json
        pub = self.topics.publishers.get(topic)
        if pub is None:
            pub = self.topics.publishers[topic] = self.graph.acquire_publisher(topic, cls, False,
                                                                               10)
        self._publisher_refs[topic] = self._publisher_refs.get(topic, 0) + 1
        conv = pub.conv

        def convert(payload: bytes) -> Any:
            return conv.from_obj(decode(payload), "msg")

        self.client_channels[ch.id] = _ClientChannel(ch.id, topic, ch.encoding, pub,
                                                     Inbound(convert))

    def _unadvertise(self, op: wire.ClientUnadvertise) -> None:
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

    def _publish(self, op: wire.ClientMessage) -> None:
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

    def _not_published(self, ch: _ClientChannel, why: BaseException | str) -> None:
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

    # -- services ------------------------------------------------------------------------------

    def _call(self, op: wire.ServiceCall) -> None:
        entry = self.hub.services_by_id.get(op.service_id)
        why: str | None = None
        if entry is None:
            why = f"no service {op.service_id} (unknown, or no longer advertised)"
        elif (forbidden := self.gate.forbids("call_service", entry.name)) is not None:
            why = f"forbidden: {forbidden}"
        elif op.encoding not in ENCODINGS:
            why = f"encoding {op.encoding!r} is not one of {', '.join(ENCODINGS)}"
        elif len(self.calls) >= self.config.max_calls_in_flight:
            why = f"too many calls in flight on this connection (at most " \
                  f"{self.config.max_calls_in_flight})"
        if why is not None or entry is None:
            self._call_failed(op, why or "")
            return
        try:
            args = (cdr.decode(op.payload, entry.srv.Request) if op.encoding == "cdr"
                    else wire.parse_json(op.payload))
        except (cdr.CdrError, ValueError) as exc:
            self._call_failed(op, f"the request does not decode as {entry.type_name} "
                              f"({op.encoding}): {exc}")
            return
        self.spawn(self._run_call(op, entry, args))

    async def _run_call(self, op: wire.ServiceCall, entry: ServiceEntry, args: Any) -> None:
        try:
            values = await self.graph.call_service(
                entry.name, entry.type_name, args, self.config.call_timeout,
                self.config.discovery_wait)
            if op.encoding == "cdr":
                payload = cdr.encode(entry.srv.Response.from_json(values))
            else:
                payload = json.dumps(values).encode()
        except (BridgeError, ValidationError, ValueError) as exc:
            self._call_failed(op, str(exc))
            return
        self.send_text(wire.service_response_frame(op.service_id, op.call_id, op.encoding,
                                                   payload))

    def _call_failed(self, op: wire.ServiceCall, why: str) -> None:
        log.info("foxglove client %d: service call %d failed: %s", self.sid, op.call_id, why)
        self.shared.metrics.error("request")
        self.send_text(wire.json_frame("serviceCallFailure", serviceId=op.service_id,
                                       callId=op.call_id, message=why))

    # -- parameters ----------------------------------------------------------------------------

    def _get_parameters(self, op: wire.GetParameters) -> None:
        for name in op.names:
            _split(name)  # a name that is not /node.param is refused now
        if op.names or self.gate.allowed(op, *PARAMETER_LISTING):
            self.spawn(self._answer_parameters(list(op.names), op.id))
        elif op.id is not None:  # refused (the client was told): no values for the id
            self.send_text(wire.json_frame("parameterValues", parameters=[], id=op.id))

    async def _answer_parameters(self, names: list[str], request_id: str | None) -> None:
        if not names:
            names = await self._all_parameter_names()
        found: list[dict[str, Any]] = []
        for name, value in zip(names, await asyncio.gather(
                *(self._get_one(n) for n in names)), strict=True):
            if value is not _MISSING:
                found.append(_parameter(name, value))
        self.send_text(wire.json_frame("parameterValues", parameters=found, id=request_id))

    async def _all_parameter_names(self) -> list[str]:
        nodes = [f"{ns.rstrip('/')}/{n}" for n, ns in self.graph.node_names()]

        async def of(node: str) -> list[str]:
            try:
                names = await self.graph.parameter_names(node, 2.0)
            except Exception:  # a node without parameter services, or gone
                return []
            return [f"{node}.{p}" for p in names
                    if self.gate.forbids("params", f"{node}:{p}") is None]

        return [name for names in await asyncio.gather(*(of(n) for n in nodes))
                for name in names]

    async def _get_one(self, name: str) -> Any:
        node, param = _split(name)
        why = self.gate.forbids("params", f"{node}:{param}")
        if why is not None:
            self.error(f"getParameters: {name}: forbidden: {why}")
            return _MISSING
        try:
            is_set, value = await self.graph.get_parameter(node, param)
        except (TimeoutError, LookupError, BridgeError) as exc:
            self.error(f"getParameters: {name}: node {node} did not answer ({exc or 'timeout'})")
            return _MISSING
        return value if is_set else _MISSING

    def _set_parameters(self, op: wire.SetParameters) -> None:
        for name, _, _ in op.parameters:
            _split(name)
        self.spawn(self._run_set(op))

    async def _run_set(self, op: wire.SetParameters) -> None:
        done: list[str] = []
        for name, raw, kind in op.parameters:
            node, param = _split(name)
            why = self.gate.forbids("params", f"{node}:{param}")
            if why is not None:
                self.error(f"setParameters: {name}: forbidden: {why}")
                continue
            try:
                value = _from_wire(raw, kind)
                ok, reason = await self.graph.set_parameter(node, param, value)
            except (ValueError, TypeError) as exc:
                self.error(f"setParameters: {name}: {exc}")
                continue
            except (TimeoutError, LookupError, BridgeError) as exc:
                self.error(f"setParameters: {name}: node {node} did not answer "
                           f"({exc or 'timeout'})")
                continue
            if not ok:
                self.error(f"setParameters: {name}: the node refused: {reason or 'no reason'}")
                continue
            done.append(name)
        if op.id is not None:
            await self._answer_parameters(done, op.id) if done else self.send_text(
                wire.json_frame("parameterValues", parameters=[], id=op.id))

    def _follow_parameters(self, op: wire.SubscribeParameterUpdates) -> None:
        if not self.gate.allowed(op, *PARAMETER_LISTING):
            return
        current = self.parameter_names
        if not op.names:
            self.parameter_names = set()
        elif current is None:
            self.parameter_names = set(op.names)
        elif current:
            current.update(op.names)
        self.hub.update_watches()

    def _unfollow_parameters(self, op: wire.UnsubscribeParameterUpdates) -> None:
        current = self.parameter_names
        if not op.names or current is None:
            self.parameter_names = None
        else:
            current.difference_update(op.names)
            if not current:
                self.parameter_names = None
        self.hub.update_watches()

    # -- connection graph, assets ----------------------------------------------------------------

    def _follow_graph(self, op: wire.SubscribeConnectionGraph) -> None:
        if self.gate.allowed(op, *LISTING):
            self.hub.follow_graph(self)

    def _unfollow_graph(self, op: wire.UnsubscribeConnectionGraph) -> None:
        self.graph_seen = None

    def _fetch_asset(self, op: wire.FetchAsset) -> None:
        self.error(f"fetchAsset {op.uri}: this server has no assets (no 'assets' capability)")

    _HANDLERS: dict[type[Any], Callable[[FoxgloveSession, Any], None]] = {
        wire.Subscribe: _subscribe,
        wire.Unsubscribe: _unsubscribe,
        wire.ClientAdvertise: _advertise,
        wire.ClientUnadvertise: _unadvertise,
        wire.ClientMessage: _publish,
        wire.ServiceCall: _call,
        wire.GetParameters: _get_parameters,
        wire.SetParameters: _set_parameters,
        wire.SubscribeParameterUpdates: _follow_parameters,
        wire.UnsubscribeParameterUpdates: _unfollow_parameters,
        wire.SubscribeConnectionGraph: _follow_graph,
        wire.UnsubscribeConnectionGraph: _unfollow_graph,
        wire.FetchAsset: _fetch_asset,
    }

    # -- grants --------------------------------------------------------------------------------

    def recheck_grants(self) -> int:
        """The role changed (SIGHUP): end the subscriptions, publishers, time and graph
        updates it no longer allows, and bring the client's channels and services to it; how
        many ended."""
        ended = 0
        for sub_id, (sub, channel) in list(self.subscriptions.items()):
            why = self.gate.forbids("subscribe", channel.topic)
            if why is not None:
                del self.subscriptions[sub_id]
                self._drop(sub)
                self.error(f"subscription {sub_id} to {channel.topic} ended: {why}")
                ended += 1
        for channel_id, ch in list(self.client_channels.items()):
            why = self.gate.forbids("publish", ch.topic)
            if why is not None:
                self._unadvertise(wire.ClientUnadvertise((channel_id,)))
                self.error(f"client channel {channel_id} to {ch.topic} ended: {why}")
                ended += 1
        self.show_lists()
        if self.uses_time and (why := self.gate.forbids("subscribe", CLOCK)) is not None:
            self.uses_time = False
            self.error(f"time from {CLOCK} ended: {why}")
            ended += 1
        if self.graph_seen is not None:
            if (why := self.gate.forbids(*LISTING)) is None:
                self.show_graph(self.hub.connection_graph)  # what it no longer sees goes
            else:
                self.graph_seen = None
                self.error(f"connection graph updates ended: {why}")
                ended += 1
        return ended


_MISSING = object()


def _split(name: str) -> tuple[str, str]:
    """``/node.param`` as (``/node``, ``param``): node names have no dots, parameters may."""
    node, dot, param = name.partition(".")
    if not dot or not node or not param:
        raise BridgeError(f"parameter {name!r}: expected '/node_name.parameter_name'")
    return full_name(node), param


def _parameter(name: str, value: Any) -> dict[str, Any]:
    """One entry of ``parameterValues`` from a Graph parameter value, as the spec has it: a
    byte array as base64 text typed ``byte_array``, a double typed ``float64``, a non-empty
    double array typed ``float64_array`` (an empty one cannot be told from other empty
    arrays), ``None`` (unset) with no value. JSON has no NaN or infinity: a double that is
    one is its text (``"nan"``, ``"inf"``, ``"-inf"``) and the value is not typed as a
    number, in an array too."""
    if isinstance(value, bytes | bytearray):
        return {"name": name, "value": base64.b64encode(value).decode(), "type": "byte_array"}
    if isinstance(value, float):
        if not math.isfinite(value):
            return {"name": name, "value": str(value)}
        return {"name": name, "value": value, "type": "float64"}
    if isinstance(value, list) and value and all(isinstance(v, float) for v in value):
        if not all(math.isfinite(v) for v in value):
            return {"name": name, "value": [v if math.isfinite(v) else str(v) for v in value]}
        return {"name": name, "value": value, "type": "float64_array"}
    if value is None:
        return {"name": name}
    return {"name": name, "value": value}


def _from_wire(value: Any, kind: str | None) -> Any:
    """A ``setParameters`` value as the Graph takes it."""
    if value is None:
        return None
    if kind == "byte_array":
        if not isinstance(value, str):
            raise ValueError("a byte_array value must be a base64 string")
        try:
            return base64.b64decode(value, validate=True)
        except binascii.Error as exc:
            raise ValueError(f"a byte_array value is not base64: {exc}") from None
    if kind == "float64":
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"a float64 value must be a number, got {type(value).__name__}")
        return float(value)
    if kind == "float64_array":
        if not isinstance(value, list) or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value):
            raise ValueError("a float64_array value must be a list of numbers")
        return [float(v) for v in value]
    return value
