"""What one websocket client owns, and how its ops are carried out.

A :class:`Session` holds the client's publishers (advertise), its
subscriptions (merged per topic, any number of ids each), the services it
serves, its service calls in flight (concurrent asyncio tasks, each with a
timeout) and its outgoing queues.

Outgoing queues and the drop policy
-----------------------------------
Every subscription (one per topic, whatever the number of ids) has its own
bounded queue of ``queue_length`` messages (0 means :data:`DEFAULT_QUEUE_LENGTH`);
when it is full the OLDEST message of that subscription is dropped. Replies
(service responses, status ops, ROS calls to client-served services) go to a
separate control queue, bounded by ``control_limit`` (oldest dropped, logged).
The per-ROS-message fan-out only appends to these queues and sets an event;
one writer task per session drains them into the socket, so a client that
stops reading holds at most its queues plus the socket's write buffer, and
never delays anyone else. Dropped messages are counted per subscription and
reported to the client as a ``status`` warning (``dropped N messages on
/topic ...``) at most once per ``drop_report_interval`` seconds (5 s); drops
inside that interval are summed into the next report. ``set_level`` ``error``
silences these warnings.

The writer gathers whatever is ready (up to :data:`BATCH_FRAMES` frames or
:data:`BATCH_BYTES` bytes) and writes it with one socket write.

Merged subscriptions
--------------------
Several subscribe ops of one client to one topic (different ids) share one
queue, and each message is sent once. The merged options are: the least
``throttle_rate``, the largest ``queue_length``, the least ``fragment_size``,
and the ``compression`` of the latest subscribe. ``throttle_rate`` keeps the
newest message of a burst and sends it when the interval is over.
``fragment_size`` applies to JSON text only (binary CBOR frames are never
split); ``compression: png`` (legacy) falls back to plain JSON with a warning.

Service calls
-------------
Each ``call_service`` runs as its own task (at most ``max_calls_in_flight``,
1024, per connection; more fail at once), with ``timeout`` seconds (default
5). Without a type, a service that is not in the ROS graph within
``discovery_wait`` (2 s) fails with "does not exist"; with a type, one the graph
still lists no server of after twice that fails so too (a server started just
before the call can take ~3 s to appear on a loaded machine). A listed service
is waited for (its server to match) up to the call's timeout.
``fragment_size`` on a call splits its ``service_response``.

Client-served services
----------------------
A ROS caller of a service advertised by the client reaches it as
``call_service`` with id ``service_request:<service>:<n>``. If the client
answers ``result: false``, does not answer within ``served_call_timeout``
(10 s) or answers with a response that does not convert, the ROS caller is
not answered (an rclpy service cannot reply with an error, and the bridge
never invents a default response): the caller's own timeout ends its wait.
When the client unadvertises the service or disconnects, the ROS service is
destroyed at once; rclpy callers then see ``service_is_ready()`` turn false,
and requests in flight stay unanswered until the caller's timeout.

A name another client serves stays with its first owner: advertising it
again fails, unless the same principal asks (a reconnect), the role has
``take_over`` on the name, or the owner's connection does not answer a ping
within 2 s (a network drop the bridge has not noticed yet)
(:mod:`bridge_server.security`).

Actions
-------
Action ops go to ``self.actions`` (:class:`bridge_server.actions.SessionActions`,
closed with the session); see :mod:`bridge_server.actions`.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import itertools
import logging
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from websockets.exceptions import ConnectionClosed

from roslibpy_lite import keepalive, ops
from roslibpy_lite.exceptions import ProtocolError
from roslibpy_lite.ops import ACKS_HEADER, parse_op
from roslibpy_lite.protocol import Protocol, decode_frame, split_fragments

from . import convert, rosapi
from .actions import SessionActions
from .metrics import outcome
from .types import BridgeError, canonical_name

if TYPE_CHECKING:
    from websockets.asyncio.server import ServerConnection

    from .ros import Incoming, PendingRosCall, RosNode, ServedService, SharedPublisher
    from .ros import SharedSubscription as _Shared
    from .server import Bridge

__all__ = ["DEFAULT_QUEUE_LENGTH", "Session", "SessionConfig"]

log = logging.getLogger("bridge_server.session")

DEFAULT_QUEUE_LENGTH = 100
"""Bound of a subscription's queue when the client asked for ``queue_length`` 0."""

BATCH_FRAMES = 128
"""Most frames the writer sends with one socket write."""

BATCH_BYTES = 256 * 1024
"""Most bytes the writer gathers for one socket write (a large frame goes alone)."""


_LEVELS = {"none": 0, "error": 1, "warning": 2, "info": 3}

_ACKED = (ops.Advertise, ops.Subscribe, ops.AdvertiseService, ops.AdvertiseAction)
_ACTION_OPS = (
    ops.SendActionGoal,
    ops.CancelActionGoal,
    ops.ActionFeedback,
    ops.ActionResult,
    ops.AdvertiseAction,
    ops.UnadvertiseAction,
)


@dataclass
class SessionConfig:
    """Per-session limits and defaults (set from the command line)."""

    default_queue_length: int = DEFAULT_QUEUE_LENGTH
    control_limit: int = 10_000
    call_timeout: float = 5.0
    served_call_timeout: float = 10.0
    drop_report_interval: float = 5.0
    discovery_wait: float = 2.0
    max_calls_in_flight: int = 1024
    goal_timeout: float = 0.0  # action goals: seconds before one is canceled/aborted, 0 = never


class _Sub:
    """One client's (merged) subscription to one topic."""

    def __init__(self, session: Session, topic: str, wire: str) -> None:
        self.session = session
        self.topic = topic
        self.wire = None if wire == topic else wire  # the client's spelling, if different
        self.ids: dict[ops.Id | None, ops.Subscribe] = {}
        self.shared: _Shared | None = None
        self.queue: deque[Incoming] = deque()
        self.maxlen = DEFAULT_QUEUE_LENGTH
        self.throttle = 0.0
        self.fragment_size: int | None = None
        self.compression = "none"
        self.last_sent = 0.0
        self.pending: Incoming | None = None
        self.timer: asyncio.TimerHandle | None = None
        self.dropped = 0
        self.dropped_total = 0
        self.sent = 0  # frames of this subscription written, and their bytes (for /metrics)
        self.sent_bytes = 0
        self.last_report = -1e9
        self.report_timer: asyncio.TimerHandle | None = None
        self.active = True

    def configure(self, default_len: int, max_len: int = 0, min_fragment: int = 0) -> None:
        """Merge the options of every id: least throttle, largest queue, least fragment size
        (the queue at most ``max_len``, fragments at least ``min_fragment`` bytes)."""
        subs = list(self.ids.values())
        self.throttle = min(s.throttle_rate for s in subs) / 1000.0
        lens = [s.queue_length or default_len for s in subs]
        self.maxlen = min(max(lens), max_len) if max_len else max(lens)
        sizes = [s.fragment_size for s in subs if s.fragment_size]
        self.fragment_size = max(min(sizes), min_fragment) if sizes else None
        self.compression = subs[-1].compression
        while len(self.queue) > self.maxlen:
            self.queue.popleft()
            self.session.queued -= 1

    def on_message(self, inc: Incoming) -> None:
        """Called on the loop for each message of the topic: throttle, then queue."""
        if self.throttle > 0:
            now = time.monotonic()
            wait = self.last_sent + self.throttle - now
            if wait > 0:
                self.pending = inc
                if self.timer is None:
                    self.timer = self.session.loop.call_later(wait, self._flush)
                return
            self.last_sent = now
        self.push(inc)

    def _flush(self) -> None:
        self.timer = None
        inc, self.pending = self.pending, None
        if inc is not None and self.active:
            self.last_sent = time.monotonic()
            self.push(inc)

    def push(self, inc: Incoming) -> None:
        """Queue one message, dropping this subscription's oldest when full (or when the
        client's queues hold :attr:`Session.max_queued` messages in all)."""
        q = self.queue
        s = self.session
        if len(q) >= self.maxlen or (s.queued >= s.max_queued and q):
            q.popleft()
            self.dropped += 1
            self.dropped_total += 1
            s._note_drop(self)
        elif s.queued >= s.max_queued:  # full with other subscriptions' messages: drop this one
            self.dropped += 1
            self.dropped_total += 1
            s._note_drop(self)
            return
        else:
            s._order.append(self)
            s.queued += 1
        q.append(inc)
        s._wake.set()

    def close(self) -> None:
        """Stop delivering: clear the queue and any throttle timer."""
        self.active = False
        self.session.queued -= len(self.queue)
        self.queue.clear()
        if self.report_timer is not None:
            self.report_timer.cancel()
            self.report_timer = None
        self.pending = None
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None


class _Served:
    """A service this client serves, with the ROS callers waiting on it."""

    def __init__(self, name: str, type_name: str, wire: str | None = None) -> None:
        self.name = name
        self.wire = wire or name  # the name as the client spelled it
        self.type_name = type_name
        self.ros: ServedService | None = None
        self.pending: dict[str, tuple[PendingRosCall | _DirectCall, asyncio.TimerHandle]] = {}


class _DirectCall:
    """A call from another client of this bridge to a service this client serves.

    It goes from session to session without a ROS hop, so a failure keeps its
    ``result: false`` and text (a ROS service has no way to report one).
    """

    def __init__(self, future: asyncio.Future[tuple[bool, Any]]) -> None:
        self.future = future

    def fail(self, reason: str) -> None:
        if not self.future.done():
            self.future.set_result((False, reason))

    def succeed(self, values: Mapping[str, Any]) -> None:
        if not self.future.done():
            self.future.set_result((True, values))


class Session:
    """One websocket client of the bridge."""

    def __init__(self, bridge: Bridge, ws: ServerConnection, sid: int) -> None:
        self.bridge = bridge
        self.ros: RosNode = bridge.ros
        self.ws = ws
        self.sid = sid
        self.config: SessionConfig = bridge.session_config
        self.loop = asyncio.get_running_loop()
        # Reassembled fragments are held to the same bound as a single frame.
        self.protocol = Protocol(
            max_partial=16, max_fragment_bytes=bridge.config.max_message_size
        )
        self.publishers: dict[str, SharedPublisher] = {}
        self.subs: dict[str, _Sub] = {}
        self.served: dict[str, _Served] = {}
        self.calls: set[asyncio.Task[None]] = set()
        self.level = _LEVELS["warning"]
        request = getattr(ws, "request", None)
        self.acks = request is not None and request.headers.get(ACKS_HEADER) == "1"
        self.errors_sent = 0
        self._control: deque[str | bytes] = deque()
        self._order: deque[_Sub] = deque()
        limits = bridge.security.config
        self.queued = 0  # messages in all of this client's subscription queues
        self.max_queued = limits.max_queued_messages or 1 << 62
        self._wake = asyncio.Event()
        self._closed = False
        self._frag_ids = itertools.count()
        self._request_ids = itertools.count()
        self.control_dropped = 0
        self.peer = ""  # the client's address, and since when (for the status page)
        self.connected_at = time.time()
        self._frame_len = 0
        self.actions = SessionActions(self)
        self.gate = bridge.security.gate(self)  # auth, rate, names, permissions (security/gate.py)

    # -- running -------------------------------------------------------------------------------

    @property
    def closed(self) -> bool:
        """Whether the connection has ended (nothing more is handled or sent)."""
        return self._closed

    async def run(self) -> None:
        """Serve the client until it disconnects; then release everything it owned."""
        writer = asyncio.create_task(self._writer(), name=f"session-{self.sid}-writer")
        cfg = self.bridge.config
        watcher = None
        transport = getattr(self.ws, "transport", None)
        if cfg.keepalive_interval and keepalive.supported_here() and transport is not None:
            watcher = asyncio.create_task(keepalive.watch(
                transport, self.ws.ping, self._link_dead, cfg.keepalive_interval,
                cfg.keepalive_timeout), name=f"session-{self.sid}-keepalive")
        try:
            async for frame in self.ws:
                self.handle_frame(frame)
        except ConnectionClosed:
            pass
        finally:
            self._closed = True
            self._wake.set()
            if watcher is not None:
                watcher.cancel()
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, ConnectionClosed):
                await writer
            await self.cleanup()

    def _link_dead(self, silence: float) -> None:
        log.warning("client %d: no sign of it for %.1f s (a silent link): dropping it and "
                    "what it owned", self.sid, silence)

    async def _writer(self) -> None:
        ws = self.ws
        wake = self._wake
        batched = hasattr(ws, "send_context") and hasattr(ws, "protocol")
        try:
            while not self._closed:
                frames = self._collect()
                if not frames:
                    wake.clear()
                    await wake.wait()
                    continue
                if batched:
                    await self._send_batch(frames)
                else:  # pragma: no cover - websockets without send_context
                    for frame in frames:
                        await ws.send(frame)
        except ConnectionClosed:
            pass
        except Exception:
            log.exception("session %d: the writer failed; closing the connection", self.sid)
            await ws.close(1011, "internal error")

    def _collect(self) -> list[str | bytes]:
        """Take the frames ready to go: replies first, then messages in arrival order."""
        frames: list[str | bytes] = []
        size = 0
        control = self._control
        order = self._order
        while control and len(frames) < BATCH_FRAMES and size < BATCH_BYTES:
            frame = control.popleft()
            frames.append(frame)
            size += len(frame)
        while order and len(frames) < BATCH_FRAMES and size < BATCH_BYTES:
            sub = order.popleft()
            if not sub.queue:
                continue
            inc = sub.queue.popleft()
            self.queued -= 1
            try:
                encoded = self._frames(sub, inc)
            except Exception:
                log.exception("session %d: cannot encode a message of %s", self.sid, sub.topic)
                continue
            before = size
            for frame in encoded:
                frames.append(frame)
                size += len(frame)
            sub.sent += 1
            sub.sent_bytes += size - before
        return frames

    async def _send_batch(self, frames: list[str | bytes]) -> None:
        """Write several frames with one socket write (one system call, not one per frame).

        Uses websockets' own send context, so its state checks, flow control
        (``write_limit``) and closing rules apply as for ``send``.
        """
        ws = self.ws
        async with ws.send_context():
            protocol = ws.protocol
            for frame in frames:
                if isinstance(frame, str):
                    protocol.send_text(frame.encode())
                else:
                    protocol.send_binary(frame)
            chunks = protocol.data_to_send()
            if all(chunks):
                ws.transport.write(b"".join(chunks))
            else:  # an end-of-stream marker: let websockets handle these chunks itself
                for chunk in chunks:
                    if chunk:
                        ws.transport.write(chunk)
                    elif ws.transport.can_write_eof():
                        ws.transport.write_eof()

    def _frames(self, sub: _Sub, inc: Incoming) -> list[str | bytes]:
        comp = sub.compression
        if comp == "cbor":
            return [inc.cbor(sub.wire)]
        if comp == "cbor-raw":
            return [inc.cbor_raw(sub.wire)]
        text = inc.json_text(sub.wire)
        size = sub.fragment_size
        if size is not None and len(text) > size:
            return list(split_fragments(text, size, f"{sub.topic}:{next(self._frag_ids)}"))
        return [text]

    async def cleanup(self) -> None:
        """Release what this client owned (subscriptions and services at once, publishers later)."""
        self.gate.end()
        for sub in list(self.subs.values()):
            self._drop_sub(sub)
        self.subs.clear()
        for served in list(self.served.values()):
            self._remove_served(served, "the client that served it disconnected")
        self.served.clear()
        await self.actions.close()
        for task in list(self.calls):
            task.cancel()
        if self.calls:
            await asyncio.gather(*self.calls, return_exceptions=True)
        grace = self.bridge.publisher_grace
        for pub in self.publishers.values():
            if grace > 0:
                self.loop.call_later(grace, self.ros.release_publisher, pub)
            else:
                self.ros.release_publisher(pub)
        self.publishers.clear()

    # -- sending -------------------------------------------------------------------------------

    def send_text(self, text: str | bytes) -> None:
        """Queue one control frame (replies and status) for the writer."""
        if self._closed:
            return
        control = self._control
        if len(control) >= self.config.control_limit:
            control.popleft()
            self.control_dropped += 1
            if self.control_dropped in (1, 10, 100) or self.control_dropped % 1000 == 0:
                log.warning(
                    "session %d: dropped %d replies: the client does not read",
                    self.sid,
                    self.control_dropped,
                )
        control.append(text)
        self._wake.set()

    def send_op(self, op: ops.Op) -> None:
        """Queue one op as JSON text."""
        self.send_text(ops.encode(op))

    def status(self, level: str, msg: str, id: ops.Id | None = None) -> None:
        """Send a ``status`` op if the client's level admits it."""
        if _LEVELS.get(level, 1) > self.level:
            return
        self.send_op(ops.Status(level=level, msg=msg, id=id))

    def error(self, msg: str, id: ops.Id | None = None, kind: str = "request") -> None:
        """Report a failed request to the client (``status`` level error); count it by kind."""
        log.info("session %d: %s", self.sid, msg)
        self.errors_sent += 1
        self.bridge.metrics.error(kind)
        self.status("error", msg, id)

    def _note_drop(self, sub: _Sub) -> None:
        if sub.report_timer is not None:
            return  # a report is already scheduled
        wait = sub.last_report + self.config.drop_report_interval - time.monotonic()
        if wait > 0:
            sub.report_timer = self.loop.call_later(wait, self._report_drops, sub)
        else:
            self._report_drops(sub)

    def _report_drops(self, sub: _Sub) -> None:
        sub.report_timer = None
        n, sub.dropped = sub.dropped, 0
        if n == 0 or not sub.active:
            return
        sub.last_report = time.monotonic()
        log.info("session %d: dropped %d messages on %s", self.sid, n, sub.topic)
        self.status(
            "warning",
            f"dropped {n} messages on {sub.topic} (queue_length {sub.maxlen}, "
            f"{sub.dropped_total} in all): the client reads slower than messages arrive",
        )

    # -- receiving -----------------------------------------------------------------------------

    def handle_frame(self, frame: str | bytes) -> None:
        """Decode one frame and carry out the op it completes; errors go back as ``status``."""
        self._frame_len = len(frame)
        if not self.gate.admit_frame(len(frame)):
            return
        try:
            # Before authentication a frame is one op: fragments are not held for reassembly
            # (the gate refuses a fragment like any op but auth).
            op = (self.protocol.receive(frame) if self.gate.authenticated
                  else parse_op(decode_frame(frame)))
        except ProtocolError as exc:
            if not self.gate.authenticated:  # one answer, not one per frame of a flood
                self.gate.close(f"authentication required: the first op must be auth "
                                f"({exc.message[:60]})")
                return
            self.error(exc.message, exc.id, "protocol")
            return
        except Exception as exc:  # the core promises ProtocolError; stay up regardless
            log.exception("session %d: decoding a frame failed", self.sid)
            self.error(f"cannot decode the frame: {type(exc).__name__}", kind="internal")
            return
        if self.protocol.evicted:
            self._report_evicted()
        if op is not None:
            self.handle_op(op)

    def handle_op(self, op: ops.Op) -> None:
        """Carry out one parsed op."""
        if not self.gate.check(op):
            return
        errors = self.errors_sent
        try:
            if isinstance(op, ops.Publish):
                self.publish(op)
            elif isinstance(op, ops.Subscribe):
                self.subscribe(op)
            elif isinstance(op, ops.Unsubscribe):
                self.unsubscribe(op)
            elif isinstance(op, ops.Advertise):
                self.advertise(op)
            elif isinstance(op, ops.Unadvertise):
                self.unadvertise(op)
            elif isinstance(op, ops.CallService):
                if len(self.calls) >= self.config.max_calls_in_flight:
                    self._respond(
                        op.service,
                        op.id,
                        False,
                        f"too many calls in flight on this connection "
                        f"(at most {self.config.max_calls_in_flight})",
                    )
                    return
                task = self.loop.create_task(self.call_service(op))
                self.calls.add(task)
                task.add_done_callback(self.calls.discard)
            elif isinstance(op, ops.ServiceResponse):
                self.service_response(op)
            elif isinstance(op, ops.AdvertiseService):
                self.advertise_service(op)
            elif isinstance(op, ops.UnadvertiseService):
                self.unadvertise_service(op)
            elif isinstance(op, ops.SetLevel):
                self.set_level(op)
            elif isinstance(op, _ACTION_OPS):
                self.actions.handle(op)
            else:
                self.error(f"{op.OP}: a client may not send this op", getattr(op, "id", None))
        except BridgeError as exc:
            self.error(f"{op.OP}: {exc}", getattr(op, "id", None))
        except UnicodeError:  # a JSON string with a lone surrogate ("\ud800") reached rclpy
            self.error(
                f"{op.OP}: a string in the op is not valid Unicode text (a lone surrogate "
                "such as \\ud800?); ROS strings must be UTF-8",
                getattr(op, "id", None),
            )
        except Exception:
            log.exception("session %d: %s failed", self.sid, op.OP)
            self.error(
                f"{op.OP}: internal error (the bridge log has the details)",
                getattr(op, "id", None), "internal",
            )
        if self.acks and isinstance(op, _ACKED) and self.errors_sent == errors:
            # The client asked for verdicts (ACKS_HEADER): no error means accepted.
            name = (op.service if isinstance(op, ops.AdvertiseService)
                    else op.action if isinstance(op, ops.AdvertiseAction) else op.topic)
            self.send_op(ops.Status(level="info", msg=f"ok: {op.OP} {name}", id=op.id))

    def _report_evicted(self) -> None:
        """Tell the sender which incomplete fragmented ops were dropped to make room."""
        limit = self.protocol.max_partial
        for frag_id, have, total in self.protocol.evicted:
            self.error(
                f"fragment {frag_id!r}: dropped with {have} of {total} pieces: more than "
                f"{limit} fragmented ops were incomplete at once on this connection",
                frag_id,
            )
        self.protocol.evicted.clear()

    # -- topics --------------------------------------------------------------------------------

    def advertise(self, op: ops.Advertise) -> None:
        """Create (or share) a ROS publisher for the topic."""
        topic = _topic_name(op.topic)
        cls = self.ros.resolve_message(op.type)
        type_name = canonical_name(op.type, "msg")
        current = self.publishers.get(topic)
        if current is not None:
            if current.type_name == type_name:
                return
            self.error(
                f"advertise: topic {topic} is already advertised by this client with type "
                f"{current.type_name}, not {type_name}",
                op.id,
            )
            return
        existing = [t for t in self.ros.topic_types(topic) if t != type_name]
        existing += [t for t in self.ros.publisher_types(topic) if t != type_name]
        if existing:
            self.error(
                f"advertise: topic {topic} already has type {existing[0]}; "
                f"cannot advertise it as {type_name}",
                op.id,
            )
            return
        self.publishers[topic] = self.ros.acquire_publisher(
            topic, cls, bool(op.latch), op.queue_size or 1
        )

    def unadvertise(self, op: ops.Unadvertise) -> None:
        """Release this client's publisher for the topic."""
        topic = _topic_name(op.topic)
        pub = self.publishers.pop(topic, None)
        if pub is None:
            self.error(f"unadvertise: topic {topic} is not advertised by this client", op.id)
            return
        self.ros.release_publisher(pub)

    def publish(self, op: ops.Publish) -> None:
        """Convert the message and publish it (auto-advertising a topic the graph knows)."""
        topic = _topic_name(op.topic)
        pub = self.publishers.get(topic)
        if pub is None:
            types = self.ros.topic_types(topic)
            if not types:
                self.error(
                    f"publish: topic {topic} is not advertised and the ROS graph has no type "
                    "for it; send advertise first",
                    op.id,
                )
                return
            cls = self.ros.resolve_message(types[0])
            pub = self.publishers[topic] = self.ros.acquire_publisher(
                topic, cls, bool(op.latch), op.queue_size or 10
            )
        try:
            msg = pub.conv.from_obj(op.msg, "msg")
        except convert.ConversionError as exc:
            self.error(f"publish to {topic} ({pub.type_name}): {exc}", op.id)
            return
        pub.publish(msg)
        self.bridge.metrics.published(topic, self._frame_len)

    def subscribe(self, op: ops.Subscribe) -> None:
        """Add this id to the client's subscription of the topic."""
        topic = _topic_name(op.topic)
        if op.compression == "png":
            # Stock clients still offer png; they all read plain JSON publish ops too.
            self.status(
                "warning",
                f"subscribe to {topic}: compression 'png' is not supported; "
                "sending plain JSON instead (use cbor or cbor-raw for compact messages)",
                op.id,
            )
            op = dataclasses.replace(op, compression="none")
        self._warn_limits(op, topic)
        cls: type[Any] | None = None
        if op.type is None:
            graph = self.ros.topic_types(topic)
            if graph:  # known now: an uninstalled type is an error the client should hear
                cls = self.ros.resolve_message(graph[0])
        else:
            cls = self.ros.resolve_message(op.type)
            type_name = canonical_name(op.type, "msg")
            graph = self.ros.topic_types(topic)
            if graph and type_name not in graph:
                self.error(
                    f"subscribe: topic {topic} has type {graph[0]} in the ROS graph, "
                    f"not {type_name}",
                    op.id,
                )
                return
        sub = self.subs.get(topic)
        if sub is None:
            sub = _Sub(self, topic, op.topic)
            sub.ids[op.id] = op
            self._configure(sub)
            try:
                sub.shared = self.ros.subscribe(topic, cls, sub.on_message)
            except ValueError as exc:
                self.error(f"subscribe: {exc}", op.id)
                return
            self.subs[topic] = sub
            self.bridge.graph_changed()
            latched = sub.shared.latched
            if latched is not None:
                sub.push(latched)
            return
        shared = sub.shared
        if cls is not None and shared is not None:
            if shared.msg_cls is None:
                try:
                    self.ros.subscribe(topic, cls, sub.on_message)
                finally:
                    self.ros.unsubscribe(shared, sub.on_message)
            elif shared.msg_cls is not cls:
                self.error(
                    f"subscribe: topic {topic} is already subscribed with type "
                    f"{shared.type_name}",
                    op.id,
                )
                return
        sub.ids[op.id] = op
        self._configure(sub)

    def unsubscribe(self, op: ops.Unsubscribe) -> None:
        """Remove one id (or, without id, every id) of the client's subscription."""
        topic = _topic_name(op.topic)
        sub = self.subs.get(topic)
        if sub is None:
            self.status("warning", f"unsubscribe: not subscribed to {topic}", op.id)
            return
        if op.id is not None and op.id in sub.ids:
            del sub.ids[op.id]
        elif op.id is not None:
            self.status("warning", f"unsubscribe: no subscription {op.id!r} on {topic}", op.id)
            return
        else:
            sub.ids.clear()
        if sub.ids:
            self._configure(sub)
            return
        del self.subs[topic]
        self._drop_sub(sub)

    def _configure(self, sub: _Sub) -> None:
        """Apply the merged options of a subscription's ids, within the bridge's limits."""
        limits = self.bridge.security.config
        sub.configure(self.config.default_queue_length, limits.max_queue_length,
                      limits.min_fragment_size)

    def _warn_limits(self, op: ops.Subscribe, topic: str) -> None:
        """Say which of a subscribe's options the bridge's limits lower or raise."""
        limits = self.bridge.security.config
        if limits.max_queue_length and op.queue_length > limits.max_queue_length:
            self.status("warning", f"subscribe to {topic}: queue_length {op.queue_length} is "
                        f"over this bridge's limit; using {limits.max_queue_length}", op.id)
        size = op.fragment_size
        if size is not None and 0 < size < limits.min_fragment_size:
            self.status("warning", f"subscribe to {topic}: fragment_size {size} is under this "
                        f"bridge's floor; using {limits.min_fragment_size} bytes", op.id)

    def _drop_sub(self, sub: _Sub) -> None:
        sub.close()
        metrics = self.bridge.metrics
        metrics.retire_subscription(sub.topic, sub.sent, sub.sent_bytes, sub.dropped_total)
        if sub.shared is not None:
            shared, sub.shared = sub.shared, None
            self.ros.unsubscribe(shared, sub.on_message)
            if self.ros.subscriptions.get(shared.topic) is not shared:  # it went: keep its count
                metrics.retire_ros_subscription(shared.topic, shared.received)

    # -- services ------------------------------------------------------------------------------

    async def call_service(self, op: ops.CallService) -> None:
        """Call a ROS service (or a rosapi one) and answer with ``service_response``."""
        service = _topic_name(op.service)
        wire = op.service  # answer with the name as the client spelled it
        timeout = op.timeout if op.timeout is not None else self.config.call_timeout
        values: Mapping[str, Any]
        t0 = time.perf_counter()
        try:
            handler = rosapi.HANDLERS.get(service)
            ahandler = rosapi.ASYNC_HANDLERS.get(service)
            if handler is not None:
                values = handler(self.bridge, rosapi.request_args(service, op.args))
                values = self.gate.filter_rosapi(service, values)  # what the role may see
            elif ahandler is not None:
                values = await ahandler(self.bridge, rosapi.request_args(service, op.args))
                values = self.gate.filter_rosapi(service, values)
            elif (owner := self.bridge.service_owners.get(service)) is not None:
                result, direct = await owner.call_direct(service, op, timeout)
                self._respond(wire, op.id, result, direct, op.fragment_size, t0)
                return
            else:
                values = await self._call_ros(service, op, timeout)
        except _CallFailed as exc:
            self._respond(wire, op.id, False, str(exc), op.fragment_size, t0)
            return
        except (BridgeError, rosapi.RosapiError) as exc:
            self._respond(wire, op.id, False, f"{service}: {exc}", op.fragment_size, t0)
            return
        except UnicodeError:  # a lone surrogate ("\ud800") in a string reached rclpy
            why = f"{service}: a string in args is not valid Unicode text (a lone surrogate?)"
            self._respond(wire, op.id, False, why, op.fragment_size, t0)
            return
        except Exception as exc:  # answered, never left as an unretrieved task exception
            log.exception("session %d: call to %s failed", self.sid, service)
            why = f"{service}: internal error: {type(exc).__name__}"
            self._respond(wire, op.id, False, why, op.fragment_size, t0)
            return
        self._respond(wire, op.id, True, values, op.fragment_size, t0)

    def _respond(
        self,
        service: str,
        id: ops.Id | None,
        result: bool,
        values: Mapping[str, Any] | str,
        fragment_size: int | None = None,
        started: float | None = None,
    ) -> None:
        if started is not None:  # a call_service: count it for /metrics
            self.bridge.metrics.service_call(
                _topic_name(service), outcome(result, values), time.perf_counter() - started
            )
        if not result:
            log.info("session %d: call to %s failed: %s", self.sid, service, values)
        text = ops.encode(ops.ServiceResponse(service=service, result=result, values=values, id=id))
        if fragment_size is not None and len(text) > fragment_size:
            frag_id = id if id is not None else f"{service}:{next(self._frag_ids)}"
            for piece in split_fragments(text, fragment_size, frag_id):
                self.send_text(piece)
        else:
            self.send_text(text)

    async def _call_ros(
        self, service: str, op: ops.CallService, timeout: float
    ) -> Mapping[str, Any]:
        ros = self.ros
        loop = self.loop
        deadline = loop.time() + timeout
        if op.type is not None:
            srv_cls = ros.resolve_service(op.type)
        else:
            types = ros.service_types(service)
            if not types:
                wait_until = min(deadline, loop.time() + self.config.discovery_wait)
                while not types and loop.time() < wait_until:
                    await asyncio.sleep(0.02)
                    types = ros.service_types(service)
            if not types:
                raise _CallFailed(f"service {service} does not exist (not in the ROS graph)")
            srv_cls = ros.resolve_service(types[0])
        req_conv = convert.converter_for(srv_cls.Request)
        try:
            request = req_conv.from_obj(_args_obj(op.args, req_conv.fields), "args")
        except convert.ConversionError as exc:
            raise _CallFailed(f"{service}: bad request: {exc}") from None
        client = ros.client_for(service, srv_cls)
        if not client.service_is_ready():
            # Wait for a server to be discovered and matched: while the graph lists no
            # server, at most twice discovery_wait (a server that was just started can take
            # ~3 s to show on a loaded machine); once it does, up to the call's timeout.
            unlisted_wait = 2 * self.config.discovery_wait
            unlisted_by = loop.time() + unlisted_wait
            delay = 0.002
            while not _ready(client):
                if loop.time() >= unlisted_by and ros.server_count(service) == 0:
                    ros.drop_client(service, srv_cls)  # so the graph forgets the name
                    raise _CallFailed(
                        f"service {service} does not exist (not in the ROS graph after "
                        f"{unlisted_wait:g} s)"
                    )
                if _ready(client) is None:  # another call dropped the cached client
                    client = ros.client_for(service, srv_cls)
                if loop.time() >= deadline:
                    ros.drop_client(service, srv_cls)  # so the graph forgets the name
                    if ros.server_count(service) == 0:
                        raise _CallFailed(
                            f"service {service} does not exist (no server appeared within "
                            f"{timeout} s)"
                        )
                    raise _CallFailed(
                        f"service {service} did not become available in {timeout} s"
                    )
                await asyncio.sleep(delay)
                delay = min(delay * 2, 0.05)
        await ros.settled(client)  # a newly matched server may not hear back yet
        # A timer that fails the future is cheaper than asyncio.wait_for (no extra task).
        future = ros.call(client, request)
        timer = loop.call_at(deadline, _expire, future)
        try:
            response = await future
        except _Expired:
            raise _CallFailed(f"service {service} timed out after {timeout} s") from None
        finally:
            timer.cancel()
            if not future.done():  # this task was cancelled: forget the request
                future.cancel()
        obj: Mapping[str, Any] = convert.converter_for(srv_cls.Response).to_obj(response)
        return obj

    def advertise_service(self, op: ops.AdvertiseService) -> None:
        """Serve a ROS service from this client."""
        name = _topic_name(op.service)
        srv_cls = self.ros.resolve_service(op.type)
        type_name = canonical_name(op.type, "srv")
        if name in rosapi.HANDLERS or name in rosapi.ASYNC_HANDLERS:
            self.error(f"advertise_service: {name} is answered by the bridge itself", op.id)
            return
        mine = self.served.get(name)
        if mine is not None:
            if mine.type_name == type_name:
                return
            self._remove_served(mine, "the client advertised it again with another type")
            del self.served[name]
        owner = self.bridge.service_owners.get(name)
        if owner is not None and owner is not self:
            if not self.gate.may_take_over(name, owner.gate):
                # The first owner keeps it while it answers a ping (security/gate.py).
                self.gate.claim_if_owner_gone(op, owner)
                return
            owner.drop_served(name, f"taken over by client {self.sid}")
        elif owner is None and self.ros.service_types(name):
            others = self.ros.other_servers(name)
            if others and not self.gate.may_take_over(name, None):
                self.error(
                    f"advertise_service: {name} is already served by "
                    f"{others[0]}; a bridge client may serve it too only with the take_over "
                    "capability",
                    op.id,
                )
                return
        served = _Served(name, type_name, op.service)
        served.ros = self.ros.serve(
            name, srv_cls, lambda pending: self._on_ros_request(served, pending)
        )
        self.served[name] = served
        self.bridge.service_owners[name] = self

    def _on_ros_request(self, served: _Served, pending: PendingRosCall) -> None:
        if self.served.get(served.name) is not served or self._closed:
            log.warning("a ROS call to %s arrived after it was unadvertised: not answered",
                        served.name)
            return
        rid = f"service_request:{served.name}:{next(self._request_ids)}"
        try:
            args = pending.served.request_conv.to_obj(pending.request)
        except Exception:
            log.exception("cannot convert a request to %s", served.name)
            return
        timer = self.loop.call_later(
            self.config.served_call_timeout, self._served_timeout, served, rid
        )
        served.pending[rid] = (pending, timer)
        self.send_op(ops.CallService(service=served.wire, args=args, id=rid))

    def _served_timeout(self, served: _Served, rid: str, timeout: float | None = None) -> None:
        entry = served.pending.pop(rid, None)
        if entry is None:
            return
        pending = entry[0]
        if isinstance(pending, _DirectCall):
            pending.fail(f"service {served.name} timed out after {timeout} s")
            return
        log.warning(
            "session %d: no answer for %s within %s s; the ROS caller is not answered "
            "(a ROS service cannot send an error, and the bridge never invents a response)",
            self.sid,
            rid,
            self.config.served_call_timeout,
        )

    def service_response(self, op: ops.ServiceResponse) -> None:
        """The client answers a ROS caller of a service it serves."""
        name = _topic_name(op.service)
        served = self.served.get(name)
        entry = None
        if served is not None and op.id is not None:
            entry = served.pending.pop(str(op.id), None)
        if entry is None:
            for s in self.served.values():
                if op.id is not None and str(op.id) in s.pending:
                    served = s
                    entry = s.pending.pop(str(op.id))
                    break
        if entry is None or served is None or served.ros is None:
            self.error(
                f"service_response: no ROS call {op.id!r} is waiting on {name}", op.id
            )
            return
        pending, timer = entry
        timer.cancel()
        if isinstance(pending, _DirectCall):
            if not op.result:
                reason = op.values if isinstance(op.values, str) else "the serving client failed"
                pending.fail(f"service {name} failed: {reason}")
                return
            conv = served.ros.response_conv
            try:
                obj = conv.to_obj(conv.from_obj(op.values or {}, "values"))
            except convert.ConversionError as exc:
                self.error(f"service_response for {name}: {exc}", op.id)
                pending.fail(f"service {name} answered with a bad response: {exc}")
                return
            pending.succeed(obj)
            return
        if not op.result:
            log.warning(
                "session %d: the client failed %s (%.200s); the ROS caller is not answered "
                "(a ROS service cannot send an error, and the bridge never invents a response)",
                self.sid,
                op.id,
                op.values if isinstance(op.values, str) else "no reason given",
            )
            return
        values = op.values if isinstance(op.values, Mapping) else {}
        try:
            response = served.ros.response_conv.from_obj(values, "values")
        except convert.ConversionError as exc:
            self.error(f"service_response for {name}: {exc}; the ROS caller is not answered",
                       op.id)
            return
        pending.complete(response)

    async def call_direct(
        self, name: str, op: ops.CallService, timeout: float
    ) -> tuple[bool, Any]:
        """Carry out another client's call to a service this client serves (no ROS hop)."""
        served = self.served.get(name)
        if served is None or served.ros is None:
            raise _CallFailed(f"service {name} is no longer served")
        if op.type is not None and canonical_name(op.type, "srv") != served.type_name:
            raise _CallFailed(
                f"service {name} has type {served.type_name}, not {canonical_name(op.type, 'srv')}"
            )
        conv = served.ros.request_conv
        try:
            args = conv.to_obj(conv.from_obj(_args_obj(op.args, conv.fields), "args"))
        except convert.ConversionError as exc:
            raise _CallFailed(f"{name}: bad request: {exc}") from None
        rid = f"service_request:{name}:{next(self._request_ids)}"
        future: asyncio.Future[tuple[bool, Any]] = self.loop.create_future()
        timer = self.loop.call_later(timeout, self._served_timeout, served, rid, timeout)
        served.pending[rid] = (_DirectCall(future), timer)
        self.send_op(ops.CallService(service=served.wire, args=args, id=rid))
        try:
            return await future
        finally:
            entry = served.pending.pop(rid, None)
            if entry is not None:  # the caller went away first
                entry[1].cancel()

    def unadvertise_service(self, op: ops.UnadvertiseService) -> None:
        """Stop serving a service; it leaves ROS at once (waiting ROS callers are not answered)."""
        name = _topic_name(op.service)
        served = self.served.pop(name, None)
        if served is None:
            self.error(f"unadvertise_service: {name} is not served by this client", op.id)
            return
        self._remove_served(served, "the client unadvertised it")

    def _remove_served(self, served: _Served, why: str) -> None:
        unanswered = 0
        for _rid, (pending, timer) in list(served.pending.items()):
            timer.cancel()
            if isinstance(pending, _DirectCall):
                pending.fail(f"service {served.name} failed: {why}")
            else:
                unanswered += 1
        served.pending.clear()
        if unanswered:
            log.warning("service %s went (%s): %d ROS caller(s) not answered", served.name, why,
                        unanswered)
        if served.ros is not None:
            # At once: ROS callers see the server leave the graph; nobody gets an invented
            # default response (an rclpy service has no way to send an error).
            served.ros.destroy()
            served.ros = None
        if self.bridge.service_owners.get(served.name) is self:
            del self.bridge.service_owners[served.name]

    def drop_served(self, name: str, why: str) -> None:
        """Another client took the service over: forget it here."""
        served = self.served.pop(name, None)
        if served is not None:
            self._remove_served(served, why)
            self.status("warning", f"service {name}: {why}")

    # -- grants --------------------------------------------------------------------------------

    def recheck_grants(self) -> int:
        """The role changed (SIGHUP): end at once what it no longer allows; how many ended.

        Subscriptions, publishers, served services and served actions are checked against
        the gate as a new op for them would be; the client hears of each one that ends.
        """
        gate = self.gate
        ended = 0
        for topic, sub in list(self.subs.items()):
            why = gate.forbids("subscribe", topic)
            if why is not None:
                for op_id in list(sub.ids) or [None]:
                    self.error(f"subscribe: subscription to {topic} ended: {why}", op_id)
                del self.subs[topic]
                self._drop_sub(sub)
                ended += 1
        for topic in list(self.publishers):
            why = gate.forbids("publish", topic)
            if why is not None:
                self.ros.release_publisher(self.publishers.pop(topic))
                self.error(f"advertise: publisher of {topic} ended: {why}")
                ended += 1
        for name in list(self.served):
            why = gate.forbids("serve_service", name)
            if why is not None:
                self.drop_served(name, f"no longer served: {why}")
                ended += 1
        for name in list(self.actions.served):
            why = gate.forbids("serve_action", name)
            if why is not None:
                self.actions.drop_served(name, f"no longer served: {why}")
                ended += 1
        return ended

    # -- misc ----------------------------------------------------------------------------------

    def set_level(self, op: ops.SetLevel) -> None:
        """Set the least status level this client hears."""
        level = op.level.lower()
        if level not in _LEVELS:
            self.error(
                f"set_level: level must be one of none, error, warning, info, got {op.level!r}",
                op.id,
            )
            return
        self.level = _LEVELS[level]


class _Expired(Exception):
    """A ROS service call ran out of time."""


def _expire(future: asyncio.Future[Any]) -> None:
    if not future.done():
        future.set_exception(_Expired())


class _CallFailed(Exception):
    """A service call failed; the text is sent as the ``service_response`` values."""


def _ready(client: Any) -> bool | None:
    """Whether ``client`` has a matched server; None once the client was destroyed."""
    try:
        return bool(client.service_is_ready())
    except Exception:  # rclpy's InvalidHandle: dropped by another call in the meantime
        return None


def _topic_name(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _args_obj(args: Mapping[str, Any] | list[Any] | None, fields: tuple[str, ...] | Any) -> Any:
    if args is None:
        return {}
    if isinstance(args, list):
        names = tuple(fields)
        if len(args) > len(names):
            raise _CallFailed(
                f"args: {len(args)} values given but the request has {len(names)} fields"
                + (f" ({', '.join(names)})" if names else "")
            )
        return dict(zip(names, args, strict=False))
    return args
