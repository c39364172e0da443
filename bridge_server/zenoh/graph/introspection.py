"""The introspection part of a robot's Graph on the relay (:class:`SnapshotIntrospection`):
the robot's topics, services, nodes and their endpoints, as its latest graph snapshot
(:class:`~bridge_server.zenoh.keys.Snapshot`) lists them, so the sessions' synchronous
questions read a cache."""

from __future__ import annotations

import time
from typing import Any

from bridge_server.zenoh.keys import Snapshot
from rosbridge_core.graph import shared_types
from rosbridge_core.protocol.names import node_path

__all__ = ["SnapshotIntrospection"]


class SnapshotIntrospection:
    """The introspection methods of :class:`~.zenoh_graph.ZenohGraph` (a mixin): each reads
    :attr:`snapshot`, the robot's graph as it last put it."""

    robot: str
    relay: str
    snapshot: Snapshot
    publishers: dict[tuple[str, str, bool], Any]
    """This relay's own publishers to the robot, by (topic, type, latch)."""

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
        node = self.snapshot.nodes.get(node_path(namespace, name))
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
                found.append("the ROS node " + node_path(n["namespace"], n["name"]))
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

