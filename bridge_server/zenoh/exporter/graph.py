"""The robot's graph offered to relays: its topics, services, nodes and the definitions of
their types (:class:`~bridge_server.zenoh.robot_graph.GraphSnapshots`), put when it changes
and answering queries."""

from __future__ import annotations

import zenoh

from bridge_server.zenoh import keys
from bridge_server.zenoh.exporter.base import ExporterBase, log
from bridge_server.zenoh.keys import Snapshot
from bridge_server.zenoh.link import answering
from bridge_server.zenoh.robot_graph import GraphSnapshots

__all__ = ["GraphOffer"]


class GraphOffer(ExporterBase):
    """The exporter's part that keeps the robot's graph snapshot and offers it."""

    snapshot: Snapshot
    _snapshot_bytes: bytes
    graph_snapshots: GraphSnapshots

    def _answer_graph(self, query: zenoh.Query) -> None:
        with answering(query):
            query.reply(query.key_expr, self._snapshot_bytes, attachment=self.zid.encode())

    def _refresh_snapshot(self) -> None:
        try:
            snap = self._take_snapshot()
        except Exception:  # a graph query failed while a node left: try again next time
            log.debug("the graph snapshot failed", exc_info=True)
            return
        if snap == self.snapshot:  # unchanged: not encoded again (0.3 ms against 30 ms)
            return
        data = snap.encode()
        if data != self._snapshot_bytes and self.session is not None:
            self.snapshot, self._snapshot_bytes = snap, data
            self.session.put(f"{self.robot}/{keys.GRAPH}", data, attachment=self.zid.encode())

    def _take_snapshot(self) -> Snapshot:
        return self.graph_snapshots.take({name: s.relay for name, s in self.served.items()})
