"""The ROS side of the bridge (rclpy is imported only in this package).

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

:class:`RosNode` holds the node's life cycle, the hand-offs and the shared entities;
their parts live beside it:

* :mod:`.topics`: shared subscriptions and publishers, and the message they hand out
  (:class:`~.topics.Incoming`), with the QoS a subscription follows;
* :mod:`.calls`: calling ROS services (cached clients, waiting for a server, the first
  requests on a newly matched client), the base :class:`~.calls.ServiceCalls`;
* :mod:`.served`: services a client serves in ROS (:class:`~.served.ServedService`);
* :mod:`.qos`: the QoS profiles they all use.

Service clients are cached per (service, type).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from bridge_server.rclpy_graph import convert
from bridge_server.rclpy_graph.calls import ServiceCalls
from bridge_server.rclpy_graph.reader import FailureLog, Reader, open_reader
from bridge_server.rclpy_graph.served import LoopRosCall, PendingRosCall, ServedService
from bridge_server.rclpy_graph.topics import (
    Incoming,
    Listener,
    SharedPublisher,
    SharedSubscription,
)
from bridge_server.rclpy_graph.types import resolve_message, resolve_service
from msgs import dynamic
from rosbridge_core.graph import acquire_shared, release_shared, shared_types
from rosbridge_core.protocol.names import node_path

if TYPE_CHECKING:
    from rosbridge_core.graph import Publisher, TopicFeed

__all__ = [  # the shared entities are re-exported where they were always imported from
    "Incoming",
    "LoopRosCall",
    "PendingRosCall",
    "RosNode",
    "ServedService",
    "SharedPublisher",
    "SharedSubscription",
]

log = logging.getLogger("bridge_server.rclpy_graph.node")


class RosNode(ServiceCalls):
    """The bridge's rclpy node, its executor thread and the shared ROS entities (its service
    calls are :class:`~.calls.ServiceCalls`'s).

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
                named.append("the ROS node " + node_path(namespace, name))
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
