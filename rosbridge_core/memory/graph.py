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

Nothing here imports rclpy, cbor2 (only :meth:`MsgsConverter.to_cbor_obj` does, when a
client asks for CBOR), prometheus_client or pybase64: a client-only install runs it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
import time
from collections.abc import Awaitable, Callable, Mapping
from typing import Any

from msgs import cdr, dynamic
from msgs.runtime import Action, Message, Service
from msgs.runtime import UnknownTypeError as WireUnknownType
from rosbridge_core.codec.encodings import EncodedMessage
from rosbridge_core.codec.msgs_types import MsgsConverter
from rosbridge_core.graph import (
    ACTIVE,
    GoalListener,
    Listener,
    RosCall,
    ServedGoal,
    Status,
    acquire_shared,
    parameter_value,
    release_shared,
    service_request,
    shared_types,
)
from rosbridge_core.interfaces import (
    BridgeError,
    ServiceCallError,
    UnknownTypeError,
    canonical_name,
    parse_type_name,
)

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

log = logging.getLogger("bridge_server.memory.graph")

Handler = Callable[[Any], Awaitable[Any]]
"""How a server answers a request message: with its response message (or raises)."""

_ACTION_SERVICES = {"send_goal": "_SendGoal", "cancel_goal": None, "get_result": "_GetResult"}
_CANCEL_TYPE = "action_msgs/srv/CancelGoal"


class MemoryMessage(EncodedMessage):
    """One message published in memory, encoded for clients lazily and once per encoding."""

    __slots__ = ("conv", "msg")

    def __init__(self, topic: str, msg: Message, conv: MsgsConverter) -> None:
        super().__init__(topic, cdr.encode(msg), time.time_ns())
        self.msg = msg
        self.conv = conv

    def message_json(self) -> str:
        """The message as JSON text."""
        return self.conv.to_json(self.msg)

    def cbor_obj(self) -> Any:
        """The message as a CBOR-ready object."""
        return self.conv.to_cbor_obj(self.msg)


class MemoryFeed:
    """A node's one subscription to a topic, shared by its listeners."""

    def __init__(self, graph: MemoryGraph, topic: str, msg_cls: type[Message] | None) -> None:
        self.graph = graph
        self.topic = topic
        self.msg_cls = msg_cls
        self.received = 0
        self.listeners: list[Listener] = []
        self._latched: MemoryMessage | None = None

    @property
    def latched(self) -> MemoryMessage | None:
        """The last message of a latched topic, for a late subscriber."""
        return self._latched

    @property
    def type_name(self) -> str | None:
        """Canonical type of the topic, once known."""
        return self.msg_cls._type if self.msg_cls is not None else None

    def deliver(self, msg: MemoryMessage, latched: bool) -> None:
        """Hand ``msg`` to every listener, in order; one that raises is logged and the others
        still get it (as the rclpy Graph's executor goes on)."""
        self.received += 1
        if latched:
            self._latched = msg
        for listener in list(self.listeners):
            try:
                listener(msg)
            except Exception:
                log.exception("a listener of %s failed on a message", self.topic)


class MemoryPublisher:
    """A node's publisher of (topic, type, latch), shared by reference count."""

    def __init__(self, graph: MemoryGraph, topic: str, msg_cls: type[Message], latch: bool,
                 depth: int) -> None:
        self.graph = graph
        self.topic = topic
        self.latch = latch
        self.depth = depth
        self.refs = 0
        self.conv = graph.converter(msg_cls)
        self.last: MemoryMessage | None = None
        """The last message, kept for late subscribers when latched."""

    @property
    def type_name(self) -> str:
        """Canonical message type."""
        return self.conv.type_name

    def publish(self, msg: Any) -> None:
        """Publish one message (a ``msgs`` instance, or its CDR bytes) to every subscription
        of the topic and type in the graph, before returning."""
        if isinstance(msg, bytes | bytearray):
            msg = self.conv.cls.from_json(cdr.decode(bytes(msg), self.conv.cls))
        sent = MemoryMessage(self.topic, msg, self.conv)
        if self.latch:
            self.last = sent
        for tap in self.graph.ros.taps:
            tap(self, sent)
        for feed in self.graph.ros.feeds(self.topic, self.conv.cls):
            feed.deliver(sent, self.latch)


class _Server:
    """A service in the graph: its node, type and how it answers."""

    def __init__(self, node: MemoryGraph, name: str, type_name: str, handler: Handler) -> None:
        self.node = node
        self.name = name
        self.type_name = type_name
        self.handler = handler


class MemoryRosCall:
    """A caller waiting for a service a session serves."""

    def __init__(self, served: MemoryServedService, request: Any,
                 answer: asyncio.Future[Any]) -> None:
        self.served = served
        self.request = request
        self._answer = answer

    def complete(self, response: Any | None = None) -> bool:
        """Answer the caller (``None``: a default response); False if already answered."""
        if self._answer.done():
            return False
        self._answer.set_result(response if response is not None
                                else self.served.srv_cls.Response())
        return True


class MemoryServedService:
    """A service of the graph whose calls go to ``on_request``."""

    def __init__(self, graph: MemoryGraph, name: str, srv_cls: type[Service],
                 on_request: Callable[[RosCall], None]) -> None:
        self.graph = graph
        self.name = name
        self.srv_cls = srv_cls
        self.request_conv = graph.converter(srv_cls.Request)
        self.response_conv = graph.converter(srv_cls.Response)
        self.on_request = on_request
        self.server = _Server(graph, name, srv_cls._type, self._answer)

    async def _answer(self, request: Any) -> Any:
        answer: asyncio.Future[Any] = self.graph.loop.create_future()
        self.on_request(MemoryRosCall(self, request, answer))
        return await answer

    def destroy(self) -> None:
        """Remove the service from the graph (a call in flight stays unanswered)."""
        self.graph.ros.remove_server(self.server)


class _Handle:
    """A goal's id as the sessions read it (``handle.goal_id.uuid``)."""

    def __init__(self, uuid: bytes) -> None:
        self.goal_id = self
        self.uuid = uuid


class MemorySentGoal:
    """A goal sent through a :class:`MemoryActionClient`."""

    def __init__(self, shared: MemoryActionClient, listener: GoalListener,
                 feedback: bool) -> None:
        self.shared = shared
        self.listener = listener
        self.feedback = feedback
        self.handle: _Handle | None = None
        self.served: MemoryServedGoal | None = None
        self.cancel_wanted = False

    def cancel(self) -> None:
        """Ask the server to cancel the goal (before or after it was accepted)."""
        self.cancel_wanted = True
        served = self.served
        if served is not None and served.status in ACTIVE:
            self.listener.on_cancel_answer(served.served.cancel(served))


class MemoryActionClient:
    """A client of one action (of one type) in the graph."""

    def __init__(self, graph: MemoryGraph, name: str, action_cls: type[Action]) -> None:
        self.graph = graph
        self.name = name
        self.action_cls = action_cls
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)

    def _server(self) -> MemoryServedAction | None:
        return next((a for a in self.graph.ros.actions.get(self.name, [])
                     if a.action_cls is self.action_cls and a.alive), None)

    def matched(self) -> bool:
        """Whether a server of the action and its type is in the graph."""
        return self._server() is not None

    def ready(self) -> bool:
        """As :meth:`matched`: a goal sent now reaches it."""
        return self.matched()

    def send(self, goal: Any, listener: GoalListener, feedback: bool) -> MemorySentGoal:
        """Send ``goal``; it is accepted (or fails: no server) on the loop's next turn."""
        sent = MemorySentGoal(self, listener, feedback)
        self.graph.loop.call_soon(self._deliver, sent, goal)
        return sent

    def _deliver(self, sent: MemorySentGoal, goal: Any) -> None:
        server = self._server()
        if server is None:
            sent.listener.on_failed(f"action {self.name} has no action server in the graph")
            return
        server.take(goal, sent)

    def destroy(self) -> None:
        """Nothing to remove: each goal holds its own way back."""


class MemoryServedGoal:
    """A goal of an action a session serves."""

    def __init__(self, served: MemoryServedAction, request: Any, uuid: bytes,
                 sent: MemorySentGoal | None) -> None:
        self.served = served
        self.request = request
        self.uuid = uuid
        self.sent = sent
        self.stamp_ns = time.time_ns()
        self.status = Status.EXECUTING
        self.result: asyncio.Future[tuple[int, Any]] = served.graph.loop.create_future()

    def feedback(self, msg: Any) -> None:
        """One feedback message to the goal's client (if it asked for feedback)."""
        sent = self.sent
        if self.status in ACTIVE and sent is not None and sent.feedback:
            sent.listener.on_feedback(msg)

    def finish(self, status: int, result: Any | None = None) -> bool:
        """End the goal with ``status`` (``None`` result: default values); False if it had
        ended."""
        if self.status not in ACTIVE:
            return False
        self.status = Status(status)
        result = result if result is not None else self.served.action_cls.Result()
        self.served.goals.pop(self.uuid, None)
        self.result.set_result((int(status), result))
        if self.sent is not None:
            self.sent.listener.on_result(int(status), result)
        return True


class MemoryServedAction:
    """An action of the graph whose goals and cancel requests go to the callbacks; every
    goal is accepted while it is served, every cancel request too."""

    def __init__(self, graph: MemoryGraph, name: str, action_cls: type[Action],
                 on_goal: Callable[[ServedGoal], None],
                 on_cancel: Callable[[ServedGoal], None]) -> None:
        self.graph = graph
        self.name = name
        self.action_cls = action_cls
        self.goal_conv = graph.converter(action_cls.Goal)
        self.feedback_conv = graph.converter(action_cls.Feedback)
        self.result_conv = graph.converter(action_cls.Result)
        self.on_goal = on_goal
        self.on_cancel = on_cancel
        self.alive = True
        self.goals: dict[bytes, MemoryServedGoal] = {}
        base = f"{name}/_action/"
        self.servers = [
            _Server(graph, base + "cancel_goal", _CANCEL_TYPE, self._cancel_service),
            *(_Server(graph, base + part, action_cls._type + suffix, self._internal)
              for part, suffix in _ACTION_SERVICES.items() if suffix is not None),
        ]

    def take(self, goal: Any, sent: MemorySentGoal | None) -> MemoryServedGoal:
        """A goal accepted: handed to ``on_goal`` (a cancel asked before it came follows)."""
        uuid = secrets.token_bytes(16)
        served = self.goals[uuid] = MemoryServedGoal(self, goal, uuid, sent)
        if sent is not None:
            sent.served = served
            sent.handle = _Handle(uuid)
            sent.listener.on_accepted()
        self.on_goal(served)
        if sent is not None and sent.cancel_wanted:
            sent.cancel()
        return served

    def cancel(self, goal: MemoryServedGoal) -> int:
        """A cancel request for ``goal``: ``CancelGoal`` return code (0: canceling)."""
        if goal.status not in ACTIVE:
            return 3
        if goal.status != Status.CANCELING:
            goal.status = Status.CANCELING
            self.on_cancel(goal)
        return 0

    async def _cancel_service(self, request: Any) -> Any:
        """``<action>/_action/cancel_goal``: action_msgs' policy by goal id and stamp."""
        info = request.goal_info
        uuid = bytes(info.goal_id.uuid)
        stamp = info.stamp.sec * 1_000_000_000 + info.stamp.nanosec
        if any(uuid):
            picked = [g for g in [self.goals.get(uuid)] if g is not None]
            if not picked:
                return _cancel_response(self, 2, [])
        else:
            picked = [g for g in self.goals.values() if not stamp or g.stamp_ns <= stamp]
        canceling = [g for g in picked if self.cancel(g) == 0]
        for g in canceling:
            if g.sent is not None:
                g.sent.listener.on_cancel_answer(0)
        return _cancel_response(self, 0 if canceling or not any(uuid) else 3, canceling)

    async def _internal(self, request: Any) -> Any:
        raise ServiceCallError(f"{self.name}: the in-memory graph answers only cancel_goal of "
                               "an action's services as a service (send goals as goals)")

    def destroy(self) -> None:
        """Remove the action server; open goals are aborted."""
        self.alive = False
        for goal in list(self.goals.values()):
            goal.finish(Status.ABORTED)
        self.graph.ros.remove_action(self)


def _cancel_response(action: MemoryServedAction, code: int,
                     goals: list[MemoryServedGoal]) -> Any:
    cls = action.graph.resolve_service(_CANCEL_TYPE).Response
    return cls.from_json({"return_code": code, "goals_canceling": [
        {"goal_id": {"uuid": list(g.uuid)},
         "stamp": {"sec": g.stamp_ns // 1_000_000_000, "nanosec": g.stamp_ns % 1_000_000_000}}
        for g in goals]})


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
        self.servers: dict[str, list[_Server]] = {}
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

    def add_server(self, server: _Server) -> None:
        """A service comes into the graph."""
        self.servers.setdefault(server.name, []).append(server)
        self._change()

    def remove_server(self, server: _Server) -> None:
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


class MemoryGraph:
    """One node of a :class:`MemoryRos` as the sessions see it (the
    :class:`~rosbridge_core.graph.Graph` port; see the module's text).

    ``parameters``: the node's parameters, served as an rclpy node serves them (``None``: the
    node has no parameter services, as the bridge's own node): these are declared (their type
    is kept, they cannot be unset); others may be set and unset freely. Methods run on the
    loop.
    """

    wire_types: dynamic.TypeStore = dynamic.DEFAULT
    """The ``msgs`` classes of the graph's types."""

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
            self._serve_parameters()

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

    # -- types ----------------------------------------------------------------------------------

    def _load(self, name: str, kind: str) -> Any:
        canonical = canonical_name(name, kind)  # type: ignore[arg-type]
        types = self.wire_types
        try:
            return {"msg": types.lookup_message, "srv": types.lookup_service,
                    "action": types.lookup_action}[kind](canonical)
        except WireUnknownType:
            raise UnknownTypeError(name, f"no installed package provides {canonical}") from None

    def resolve_message(self, name: str) -> Any:
        """The ``msgs`` class of message type ``name`` (both spellings)."""
        return self._load(name, "msg")

    def resolve_service(self, name: str) -> Any:
        """The ``msgs`` service type named ``name``."""
        return self._load(name, "srv")

    def resolve_action(self, name: str) -> Any:
        """The ``msgs`` action type named ``name``."""
        return self._load(name, "action")

    def converter(self, cls: Any) -> MsgsConverter:
        """The converter of a ``msgs`` message class."""
        conv = self._converters.get(cls)
        if conv is None:
            conv = self._converters[cls] = MsgsConverter(cls)
        return conv

    def typedefs(self, name: str, kind: str, part: str | None = None) -> list[dict[str, Any]]:
        """rosapi typedefs of a type (``part`` of a service or action) and its nested types."""
        from rosbridge_core.typedefs import msgs_typedefs

        cls = self._load(name, kind)
        canonical = canonical_name(name, kind)  # type: ignore[arg-type]
        if kind != "msg":
            cls, canonical = getattr(cls, part or ""), f"{canonical}_{part}"
        return msgs_typedefs(cls, canonical)

    def installed_interfaces(self) -> list[str]:
        """Every type ``msgs`` generates."""
        from msgs.runtime import available_types

        return available_types()

    def interface_definition(self, name: str) -> dict[str, Any]:
        """The full definition text of a type ``msgs`` has (the ``ros2msg`` layout)."""
        try:
            tn = next(t for t in (_parsed(name, k) for k in ("msg", "srv", "action"))
                      if t is not None and _has(self.wire_types, str(t)))
        except StopIteration:
            raise BridgeError(f"type: {name} is not installed on the robot (msgs has no "
                              "such type)") from None
        cls = self._load(str(tn), tn.kind)
        if tn.kind == "msg":
            return {"type": str(tn), "definition": dynamic.full_text(cls)}
        parts = ((cls.Request, cls.Response) if tn.kind == "srv"
                 else (cls.Goal, cls.Result, cls.Feedback))
        text = cls._definition.rstrip("\n") + "\n"
        seen = {p._type for p in parts}
        for part in parts:
            for dep in dynamic.full_text(part).split(dynamic.DELIMITER + "\n")[1:]:
                head = dep.split("\n", 1)[0]
                if head not in seen:
                    seen.add(head)
                    text += dynamic.DELIMITER + "\n" + dep
        return {"type": str(tn), "definition": text}

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
        return ["the ROS node " + s.node.namespace.rstrip("/") + "/" + s.node.name
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

        def server() -> _Server | None:
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

    # -- parameters -----------------------------------------------------------------------------

    def _serve_parameters(self) -> None:
        base = self.namespace.rstrip("/") + "/" + self.name
        for part, handler in (("list_parameters", self._list_parameters),
                              ("get_parameters", self._get_parameters),
                              ("set_parameters", self._set_parameters)):
            kind = "".join(w.capitalize() for w in part.split("_"))
            self.ros.add_server(_Server(self, f"{base}/{part}", f"rcl_interfaces/srv/{kind}",
                                        handler))

    def _params(self) -> dict[str, Any]:
        assert self.parameters is not None
        return self.parameters

    async def _list_parameters(self, request: Any) -> Any:
        cls = self.resolve_service("rcl_interfaces/srv/ListParameters").Response
        return cls.from_json({"result": {"names": sorted(self._params())}})

    async def _get_parameters(self, request: Any) -> Any:
        cls = self.resolve_service("rcl_interfaces/srv/GetParameters").Response
        params = self._params()
        return cls.from_json({"values": [parameter_obj(params.get(n)) for n in request.names]})

    async def _set_parameters(self, request: Any) -> Any:
        """Each parameter set as an rclpy node sets it: one the node was made with (declared)
        keeps its type and cannot be unset (rclpy's refusals); others may be anything."""
        cls = self.resolve_service("rcl_interfaces/srv/SetParameters").Response
        params = self._params()
        results = []
        for p in request.parameters:
            value = parameter_value(p.value)
            old = params.get(p.name) if p.name in self._declared else None
            old_type, new_type = _parameter_type(old), int(p.value.type)
            if old is not None and value is None:
                results.append({"successful": False,
                                "reason": "Static parameter cannot be undeclared"})
            elif old is not None and old_type != new_type:
                results.append({"successful": False, "reason": (
                    f"Wrong parameter type, expected 'Type.{_TYPE_NAMES[old_type]}' got "
                    f"'Type.{_TYPE_NAMES[new_type]}'")})
            else:
                if value is None:
                    params.pop(p.name, None)
                else:
                    params[p.name] = value
                results.append({"successful": True, "reason": ""})
        return cls.from_json({"results": results})

    async def _parameter_call(self, node: str, part: str, args: Mapping[str, Any],
                              timeout: float) -> Any:
        """The answer of ``node``'s parameter service ``part`` (as an rclpy node's):
        ``LookupError`` if the node has none, ``TimeoutError`` if it does not answer."""
        service = f"{node}/{part}"
        kind = "".join(w.capitalize() for w in part.split("_"))
        srv_cls = self.resolve_service(f"rcl_interfaces/srv/{kind}")
        try:
            return await self._request(service, srv_cls, srv_cls.Request.from_json(args),
                                       timeout, timeout / 2)
        except ServiceCallError as exc:
            if self.server_count(service):
                raise TimeoutError(f"service {service} did not answer") from exc
            raise LookupError(f"service {service} does not exist (not in the ROS graph)"
                              ) from None

    async def parameter_names(self, node: str, timeout: float) -> list[str]:
        """Names of ``node``'s parameters (any failure raises)."""
        answer = await self._parameter_call(node, "list_parameters", {}, timeout)
        return list(answer.result.names)

    async def get_parameter(self, node: str, name: str) -> tuple[bool, Any]:
        """(is set, value) of one parameter of ``node``."""
        answer = await self._parameter_call(node, "get_parameters", {"names": [name]},
                                            PARAM_WAIT)
        values = answer.values
        if not values or values[0].type == 0:
            return False, None
        return True, parameter_value(values[0])

    async def set_parameter(self, node: str, name: str, value: Any) -> tuple[bool, str]:
        """Set (``None``: unset) one parameter of ``node``: (accepted, reason); ``ValueError``
        for a value a parameter cannot hold."""
        param = {"name": name, "value": parameter_obj(value)}
        answer = await self._parameter_call(node, "set_parameters", {"parameters": [param]},
                                            PARAM_WAIT)
        result = answer.results[0]
        return bool(result.successful), str(result.reason)

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


PARAM_WAIT = 5.0
"""Seconds a parameter get or set waits for the node's parameter service."""


def parameter_obj(value: Any) -> dict[str, Any]:
    """A plain value as a ``rcl_interfaces/msg/ParameterValue`` object (``None``: not set;
    ``bytes``: a byte array); ``ValueError`` for what a parameter cannot hold."""
    if value is None:
        return {"type": 0}
    for kind, field, test in _PARAMETER_KINDS:
        if test(value):
            if kind == 5:
                return {"type": 5, field: list(value)}
            return {"type": kind, field: [float(v) for v in value] if kind == 8 else value}
    raise ValueError("args.value: a ROS 2 parameter is a bool, int, float, string or a list "
                     f"of one of those, got {type(value).__name__}")


def _parameter_type(value: Any) -> int:
    """The ``ParameterType`` number of a plain value (0: not set)."""
    return int(parameter_obj(value)["type"])


_TYPE_NAMES = ("NOT_SET", "BOOL", "INTEGER", "DOUBLE", "STRING", "BYTE_ARRAY", "BOOL_ARRAY",
               "INTEGER_ARRAY", "DOUBLE_ARRAY", "STRING_ARRAY")
"""rclpy's ``Parameter.Type`` names, by number."""


def _all(kind: type | tuple[type, ...]) -> Callable[[Any], bool]:
    return lambda v: isinstance(v, list) and all(isinstance(x, kind) for x in v)


_PARAMETER_KINDS: tuple[tuple[int, str, Callable[[Any], bool]], ...] = (
    (1, "bool_value", lambda v: isinstance(v, bool)),
    (2, "integer_value", lambda v: isinstance(v, int)),
    (3, "double_value", lambda v: isinstance(v, float)),
    (4, "string_value", lambda v: isinstance(v, str)),
    (5, "byte_array_value", lambda v: isinstance(v, bytes | bytearray)),
    (6, "bool_array_value", _all(bool)),
    (7, "integer_array_value", _all(int)),
    (8, "double_array_value", _all((int, float))),
    (9, "string_array_value", _all(str)),
)


def _parsed(name: str, kind: str) -> Any:
    try:
        return parse_type_name(name, kind)  # type: ignore[arg-type]
    except BridgeError:
        return None


def _has(types: dynamic.TypeStore, name: str) -> bool:
    try:
        types.lookup(name)
    except WireUnknownType:
        return False
    return True
