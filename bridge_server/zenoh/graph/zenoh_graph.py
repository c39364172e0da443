"""The Graph of one robot on the relay (:class:`ZenohGraph`): its life (the robot's
liveliness, claims and graph documents), its types, and the topics, services and actions its
sessions use, each a part of its own module; introspection, service calls and parameters come
from its mixins (:mod:`.introspection`, :mod:`.queries`). The package's text says how each
maps to Zenoh."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
from collections.abc import Callable
from typing import Any

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.graph.actions import ZenohActionClient, ZenohServedAction
from bridge_server.zenoh.graph.converter import RelayConverter
from bridge_server.zenoh.graph.introspection import SnapshotIntrospection
from bridge_server.zenoh.graph.queries import RobotQueries
from bridge_server.zenoh.graph.robot import NotHolder
from bridge_server.zenoh.graph.services import ZenohServedService
from bridge_server.zenoh.graph.topics import ZenohFeed, ZenohPublisher
from bridge_server.zenoh.inbox import Inbox, direct
from bridge_server.zenoh.keys import Snapshot
from bridge_server.zenoh.typestore import GraphReader, RobotTypes, TypeLimits, let_go
from msgs.dynamic import TypeStore
from msgs.runtime import UnknownTypeError as WireUnknownType
from rosbridge_core.graph import Listener, RosCall, ServedGoal, acquire_shared, release_shared
from rosbridge_core.interfaces import BridgeError, canonical_name

__all__ = ["GONE_WAIT", "SNAPSHOT_WAIT", "ZenohGraph"]

log = logging.getLogger("bridge_server.zenoh.graph")

SNAPSHOT_WAIT = 5.0
"""Seconds a new robot's first graph snapshot is waited for."""

GONE_WAIT = 2.0
"""Seconds a query to the robot that ended unanswered waits for the robot's token to go."""


class ZenohGraph(SnapshotIntrospection, RobotQueries):
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
                f"{r}/{keys.ALIVE}/**", direct(self.on_loop(self._on_alive)), history=True),
            self.session.declare_subscriber(f"{r}/{keys.GRAPH}",
                                            direct(self.inbox.graph(self._on_graph))),
        ]
        self.session.get(f"{r}/{keys.GRAPH}",
                         direct(self.inbox.graph(self._on_graph_reply)))

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
