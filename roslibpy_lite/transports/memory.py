"""The bridge's part, played by the bridge itself in memory: what
:class:`~roslibpy_lite.mock.MockRos` runs on.

:class:`MemoryTransport` carries the client's ops as frames (their JSON text) to a real
rosbridge session of the bridge (:class:`rosbridge_core.session.session.Session`) over an
in-memory link, and the session's frames back to the client
(:class:`rosbridge_core.memory.server.MemoryServer`); the session's ROS side is a whole ROS
graph in memory (:class:`rosbridge_core.memory.graph.MemoryGraph`). So every answer, refusal
and error text is the bridge's own, and MockRos follows every op the bridge learns.

What a client's op sets off at once (the session's verdict, a message to the subscriptions
of the topic it publishes) reaches the client before :meth:`MemoryTransport.write` returns;
what takes the session longer (a service call, an action goal) comes as it does on a bridge.
A second node of the graph, ``robot``, plays the robot: :meth:`MemoryTransport.inject`
publishes from it.

A client-only install (websockets, no cbor2, no prometheus_client, no rclpy) runs it.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from rosbridge_core.interfaces import BridgeError
from rosbridge_core.memory.graph import MemoryGraph, MemoryRos
from rosbridge_core.memory.server import MemoryConnection, MemoryServer
from rosbridge_core.protocol import ops
from rosbridge_core.protocol.errors import ProtocolError
from rosbridge_core.protocol.frames import Conversation

from ..exceptions import InvalidMessageError, UsageError

if TYPE_CHECKING:
    from rosbridge_core.memory.graph import MemoryMessage, MemoryPublisher

    from .base import Link

__all__ = ["MOCK_NODE", "MemoryTransport"]

MOCK_NODE = "/roslibpy_lite_mock"
"""The bridge's node in MockRos's graph (it publishes, subscribes and serves for the client)."""


class MemoryTransport:
    """A :class:`~roslibpy_lite.transports.base.Transport` to a bridge session in memory
    (module doc). Made on the event loop."""

    url = "memory://mock"
    acks = True

    def __init__(self) -> None:
        self.server = MemoryServer(MemoryGraph(MemoryRos(), MOCK_NODE.lstrip("/")))
        """The in-memory bridge: its sessions, its node of the graph."""
        self.robot: MemoryGraph = self.server.ros.node("robot")
        """The node that plays the robot's side (:meth:`inject`)."""
        self.history: dict[str, list[dict[str, Any]]] = {}
        """What the client published through the bridge, by topic, as it sent it."""
        self.server.ros.taps.append(self._record)
        self._published = False  # the frame being sent published a message in the graph
        self._robot_pubs: dict[tuple[str, str, bool], MemoryPublisher] = {}
        self._frames = Conversation()
        self._conn: MemoryConnection | None = None
        self._link: Link | None = None

    def bind(self, link: Link) -> None:
        """Attach the client."""
        self._link = link

    @property
    def connected(self) -> bool:
        """True between :meth:`open` and :meth:`drop`."""
        return self._conn is not None

    async def start(self) -> None:
        """Open (at once)."""
        self.open()

    def open(self) -> None:
        """Play a (re)connect: a new session, on which the client restores its handles."""
        assert self._link is not None
        self._frames = Conversation()  # fragments cut off with the old link are not completed
        self._conn = self.server.connect(self._deliver, headers={ops.ACKS_HEADER: "1"},
                                         on_close=self._closed)
        self._link.link_up()
        self._conn.flush()

    def drop(self) -> None:
        """Play a dropped connection: the session releases what the client owned."""
        assert self._link is not None
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.drop()
        self._link.link_down()

    def encode(self, op: ops.Op) -> str:
        """The JSON text of ``op`` (a snapshot: later changes to its message do not matter)."""
        return ops.encode(op)

    def write(self, frame: str) -> None:
        """Send one frame to the session; what it answers at once is delivered before this
        returns."""
        if self._conn is None:
            return
        self._published = False
        self._conn.send(frame)
        if self._published:  # a publish the bridge took: kept as the client sent it
            op = json.loads(frame)
            self.history.setdefault(op["topic"], []).append(op["msg"])

    @property
    def backlog(self) -> int:
        """Nothing ever waits."""
        return 0

    async def flush(self) -> None:
        """Nothing to flush."""

    async def close(self) -> None:
        """Stop: the client's session ends as with a close frame, the server goes."""
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.drop(by_client=True)
        await self.server.close()

    # -- the session's side ----------------------------------------------------------------------

    def _deliver(self, frame: str | bytes) -> None:
        """A frame the session wrote: the op it completes goes to the client."""
        try:
            op = self._frames.receive(frame)
        except ProtocolError as exc:  # the bridge sent what its own client cannot read
            raise AssertionError(f"MockRos: the session sent a bad frame: {exc}") from exc
        if op is not None and self._link is not None and self._conn is not None:
            self._link.receive_op(op)

    def _closed(self, code: int, reason: str) -> None:
        """The session closed the link (its gate refused the client, an internal error)."""
        if self._conn is not None and self._link is not None:
            self._conn = None
            self._link.link_down()

    def _record(self, pub: MemoryPublisher, msg: MemoryMessage) -> None:
        if pub.graph is self.server.node:
            self._published = True

    # -- the robot's side ------------------------------------------------------------------------

    def add_node(self, name: str, parameters: Mapping[str, Any] | None = None) -> None:
        """Another node in the graph, ``/ns/name`` (``parameters``: it serves them as an rclpy
        node does)."""
        namespace, _, short = name.rpartition("/")
        self.server.ros.node(short, namespace or "/", parameters=parameters)

    def topic_type(self, topic: str) -> str | None:
        """The type the graph lists for ``topic`` (None: not in the graph)."""
        types = self.server.node.topic_types(topic)
        return types[0] if types else None

    def inject(self, topic: str, type_name: str, msg: Mapping[str, Any], *, latch: bool) -> None:
        """Publish ``msg`` from the robot's node (not recorded in the history); what reaches
        the client's subscriptions is delivered before this returns."""
        known = self.topic_type(topic)
        if known is not None and known != type_name:
            raise UsageError(f"inject: topic {topic} already has type {known}, not {type_name}")
        key = (topic, type_name, latch)
        pub = self._robot_pubs.get(key)
        try:
            if pub is None:
                cls = self.robot.resolve_message(type_name)
                pub = self._robot_pubs[key] = self.robot.acquire_publisher(topic, cls, latch, 10)
            message = pub.conv.from_obj(msg)
        except BridgeError as exc:
            raise InvalidMessageError(f"inject to {topic}: {exc}") from None
        pub.publish(message)
        if self._conn is not None:
            self._conn.flush()
