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

The session is built of parts along its jobs: :mod:`.base` (its state and the frames that
tell the client something), :mod:`.channels` (subscriptions and client publishing) and
:mod:`.parameters`; this module runs the frame loop, answers service calls and the
connection graph, and re-checks grants.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from bridge_server.foxglove import ops
from bridge_server.foxglove.base import ENCODINGS, log
from bridge_server.foxglove.channels import QUEUE_BYTES, ChannelOps
from bridge_server.foxglove.hub import CLOCK
from bridge_server.foxglove.parameters import ParameterOps
from msgs import cdr
from msgs.runtime import ValidationError
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol.constants import POLICY_VIOLATION
from rosbridge_core.security.permissions import LISTING, PARAMETER_LISTING
from rosbridge_core.session.client_status import ClientStatus, client_status
from rosbridge_core.session.liveness import watch_link

if TYPE_CHECKING:
    from bridge_server.foxglove.hub import GraphState, Hub, ServiceEntry
    from rosbridge_core.session.host import Shared
    from rosbridge_core.session.link import ClientLink

__all__ = ["ENCODINGS", "OVERSIZE_GRACE", "QUEUE_BYTES", "FoxgloveSession"]

OVERSIZE_GRACE = 1024 * 1024
"""Bytes past ``--max-message-size`` a Foxglove frame may have and still be answered
with a ``status`` error (and dropped) rather than a close (1009)."""


class FoxgloveSession(ChannelOps, ParameterOps):
    """One Foxglove client (see the module's text)."""

    hub: Hub[FoxgloveSession]

    def __init__(self, shared: Shared, hub: Hub[FoxgloveSession], link: ClientLink, sid: int
                 ) -> None:
        """Client ``sid``'s session over ``link``, sharing ``shared`` with the other sessions
        of its server and ``hub`` with the other Foxglove ones."""
        super().__init__(shared, hub, link, sid)
        self.gate = shared.security.gate(self)

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
        self.send_text(ops.json_frame(
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

    def graph_changed(self, added: list[ops.Channel], removed: list[ops.Channel],
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
            self.send_text(ops.json_frame("unadvertise", channelIds=gone))
        if gone := sorted(self.shown_services - services.keys()):
            self.send_text(ops.json_frame("unadvertiseServices", serviceIds=gone))
        if new := [c.to_json() for i, c in channels.items() if i not in self.shown_channels]:
            self.send_text(ops.json_frame("advertise", channels=new))
        if new := [e.to_json() for i, e in services.items() if i not in self.shown_services]:
            self.send_text(ops.json_frame("advertiseServices", services=new))
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
            self.send_text(ops.json_frame("connectionGraphUpdate", **update))

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
            op = ops.parse_text(frame) if isinstance(frame, str) else ops.parse_binary(frame)
        except ops.OpError as exc:
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

    # -- services ------------------------------------------------------------------------------

    def _call(self, op: ops.ServiceCall) -> None:
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
                    else ops.parse_json(op.payload))
        except (cdr.CdrError, ValueError) as exc:
            self._call_failed(op, f"the request does not decode as {entry.type_name} "
                              f"({op.encoding}): {exc}")
            return
        self.spawn(self._run_call(op, entry, args))

    async def _run_call(self, op: ops.ServiceCall, entry: ServiceEntry, args: Any) -> None:
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
        self.send_text(ops.service_response_frame(op.service_id, op.call_id, op.encoding,
                                                   payload))

    def _call_failed(self, op: ops.ServiceCall, why: str) -> None:
        log.info("foxglove client %d: service call %d failed: %s", self.sid, op.call_id, why)
        self.shared.metrics.error("request")
        self.send_text(ops.json_frame("serviceCallFailure", serviceId=op.service_id,
                                       callId=op.call_id, message=why))

    # -- connection graph, assets ----------------------------------------------------------------

    def _follow_graph(self, op: ops.SubscribeConnectionGraph) -> None:
        if self.gate.allowed(op, *LISTING):
            self.hub.follow_graph(self)

    def _unfollow_graph(self, op: ops.UnsubscribeConnectionGraph) -> None:
        self.graph_seen = None

    def _fetch_asset(self, op: ops.FetchAsset) -> None:
        self.error(f"fetchAsset {op.uri}: this server has no assets (no 'assets' capability)")

    _HANDLERS: dict[type[Any], Callable[[FoxgloveSession, Any], None]] = {
        ops.Subscribe: ChannelOps._subscribe,
        ops.Unsubscribe: ChannelOps._unsubscribe,
        ops.ClientAdvertise: ChannelOps._advertise,
        ops.ClientUnadvertise: ChannelOps._unadvertise,
        ops.ClientMessage: ChannelOps._publish,
        ops.ServiceCall: _call,
        ops.GetParameters: ParameterOps._get_parameters,
        ops.SetParameters: ParameterOps._set_parameters,
        ops.SubscribeParameterUpdates: ParameterOps._follow_parameters,
        ops.UnsubscribeParameterUpdates: ParameterOps._unfollow_parameters,
        ops.SubscribeConnectionGraph: _follow_graph,
        ops.UnsubscribeConnectionGraph: _unfollow_graph,
        ops.FetchAsset: _fetch_asset,
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
                self._unadvertise(ops.ClientUnadvertise((channel_id,)))
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
