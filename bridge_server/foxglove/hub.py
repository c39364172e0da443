"""What the Foxglove sessions of one bridge share: the channels, the services, the watches.

One :class:`Hub` per bridge follows the ROS graph (through the bridge's
:class:`~rosbridge_core.graph.Graph`, never rclpy) while Foxglove clients are connected:
every :data:`REFRESH_S` seconds it lists topics and services, gives each a stable id
(kept while its topic and type stay the same, as the spec allows clients to cache
schemas by id), and tells every session what appeared and what went. Types whose
definition text the ROS side cannot give are not advertised (logged once).

It also holds the watches several sessions may want at once, each made once: ``/clock``
(the ``time`` op), ``/parameter_events`` (parameter updates) and the connection graph.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from bridge_server.foxglove.ops import Channel
from msgs import cdr, dynamic
from msgs.runtime import Message as MsgsMessage
from msgs.runtime import Service as MsgsService
from msgs.runtime import lookup
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.parameters import PARAMETER_EVENTS, parameter_value

if TYPE_CHECKING:
    from rosbridge_core.graph import Graph, Listener, TopicFeed, TypesPort
    from rosbridge_core.graph import Message as RosMessage

__all__ = ["CLOCK", "REFRESH_S", "GraphState", "Hub", "ServiceEntry", "Viewer", "foxglove_schema",
           "message_class", "service_class"]

log = logging.getLogger("bridge_server.foxglove")

REFRESH_S = 0.5
"""Seconds between two looks at the ROS graph while Foxglove clients are connected."""

CLOCK = "/clock"
"""The topic whose ticks are the ``time`` op (to clients whose role may subscribe it)."""
_CLOCK = struct.Struct("<iI")  # builtin_interfaces/Time after the 4-byte CDR header


def message_class(graph: TypesPort, type_name: str) -> type[MsgsMessage]:
    """The pure-Python class of a message type (generated, or built from the ROS side's
    definition text), for CDR decoding and encoding without rclpy."""
    found: type[MsgsMessage] = _loaded(graph, type_name, MsgsMessage)
    return found


def service_class(graph: TypesPort, type_name: str) -> type[MsgsService]:
    """The pure-Python class of a service type (``.Request``, ``.Response``)."""
    found: type[MsgsService] = _loaded(graph, type_name, MsgsService)
    return found


def _loaded(graph: TypesPort, type_name: str, kind: Any) -> Any:
    """The class from the graph's own store (a relay's robot has its own types)."""
    types = graph.wire_types
    found: Any = None
    with contextlib.suppress(Exception):
        found = types.lookup(type_name)
    if found is None:
        try:
            found = types.load(type_name, graph.interface_definition(type_name)["definition"])
        except BridgeError:
            raise
        except Exception as exc:
            raise BridgeError(f"type {type_name}: its definition cannot be loaded: {exc}"
                              ) from None
    if not (isinstance(found, type) and issubclass(found, kind)):
        raise BridgeError(f"type {type_name} is not a {kind.__name__.lower()} type")
    return found


@dataclass(frozen=True)
class ServiceEntry:
    """A service the Foxglove clients are told of, with its pure-Python classes."""

    id: int
    name: str
    type_name: str
    srv: type[MsgsService]

    def to_json(self) -> dict[str, Any]:
        """The service as ``advertiseServices`` lists it (the ``request``/``response``
        objects, and the older ``requestSchema``/``responseSchema`` beside them)."""
        req = foxglove_schema(dynamic.full_text(self.srv.Request))
        res = foxglove_schema(dynamic.full_text(self.srv.Response))
        return {
            "id": self.id, "name": self.name, "type": self.type_name,
            "request": {"encoding": "cdr", "schemaName": self.srv.Request._type,
                        "schemaEncoding": "ros2msg", "schema": req},
            "response": {"encoding": "cdr", "schemaName": self.srv.Response._type,
                         "schemaEncoding": "ros2msg", "schema": res},
            "requestSchema": req, "responseSchema": res,
        }


@dataclass
class GraphState:
    """Who publishes, subscribes and serves what (the connection graph), by name."""

    published: dict[str, list[str]] = field(default_factory=dict)
    subscribed: dict[str, list[str]] = field(default_factory=dict)
    services: dict[str, list[str]] = field(default_factory=dict)

    def seen_by(self, sees: Callable[[str], bool]) -> GraphState:
        """The graph with only the names ``sees`` lets through: topics and services by their
        names, node ids by theirs (a topic shown keeps its entry when none of its nodes is)."""
        def keep(entries: dict[str, list[str]]) -> dict[str, list[str]]:
            return {k: [n for n in v if sees(n)] for k, v in entries.items() if sees(k)}

        return GraphState(keep(self.published), keep(self.subscribed), keep(self.services))

    def update_since(self, old: GraphState) -> dict[str, Any] | None:
        """The ``connectionGraphUpdate`` fields that bring ``old`` to this (None: same)."""
        pub = [{"name": k, "publisherIds": v} for k, v in self.published.items()
               if old.published.get(k) != v]
        sub = [{"name": k, "subscriberIds": v} for k, v in self.subscribed.items()
               if old.subscribed.get(k) != v]
        srv = [{"name": k, "providerIds": v} for k, v in self.services.items()
               if old.services.get(k) != v]
        gone_topics = sorted((set(old.published) | set(old.subscribed))
                             - (set(self.published) | set(self.subscribed)))
        gone_services = sorted(set(old.services) - set(self.services))
        if not (pub or sub or srv or gone_topics or gone_services):
            return None
        return {"publishedTopics": pub, "subscribedTopics": sub, "advertisedServices": srv,
                "removedTopics": gone_topics, "removedServices": gone_services}


_MSG_LINE = re.compile(r"^MSG: ([a-z][a-z0-9_]*)/msg/", re.MULTILINE)


def foxglove_schema(text: str) -> str:
    """A ``ros2msg`` definition text as Foxglove's parser (``@foxglove/rosmsg``) reads it: each
    dependency introduced as ``MSG: pkg/Name``, the spelling the fields use
    (``std_msgs/Header header``), rather than rosbag2's ``MSG: pkg/msg/Name``, which that
    parser cannot match to the fields."""
    return _MSG_LINE.sub(r"MSG: \1/", text)


def _hidden(name: str) -> bool:
    """Names ROS keeps to itself (an action's parts, ``_``-prefixed tokens)."""
    return any(part.startswith("_") for part in name.split("/"))


class Viewer(Protocol):
    """A Foxglove client as its hub tells it of the graph
    (:class:`~bridge_server.foxglove.session.FoxgloveSession`)."""

    graph_seen: GraphState | None
    """The connection graph it was told of (``None``: it does not follow it)."""
    parameter_names: set[str] | None
    """The parameters it follows (``None``: none; empty: all)."""

    @property
    def wants_graph(self) -> bool:
        """Whether the client follows the connection graph."""

    def graph_changed(self, added: list[Channel], removed: list[Channel],
                      s_added: list[ServiceEntry], s_removed: list[ServiceEntry]) -> None:
        """Channels and services came and went."""

    def show_graph(self, state: GraphState) -> None:
        """The connection graph is now ``state``."""

    def send_time(self, stamp_ns: int) -> None:
        """The ROS clock's time now."""

    def parameters_changed(self, changed: list[tuple[str, Any]]) -> None:
        """Parameters changed in ROS."""


V = TypeVar("V", bound=Viewer)


class Hub(Generic[V]):
    """The Foxglove side of one bridge (see the module's text)."""

    def __init__(self, graph: Graph, graph_changed: Callable[[], None]) -> None:
        self.graph = graph
        self.graph_changed = graph_changed
        self.sessions: set[V] = set()
        self.channels: dict[str, Channel] = {}  # by topic
        self.by_id: dict[int, Channel] = {}
        self.services: dict[str, ServiceEntry] = {}  # by name
        self.services_by_id: dict[int, ServiceEntry] = {}
        self._ids = itertools.count(1)
        self._channel_ids: dict[tuple[str, str], int] = {}  # an id per (topic, type) for good
        self._service_ids: dict[tuple[str, str], int] = {}
        self._schemas: dict[str, str | None] = {}
        self._srv_classes: dict[str, type[MsgsService] | None] = {}
        self._task: asyncio.Task[None] | None = None
        self._wake = asyncio.Event()
        self.clock_ns: int | None = None
        self._watches: dict[str, tuple[TopicFeed, Listener]] = {}
        self.connection_graph = GraphState()

    # -- sessions ------------------------------------------------------------------------------

    def attach(self, session: V) -> None:
        """A new Foxglove client: look at the graph now (what it is offered, ``time`` among
        it, is the graph as it is, not as the last periodic look saw it), and keep looking
        while it stays."""
        self.refresh()
        self.sessions.add(session)
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="foxglove-hub")

    def detach(self, session: V) -> None:
        """The client left; the hub's watches go with the last one that wanted them."""
        self.sessions.discard(session)
        self.update_watches()
        if not self.sessions and self._task is not None:
            self._task.cancel()
            self._task = None

    def poke(self) -> None:
        """Look at the graph soon (a client asked for something that depends on it)."""
        self._wake.set()

    async def _run(self) -> None:
        while True:
            with contextlib.suppress(TimeoutError):  # not wait_for: see Bridge._refresh_loop
                async with asyncio.timeout(REFRESH_S):
                    await self._wake.wait()
            self._wake.clear()
            try:
                self.refresh()
            except Exception:  # the ROS side may be going away; try again next round
                log.exception("looking at the ROS graph for the Foxglove clients failed")

    async def close(self) -> None:
        """Stop following the graph (the bridge is closing)."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
        for topic in list(self._watches):
            self._unwatch(topic)

    # -- the graph -----------------------------------------------------------------------------

    def refresh(self) -> None:
        """Compare the graph with what the clients were told; tell them what changed."""
        topics = self.graph.topic_names_and_types()
        added, removed = self._refresh_channels(topics)
        s_added, s_removed = self._refresh_services()
        if added or removed or s_added or s_removed:
            for session in list(self.sessions):
                session.graph_changed(added, removed, s_added, s_removed)
        self.update_watches({name for name, _ in topics})
        if any(s.wants_graph for s in self.sessions):
            self._refresh_connection_graph(topics)

    def _schema(self, type_name: str) -> str | None:
        if type_name not in self._schemas:
            try:
                text: str | None = foxglove_schema(
                    self.graph.interface_definition(type_name)["definition"])
            except Exception as exc:
                log.warning("topics of type %s are not advertised to Foxglove clients: %s",
                            type_name, exc)
                text = None
            self._schemas[type_name] = text
        return self._schemas[type_name]

    def _refresh_channels(self, topics: list[tuple[str, list[str]]]
                          ) -> tuple[list[Channel], list[Channel]]:
        now: dict[str, Channel] = {}
        for topic, types in topics:
            if not types or _hidden(topic):
                continue
            kept = self.channels.get(topic)
            if kept is not None and kept.schema_name == types[0]:
                now[topic] = kept
                continue
            schema = self._schema(types[0])
            if schema is None:
                continue
            key = (topic, types[0])
            cid = self._channel_ids.setdefault(key, next(self._ids))
            now[topic] = Channel(cid, topic, types[0], schema)
        added = [c for t, c in now.items() if self.channels.get(t) is not c]
        removed = [c for t, c in self.channels.items() if now.get(t) is not c]
        self.channels = now
        self.by_id = {c.id: c for c in now.values()}
        return added, removed

    def _service_class(self, type_name: str) -> type[MsgsService] | None:
        if type_name not in self._srv_classes:
            try:
                found: type[MsgsService] | None = service_class(self.graph, type_name)
            except Exception as exc:
                log.warning("services of type %s are not advertised to Foxglove clients: %s",
                            type_name, exc)
                found = None
            self._srv_classes[type_name] = found
        return self._srv_classes[type_name]

    def _refresh_services(self) -> tuple[list[ServiceEntry], list[ServiceEntry]]:
        now: dict[str, ServiceEntry] = {}
        for name, types in self.graph.service_names_and_types():
            if not types or _hidden(name) or self.graph.server_count(name) == 0:
                continue
            kept = self.services.get(name)
            if kept is not None and kept.type_name == types[0]:
                now[name] = kept
                continue
            srv = self._service_class(types[0])
            if srv is None:
                continue
            sid = self._service_ids.setdefault((name, types[0]), next(self._ids))
            now[name] = ServiceEntry(sid, name, types[0], srv)
        added = [e for n, e in now.items() if self.services.get(n) is not e]
        removed = [e for n, e in self.services.items() if now.get(n) is not e]
        self.services = now
        self.services_by_id = {e.id: e for e in now.values()}
        return added, removed

    def current_graph(self, topics: list[tuple[str, list[str]]] | None = None) -> GraphState:
        """The connection graph now (node names as ids)."""
        graph = self.graph
        state = GraphState()
        for topic, _ in topics if topics is not None else graph.topic_names_and_types():
            pubs = sorted(_node_id(n, ns) for n, ns in graph.topic_publishers(topic))
            subs = sorted(_node_id(n, ns) for n, ns in graph.topic_subscribers(topic))
            if pubs:
                state.published[topic] = pubs
            if subs:
                state.subscribed[topic] = subs
        for name, ns in graph.node_names():
            try:
                served = graph.node_services(name, ns)
            except Exception:  # the node went meanwhile
                continue
            for service, _ in served:
                state.services.setdefault(service, []).append(_node_id(name, ns))
        for providers in state.services.values():
            providers.sort()
        return state

    def follow_graph(self, session: V) -> None:
        """``session`` follows the connection graph: the followers so far hear what changed
        since they were told, and ``session`` hears the whole graph as it is now (each of
        what its role lets it see)."""
        if session.wants_graph:
            return
        self._refresh_connection_graph(self.graph.topic_names_and_types())
        session.graph_seen = GraphState()
        session.show_graph(self.connection_graph)

    def _refresh_connection_graph(self, topics: list[tuple[str, list[str]]]) -> None:
        new = self.current_graph(topics)
        changed, self.connection_graph = new != self.connection_graph, new
        if changed:
            for session in list(self.sessions):
                session.show_graph(new)

    # -- watches (/clock, /parameter_events) -----------------------------------------------------

    def update_watches(self, topics: set[str] | None = None) -> None:
        """Watch ``/clock`` while it is in the graph and ``/parameter_events`` while a client
        follows parameters; stop when that ends."""
        if topics is None:
            topics = set(self._watches)
        wanted = set()
        if self.sessions and CLOCK in topics:
            wanted.add(CLOCK)
        if any(s.parameter_names is not None for s in self.sessions):
            wanted.add(PARAMETER_EVENTS)
        for topic in set(self._watches) - wanted:
            self._unwatch(topic)
        for topic in wanted - set(self._watches):
            self._watch(topic)

    def _watch(self, topic: str) -> None:
        listener = self._on_clock if topic == CLOCK else self._on_parameter_event
        type_name = ("rosgraph_msgs/msg/Clock" if topic == CLOCK
                     else "rcl_interfaces/msg/ParameterEvent")
        try:
            feed = self.graph.subscribe(topic, self.graph.resolve_message(type_name), listener)
        except Exception as exc:
            log.warning("cannot follow %s for the Foxglove clients: %s", topic, exc)
            return
        self._watches[topic] = (feed, listener)
        self.graph_changed()

    def _unwatch(self, topic: str) -> None:
        feed, listener = self._watches.pop(topic)
        self.graph.unsubscribe(feed, listener)

    def _on_clock(self, msg: RosMessage) -> None:
        data = msg.data
        if len(data) < 12:
            return
        sec, nsec = _CLOCK.unpack_from(data, 4)
        self.clock_ns = max(sec, 0) * 1_000_000_000 + nsec
        for session in self.sessions:
            session.send_time(self.clock_ns)

    def _on_parameter_event(self, msg: RosMessage) -> None:
        event_cls = lookup("rcl_interfaces/msg/ParameterEvent")
        assert isinstance(event_cls, type) and issubclass(event_cls, MsgsMessage)
        try:
            event = cdr.decode(msg.data, event_cls)
        except cdr.CdrError as exc:
            log.warning("a /parameter_events message does not decode: %s", exc)
            return
        node = event["node"]
        changed = [(f"{node}.{p['name']}", parameter_value(p["value"]))
                   for p in [*event["new_parameters"], *event["changed_parameters"]]]
        changed += [(f"{node}.{p['name']}", None) for p in event["deleted_parameters"]]
        if changed:
            for session in self.sessions:
                session.parameters_changed(changed)


def _node_id(name: str, namespace: str) -> str:
    return f"{namespace.rstrip('/')}/{name}"
