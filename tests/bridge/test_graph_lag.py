"""The rclpy graph while a server's node name lags behind its endpoints.

DDS announces a server's endpoints before its node's name (``ros_discovery_info``); on a
busy machine the gap is seconds. That state cannot be made on demand with real nodes, so the
graph's node is replaced here by one frozen in it.
"""

from __future__ import annotations

from typing import Any

from bridge_server.rclpy_graph.graph import RclpyGraph

SERVICE = "/fib/_action/send_goal"
TYPE = "example_interfaces/action/Fibonacci_SendGoal"


class _Lagging:
    """An rclpy node whose graph knows a server of SERVICE but not yet its node's name."""

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        return [("bridge", "/")]

    def get_service_names_and_types_by_node(self, name: str, ns: str
                                            ) -> list[tuple[str, list[str]]]:
        return []

    def count_services(self, name: str) -> int:
        return 1 if name == SERVICE else 0

    def get_service_names_and_types(self) -> list[tuple[str, list[str]]]:
        return [(SERVICE, [TYPE]), ("/other", ["std_srvs/srv/Empty"])]


def _graph(node: Any) -> RclpyGraph:
    graph = RclpyGraph.__new__(RclpyGraph)  # no rclpy: only the graph queries are used
    graph.node = node
    return graph


def test_a_server_whose_node_is_not_named_yet_has_its_types() -> None:
    """A server the graph counts has its types before its node's name arrives (a goal sent
    then was refused as "no action server in the ROS graph" on a loaded CI machine)."""
    graph = _graph(_Lagging())
    assert graph.server_types(SERVICE) == [TYPE]
    assert graph.server_types("/other") == [], "a name with no server has no server types"
