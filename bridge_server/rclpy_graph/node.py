"""The ROS side of the bridge (rclpy is imported only here, in ros_*, convert and types).

One rclpy node lives in its own context; an executor spins it in a thread of
its own. The topics the bridge subscribes to are not the executor's
(:mod:`.reader`): the middleware wakes the asyncio loop itself when
one of their messages arrives, and the loop takes it (a reader thread does that
where the loop cannot be woken so). Everything the executor learns (a ROS caller
reaching a client-served service under the thread reader, a service response) crosses
to the asyncio loop with ``loop.call_soon_threadsafe``; hand-offs are batched, so a
burst of messages costs one wake-up of the loop, not one each.
The loop never waits on the executor. The other way, :meth:`RosNode.in_executor`
runs work on the executor thread (a guard condition), for rclpy APIs that are
not thread safe (actions: :mod:`bridge_server.rclpy_graph.actions`).

Sharing
-------
* :class:`SharedSubscription`: one ROS subscription per topic for every
  client, taking messages serialized. Each message becomes one
  :class:`Incoming`: ``cbor-raw`` subscribers get its CDR bytes as they came; it
  is deserialized only to build its JSON or CBOR encoding, each at most once;
  every subscribed session is handed the same ``str``/``bytes``.
* :class:`SharedPublisher`: one rclpy publisher per (topic, type, latch),
  reference counted across sessions.
* Service clients are cached per (service, type).

QoS
---
A shared subscription follows the publishers it sees
(``get_publishers_info_by_topic``): best effort if any publisher is best
effort (a reliable reader would not match it), transient local if every
publisher is transient local (a transient-local reader does not match a
volatile writer). :meth:`RosNode.refresh` re-checks this periodically and
replaces a subscription whose profile no longer fits, and resolves the type of
subscriptions made before any publisher existed ("late publishers"). The last
message of a transient-local topic is kept and handed to each client that
subscribes later.

Served services
---------------
A client-served service is a real ROS service whose response is deferred: it is
sent from the loop when the client answers, fails, times out or goes away (see
:class:`PendingRosCall`). With the loop reader the middleware wakes the loop for each
request, which takes it itself and answers it on the loop (:class:`ServedService`,
:class:`LoopRosCall`); otherwise it is an rclpy service whose callback returns at once, so the
executor is never blocked.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
import threading
import warnings
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.reader import (
    FailureLog,
    LoopReader,
    Reader,
    ReaderService,
    open_reader,
)
from bridge_server.rclpy_graph.types import resolve_message, resolve_service
from msgs import dynamic
from rosbridge_core.codec.encodings import EncodedMessage
from rosbridge_core.graph import acquire_shared, release_shared, shared_types

if TYPE_CHECKING:
    from rosbridge_core.graph import Publisher, TopicFeed

__all__ = [
    "Incoming",
    "LoopRosCall",
    "PendingRosCall",
    "RosNode",
    "ServedService",
    "SharedPublisher",
    "SharedSubscription",
]

log = logging.getLogger("bridge_server.rclpy_graph.node")

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

SERVICE_DEPTH = 1000
"""History depth of the bridge's service clients and servers: the ROS default of 10 loses
requests and responses when more than 10 calls are in flight."""

REPLAY_MEMORY = 1000
"""Source timestamps a subscription remembers of the messages it took, so that one made
to replace it (its publishers turned out transient local) skips the history it already
handed out when the writers replay it."""

RESEND_S = 0.1
"""Seconds a read-only request on a newly matched client waits for its answer before it is
sent again (see call_when_ready): a server drops an answer when it has not matched our
response reader within 100 ms of the request."""

SETTLE_S = 1.2
"""Seconds a newly matched service client waits before its first request (see settled).

The server drops its answer if it has not matched our response reader within 100 ms of the
request (rmw_fastrtps: the response writer's max blocking time). Discovery normally takes
milliseconds, but one lost discovery sample is repaired only on Fast DDS's next discovery
heartbeat (1 s, answered after 100 ms): 0.5 s did not cover that, and CI lost first answers
that way. Paid once per service and type for the bridge's life (clients are kept)."""


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


def _qos(reliable: bool, transient_local: bool, depth: int) -> Any:
    return QoSProfile(  # type: ignore[no-untyped-call]
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL if transient_local else DurabilityPolicy.VOLATILE
        ),
    )


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
    a type before any publisher appeared); :meth:`RosNode.refresh` fills it in.
    """

    def __init__(self, ros: RosNode, topic: str, msg_cls: type[Any] | None) -> None:
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
        qos = _qos(self.reliable, self.transient_local, depth)
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

    def __init__(self, ros: RosNode, topic: str, msg_cls: type[Any], latch: bool, depth: int):
        self.ros = ros
        self.topic = topic
        self.msg_cls = msg_cls
        self.conv = convert.converter_for(msg_cls)
        self.latch = latch
        self.refs = 0
        depth = 1 if latch else max(depth, 1)
        self.pub = ros.node.create_publisher(msg_cls, topic, _qos(True, latch, depth))

    @property
    def type_name(self) -> str:
        """Canonical message type."""
        return self.conv.type_name

    def publish(self, msg: Any) -> None:
        """Publish one message (callable from the loop thread; rcl publish is thread safe)."""
        self.pub.publish(msg)


class PendingRosCall:
    """A ROS caller waiting for a client-served service's answer.

    The rclpy callback returns this object at once; rclpy then hands it with
    the request header to the service's ``send_response``, which the bridge
    intercepts. Whichever of (header, answer) arrives second sends the real
    response, from whichever thread that is.
    """

    def __init__(self, served: ServedService, request: Any) -> None:
        self.served = served
        self.request = request
        self._lock = threading.Lock()
        self._header: Any = None
        self._response: Any = None
        self.done = False

    def _attach(self, header: Any) -> None:
        with self._lock:
            self._header = header
            response = self._response
        if response is not None:
            self.served._send(response, header)

    def complete(self, response: Any | None = None) -> bool:
        """Answer the ROS caller (``None``: a default response). False if already answered."""
        if self.done:
            return False
        self.done = True
        if response is None:
            response = self.served.srv_cls.Response()
        with self._lock:
            self._response = response
            header = self._header
        if header is not None:
            self.served._send(response, header)
        return True


class LoopRosCall:
    """A ROS caller of a service the loop reader serves: taken on the loop with its header,
    answered on the loop, so unlike :class:`PendingRosCall` it needs no lock."""

    __slots__ = ("done", "header", "request", "served")

    def __init__(self, served: ServedService, request: Any, header: Any) -> None:
        self.served = served
        self.request = request
        self.header = header
        self.done = False

    def complete(self, response: Any | None = None) -> bool:
        """Answer the ROS caller (``None``: a default response). False if already answered."""
        if self.done:
            return False
        self.done = True
        served = self.served
        served._send(response if response is not None else served.srv_cls.Response(),
                     self.header)
        return True


UNMATCHED_CALLER = "client will not receive response"
"""rmw_fastrtps's words when it drops an answer: the service's reply writer has not matched
the caller's reply reader within its ``max_blocking_time`` (100 ms); rclpy says so with a
RuntimeWarning, not an exception."""

ANSWER_RETRIES = (0.1, 0.2, 0.4, 0.8, 1.6, 3.2)
"""Seconds before each new attempt to answer a ROS caller whose reply reader the bridge has
not matched yet (6.3 s in all; each attempt may wait 100 ms in rmw_fastrtps).

A caller's ``wait_for_service`` is true once the caller's side has matched the service's
two topics, which says nothing of the bridge's side (it is true even while the bridge is
stopped with SIGSTOP); a caller that calls at once can get its answer sent before the
bridge's discovery has seen the caller's reply reader, and on a loaded machine that takes
more than the 100 ms rmw_fastrtps waits: the answer was lost and the caller waited for
ever (issue 43, test_served_service_comes_back_after_bridge_restart)."""

_SENDING = threading.Lock()
"""Held while an answer is sent with the warnings caught (catch_warnings is process-wide)."""


class ServedService:
    """A ROS service whose requests are answered by a websocket client.

    With the loop reader (:class:`~bridge_server.rclpy_graph.reader.LoopReader`) the middleware
    wakes the loop for each request, which takes it with its header and answers it on the
    loop: no executor round, no thread between the caller and the client. Otherwise the
    service is rclpy's, served by the executor's thread as :class:`PendingRosCall` says.
    """

    def __init__(
        self,
        ros: RosNode,
        name: str,
        srv_cls: type[Any],
        on_request: Callable[[PendingRosCall | LoopRosCall], None],
    ) -> None:
        self.ros = ros
        self.name = name
        self.srv_cls = srv_cls
        self.request_conv = convert.converter_for(srv_cls.Request)
        self.response_conv = convert.converter_for(srv_cls.Response)
        self.on_request = on_request
        qos = _qos(True, False, SERVICE_DEPTH)
        reader = ros.reader
        self._served: ReaderService | None = None
        if isinstance(reader, LoopReader):
            self._served = reader.serve(srv_cls, name, qos, self._on_loop_request)
            self._real_send: Callable[[Any, Any], None] = self._served.respond
            return
        post = ros.post

        def callback(request: Any, _response: Any) -> Any:
            pending = PendingRosCall(self, request)
            post(self.on_request, pending)
            return pending

        self.srv: Any = ros.node.create_service(srv_cls, name, callback, qos_profile=qos)
        self._real_send = self.srv.send_response

        def send_response(response: Any, header: Any) -> None:
            if isinstance(response, PendingRosCall):
                response._attach(header)
            else:
                self._real_send(response, header)

        self.srv.send_response = send_response

    def _on_loop_request(self, request: Any, header: Any) -> None:
        self.on_request(LoopRosCall(self, request, header))

    def _send(self, response: Any, header: Any, attempt: int = 0) -> None:
        """Answer a ROS caller; again later while its reply reader is not matched here yet
        (see :data:`ANSWER_RETRIES`), from the loop."""
        with _SENDING, warnings.catch_warnings(record=True) as warned:
            warnings.simplefilter("always", RuntimeWarning)
            try:
                self._real_send(response, header)
            except Exception as exc:  # destroyed meanwhile, or the caller went away
                log.debug("could not answer a ROS caller of %s: %s", self.name, exc)
                return
        if not any(UNMATCHED_CALLER in str(w.message) for w in warned):
            return
        if attempt < len(ANSWER_RETRIES):
            loop = self.ros.loop
            with contextlib.suppress(RuntimeError):  # the loop closed while shutting down
                loop.call_soon_threadsafe(loop.call_later, ANSWER_RETRIES[attempt], self._send,
                                          response, header, attempt + 1)
            return
        log.warning("could not answer a ROS caller of %s: its reply reader never matched "
                    "the bridge's reply writer (%d tries over %.1f s; incompatible QoS?)",
                    self.name, attempt + 1, sum(ANSWER_RETRIES))

    def destroy(self) -> None:
        """Remove the ROS service."""
        if self._served is not None:
            reader = self.ros.reader
            if isinstance(reader, LoopReader):
                reader.unserve(self._served)
            return
        with contextlib.suppress(Exception):
            self.ros.node.destroy_service(self.srv)


class RosNode:
    """The bridge's rclpy node, its executor thread and the shared ROS entities.

    All public methods are called from the asyncio loop thread.
    """

    wire_types: dynamic.TypeStore = dynamic.DEFAULT
    """The ``msgs`` classes of the ROS types (Foxglove's CDR): one ROS graph, one store."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        *,
        name: str = "roslibpy_lite_bridge",
        topic_reader: str = "auto",
    ) -> None:
        self.loop = loop
        self.name = name
        self.topic_reader = topic_reader
        """Who waits on the topics: ``auto`` or ``thread`` (:func:`.reader.open_reader`)."""
        self.context = Context()
        self._inbox: deque[tuple[Callable[..., None], tuple[Any, ...]]] = deque()
        self._scheduled = False
        self.subscriptions: dict[str, SharedSubscription] = {}
        self.publishers: dict[tuple[str, str, bool], SharedPublisher] = {}
        self._clients: dict[tuple[str, type[Any]], Any] = {}
        self._thread: threading.Thread | None = None
        self.node: Any = None
        self.executor: Any = None
        self.reader: Reader | None = None
        """What takes the topics' messages (:mod:`.reader`)."""
        self._calls: deque[tuple[Callable[..., None], tuple[Any, ...]]] = deque()
        self._calls_gc: Any = None
        self._spin_failures = FailureLog("ROS executor round failed; spinning on")

    @property
    def reader_kind(self) -> str:
        """``loop`` or ``thread``: what waits on the topics (:mod:`.reader`)."""
        return self.reader.kind if self.reader is not None else "none"

    @property
    def spin_errors(self) -> int:
        """Executor rounds that raised (logged and survived, see :meth:`_spin`)."""
        return self._spin_failures.count

    # -- life cycle --------------------------------------------------------------------------

    def start(self) -> None:
        """Initialise rclpy (own context, no signal handlers) and start spinning."""
        rclpy.init(
            context=self.context,
            signal_handler_options=rclpy.signals.SignalHandlerOptions.NO,
        )
        # No parameter services: fewer entities in the executor's wait set (it is rebuilt on
        # every spin), and the bridge has no parameters to offer.
        self.node = rclpy.create_node(
            self.name, context=self.context, start_parameter_services=False
        )
        # One thread: measured faster than MultiThreadedExecutor here (the GIL serialises
        # the callbacks anyway), and no callback of the bridge ever blocks.
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, name="bridge-ros-spin", daemon=True)
        self._thread.start()
        self.reader = open_reader(self.context, self.node, self.loop, self.post,
                                  self.topic_reader)

    def _spin(self) -> None:
        """Spin until shutdown; an exception out of one round never stops the bridge's ROS side.

        A callback that raises, or one of rclpy's known wait-set races (an action
        client made while the executor waits: ros2/rclpy#1589, #1455), surfaces
        here as an exception from ``spin``. Spinning goes on after it, or every
        client would lose ROS for good; the error is logged with its traceback,
        at most once per :data:`.reader.ERROR_LOG_INTERVAL` seconds (the rest counted).
        """
        while True:
            try:
                self.executor.spin()  # returns once the context is shut down
                return
            except ExternalShutdownException:
                return
            except Exception:
                self._spin_failures.failed()

    def close(self) -> None:
        """Stop spinning, destroy the node and shut this context down."""
        if self.node is None:
            return
        if self.reader is not None:
            self.reader.stop()
        with contextlib.suppress(Exception):
            self.executor.shutdown(timeout_sec=0.5)
        with contextlib.suppress(Exception):
            self.context.try_shutdown()
        if self._thread is not None:
            self._thread.join(2.0)
        with contextlib.suppress(Exception):
            self.node.destroy_node()
        self.node = None

    # -- hand-off to the loop ------------------------------------------------------------------

    def post(self, fn: Callable[..., None], *args: Any) -> None:
        """Run ``fn(*args)`` on the loop thread soon (callable from any thread, batched)."""
        self._inbox.append((fn, args))
        if not self._scheduled:
            self._scheduled = True
            with contextlib.suppress(RuntimeError):  # the loop closed while shutting down
                self.loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        self._scheduled = False
        inbox = self._inbox
        while inbox:
            fn, args = inbox.popleft()
            try:
                fn(*args)
            except Exception:
                log.exception("hand-off callback failed")

    def in_executor(self, fn: Callable[..., None], *args: Any) -> None:
        """Run ``fn(*args)`` on the executor thread soon (callable from any thread, batched).

        For rclpy APIs that are not thread safe (action clients and servers): the
        loop hands the work over and never waits for it.
        """
        self._calls.append((fn, args))
        gc = self._calls_gc
        if gc is None:
            if self.node is None:
                return
            # Made on first use: one more entity in every wait set of the executor.
            gc = self._calls_gc = self.node.create_guard_condition(self._run_calls)
        with contextlib.suppress(Exception):  # destroyed while shutting down
            gc.trigger()

    def _run_calls(self) -> None:
        # Only what was handed over before this round: work handed over from in here runs
        # in the next round, after the executor tasks this round created.
        calls = self._calls
        for _ in range(len(calls)):
            fn, args = calls.popleft()
            try:
                fn(*args)
            except Exception:
                log.exception("executor hand-off failed")
        if calls and self._calls_gc is not None:
            with contextlib.suppress(Exception):
                self._calls_gc.trigger()

    # -- graph ---------------------------------------------------------------------------------

    def topic_types(self, topic: str) -> list[str]:
        """Types the ROS graph lists for ``topic`` (empty if unknown)."""
        for name, types in self.node.get_topic_names_and_types():
            if name == topic:
                return list(types)
        return []

    def service_types(self, service: str) -> list[str]:
        """Types the ROS graph lists for ``service`` (empty if unknown)."""
        for name, types in self.node.get_service_names_and_types():
            if name == service:
                return list(types)
        return []

    def other_servers(self, service: str) -> list[str]:
        """Servers of ``service`` in the ROS graph other than the bridge's own node, as
        "the ROS node /name" where the graph names them yet ("another ROS node" where not).

        Servers are counted by service name (a node's name reaches the graph later than its
        endpoints, and two nodes may share a name); the bridge's own entry, which can linger
        a moment after it destroyed a service, is left out.
        """
        node = self.node
        me = (node.get_name(), node.get_namespace())
        total = self.server_count(service)
        mine = any(s == service for s, _ in node.get_service_names_and_types_by_node(*me))
        others = total - (1 if mine else 0)
        if others <= 0:
            return []
        named = []
        for name, namespace in node.get_node_names_and_namespaces():
            if (name, namespace) == me:
                continue
            try:
                served = node.get_service_names_and_types_by_node(name, namespace)
            except Exception:  # the node left between the two graph queries
                continue
            if any(s == service for s, _ in served):
                named.append("the ROS node " + namespace.rstrip("/") + "/" + name)
        return (named or ["another ROS node"])[:others]

    def now(self) -> tuple[int, int]:
        """The node clock's time as (sec, nanosec)."""
        t = self.node.get_clock().now().seconds_nanoseconds()
        return int(t[0]), int(t[1])

    # -- subscriptions -------------------------------------------------------------------------

    def subscribe(
        self, topic: str, msg_cls: type[Any] | None, listener: Listener
    ) -> SharedSubscription:
        """Add ``listener`` to the topic's shared subscription (created if needed).

        ``msg_cls`` may be ``None`` when the type is to be learned from the graph.
        Raises ``ValueError`` if the topic is already subscribed with another type.
        """
        shared = self.subscriptions.get(topic)
        if shared is None:
            shared = SharedSubscription(self, topic, msg_cls)
            if msg_cls is None:
                shared.refresh()
            else:
                shared._create()
            self.subscriptions[topic] = shared
        elif msg_cls is not None:
            if shared.msg_cls is None:
                shared.msg_cls = msg_cls
                shared._create()
            elif shared.msg_cls is not msg_cls:
                raise ValueError(
                    f"topic {topic} is already subscribed with type {shared.type_name}"
                )
        shared.listeners.append(listener)
        return shared

    def unsubscribe(self, shared: TopicFeed, listener: Listener) -> None:
        """Remove ``listener``; the ROS subscription goes when its last listener does."""
        assert isinstance(shared, SharedSubscription)  # one of this node's
        with contextlib.suppress(ValueError):
            shared.listeners.remove(listener)
        if not shared.listeners and self.subscriptions.get(shared.topic) is shared:
            del self.subscriptions[shared.topic]
            shared._destroy()

    def refresh(self) -> None:
        """Resolve late types and re-check QoS of every shared subscription."""
        if self.node is None:
            return
        for shared in list(self.subscriptions.values()):
            try:
                shared.refresh()
            except Exception:
                log.exception("refreshing %s failed", shared.topic)

    # -- publishers ----------------------------------------------------------------------------

    def acquire_publisher(
        self, topic: str, msg_cls: type[Any], latch: bool, depth: int
    ) -> SharedPublisher:
        """A shared publisher for (topic, type, latch), its reference count raised by one."""
        key = (topic, convert.converter_for(msg_cls).type_name, latch)
        return acquire_shared(self.publishers, key,
                              lambda: SharedPublisher(self, topic, msg_cls, latch, depth))

    def release_publisher(self, pub: Publisher) -> None:
        """Lower the reference count; the ROS publisher goes with the last reference."""
        assert isinstance(pub, SharedPublisher)  # one of this node's
        if not release_shared(self.publishers, (pub.topic, pub.type_name, pub.latch), pub):
            return
        if self.node is not None:
            with contextlib.suppress(Exception):
                self.node.destroy_publisher(pub.pub)

    def publisher_types(self, topic: str) -> set[str]:
        """Types of this bridge's own publishers on ``topic``."""
        return shared_types(self.publishers, topic)

    # -- services ------------------------------------------------------------------------------

    def client_for(self, service: str, srv_cls: type[Any]) -> Any:
        """A cached rclpy client for ``service`` of ``srv_cls``."""
        key = (service, srv_cls)
        client = self._clients.get(key)
        if client is None:
            client = self._clients[key] = self.node.create_client(
                srv_cls, service, qos_profile=_qos(True, False, SERVICE_DEPTH)
            )
            _inline_done_callbacks(client)
        return client

    async def settled(self, client: Any) -> None:
        """Return once ``client`` has had a matched server for :data:`SETTLE_S` seconds.

        DDS matches each direction of a service on its own: the bridge can see a server as
        ready (our request writer and response reader matched) before the server has
        matched our response reader, and a request sent in that window is executed but its
        answer lost (rmw_fastrtps: "failed to send response"). Nothing on our side shows the
        server's half, so the first requests on a newly matched client wait a moment; later
        calls on the same client do not wait at all.
        """
        now = self.loop.time()
        since = getattr(client, "_bridge_ready_at", None)
        if since is None:
            since = now
            client._bridge_ready_at = since
        wait = since + SETTLE_S - now
        if wait > 0:
            await asyncio.sleep(wait)

    async def call_when_ready(
        self,
        service: str,
        srv_cls: type[Any],
        request: Any,
        timeout: float,
        discovery_wait: float | None = None,
        *,
        read_only: bool = False,
    ) -> Any:
        """Call ``service`` once a server is matched; ``TimeoutError`` after ``timeout`` s.

        With ``discovery_wait``, a service the ROS graph still does not list after that
        many seconds fails then (``LookupError``), not after the whole timeout.
        ``read_only`` (a request that may run twice, such as listing or reading parameters):
        a newly matched client sends at once and again after :data:`RESEND_S` (backing off)
        until an answer comes, instead of waiting :data:`SETTLE_S` before its first request.
        """
        loop = self.loop
        deadline = loop.time() + timeout
        unlisted_by = loop.time() + (discovery_wait if discovery_wait is not None else timeout)
        client = self.client_for(service, srv_cls)
        delay = 0.002
        while not client.service_is_ready():
            if loop.time() >= unlisted_by and self.server_count(service) == 0:
                raise LookupError(f"service {service} does not exist (not in the ROS graph)")
            if loop.time() >= deadline:
                raise TimeoutError(f"service {service} is not available")
            await asyncio.sleep(delay)
            delay = min(delay * 2, 0.05)
        if read_only and getattr(client, "_bridge_ready_at", None) is None:
            return await self._resent(client, request, deadline, service)
        await self.settled(client)
        future = self.call(client, request)
        timer = loop.call_at(deadline, _fail_timeout, future)
        try:
            return await future
        finally:
            timer.cancel()

    async def _resent(self, client: Any, request: Any, deadline: float, service: str) -> Any:
        """The answer to a read-only ``request`` on a client not settled yet: sent again
        after RESEND_S, then twice as long each time up to 1 s (an answer the server sent
        before it matched our reader is lost) until one comes; the client counts as settled
        from then on."""
        loop = self.loop
        every = RESEND_S
        while True:
            future = self.call(client, request)
            wait = min(every, deadline - loop.time())
            every = min(every * 2, 1.0)  # a server that is slow, not deaf: ask less often
            try:
                response = await asyncio.wait_for(asyncio.shield(future), max(wait, 0.0))
            except TimeoutError:
                future.cancel()  # forgets the request: a late answer to it is dropped
                if loop.time() >= deadline:
                    raise TimeoutError(f"service {service} did not answer") from None
                continue
            client._bridge_ready_at = loop.time() - SETTLE_S  # answered: settled
            return response

    def drop_client(self, service: str, srv_cls: type[Any]) -> None:
        """Destroy the cached client (after a call found no server)."""
        client = self._clients.pop((service, srv_cls), None)
        if client is not None:
            with contextlib.suppress(Exception):
                self.node.destroy_client(client)

    def server_count(self, service: str) -> int:
        """How many servers of ``service`` the graph knows."""
        return int(self.node.count_services(service))

    def call(self, client: Any, request: Any) -> asyncio.Future[Any]:
        """Send ``request`` now; the returned asyncio future gets the response.

        Cancelling the returned future (or failing it, e.g. on a timeout) forgets the
        pending request.
        """
        loop = self.loop
        result: asyncio.Future[Any] = loop.create_future()
        rfuture = client.call_async(request)

        def done(f: Any) -> None:
            exc = f.exception()
            self.post(_settle, result, exc, None if exc is not None else f.result())

        rfuture.add_done_callback(done)

        def forget(f: asyncio.Future[Any]) -> None:
            if f.cancelled() or f.exception() is not None:
                with contextlib.suppress(Exception):
                    client.remove_pending_request(rfuture)

        result.add_done_callback(forget)
        return result

    def serve(
        self, name: str, srv_cls: type[Any],
        on_request: Callable[[PendingRosCall | LoopRosCall], None],
        on_refused: Callable[[str], None] | None = None,
    ) -> ServedService:
        """Create a ROS service answered through ``on_request`` (see :class:`PendingRosCall`
        and :class:`LoopRosCall`); ``on_refused`` is never called (ROS refuses no name)."""
        return ServedService(self, name, srv_cls, on_request)

    @staticmethod
    def resolve_message(name: str) -> type[Any]:
        """The message class for a type string (both spellings)."""
        return resolve_message(name)

    @staticmethod
    def resolve_service(name: str) -> type[Any]:
        """The service class for a type string (both spellings)."""
        return resolve_service(name)


class _InlineFuture:
    """What the executor gets for a pending request: completing it runs the done callbacks
    right there, instead of scheduling each as an executor task (two more wait-set rounds
    per call)."""

    __slots__ = ("_future",)

    def __init__(self, future: Any) -> None:
        self._future = future

    def _set_executor(self, executor: Any) -> None:
        pass

    def set_result(self, result: Any) -> None:
        self._future.set_result(result)

    def set_exception(self, exc: BaseException) -> None:
        self._future.set_exception(exc)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._future, name)


def _inline_done_callbacks(client: Any) -> None:
    get = client.get_pending_request

    def get_pending_request(sequence_number: int) -> Any:
        return _InlineFuture(get(sequence_number))

    client.get_pending_request = get_pending_request


def _fail_timeout(fut: asyncio.Future[Any]) -> None:
    if not fut.done():
        fut.set_exception(TimeoutError("the service did not answer in time"))


def _settle(fut: asyncio.Future[Any], exc: BaseException | None, value: Any) -> None:
    if fut.done():
        return
    if exc is not None:
        fut.set_exception(exc)
    else:
        fut.set_result(value)
