"""A robot's topics on the relay: :class:`ZenohFeed`, the relay's one subscription to a
topic shared by its sessions, each message a :class:`ZenohMessage` encoded lazily from the
CDR bytes the robot put; :class:`ZenohPublisher`, a publisher shared by the sessions that
advertised the topic (one put per message)."""

from __future__ import annotations

import contextlib
import logging
import time
from collections import deque
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.decode import DECODED, TopicLane, wanted
from bridge_server.zenoh.graph.converter import RelayConverter
from bridge_server.zenoh.graph.robot import NotHolder, Robot
from bridge_server.zenoh.inbox import SAMPLE_LIMIT, Faults, direct
from bridge_server.zenoh.keys import Meta
from bridge_server.zenoh.replay import recovering_subscriber, undeclare_aside
from bridge_server.zenoh.typestore import TypeRefused
from msgs import cdr
from rosbridge_core.codec.encodings import Encoded, EncodedMessage
from rosbridge_core.graph import Listener
from rosbridge_core.interfaces import BridgeError, ReportedError

log = logging.getLogger("bridge_server.zenoh.graph")

__all__ = ["ZenohFeed", "ZenohMessage", "ZenohPublisher"]

STAMP_END = 1 << 63
"""A message's stamp (ns since the epoch) is below this (an int64 for every encoding)."""


class ZenohMessage(EncodedMessage):
    """One message the robot put, encoded for clients lazily and once per encoding; bytes
    that do not decode as the type the robot named are the robot's fault, counted once."""

    __slots__ = ("_bad", "_msg_json", "_refused", "conv", "faults")

    def __init__(self, topic: str, data: bytes, conv: RelayConverter, stamp_ns: int,
                 faults: Faults) -> None:
        super().__init__(topic, data, stamp_ns)
        self.conv = conv
        self.faults = faults
        self._bad = False
        self._msg_json: str | None = None
        self._refused: str | None = None

    def take_json(self, text: str) -> None:
        """Its JSON text, made on a worker thread (:func:`.decode.prepare`)."""
        self._msg_json = text

    def take_encoded(self, encoding: str, done: Encoded) -> None:
        """Its whole op in ``encoding``, made on a worker thread."""
        self._encoded[encoding] = done

    def refuse(self, why: str) -> None:
        """It could not be decoded off the loop (``why``): counted once as the robot's fault;
        its viewers that need it decoded do not get it (its raw viewers do)."""
        self._refused = why
        self._undecodable(ValueError(why))

    def message_json(self) -> str:
        """The message as JSON text."""
        if self._refused is not None:
            raise ReportedError(f"a message of {self.topic} does not decode")
        if self._msg_json is None:
            try:
                self._msg_json = self.conv.text_of(self.data)
            except Exception as exc:
                raise self._undecodable(exc) from None
        return self._msg_json

    def cbor_obj(self) -> Any:
        """The message as a CBOR-ready object."""
        if self._refused is not None:
            raise ReportedError(f"a message of {self.topic} does not decode")
        try:
            return self.conv.decode_cbor(self.data)
        except Exception as exc:
            raise self._undecodable(exc) from None

    def _undecodable(self, exc: Exception) -> ReportedError:
        """The robot's bytes do not decode as the type it named: counted once per message
        (whatever the number of viewers) as the robot's fault."""
        if not self._bad:
            self._bad = True
            self.faults.add("bad_messages", f"messages of {self.topic} that do not decode as "
                            f"{self.conv.type_name} dropped ({type(exc).__name__}: "
                            f"{str(exc)[:400]})")
        return ReportedError(f"a message of {self.topic} does not decode")


PLACE_WAIT = 5.0
"""Seconds a new subscription to a robot's topic waits at most for the robot to say where
the topic's stream is (:data:`keys.PLACE`), holding what it hears meanwhile; then (an older
robot does not say) it hands on what it holds."""

HOLD_BYTES = 16 * 1024 * 1024
"""Payload bytes a new subscription holds at most while it waits (the oldest go first, as
in the robot's inbox, the newest always kept; at most :data:`SAMPLE_LIMIT` messages)."""


class ZenohFeed:
    """The relay's one subscription to a robot's topic, shared by its sessions."""

    def __init__(self, graph: Robot, topic: str, msg_cls: Any) -> None:
        self.graph = graph
        self.topic = topic
        self.msg_cls = msg_cls
        self.received = 0
        self.listeners: list[Listener] = []
        self._latched: ZenohMessage | None = None
        self._type: str | None = msg_cls._type if msg_cls is not None else None
        self._place = ("", 0)  # (epoch, seq) of the last message taken
        # what is heard until the robot says where the stream is (None: said, or given up)
        self._held: deque[zenoh.Sample] | None = deque()
        self._held_bytes = 0
        self._entities: list[Any] = []
        # the converter of the type the last message named, with what it was resolved in
        self._resolved: tuple[str, Any, Any, RelayConverter] | None = None
        self._lane = TopicLane(self)  # large messages decoded off the loop, in order

    @property
    def latched(self) -> ZenohMessage | None:
        """The last message of a latched topic, for a late subscriber."""
        return self._latched

    @property
    def type_name(self) -> str | None:
        """Canonical type of the topic, once known."""
        return self._type

    @property
    def placed(self) -> bool:
        """Whether what the feed hears goes to its viewers: once the robot said where the
        topic's stream is, or did not within :data:`PLACE_WAIT` s."""
        return self._held is None

    def open(self) -> None:
        """Listen, then tell the robot (so nothing it puts is missed), then ask for the
        latched message and the topic's place, holding what is heard until the answer."""
        g = self.graph
        session = g.session
        here = g.inbox.sample  # latest-only: past the robot's bound its oldest go
        self._entities = [
            *recovering_subscriber(session, keys.key_of(g.robot, self.topic),
                                   direct(here(self.on_sample)), g.on_loop(self.on_miss)),
            session.liveliness().declare_token(
                keys.key_of(g.robot, self.topic, f"{keys.DEMAND}/{g.relay}")),
        ]
        place = g.on_loop(self.on_place)  # in order before the query's end, never dropped
        message = here(self.on_reply)  # a latched message, bounded as any message (32 MiB)

        def reply(r: zenoh.Reply) -> None:
            ok = r.ok
            (place if ok is not None and not len(ok.payload) else message)(r)

        session.get(f"{keys.key_of(g.robot, self.topic, keys.LATCHED)}?{keys.PLACE}",
                    direct(reply, g.inbox.end(self._placed)), timeout=PLACE_WAIT)

    def close(self) -> None:
        """Stop listening (off the loop: :func:`.undeclare_aside`; a sample that comes
        meanwhile is dropped, the feed no longer the topic's); the robot unsubscribes once
        no relay wants the topic."""
        undeclare_aside(self._entities)
        self._lane.close()
        self._held = None

    def on_miss(self, lost: int) -> None:
        """``lost`` messages in a row the robot published (while its link was down) and its
        window no longer held (on the loop): counted, and every client of the robot told."""
        graph = self.graph
        graph.faults.add("messages_lost", f"messages of {self.topic} lost in a link outage "
                         "(beyond the robot's replay window)", lost)
        text = (f"robot {graph.robot}: {lost} messages of {self.topic} were lost while its "
                "link was down (more than its replay window holds: --relay-replay-count, "
                "--relay-replay-bytes)")
        for tell in list(graph.inbox.told):
            tell(text)

    def on_reply(self, reply: zenoh.Reply) -> None:
        """The robot's latched message, asked for at :meth:`open` (on the loop)."""
        if reply.ok is not None:
            self.on_sample(reply.ok)

    def on_place(self, reply: zenoh.Reply) -> None:
        """The robot's other answer to :meth:`open`'s query (on the loop): an empty reply (no
        message is empty CDR) whose attachment numbers the last message of a replayed topic:
        nothing up to it is taken, though the new Zenoh subscription may ask the robot's
        window for it."""
        sample = reply.ok
        if sample is None or self._held is None:  # closed
            return
        try:
            meta = Meta.decode(sample.attachment.to_bytes() if sample.attachment else None)
            self.graph.check_sender(meta.zid)
        except BridgeError as exc:
            self.graph.faults.add("bad_messages", f"the place of {self.topic} ignored: {exc}")
            return
        if self._place == ("", 0):
            self._place = (meta.epoch, meta.seq)

    def _placed(self) -> None:
        """:meth:`open`'s query ended (on the loop, after its replies): what was held goes
        on, in order, and what comes next goes straight on."""
        held, self._held = self._held, None
        for sample in held or ():
            if self.graph.subscriptions.get(self.topic) is self:
                self._take(sample)

    def _hold(self, held: deque[zenoh.Sample], sample: zenoh.Sample) -> None:
        """Keep ``sample`` until the feed is placed, the oldest dropped past the bound (the
        newest always kept: a latched map larger than the bound, alone)."""
        held.append(sample)
        self._held_bytes += len(sample.payload)
        dropped = 0
        while len(held) > 1 and (len(held) > SAMPLE_LIMIT or self._held_bytes > HOLD_BYTES):
            self._held_bytes -= len(held.popleft().payload)
            dropped += 1
        if dropped:
            self.graph.faults.add("messages_dropped", f"messages of {self.topic} dropped, the "
                                  "oldest first, while the robot had not said where the "
                                  "topic's stream is", dropped)

    def _converter(self, type_name: str) -> RelayConverter:
        """The converter of ``type_name`` as the graph resolves it now: kept from the last
        message while the robot's snapshot and the relay's types of it are the same objects
        (both are replaced, never changed, when what resolves a name changes), so a message
        costs no name parsing and lookups."""
        graph = self.graph
        kept = self._resolved
        if (kept is not None and kept[0] == type_name and kept[1] is graph.snapshot
                and kept[2] is graph.wire_types):
            return kept[3]
        conv = graph.converter(graph.resolve_message(type_name))
        self._resolved = (type_name, graph.snapshot, graph.wire_types, conv)
        return conv

    def on_sample(self, sample: zenoh.Sample) -> None:
        """One message the robot put (on the loop), its payload counted as received; one
        that cannot be read is dropped and counted as the robot's fault (logged once)."""
        graph = self.graph
        graph.received_bytes += len(sample.payload)
        if graph.subscriptions.get(self.topic) is not self:
            return
        if self._held is not None:
            self._hold(self._held, sample)
        else:
            self._take(sample)

    def _take(self, sample: zenoh.Sample) -> None:
        """Hand ``sample`` on, unless it was taken already or is from before the place."""
        graph = self.graph
        try:
            meta = Meta.decode(sample.attachment.to_bytes() if sample.attachment else None)
            if not 0 <= meta.stamp_ns < STAMP_END:
                raise BridgeError(f"its stamp {meta.stamp_ns} ns is out of range")
            graph.check_sender(meta.zid)
            conv = self._converter(meta.type)
        except BridgeError as exc:
            kind = ("type_refused" if isinstance(exc, TypeRefused) else
                    "not_holder" if isinstance(exc, NotHolder) else "bad_messages")
            graph.faults.add(kind, f"messages of {self.topic} dropped: {exc}")
            return
        epoch, seq = self._place
        if meta.epoch == epoch and meta.seq <= seq:
            return  # had it already (the latched reply and the put of the same message), or
            # it is from before the place the robot said (its window, not this feed's)
        self._place = (meta.epoch, meta.seq)
        self._type = conv.type_name
        self.received += 1
        msg = ZenohMessage(self.topic, sample.payload.to_bytes(), conv,
                           meta.stamp_ns or time.time_ns(), graph.faults)
        if meta.latched:
            self._latched = msg
        if not self._lane.take(msg):  # a large one (or one behind it) goes off the loop first
            self.fan_out(msg)

    def decoded_encodings(self) -> set[str]:
        """The encodings made from the decoded message that this topic's viewers ask for."""
        return {w for w in map(wanted, self.listeners) if w in DECODED}

    def fan_out(self, msg: ZenohMessage) -> None:
        """Hand ``msg`` to every viewer of the topic (on the loop)."""
        graph = self.graph
        if graph.subscriptions.get(self.topic) is not self:
            return
        failed: Exception | None = None
        for listener in list(self.listeners):
            try:
                listener(msg)
            except Exception as exc:  # its bytes do not decode as its type, for any viewer
                failed = exc
        if failed is not None:  # once per message, whatever the number of viewers
            graph.faults.add("bad_messages", f"a message of {self.topic} could not be sent "
                             f"to its viewers ({type(failed).__name__}: {str(failed)[:200]})",
                             exc=failed)


class ZenohPublisher:
    """A publisher of a robot's topic, shared by the relay's sessions that advertised it."""

    def __init__(self, graph: Robot, topic: str, msg_cls: Any, latch: bool) -> None:
        self.graph = graph
        self.topic = topic
        self.latch = latch
        self.refs = 0
        self._conv = graph.converter(msg_cls)
        self._types = graph.wire_types  # what it was resolved in
        self.key = keys.key_of(graph.robot, topic, keys.IN)
        self.attachment = Meta(type=self.conv.type_name, latched=latch).encode()
        self.token = graph.session.liveliness().declare_token(
            keys.advertise_key(graph.robot, graph.relay, topic, self.conv.type_name, latch))

    @property
    def type_name(self) -> str:
        """Canonical message type."""
        return self._conv.type_name

    @property
    def conv(self) -> RelayConverter:
        """The converter of the type as the robot defines it now (resolved again when the
        robot's types started anew, see :meth:`ZenohGraph._redefined`)."""
        graph = self.graph
        if self._types is not graph.wire_types:
            self._conv = graph.converter(graph.resolve_message(self._conv.type_name))
            self._types = graph.wire_types
        return self._conv

    def publish(self, msg: Any) -> None:
        """Send one message (a ``msgs`` instance, or its CDR bytes) to the robot."""
        data = msg if isinstance(msg, bytes) else cdr.encode(msg)
        self.graph.session.put(self.key, data, attachment=self.attachment)

    def close(self) -> None:
        """The last reference went: the robot drops its publisher."""
        with contextlib.suppress(zenoh.ZError):
            self.token.undeclare()  # type: ignore[no-untyped-call]

