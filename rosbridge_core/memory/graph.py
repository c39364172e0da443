"""A whole ROS graph in memory: :class:`MemoryRos`, and :class:`MemoryGraph`, one node of it
seen through the :class:`~rosbridge_core.graph.Graph` port.

No rclpy, no Zenoh, no socket: the sessions' ROS side for tests without ROS and for
:class:`~roslibpy_lite.mock.MockRos`. Several :class:`MemoryGraph` on one :class:`MemoryRos`
are several nodes of one ROS graph (as two rclpy nodes in one ROS domain): what one
publishes reaches the others' subscriptions of the topic and type, one serves a service or
an action the others call, each introspects the whole graph.

- Types are ``msgs`` classes (:mod:`msgs.runtime`, :data:`msgs.dynamic.DEFAULT`); their
  converters check a value as the bridge's do (:class:`~rosbridge_core.interfaces.ConversionError`
  naming the field path).
- Topics: a subscription is shared per node and topic (``ValueError`` for another type,
  rclpy's text); a message reaches each subscription of its type synchronously, in the
  publisher's call, as a :class:`MemoryMessage` (an
  :class:`~rosbridge_core.codec.encodings.EncodedMessage`); a latched publisher's last message
  reaches a subscription made later, soon after it was made (as DDS's transient local does).
- Services: a node's served services answer :meth:`MemoryGraph.call_service`, which fails with
  the rclpy Graph's :class:`~rosbridge_core.interfaces.ServiceCallError` texts (not in the
  graph, no server within the timeout, a bad request, timed out). Waiting for a server waits
  for the graph to change, never on a poll.
- Actions: an action client's goals reach the node serving the action, with feedback, cancel
  (also through ``<action>/_action/cancel_goal``), results and ``GoalStatus``.
- Parameters: a node made with ``parameters`` serves ``<node>/list_parameters``,
  ``get_parameters`` and ``set_parameters`` from that dict (``rcl_interfaces`` types), as an
  rclpy node does; the Graph's parameter methods call them.

This module holds the graph (:class:`MemoryRos`) and the node (:class:`MemoryGraph`: its life,
introspection, topics, service calls); the parts live beside it and are re-exported here:
:mod:`.typesource` (types), :mod:`.topics` (feeds, publishers, messages), :mod:`.services`
(served services), :mod:`.actions` (action clients, served actions, goals) and
:mod:`.parameters` (a node's parameter services, the parameter calls).

Nothing here imports rclpy, cbor2 (only :meth:`MsgsConverter.to_cbor_obj` does, when a
client asks for CBOR), prometheus_client or pybase64: a client-only install runs it.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Mapping
from typing import Any

from msgs.runtime import Message
from rosbridge_core.codec.msgs_types import MsgsConverter
from rosbridge_core.graph import (
    Listener,
    RosCall,
    ServedGoal,
    acquire_shared,
    release_shared,
    service_request,
    shared_types,
)
from rosbridge_core.interfaces import ServiceCallError
from rosbridge_core.memory.actions import (
    MemoryActionClient,
    MemorySentGoal,
    MemoryServedAction,
    MemoryServedGoal,
)
from rosbridge_core.memory.parameters import ParameterCalls, ServedParameters
from rosbridge_core.memory.services import MemoryRosCall, MemoryServedService, ServiceServer
from rosbridge_core.memory.topics import MemoryFeed, MemoryMessage, MemoryPublisher
from rosbridge_core.memory.typesource import MsgsTypes
from rosbridge_core.protocol.names import node_path

__all__ = [
    "MemoryActionClient",
    "MemoryFeed",
    "MemoryGraph",
    "MemoryMessage",
    "MemoryPublisher",
    "MemoryRos",
    "MemoryRosCall",
    "MemorySentGoal",
    "MemoryServedAction",
    "MemoryServedGoal",
    "MemoryServedService",
]


def _discard(registry: dict[str, list[Any]], name: str, item: Any) -> None:
    """Take ``item`` out of ``registry[name]`` (if it is there), and the name with its last."""
    found = registry.get(name, [])
    with contextlib.suppress(ValueError):
        found.remove(item)
    if not found:
        registry.pop(name, None)


class MemoryRos:
    """The whole ROS graph: every :class:`MemoryGraph` (node) made on it, and what they
    publish, subscribe, serve. ``changed`` is set (and made anew) whenever a service or an
    action server comes, so a caller waiting for one wakes then."""

    def __init__(self) -> None:
        self.nodes: list[MemoryGraph] = []
        self.servers: dict[str, list[ServiceServer]] = {}
        self.actions: dict[str, list[MemoryServedAction]] = {}
        self.taps: list[Callable[[MemoryPublisher, MemoryMessage], None]] = []
        """Called with each message any node publishes (before it is delivered)."""
        self._changed: asyncio.Event | None = None

    def node(self, name: str, namespace: str = "/", *,
             parameters: Mapping[str, Any] | None = None) -> MemoryGraph:
        """A new node of this graph (see :class:`MemoryGraph`)."""
        return MemoryGraph(self, name, namespace, parameters=parameters)

    # -- changes ---------------------------------------------------------------------------------

    def changed(self) -> asyncio.Event:
        """An event set at the graph's next change."""
        if self._changed is None:
            self._changed = asyncio.Event()
        return self._changed

    def _change(self) -> None:
        event, self._changed = self._changed, None
        if event is not None:
            event.set()

    async def until(self, test: Callable[[], bool], deadline: float) -> bool:
        """Wait until ``test()`` holds or the loop's time passes ``deadline``; whether it held."""
        loop = asyncio.get_running_loop()
        while not test():
            left = deadline - loop.time()
            if left <= 0:
                return False
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(left):
                    await self.changed().wait()
        return True

    # -- entities --------------------------------------------------------------------------------

    def add_server(self, server: ServiceServer) -> None:
        """A service comes into the graph."""
        self.servers.setdefault(server.name, []).append(server)
        self._change()

    def remove_server(self, server: ServiceServer) -> None:
        """A service goes."""
        _discard(self.servers, server.name, server)

    def add_action(self, action: MemoryServedAction) -> None:
        """An action server comes (with its services)."""
        self.actions.setdefault(action.name, []).append(action)
        for server in action.servers:
            self.add_server(server)

    def remove_action(self, action: MemoryServedAction) -> None:
        """An action server goes (with its services)."""
        _discard(self.actions, action.name, action)
        for server in action.servers:
            self.remove_server(server)

    def feeds(self, topic: str, cls: type[Message]) -> list[MemoryFeed]:
        """Every node's subscription to ``topic`` with type ``cls`` (or none yet: it takes
        ``cls`` now, as an rclpy subscription learns its type from the graph)."""
        found = []
        for node in self.nodes:
            feed = node.subscriptions.get(topic)
            if feed is None:
                continue
            if feed.msg_cls is None:
                feed.msg_cls = cls
            if feed.msg_cls is cls:
                found.append(feed)
        return found

    def latched(self, topic: str, cls: type[Message]) -> list[MemoryMessage]:
        """The last message of each latched publisher of ``topic`` with type ``cls``."""
        return [pub.last for node in self.nodes for pub in node.publishers.values()
                if pub.topic == topic and pub.conv.cls is cls and pub.last is not None]

    def topic_types(self, topic: str) -> list[str]:
        """Types of ``topic`` among every node's publishers and typed subscriptions."""
        found: set[str] = set()
        for node in self.nodes:
            found |= node.publisher_types(topic)
            feed = node.subscriptions.get(topic)
            if feed is not None and feed.type_name is not None:
                found.add(feed.type_name)
        return sorted(found)


class MemoryGraph(MsgsTypes, ParameterCalls):
    """One node of a :class:`MemoryRos` as the sessions see it (the
    :class:`~rosbridge_core.graph.Graph` port; see the module's text).

    ``parameters``: the node's parameters, served as an rclpy node serves them (``None``: the
    node has no parameter services, as the bridge's own node): these are declared (their type
    is kept, they cannot be unset); others may be set and unset freely. Methods run on the
    loop. The types come from :class:`~.typesource.MsgsTypes`, the parameter methods from
    :class:`~.parameters.ParameterCalls`.
    """

    def __init__(self, ros: MemoryRos | None = None, name: str = "roslibpy_lite_bridge",
                 namespace: str = "/", *, parameters: Mapping[str, Any] | None = None) -> None:
        self.ros = ros if ros is not None else MemoryRos()
        self.name = name
        self.namespace = namespace
        self.loop = asyncio.get_running_loop()
        self.subscriptions: dict[str, MemoryFeed] = {}
        self.publishers: dict[tuple[str, str, bool], MemoryPublisher] = {}
        self._converters: dict[type[Message], MsgsConverter] = {}
        self.parameters: dict[str, Any] | None = (
            None if parameters is None else dict(parameters))
        self._declared = set(parameters or ())
        self.ros.nodes.append(self)
        if self.parameters is not None:
            ServedParameters(self, self.parameters, self._declared).serve()

    def close(self) -> None:
        """The node leaves the graph with everything it had."""
        for servers in list(self.ros.servers.values()):
            for server in list(servers):
                if server.node is self:
                    self.ros.remove_server(server)
        for actions in list(self.ros.actions.values()):
            for action in list(actions):
                if action.graph is self:
                    action.destroy()
        self.subscriptions.clear()
        self.publishers.clear()
        with contextlib.suppress(ValueError):
            self.ros.nodes.remove(self)

    def start(self) -> None:
        """Nothing to start: the node serves from its making (a bridge may run on it)."""

    def trouble(self) -> str | None:
        """Nothing keeps an in-memory graph from serving."""
        return None

    def refresh(self) -> None:
        """Nothing to refresh: subscriptions learn their type when it is published."""

    # -- introspection ---------------------------------------------------------------------------

    def _node_of(self, name: str, namespace: str) -> MemoryGraph:
        for node in self.ros.nodes:
            if (node.name, node.namespace) == (name, namespace):
                return node
        raise LookupError(f"node {namespace.rstrip('/')}/{name} is not in the graph")

    def _served(self) -> list[tuple[str, str]]:
        return [(s.name, s.type_name) for servers in self.ros.servers.values()
                for s in servers if s.node is self]

    def topic_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every topic in the graph with its types."""
        names = {t for n in self.ros.nodes for t in (*n.subscriptions, *(k[0] for k in
                                                                          n.publishers))}
        return [(t, types) for t in sorted(names) if (types := self.ros.topic_types(t))]

    def service_names_and_types(self) -> list[tuple[str, list[str]]]:
        """Every service in the graph with its types."""
        return [(name, self.service_types(name)) for name in sorted(self.ros.servers)]

    def node_names(self) -> list[tuple[str, str]]:
        """Every node as (name, namespace)."""
        return [(n.name, n.namespace) for n in self.ros.nodes]

    def own_node(self) -> tuple[str, str]:
        """This node as (name, namespace)."""
        return self.name, self.namespace

    def node_endpoints(self, name: str, namespace: str) -> tuple[list[str], list[str], list[str]]:
        """Topics a node subscribes to, topics it publishes, services it serves."""
        node = self._node_of(name, namespace)
        return (sorted(t for t, f in node.subscriptions.items() if f.msg_cls is not None),
                sorted({k[0] for k in node.publishers}), sorted({s for s, _ in node._served()}))

    def node_services(self, name: str, namespace: str) -> list[tuple[str, list[str]]]:
        """Services a node serves with their types."""
        node = self._node_of(name, namespace)
        return [(s, [t]) for s, t in sorted(node._served())]

    def topic_publishers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes publishing on ``topic``."""
        return [(n, ns) for n, ns, _ in self.topic_publishers_qos(topic)]

    def topic_publishers_qos(self, topic: str) -> list[tuple[str, str, dict[str, Any]]]:
        """Publishers of ``topic`` with the QoS each offers (rosbag2's keys and words)."""
        never = {"sec": 0, "nsec": 0}
        return [(node.name, node.namespace, {
            "history": "keep_last", "depth": pub.depth, "reliability": "reliable",
            "durability": "transient_local" if pub.latch else "volatile",
            "deadline": never, "lifespan": never, "liveliness": "automatic",
            "liveliness_lease_duration": never, "avoid_ros_namespace_conventions": False,
        }) for node in self.ros.nodes for pub in node.publishers.values() if pub.topic == topic]

    def topic_subscribers(self, topic: str) -> list[tuple[str, str]]:
        """Nodes subscribed to ``topic``."""
        return [(n.name, n.namespace) for n in self.ros.nodes if topic in n.subscriptions]

    def topic_types(self, topic: str) -> list[str]:
        """Types the graph lists for ``topic`` (empty if unknown)."""
        return self.ros.topic_types(topic)

    def publisher_types(self, topic: str) -> set[str]:
        """Types of this node's own publishers on ``topic``."""
        return shared_types(self.publishers, topic)

    def service_types(self, service: str) -> list[str]:
        """Types the graph lists for ``service``."""
        return sorted({s.type_name for s in self.ros.servers.get(service, [])})

    def server_count(self, service: str) -> int:
        """How many servers of ``service`` the graph has."""
        return len(self.ros.servers.get(service, []))

    def other_servers(self, service: str) -> list[str]:
        """Servers of ``service`` on other nodes, as "the ROS node /name"."""
        return ["the ROS node " + node_path(s.node.namespace, s.node.name)
                for s in self.ros.servers.get(service, []) if s.node is not self]

    def server_types(self, service: str) -> list[str]:
        """Types of ``service`` as its servers offer it."""
        return self.service_types(service)

    def now(self) -> tuple[int, int]:
        """The wall clock as (sec, nanosec)."""
        sec, nsec = divmod(time.time_ns(), 1_000_000_000)
        return sec, nsec

    # -- topics ---------------------------------------------------------------------------------

    def subscribe(self, topic: str, msg_cls: Any, listener: Listener) -> MemoryFeed:
        """Add ``listener`` to this node's subscription of ``topic`` (``msg_cls`` None: the
        type the graph lists, or the first published); ``ValueError`` for another type."""
        feed = self.subscriptions.get(topic)
        if feed is None:
            if msg_cls is None:
                listed = self.topic_types(topic)
                msg_cls = self.resolve_message(listed[0]) if listed else None
            feed = self.subscriptions[topic] = MemoryFeed(self, topic, msg_cls)
            if msg_cls is not None:
                self.loop.call_soon(self._catch_up, feed)
        elif msg_cls is not None:
            if feed.msg_cls is None:
                feed.msg_cls = msg_cls
                self.loop.call_soon(self._catch_up, feed)
            elif feed.msg_cls is not msg_cls:
                raise ValueError(f"topic {topic} is already subscribed with type "
                                 f"{feed.type_name}")
        feed.listeners.append(listener)
        return feed

    def _catch_up(self, feed: MemoryFeed) -> None:
        """A new subscription gets the latched publishers' last messages."""
        if self.subscriptions.get(feed.topic) is feed and feed.msg_cls is not None:
            for msg in self.ros.latched(feed.topic, feed.msg_cls):
                feed.deliver(msg, True)

    def unsubscribe(self, shared: Any, listener: Listener) -> None:
        """Remove ``listener``; the subscription goes with its last listener."""
        feed: MemoryFeed = shared
        with contextlib.suppress(ValueError):
            feed.listeners.remove(listener)
        if not feed.listeners and self.subscriptions.get(feed.topic) is feed:
            del self.subscriptions[feed.topic]

    def acquire_publisher(self, topic: str, msg_cls: Any, latch: bool, depth: int
                          ) -> MemoryPublisher:
        """A shared publisher for (topic, type, latch), its reference count raised by one."""
        return acquire_shared(self.publishers, (topic, msg_cls._type, latch),
                              lambda: MemoryPublisher(self, topic, msg_cls, latch, depth))

    def release_publisher(self, pub: Any) -> None:
        """Lower the reference count; the publisher goes with the last reference."""
        mine: MemoryPublisher = pub
        release_shared(self.publishers, (mine.topic, mine.type_name, mine.latch), mine)

    # -- services -------------------------------------------------------------------------------

    async def call_service(
        self, service: str, srv_type: str | None, args: Mapping[str, Any] | list[Any] | None,
        timeout: float, discovery_wait: float,
        check: Callable[[Any], str | None] | None = None,
    ) -> dict[str, Any]:
        """Call ``service`` with the request ``args``; the response as a dict (the rclpy
        Graph's waits and :class:`~rosbridge_core.interfaces.ServiceCallError` texts)."""
        loop = self.loop
        ros = self.ros
        deadline = loop.time() + timeout
        if srv_type is not None:
            srv_cls = self.resolve_service(srv_type)
        else:
            await ros.until(lambda: bool(self.service_types(service)),
                            min(deadline, loop.time() + discovery_wait))
            types = self.service_types(service)
            if not types:
                raise ServiceCallError(f"service {service} does not exist (not in the ROS graph)")
            srv_cls = self.resolve_service(types[0])
        request = service_request(self.converter(srv_cls.Request), service, args, check)
        response = await self._request(service, srv_cls, request, timeout, discovery_wait,
                                       deadline)
        return self.converter(srv_cls.Response).to_obj(response)

    async def _request(self, service: str, srv_cls: Any, request: Any, timeout: float,
                       discovery_wait: float, deadline: float | None = None) -> Any:
        """``request`` to a server of ``service`` and ``srv_cls`` once the graph has one: its
        response message (the waits and texts of :meth:`call_service`)."""
        loop = self.loop
        ros = self.ros
        if deadline is None:
            deadline = loop.time() + timeout

        def server() -> ServiceServer | None:
            return next((s for s in ros.servers.get(service, [])
                         if s.type_name == srv_cls._type), None)

        unlisted_wait = 2 * discovery_wait
        unlisted_by = loop.time() + unlisted_wait
        while (found := server()) is None:
            now = loop.time()
            if now >= unlisted_by and not self.server_count(service):
                raise ServiceCallError(f"service {service} does not exist (not in the ROS graph "
                                       f"after {unlisted_wait:g} s)")
            if now >= deadline:
                if not self.server_count(service):
                    raise ServiceCallError(f"service {service} does not exist (no server "
                                           f"appeared within {timeout} s)")
                raise ServiceCallError(f"service {service} did not become available in "
                                       f"{timeout} s")
            await ros.until(lambda: server() is not None,
                            min(deadline, unlisted_by) if now < unlisted_by else deadline)
        try:
            async with asyncio.timeout_at(deadline):
                return await found.handler(request)
        except TimeoutError:
            raise ServiceCallError(f"service {service} timed out after {timeout} s") from None

    def serve(self, name: str, srv_cls: Any, on_request: Callable[[RosCall], None],
              on_refused: Callable[[str], None] | None = None) -> MemoryServedService:
        """Serve ``name``; each call is handed to ``on_request`` (``on_refused`` is never
        called: ROS refuses no name)."""
        served = MemoryServedService(self, name, srv_cls, on_request)
        self.ros.add_server(served.server)
        return served

    # -- actions --------------------------------------------------------------------------------

    def action_client(self, name: str, action_cls: Any) -> MemoryActionClient:
        """A new client of action ``name``."""
        return MemoryActionClient(self, name, action_cls)

    def serve_action(
        self, name: str, action_cls: Any, on_goal: Callable[[ServedGoal], None],
        on_cancel: Callable[[ServedGoal], None],
        on_refused: Callable[[str], None] | None = None,
    ) -> MemoryServedAction:
        """Serve action ``name``; goals and cancel requests go to the callbacks."""
        served = MemoryServedAction(self, name, action_cls, on_goal, on_cancel)
        self.ros.add_action(served)
        return served
