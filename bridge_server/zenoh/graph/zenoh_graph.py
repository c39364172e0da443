"""The relay's side: a :class:`~rosbridge_core.graph.Graph` of one robot, read from Zenoh.

A relay holds one :class:`ZenohGraph` per robot its clients ask for, shared by their
sessions, over one Zenoh session. What the sessions ask of ROS becomes the keys of
:mod:`.keys`:

- a topic's shared subscription is a Zenoh advanced subscriber with recovery (what a
  robot's reliable topic published while its link was down comes from its window once
  the link is back, in order; what the window no longer held is counted and told to the
  robot's clients: :mod:`.replay`) plus a demand token (so the robot subscribes in ROS),
  and each message is built from the CDR bytes the robot put: JSON
  straight from CDR (:mod:`rosbridge_core.codec.cdr_json`), CBOR from ``msgs.cdr``'s
  decoding, ``cbor-raw`` the bytes as they came, each at most once per message;
- a shared publisher is a publisher token (the robot makes the ROS publisher) and one put
  of CDR bytes (``msgs.cdr``) per message;
- a service call is one query answered by the robot's own ``call_service``;
- a goal is one query whose replies stream its acceptance, feedback and result from the
  robot's own action client, with a liveliness token of the goal's that takes it (canceled)
  with the relay if the relay dies; a cancel is a query;
- a service a client serves is a queryable the robot's ROS service forwards each call to,
  and a token that keeps that ROS service up (a token the robot refuses, another relay's
  client serving the name, is reported to the session); an action a client serves
  likewise, each ROS goal one query whose replies stream the goal's feedback and end;
- node parameters are queries run by the robot's own parameter methods;
- the graph, the types' definitions and typedefs come from the robot's snapshot (kept
  up to date by its puts), so the sessions' synchronous questions read a cache.

Types are ``msgs`` classes: generated ones, or built at run time from the definitions the
robot sent (:mod:`msgs.dynamic`), so a robot's own types need nothing installed on the
relay. Each robot's are its own (:attr:`ZenohGraph.wire_types`, a
:class:`~msgs.dynamic.TypeStore`): two robots may define one name differently and each
robot's samples are decoded, and the publishes to it encoded, in its own layout. A
definition is built once per text (not per sample), within :class:`TypeLimits`; a robot's
types are released when it has left and none of this relay's clients uses them.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import secrets
import time
from collections.abc import Callable, Mapping
from typing import Any

import cbor2
import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.decode import DECODED, TopicLane, wanted
from bridge_server.zenoh.inbox import Faults, Inbox
from bridge_server.zenoh.keys import (
    GOAL_WAIT,
    CallRequest,
    Execute,
    GoalEvent,
    GoalRequest,
    Meta,
    ParamRequest,
    Snapshot,
)
from bridge_server.zenoh.link import answering, ignore_replies
from bridge_server.zenoh.replay import recovering_subscriber
from bridge_server.zenoh.typestore import (
    MAX_DEFINITION_BYTES,
    MAX_TYPES_PER_ROBOT,
    GraphReader,
    RobotTypes,
    TypeLimits,
    TypeRefused,
    let_go,
)
from msgs import cdr
from msgs.dynamic import TypeStore
from msgs.runtime import Message as WireMessage
from msgs.runtime import UnknownTypeError as WireUnknownType
from rosbridge_core.codec.cdr_json import JsonFromCdr, wire_encoder
from rosbridge_core.codec.encodings import Encoded, EncodedMessage
from rosbridge_core.codec.msgs_types import MsgsConverter
from rosbridge_core.graph import (
    GoalListener,
    Listener,
    RosCall,
    ServedGoal,
    Status,
    acquire_shared,
    release_shared,
    service_request,
    shared_types,
)
from rosbridge_core.interfaces import (
    BridgeError,
    ConversionError,
    Kind,
    ReportedError,
    ServiceCallError,
    canonical_name,
)

__all__ = ["MAX_DEFINITION_BYTES", "MAX_TYPES_PER_ROBOT", "RelayConverter", "TypeLimits",
           "TypeRefused", "ZenohActionClient", "ZenohFeed", "ZenohGraph", "ZenohMessage",
           "ZenohPublisher", "ZenohRosCall", "ZenohSentGoal", "ZenohServedAction",
           "ZenohServedGoal", "ZenohServedService"]

log = logging.getLogger("bridge_server.zenoh.graph")

SNAPSHOT_WAIT = 5.0
"""Seconds a new robot's first graph snapshot is waited for."""

STAMP_END = 1 << 63
"""A message's stamp (ns since the epoch) is below this (an int64 for every encoding)."""

SERVER_WAIT = 5.0
"""Seconds the robot waits for its action client to be ready for a goal (the relay's
session already waited for the robot's graph to list the action server)."""

GONE_WAIT = 2.0
"""Seconds a query to the robot that ended unanswered waits for the robot's token to go."""

PARAM_WAIT = 5.0
"""Seconds a parameter query waits for the robot beyond the robot's own timeout."""


class Refused(BridgeError):
    """The robot answered a query with an error (the text is its reason)."""


class NotHolder(BridgeError):
    """A message put by a Zenoh session that does not hold the robot's name (dropped)."""


class RelayConverter(MsgsConverter):
    """:class:`~rosbridge_core.graph.Converter` of one ``msgs`` message class (the relay's
    messages are ``msgs`` instances, as the in-memory graph's), reading CDR too."""

    def __init__(self, cls: type[WireMessage]) -> None:
        super().__init__(cls)
        self.decode = cdr.decoder_for(cls)
        self.decode_cbor = cdr.decoder_for(cls, typed=cbor2.CBORTag)  # typed arrays, as the
        # bridge's CBOR sends them (RFC 8746)
        self.json_from_cdr: JsonFromCdr = wire_encoder(cls)

    def to_cbor_obj(self, msg: Any) -> Any:
        """The message as a CBOR-ready dict (byte strings, numeric arrays typed)."""
        return self.decode_cbor(cdr.encode(msg))

    def text_of(self, data: bytes) -> str:
        """The message's JSON text from its CDR bytes."""
        text = self.json_from_cdr(data)
        if text is None:  # a NaN or infinity: null, as rosbridge sends them
            text = self.to_json(self.cls.from_json(self.decode(data)))
        return text


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


class ZenohFeed:
    """The relay's one subscription to a robot's topic, shared by its sessions."""

    def __init__(self, graph: ZenohGraph, topic: str, msg_cls: Any) -> None:
        self.graph = graph
        self.topic = topic
        self.msg_cls = msg_cls
        self.received = 0
        self.listeners: list[Listener] = []
        self._latched: ZenohMessage | None = None
        self._type: str | None = msg_cls._type if msg_cls is not None else None
        self._place = ("", 0)  # (epoch, seq) of the last message taken
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

    def open(self) -> None:
        """Listen, then tell the robot (so nothing it puts is missed), then ask for the
        latched message."""
        g = self.graph
        session = g.session
        here = g.inbox.sample  # latest-only: past the robot's bound its oldest go
        self._entities = [
            *recovering_subscriber(session, keys.key_of(g.robot, self.topic),
                                   here(self.on_sample), g.on_loop(self.on_miss)),
            session.liveliness().declare_token(
                keys.key_of(g.robot, self.topic, f"{keys.DEMAND}/{g.relay}")),
        ]
        session.get(keys.key_of(g.robot, self.topic, keys.LATCHED),
                    zenoh.handlers.Callback(here(self.on_reply)))

    def close(self) -> None:
        """Stop listening; the robot unsubscribes once no relay wants the topic."""
        for entity in self._entities:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
        self._entities.clear()
        self._lane.close()

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
        """The robot's latched message, asked for at :meth:`open`."""
        if reply.ok is not None:
            self.on_sample(reply.ok)

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
            return  # had it already (the latched reply and the put of the same message)
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

    def __init__(self, graph: ZenohGraph, topic: str, msg_cls: Any, latch: bool) -> None:
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


class _GoalId:
    """A goal's id in ROS, as the sessions read it (``handle.goal_id.uuid``)."""

    def __init__(self, uuid: bytes) -> None:
        self.uuid = uuid


class _GoalHandle:
    """The robot's answer to a goal, as far as the sessions look at it."""

    def __init__(self, uuid: bytes) -> None:
        self.goal_id = _GoalId(uuid)


class ZenohSentGoal:
    """A goal sent to the robot: one query, its replies the goal's events, and a liveliness
    token (``@running``) that takes the goal (canceled by the robot) with this relay."""

    def __init__(self, shared: ZenohActionClient, listener: GoalListener) -> None:
        self.shared = shared
        self.listener = listener
        self.handle: _GoalHandle | None = None
        self.finished = False
        graph = shared.graph
        self.id = f"{secrets.token_hex(4)}{next(graph.goal_ids)}"
        self.token: Any = None

    def cancel(self) -> None:
        """Ask the robot to cancel the goal (the answer comes among the goal's replies)."""
        if not self.finished:
            graph = self.shared.graph
            with contextlib.suppress(zenoh.ZError):  # the relay is closing: the robot cancels
                graph.session.get(f"{graph.robot}/{keys.CANCEL}/{graph.relay}/{self.id}",
                                  ignore_replies, timeout=SERVER_WAIT)

    def on_reply(self, reply: zenoh.Reply) -> None:
        """One of the robot's replies (on the loop)."""
        if self.finished:
            return
        if reply.ok is None:
            text = reply.err.payload.to_string() if reply.err is not None else "?"
            self._end()
            self.listener.on_failed(f"robot {self.shared.graph.robot}: {text}")
            return
        try:
            event = GoalEvent.decode(reply.ok.payload.to_bytes())
            self._dispatch(event)
        except BridgeError as exc:
            self.shared.graph.faults.add("bad_replies", f"a goal's reply dropped: {exc}")

    def _dispatch(self, event: GoalEvent) -> None:
        listener = self.listener
        shared = self.shared
        if event.event == "accepted":
            self.handle = _GoalHandle(bytes.fromhex(event.uuid))
            listener.on_accepted()
        elif event.event == "feedback":
            listener.on_feedback(shared.feedback_conv.from_obj(event.values, "feedback"))
        elif event.event == "cancel":
            listener.on_cancel_answer(event.code)
        else:
            self._end()
            if event.event == "rejected":
                listener.on_rejected()
            elif event.event == "failed":
                listener.on_failed(event.text)
            else:
                try:
                    result = None
                    if event.values is not None:
                        result = shared.result_conv.from_obj(event.values, "result")
                except ConversionError as exc:  # the goal ended all the same: say why so
                    listener.on_failed(f"robot {shared.graph.robot} sent a result that does "
                                       f"not fit {shared.type_name}: {exc}")
                    return
                listener.on_result(event.status, result)

    def on_end(self) -> None:
        """The query ended (on the loop): without a result, the robot went (or is not
        there: :meth:`ZenohGraph.unanswered` says which)."""
        if not self.finished:
            self._end()
            told = self.shared.graph.loop.create_task(self.shared.graph.unanswered("goal"))
            told.add_done_callback(self._told)

    def _told(self, task: asyncio.Task[str]) -> None:
        if not task.cancelled():  # cancelled: the relay is closing
            self.listener.on_failed(task.result())

    def gone(self) -> None:
        """The robot went with the goal in flight (:meth:`ZenohGraph.went`): it fails now,
        and the robot, if it comes back, cancels it (this relay's ``@running`` token goes)."""
        if not self.finished:
            self._end()
            self.listener.on_failed(self.shared.graph.went("goal"))

    def _end(self) -> None:
        self.finished = True
        self.shared.graph.in_flight.discard(self.gone)
        if self.token is not None:
            with contextlib.suppress(zenoh.ZError):
                self.token.undeclare()


class ZenohActionClient:
    """The relay's client of one action of the robot (the robot's own client sends goals)."""

    def __init__(self, graph: ZenohGraph, name: str, action_cls: Any) -> None:
        self.graph = graph
        self.name = name
        self.action_cls = action_cls
        self.type_name = action_cls._type
        self.goal_conv = graph.converter(action_cls.Goal)
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)

    def matched(self) -> bool:
        """Whether the robot is here and its graph lists a server of the action."""
        return self.graph.alive and bool(self.graph.server_types(
            self.name + "/_action/send_goal"))

    def ready(self) -> bool:
        """As :meth:`matched`: the robot itself waits for its client to be ready."""
        return self.matched()

    def send(self, goal: Any, listener: GoalListener, feedback: bool) -> ZenohSentGoal:
        """One query to the robot (see :class:`ZenohSentGoal`)."""
        graph = self.graph
        sent = ZenohSentGoal(self, listener)
        request = GoalRequest(type=self.type_name, goal=self.goal_conv.to_obj(goal),
                              feedback=feedback, relay=graph.relay, id=sent.id,
                              timeout=SERVER_WAIT)
        try:
            sent.token = graph.session.liveliness().declare_token(
                f"{graph.robot}/{keys.RUNNING}/{graph.relay}/{sent.id}")
            graph.session.get(keys.key_of(graph.robot, self.name, f"{keys.GOAL}/{graph.relay}"),
                              zenoh.handlers.Callback(graph.on_loop(sent.on_reply),
                                                      graph.inbox.end(sent.on_end)),
                              payload=request.encode(), timeout=GOAL_WAIT,
                              consolidation=zenoh.ConsolidationMode.NONE)
        except zenoh.ZError:  # the relay's Zenoh session closed: the goal ends unsent
            graph.loop.call_soon(sent.on_end)
            return sent
        graph.in_flight.add(sent.gone)
        return sent

    def destroy(self) -> None:
        """Nothing to remove: each goal holds its own query and token."""


class ZenohRosCall:
    """A ROS caller on the robot waiting for a service this relay's client serves."""

    def __init__(self, served: ZenohServedService, request: Any, query: zenoh.Query) -> None:
        self.served = served
        self.request = request
        self.query: zenoh.Query | None = query

    def complete(self, response: Any | None = None) -> bool:
        """Answer the ROS caller (through the robot); False if already answered."""
        query, self.query = self.query, None
        if query is None:
            return False
        if response is None:
            response = self.served.srv_cls.Response()
        with contextlib.suppress(zenoh.ZError):
            query.reply(query.key_expr, json.dumps(
                self.served.response_conv.to_obj(response), separators=(",", ":")).encode())
        query.drop()  # type: ignore[no-untyped-call]
        return True


class _ServedHere:
    """What a client of this relay serves on the robot: the relay's queryable (under
    ``where``) the robot forwards to, a subscriber of the robot's refusal (``@refused``:
    another relay's client serves the name, handed to ``on_refused``), and the ``@serve``
    token that makes the robot serve it in ROS. Declared last (:meth:`_declare`), once the
    subclass can answer."""

    def __init__(self, graph: ZenohGraph, name: str,
                 on_refused: Callable[[str], None] | None) -> None:
        self.graph = graph
        self.name = name
        self.on_refused = on_refused
        self._entities: list[Any] = []

    def _declare(self, where: str, type_name: str, kind: Kind) -> None:
        graph = self.graph
        self._entities = [
            graph.session.declare_queryable(
                keys.key_of(graph.robot, self.name, f"{where}/{graph.relay}"),
                graph.on_loop(self._on_query)),
            graph.session.declare_subscriber(
                keys.refused_key(graph.robot, graph.relay, self.name, kind),
                graph.on_loop(self._on_refused)),
            graph.session.liveliness().declare_token(
                keys.serve_key(graph.robot, graph.relay, self.name, type_name, kind)),
        ]

    def _on_refused(self, sample: zenoh.Sample) -> None:
        """The robot does not take this relay's token (on the loop): say why, once."""
        refused, self.on_refused = self.on_refused, None
        if refused is None or not self._entities:
            return
        why = sample.payload.to_string()
        log.warning("robot %s refused this relay's %s: %s", self.graph.robot, self.name, why)
        refused(why)

    def _on_query(self, query: zenoh.Query) -> None:
        raise NotImplementedError

    def _undeclare(self) -> None:
        for entity in self._entities:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
        self._entities.clear()


class ZenohServedService(_ServedHere):
    """A service of the robot that a client of this relay serves (``@serving``): each ROS
    call's request comes as a query, the reply answers it."""

    def __init__(self, graph: ZenohGraph, name: str, srv_cls: Any,
                 on_request: Callable[[RosCall], None],
                 on_refused: Callable[[str], None] | None = None) -> None:
        super().__init__(graph, name, on_refused)
        self.srv_cls = srv_cls
        self.request_conv = graph.converter(srv_cls.Request)
        self.response_conv = graph.converter(srv_cls.Response)
        self.on_request = on_request
        self._declare(keys.SERVING, srv_cls._type, "srv")

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            obj = json.loads(query.payload.to_bytes() if query.payload else b"")
            request = self.request_conv.from_obj(obj, "request")
        except (ValueError, ConversionError) as exc:
            with contextlib.suppress(zenoh.ZError):
                query.reply_err(f"a request to {self.name} that does not fit: {exc}".encode())
            query.drop()  # type: ignore[no-untyped-call]
            return
        # Not answered (the session failed it or gave up): the query ends when the call is
        # forgotten, and the robot leaves its ROS caller unanswered, as the bridge does.
        self.on_request(ZenohRosCall(self, request, query))

    def destroy(self) -> None:
        """The robot's ROS service goes (with the token)."""
        if self.graph.served.get(self.name) is self:
            del self.graph.served[self.name]
        self._undeclare()
        self.graph.release_types()


class ZenohServedGoal:
    """A ROS goal on the robot that a client of this relay carries out: its feedback and end
    are replies to the robot's query."""

    def __init__(self, served: ZenohServedAction, gid: str, request: Any,
                 query: zenoh.Query) -> None:
        self.served = served
        self.id = gid
        self.request = request
        self.query: zenoh.Query | None = query

    def feedback(self, msg: Any) -> None:
        """One feedback message to the robot, which publishes it."""
        if self.query is not None:
            with contextlib.suppress(zenoh.ZError):
                self.query.reply(self.query.key_expr, GoalEvent(
                    "feedback", values=self.served.feedback_conv.to_obj(msg)).encode())

    def finish(self, status: int, result: Any | None = None) -> bool:
        """End the goal on the robot with ``status`` and ``result``; False if it had ended."""
        query, self.query = self.query, None
        if query is None:
            return False
        self.served.goals.pop(self.id, None)
        values = self.served.result_conv.to_obj(result) if result is not None else None
        with contextlib.suppress(zenoh.ZError):
            query.reply(query.key_expr, GoalEvent("result", status=int(status),
                                                  values=values).encode())
        query.drop()  # type: ignore[no-untyped-call]
        return True


class ZenohServedAction(_ServedHere):
    """An action of the robot that a client of this relay serves (``@executing``): each ROS
    goal comes as a query whose replies are its feedback and end; a ROS cancel is a query."""

    def __init__(self, graph: ZenohGraph, name: str, action_cls: Any,
                 on_goal: Callable[[ServedGoal], None],
                 on_cancel: Callable[[ServedGoal], None],
                 on_refused: Callable[[str], None] | None = None) -> None:
        super().__init__(graph, name, on_refused)
        self.alive = True
        self.goal_conv = graph.converter(action_cls.Goal)
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.goals: dict[str, ZenohServedGoal] = {}
        self._declare(keys.EXECUTING, action_cls._type, "action")

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            req = Execute.decode(query.payload.to_bytes() if query.payload else b"")
        except BridgeError as exc:
            with answering(query):
                query.reply_err(str(exc).encode())
            return
        if req.cancel:
            with answering(query):
                goal = self.goals.get(req.id)
                if goal is not None:
                    self.on_cancel(goal)
            return
        try:
            request = self.goal_conv.from_obj(req.goal, "goal")
        except ConversionError as exc:
            log.warning("a goal of %s from robot %s does not fit: %s", self.name,
                        self.graph.robot, exc)
            request = None
        goal = ZenohServedGoal(self, req.id, request, query)
        if request is None or not self.alive:
            goal.finish(Status.ABORTED)
            return
        self.goals[req.id] = goal
        self.on_goal(goal)

    def destroy(self) -> None:
        """The robot's action server goes (with the token); open goals are aborted."""
        self.alive = False
        for goal in list(self.goals.values()):
            goal.finish(Status.ABORTED)
        if self.graph.served_actions.get(self.name) is self:
            del self.graph.served_actions[self.name]
        self._undeclare()
        self.graph.release_types()


class ZenohGraph:
    """The Graph of robot ``robot`` over a Zenoh session (see the module's text)."""

    def __init__(self, session: zenoh.Session, robot: str, relay: str,
                 type_limits: TypeLimits | None = None) -> None:
        self.session = session
        self.robot = keys.check_robot(robot)
        self.relay = keys.check_relay(relay)
        self.type_limits = type_limits or TypeLimits()
        self.types = RobotTypes(self.robot, self.type_limits)
        """The robot's own types (released when it left and nothing here uses them)."""
        self.loop = asyncio.get_running_loop()
        self.inbox = Inbox(self.loop, self.robot)
        """What the robot's Zenoh callbacks hand to the loop, bounded (inbox.py)."""
        self.faults = self.inbox.faults
        """What the robot sent that was dropped, by kind."""
        self.reader = GraphReader(self.loop, self.types, self.faults, self._took_snapshot)
        """Its graph documents, read and their types built off the loop (typestore.py)."""
        self.snapshot = Snapshot()
        self.claims = keys.Claims()
        """The sessions announcing the robot's name: the first holds it (the one served)."""
        self.in_flight: set[Callable[[], None]] = set()
        """Each call, parameter request and goal waiting on the robot: failed when the robot
        goes (:meth:`went` says why)."""
        self.presence_listeners: list[Callable[[bool], None]] = []
        """Called on the loop when the robot goes (False) or comes back (True)."""
        self.received_bytes = 0
        """Payload bytes of the robot's topic messages as they came from Zenoh (every sample
        of every feed, the latched replies and the ones dropped as already had too)."""
        self.subscriptions: dict[str, ZenohFeed] = {}
        self.publishers: dict[tuple[str, str, bool], ZenohPublisher] = {}
        self.served: dict[str, ZenohServedService] = {}
        self.served_actions: dict[str, ZenohServedAction] = {}
        self.goal_ids = itertools.count()
        self._converters: dict[type[Any], RelayConverter] = {}
        self._converters_of = self.types.store  # the store the converters' classes are of
        self._entities: list[Any] = []
        self._have_snapshot = asyncio.Event()

    @property
    def wire_types(self) -> TypeStore:
        """The store of the robot's own types now (replaced, never changed, when the robot
        redefines a type or its types are released)."""
        return self.types.store

    @property
    def name(self) -> str:
        """The robot's bridge node name, as the robot reports it."""
        return self.snapshot.node or f"relay_{self.relay}_{self.robot}"

    def on_loop(self, fn: Callable[[Any], None]) -> Callable[[Any], None]:
        """A Zenoh callback that hands its argument to ``fn`` on the event loop, in order,
        through the robot's bounded inbox (reliable data: counted and told if dropped)."""
        return self.inbox.reliable(fn)

    # -- life ----------------------------------------------------------------------------------

    def start(self) -> None:
        """Follow the robot's liveliness and graph (once: the relay starts it to wait for the
        first snapshot, and the Bridge starts its graph again)."""
        if self._entities:
            return
        r = self.robot
        self._entities = [
            self.session.liveliness().declare_subscriber(
                f"{r}/{keys.ALIVE}/**", self.on_loop(self._on_alive), history=True),
            self.session.declare_subscriber(f"{r}/{keys.GRAPH}",
                                            self.inbox.graph(self._on_graph)),
        ]
        self.session.get(f"{r}/{keys.GRAPH}",
                         zenoh.handlers.Callback(self.inbox.graph(self._on_graph_reply)))

    async def ready(self, timeout: float = SNAPSHOT_WAIT) -> bool:
        """Whether the robot's first graph snapshot came within ``timeout`` s."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout):  # keeps a cancel (3.11's wait_for may not)
                await self._have_snapshot.wait()
        return self._have_snapshot.is_set()

    def refresh(self) -> None:
        """Nothing to do: the robot follows its own graph."""

    def close(self) -> None:
        """Drop every subscription, publisher and declaration."""
        for feed in self.subscriptions.values():
            feed.close()
        self.subscriptions.clear()
        for pub in self.publishers.values():
            pub.close()
        self.publishers.clear()
        for served in list(self.served.values()):
            served.destroy()
        for action in list(self.served_actions.values()):
            action.destroy()
        for entity in self._entities:
            with contextlib.suppress(zenoh.ZError):
                entity.undeclare()
        self._entities.clear()
        self.reader.close()

    def trouble(self) -> str | None:
        """Why the robot is not served (``None``: it is)."""
        if not self.alive:
            return f"robot {self.robot} is not connected to this relay's Zenoh network"
        return None

    @property
    def alive(self) -> bool:
        """Whether a robot holds the name (its liveliness token is on the network)."""
        return self.claims.holder is not None

    def _on_alive(self, sample: zenoh.Sample) -> None:
        """A token of the robot's name came or went. Only the holder's count: a robot
        refused the name (the relay's log says so) changes nothing here; the holder gone,
        what waits on it fails at once, and a robot announcing the name meanwhile is the
        robot from then on."""
        before = self.claims.holder
        self.claims.seen(keys.parse_alive(str(sample.key_expr))[1],
                         sample.kind == zenoh.SampleKind.PUT)
        after = self.claims.holder
        if after == before:
            return
        if before is not None:
            log.info("robot %s went away", self.robot)
            waiting, self.in_flight = self.in_flight, set()
            for fail in waiting:
                fail()
            for listener in list(self.presence_listeners):
                listener(False)
        if after is not None:
            log.info("robot %s is here", self.robot)
            for listener in list(self.presence_listeners):
                listener(True)
        self.release_types()

    def check_sender(self, zid: str) -> None:
        """``NotHolder`` unless the Zenoh session ``zid`` that put a message holds the robot's
        name (while one does): what a robot refused the name puts is dropped."""
        holder = self.claims.holder
        if holder is not None and zid != holder:
            raise NotHolder(
                f"put by Zenoh session {zid or '(one that names none)'}, not by {holder}, "
                f"which holds the name (a robot refused the name, or one older than this "
                "relay that does not say its session)")

    def went(self, what: str) -> str:
        """Why a ``what`` (call, goal) in flight fails when the robot goes (its link's
        lease ended, or it left): it will not be answered, so nobody waits for their own
        timeout."""
        return (f"robot {self.robot} went away (its link to the Zenoh network ended) while "
                f"this {what} was in flight")

    async def unanswered(self, what: str) -> str:
        """Why a query to the robot (a ``what``) ended without an answer: the robot went
        (Zenoh ends the queries of a link it closes just before the robot's token is seen to
        go: that is waited for, at most ``GONE_WAIT`` s), or, still there, it did not
        answer."""
        if self.alive:
            gone = asyncio.Event()
            self.in_flight.add(gone.set)
            try:
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(GONE_WAIT):
                        await gone.wait()
            finally:
                self.in_flight.discard(gone.set)
            if not gone.is_set():
                return (f"robot {self.robot} did not answer the {what} (is it connected to "
                        "this relay's Zenoh network?)")
        return self.went(what)

    def _on_graph(self, sample: zenoh.Sample) -> None:
        """A graph document: read off the loop when its turn comes (:class:`GraphReader`);
        one another session than the name's holder put is dropped (its attachment names the
        session, as a message's :class:`~.keys.Meta` does)."""
        zid = sample.attachment.to_string() if sample.attachment is not None else ""
        try:
            self.check_sender(zid)
        except NotHolder as exc:
            self.faults.add("not_holder", f"a graph document dropped: {exc}")
            return
        self.reader.offer(sample.payload.to_bytes())

    def _took_snapshot(self, snapshot: Snapshot) -> None:
        """A graph document read, its types built (on the loop); the one before is freed
        off the loop."""
        old, self.snapshot = self.snapshot, snapshot
        let_go(old)
        self._have_snapshot.set()

    def _on_graph_reply(self, reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            self._on_graph(reply.ok)

    # -- types ---------------------------------------------------------------------------------

    def release_types(self) -> None:
        """Drop the robot's types once it has left and nothing of this relay's uses them (no
        subscription, publisher or served name; a class a session still holds keeps its
        own store alive until it lets go)."""
        if (self.alive or self.subscriptions or self.publishers or self.served
                or self.served_actions or not (len(self.wire_types) or self.types.built)):
            return
        count = self.types.release()
        log.info("robot %s has left: its %d types are released", self.robot, count)

    def resolve_message(self, name: str) -> Any:
        """The ``msgs`` class of message type ``name`` (the robot's definition if it sent
        one, else the generated type)."""
        return self.types.load(name, "msg", self.snapshot.definitions)

    def resolve_service(self, name: str) -> Any:
        """The ``msgs`` service type named ``name``."""
        return self.types.load(name, "srv", self.snapshot.definitions)

    def resolve_action(self, name: str) -> Any:
        """The ``msgs`` action type named ``name`` (the robot's definition if it sent one)."""
        return self.types.load(name, "action", self.snapshot.definitions)

    def converter(self, cls: Any) -> RelayConverter:
        """The converter of a ``msgs`` message class (those of a replaced store forgotten)."""
        if self._converters_of is not self.types.store:
            self._converters.clear()
            self._converters_of = self.types.store
        conv = self._converters.get(cls)
        if conv is None:
            conv = self._converters[cls] = RelayConverter(cls)
        return conv

    def typedefs(self, name: str, kind: str, part: str | None = None) -> list[dict[str, Any]]:
        """rosapi typedefs of a type in the robot's graph."""
        key = canonical_name(name, kind) + (f"_{part}" if part else "")  # type: ignore[arg-type]
        found = self.snapshot.typedefs.get(key)
        if found is None:
            raise BridgeError(f"no typedefs of {key}: robot {self.robot} has no topic, "
                              "service or action of that type")
        return found

    def installed_interfaces(self) -> list[str]:
        """Every interface type the robot has installed."""
        return list(self.snapshot.interfaces)

    def interface_definition(self, name: str) -> dict[str, Any]:
        """The full definition text of a type in the robot's graph (or one msgs has)."""
        for kind in ("msg", "srv", "action"):
            with contextlib.suppress(BridgeError):
                canonical = canonical_name(name, kind)
                text = self.snapshot.definitions.get(canonical)
                if text:
                    return {"type": canonical, "definition": text}
        try:
            canonical = canonical_name(name, "msg")
            return {"type": canonical, "definition": self.wire_types.full_text(canonical)}
        except (BridgeError, WireUnknownType):
            raise BridgeError(f"no definition of {name!r}: robot {self.robot} has no topic "
                              "or service of that type") from None

    # -- introspection (the robot's snapshot) --------------------------------------------------

    def topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic of the robot with its types."""
        return [(n, list(ts)) for n, ts in self.snapshot.topics]

    def service_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every service of the robot with its types."""
        return [(n, list(ts)) for n, ts in self.snapshot.services]

    def node_names(self) -> list[tuple[str, str]]:
        """Every node of the robot as (name, namespace)."""
        return [(n["name"], n["namespace"]) for n in self.snapshot.nodes.values()]

    def own_node(self) -> tuple[str, str]:
        """The robot's bridge node."""
        return self.snapshot.own_node

    def _node(self, name: str, namespace: str) -> dict[str, Any]:
        node = self.snapshot.nodes.get(namespace.rstrip("/") + "/" + name)
        if node is None:
            raise LookupError(f"robot {self.robot} has no node {namespace}/{name}")
        return node

    def node_endpoints(self, name: str, namespace: str) -> tuple[list[str], list[str], list[str]]:
        """Topics a node subscribes to, publishes, services it serves."""
        node = self._node(name, namespace)
        return (list(node["subscribes"]), list(node["publishes"]),
                [s for s, _ in node["serves"]])

    def node_services(self, name: str, namespace: str) -> list[tuple[str, list[str]]]:
        """Services a node serves, with their types."""
        return [(s, list(ts)) for s, ts in self._node(name, namespace)["serves"]]

    def topic_publishers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes publishing on ``topic``."""
        return [(n, ns) for n, ns, _ in self.snapshot.publishers.get(topic, [])]

    def topic_publishers_qos(self, topic: str) -> list[tuple[str, str, dict[str, Any]]]:
        """Publishers of ``topic`` with their QoS."""
        return [(n, ns, dict(q)) for n, ns, q in self.snapshot.publishers.get(topic, [])]

    def topic_subscribers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes subscribed to ``topic``."""
        return [(n, ns) for n, ns in self.snapshot.subscribers.get(topic, [])]

    def topic_types(self, topic: str) -> list[str]:
        """Types the robot lists for ``topic``."""
        return next((list(ts) for n, ts in self.snapshot.topics if n == topic), [])

    def publisher_types(self, topic: str) -> set[str]:
        """Types of this relay's own publishers on ``topic``."""
        return shared_types(self.publishers, topic)

    def service_types(self, service: str) -> list[str]:
        """Types the robot lists for ``service``."""
        return next((list(ts) for n, ts in self.snapshot.services if n == service), [])

    def _servers(self, service: str) -> list[dict[str, Any]]:
        return [n for n in self.snapshot.nodes.values()
                if any(s == service for s, _ in n["serves"])]

    def server_count(self, service: str) -> int:
        """How many of the robot's nodes serve ``service``."""
        return len(self._servers(service))

    def other_servers(self, service: str) -> list[str]:
        """The robot's servers of ``service``. The robot's bridge serving it counts only when
        its snapshot says another relay's client serves it (named then): serving it for this
        relay's clients is not another server, and a client of this relay that serves a name
        again soon after it left is not refused while the robot's graph still lists it."""
        relay = self.snapshot.served.get(service)
        own = tuple(self.own_node())
        found = []
        for n in self._servers(service):
            if (n["name"], n["namespace"]) != own:
                found.append("the ROS node " + n["namespace"].rstrip("/") + "/" + n["name"])
            elif relay is not None and relay != self.relay:
                found.append(f"a client of relay {relay}")
        return found

    def server_types(self, service: str) -> list[str]:
        """Types of ``service`` as the robot's servers offer it."""
        found: list[str] = []
        for node in self._servers(service):
            found += [t for s, ts in node["serves"] if s == service for t in ts
                      if t not in found]
        return found

    def now(self) -> tuple[int, int]:
        """The relay's wall clock as (sec, nanosec)."""
        sec, nsec = divmod(time.time_ns(), 1_000_000_000)
        return sec, nsec

    # -- topics --------------------------------------------------------------------------------

    def subscribe(self, topic: str, msg_cls: Any, listener: Listener) -> ZenohFeed:
        """Add ``listener`` to the topic's shared subscription (made on first use)."""
        feed = self.subscriptions.get(topic)
        if feed is None:
            feed = ZenohFeed(self, topic, msg_cls)
            self.subscriptions[topic] = feed
            feed.open()
        elif msg_cls is not None and feed.msg_cls is not None and feed.msg_cls is not msg_cls:
            raise ValueError(f"topic {topic} is already subscribed with type {feed.type_name}")
        elif msg_cls is not None and feed.msg_cls is None:
            feed.msg_cls = msg_cls
        feed.listeners.append(listener)
        return feed

    def unsubscribe(self, shared: Any, listener: Listener) -> None:
        """Remove ``listener``; the subscription (and the demand) goes with the last."""
        feed: ZenohFeed = shared
        with contextlib.suppress(ValueError):
            feed.listeners.remove(listener)
        if not feed.listeners and self.subscriptions.get(feed.topic) is feed:
            del self.subscriptions[feed.topic]
            feed.close()
            self.release_types()

    def acquire_publisher(self, topic: str, msg_cls: Any, latch: bool, depth: int
                          ) -> ZenohPublisher:
        """A shared publisher for (topic, type, latch), its reference count raised."""
        return acquire_shared(self.publishers, (topic, msg_cls._type, latch),
                              lambda: ZenohPublisher(self, topic, msg_cls, latch))

    def release_publisher(self, pub: Any) -> None:
        """Lower the reference count; the publisher goes with the last reference."""
        mine: ZenohPublisher = pub
        if release_shared(self.publishers, (mine.topic, mine.type_name, mine.latch), mine):
            mine.close()
            self.release_types()

    # -- services ------------------------------------------------------------------------------

    async def _ask(self, key: str, payload: bytes, timeout: float, what: str) -> bytes:
        """One query to the robot: its reply's payload; ``ZenohGraph.Refused`` with an error
        reply's text, ``TimeoutError`` naming ``what`` if nothing came."""
        future: asyncio.Future[bytes | None] = self.loop.create_future()

        def answer(reply: zenoh.Reply) -> None:
            if future.done():
                return
            if reply.ok is not None:
                future.set_result(reply.ok.payload.to_bytes())
            elif reply.err is not None:
                future.set_exception(Refused(reply.err.payload.to_string()))

        def ended() -> None:
            if not future.done():
                future.set_result(None)

        def went() -> None:
            if not future.done():
                future.set_exception(Refused(f"{what}: {self.went('call')}"))

        try:
            self.session.get(key, zenoh.handlers.Callback(self.on_loop(answer),
                                                          self.inbox.end(ended)),
                             payload=payload, timeout=timeout)
        except zenoh.ZError as exc:  # the relay is closing
            raise Refused(f"{what}: this relay's Zenoh session is closed ({exc})") from None
        self.in_flight.add(went)
        try:
            data = await future
        finally:
            self.in_flight.discard(went)
        if data is None:
            raise TimeoutError(f"{what}: {await self.unanswered('call')}")
        return data

    async def call_service(
        self, service: str, srv_type: str | None, args: Mapping[str, Any] | list[Any] | None,
        timeout: float, discovery_wait: float,
        check: Callable[[Any], str | None] | None = None,
    ) -> dict[str, Any]:
        """One query to the robot, which calls the service itself; ``check`` (an action's
        cancel limited to the session's own goals) is asked here first, with the request
        built from the robot's type of the service."""
        if check is not None:
            type_name = srv_type or next(iter(self.service_types(service)), None)
            if type_name is not None:
                service_request(self.converter(self.resolve_service(type_name).Request),
                                service, args, check)
        request = CallRequest(type=srv_type, args=args, timeout=timeout,
                              discovery_wait=discovery_wait)
        try:
            data = await self._ask(keys.key_of(self.robot, service, f"{keys.CALL}/{self.relay}"),
                                   request.encode(), timeout + 2 * discovery_wait + 1.0,
                                   f"service {service}")
        except (Refused, TimeoutError) as exc:
            raise ServiceCallError(str(exc)) from None
        return json.loads(data)  # type: ignore[no-any-return]

    def serve(self, name: str, srv_cls: Any, on_request: Callable[[RosCall], None],
              on_refused: Callable[[str], None] | None = None) -> ZenohServedService:
        """Serve ``name`` on the robot for a client of this relay (see
        :class:`ZenohServedService`); ``on_refused`` hears the robot's refusal."""
        old = self.served.pop(name, None)
        if old is not None:
            old.destroy()
        served = self.served[name] = ZenohServedService(self, name, srv_cls, on_request,
                                                        on_refused)
        return served

    # -- parameters ----------------------------------------------------------------------------

    async def _param(self, node: str, request: ParamRequest, timeout: float) -> Any:
        """One parameter query, the robot's exceptions raised again as the bridge's."""
        try:
            data = await self._ask(keys.key_of(self.robot, node, keys.PARAM), request.encode(),
                                   timeout + PARAM_WAIT, f"parameters of {node}")
        except Refused as exc:
            try:
                err = json.loads(str(exc))
                kind, text = str(err["kind"]), str(err["text"])
            except (ValueError, KeyError, TypeError):
                kind, text = "error", str(exc)
            raise {"timeout": TimeoutError, "lookup": LookupError,
                   "value": ValueError}.get(kind, BridgeError)(text) from None
        return request.read_answer(data)

    async def parameter_names(self, node: str, timeout: float) -> list[str]:
        """Names of a robot node's parameters."""
        return [str(n) for n in await self._param(node, ParamRequest("names", timeout=timeout),
                                                  timeout)]

    async def get_parameter(self, node: str, name: str) -> tuple[bool, Any]:
        """(is set, value) of a robot node's parameter."""
        is_set, value = await self._param(node, ParamRequest("get", name=name), PARAM_WAIT)
        return is_set, value

    async def set_parameter(self, node: str, name: str, value: Any) -> tuple[bool, str]:
        """Set (``None``: unset) a robot node's parameter: (accepted, reason)."""
        ok, reason = await self._param(node, ParamRequest("set", name=name, value=value),
                                       PARAM_WAIT)
        return bool(ok), str(reason)

    # -- actions -------------------------------------------------------------------------------

    def action_client(self, name: str, action_cls: Any) -> ZenohActionClient:
        """A client of the robot's action ``name``."""
        return ZenohActionClient(self, name, action_cls)

    def serve_action(
        self, name: str, action_cls: Any, on_goal: Callable[[ServedGoal], None],
        on_cancel: Callable[[ServedGoal], None],
        on_refused: Callable[[str], None] | None = None,
    ) -> ZenohServedAction:
        """Serve action ``name`` on the robot for a client of this relay (see
        :class:`ZenohServedAction`); ``on_refused`` hears the robot's refusal."""
        old = self.served_actions.pop(name, None)
        if old is not None:
            old.destroy()
        served = self.served_actions[name] = ZenohServedAction(self, name, action_cls, on_goal,
                                                               on_cancel, on_refused)
        return served
