"""The robot's graph as relays see it: a :class:`~.keys.Snapshot` of its ROS graph.

Moved out of :mod:`.exporter` unchanged: the topics, services and nodes the robot's Graph
sees, with the definition texts and typedefs of their types (learned once per type: they do
not change) and the interfaces installed on the robot (read once: the ament index is files).
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

from bridge_server.zenoh.keys import Snapshot
from rosbridge_core.graph import IntrospectionPort, TypesPort
from rosbridge_core.interfaces import BridgeError
from rosbridge_core.protocol.names import node_path

__all__ = ["GraphSnapshots"]

log = logging.getLogger("bridge_server.zenoh.exporter")


class SnapshotSource(IntrospectionPort, TypesPort, Protocol):
    """What a snapshot reads of the robot's Graph: its name, introspection and types."""

    @property
    def name(self) -> str:
        """The robot bridge's node name."""


class GraphSnapshots:
    """Takes snapshots of ``graph`` for the robot's exporter."""

    def __init__(self, graph: SnapshotSource) -> None:
        self.graph = graph
        self._definitions: dict[str, str] = {}
        self._typedefs: dict[str, list[dict[str, Any]]] = {}
        self._interfaces: list[str] | None = None

    def take(self, served: dict[str, str]) -> Snapshot:
        """The robot's graph now, with the definitions of its types (``served``: the names
        relays' clients serve, by the relay that serves each)."""
        g = self.graph
        topics = sorted(g.topic_names_and_types())
        services = sorted(g.service_names_and_types())
        nodes: dict[str, dict[str, Any]] = {}
        for name, ns in g.node_names():
            try:
                subs, pubs, _srvs = g.node_endpoints(name, ns)
                serves = g.node_services(name, ns)
            except Exception:  # it left meanwhile
                continue
            nodes[node_path(ns, name)] = {
                "name": name, "namespace": ns, "subscribes": sorted(subs),
                "publishes": sorted(pubs), "serves": sorted(serves)}
        for type_name in {t for _, ts in topics for t in ts}:
            self._define(type_name, "msg")
        actions = {t.removesuffix("_SendGoal") for _, ts in services for t in ts
                   if t.endswith("_SendGoal") and "/action/" in t}
        for type_name in {t for _, ts in services for t in ts} - {a + "_SendGoal"
                                                                  for a in actions}:
            self._define(type_name, "srv")
        for type_name in actions:
            self._define(type_name, "action")
        wanted = {t for _, ts in [*topics, *services] for t in ts} | actions
        return Snapshot(
            node=g.name, own_node=g.own_node(), topics=topics, services=services, nodes=nodes,
            publishers={t: [(n, ns, q) for n, ns, q in g.topic_publishers_qos(t)]
                        for t, _ in topics},
            subscribers={t: g.topic_subscribers(t) for t, _ in topics},
            definitions={t: d for t, d in self._definitions.items() if t in wanted and d},
            typedefs={t: d for t, d in self._typedefs.items()
                      if t in wanted or t.rsplit("_", 1)[0] in wanted},
            interfaces=self._installed(),
            served=served)

    def _installed(self) -> list[str]:
        if self._interfaces is None:
            self._interfaces = self.graph.installed_interfaces()
        return self._interfaces

    def _define(self, type_name: str, kind: str) -> None:
        """Learn a type's definition text and typedefs once (they do not change)."""
        if type_name in self._definitions:
            return
        try:
            self._definitions[type_name] = self.graph.interface_definition(type_name)[
                "definition"]
            if kind == "msg":
                self._typedefs[type_name] = self.graph.typedefs(type_name, "msg")
            else:
                parts = ("Request", "Response") if kind == "srv" else ("Goal", "Result",
                                                                       "Feedback")
                for part in parts:
                    self._typedefs[f"{type_name}_{part}"] = self.graph.typedefs(
                        type_name, kind, part)
        except (BridgeError, LookupError, ValueError) as exc:
            self._definitions[type_name] = ""  # not installed here: asked once
            log.debug("no definition of %s: %s", type_name, exc)
