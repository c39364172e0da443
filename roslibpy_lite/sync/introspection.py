"""``ros.graph`` on the blocking client: :class:`Graph`, the asyncio
:class:`~roslibpy_lite.capabilities.introspection.Introspection` without ``await``::

    with sync.connect(URL) as ros:
        for t in ros.graph.topics():
            print(t.name, t.type)
        ros.graph.set_param("/talker:speed", 2.0)
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, overload

from .._api_types import DEFAULT_CALL_TIMEOUT

if TYPE_CHECKING:
    from ..capabilities.introspection import (
        GraphAction,
        GraphNode,
        GraphService,
        GraphTopic,
        Introspection,
    )
    from .loop import LoopThread

__all__ = ["Graph"]

Timeout = float | None


class Graph:
    """The ROS graph and parameters, blocking (each method as its asyncio twin's)."""

    def __init__(self, loop: LoopThread, aio: Introspection) -> None:
        self._loop = loop
        self.aio = aio
        """The asyncio introspection underneath (use it from the loop thread only)."""

    def topics(self, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[GraphTopic]:
        """Every topic in the graph with its type, sorted by name."""
        return self._loop.run(self.aio.topics(timeout=timeout), "graph.topics")

    def topic_type(self, topic: str, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> str | None:
        """The type of ``topic``, or None if the graph does not know it."""
        return self._loop.run(self.aio.topic_type(topic, timeout=timeout), "graph.topic_type")

    def services(self, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[GraphService]:
        """Every served service with its type, sorted by name."""
        return self._loop.run(self.aio.services(timeout=timeout), "graph.services")

    def service_type(self, service: str, *,
                     timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> str | None:
        """The type of ``service``, or None if no node serves it."""
        return self._loop.run(self.aio.service_type(service, timeout=timeout),
                              "graph.service_type")

    def actions(self, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[GraphAction]:
        """Every served action with its type, sorted by name."""
        return self._loop.run(self.aio.actions(timeout=timeout), "graph.actions")

    def action_type(self, action: str, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> str | None:
        """The type of ``action``, or None if no action server serves it."""
        return self._loop.run(self.aio.action_type(action, timeout=timeout), "graph.action_type")

    def node_names(self, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[str]:
        """Every node's fully qualified name, sorted."""
        return self._loop.run(self.aio.node_names(timeout=timeout), "graph.node_names")

    def node(self, name: str, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> GraphNode:
        """What node ``name`` publishes, subscribes to and serves (ServiceError if unknown)."""
        return self._loop.run(self.aio.node(name, timeout=timeout), "graph.node")

    def nodes(self, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[GraphNode]:
        """Every node with its interfaces, sorted by name."""
        return self._loop.run(self.aio.nodes(timeout=timeout), "graph.nodes")

    @overload
    def params(self, node: None = None, *,
               timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[str]: ...

    @overload
    def params(self, node: str, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> dict[str, Any]: ...

    def params(self, node: str | None = None, *,
               timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> list[str] | dict[str, Any]:
        """Every parameter's name (``/node:param``); with ``node``, its parameters' values
        by name."""
        if node is None:
            return self._loop.run(self.aio.params(timeout=timeout), "graph.params")
        return self._loop.run(self.aio.params(node, timeout=timeout), f"graph.params {node}")

    def get_param(self, name: str, default: Any = None, *,
                  timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> Any:
        """The value of parameter ``name`` (``/node:param``), or ``default`` if it is not set."""
        return self._loop.run(self.aio.get_param(name, default, timeout=timeout),
                              "graph.get_param")

    def set_param(self, name: str, value: Any, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> None:
        """Set parameter ``name`` to ``value`` (ServiceError if the node refuses)."""
        self._loop.run(self.aio.set_param(name, value, timeout=timeout), "graph.set_param")

    def has_param(self, name: str, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> bool:
        """Whether parameter ``name`` is set."""
        return self._loop.run(self.aio.has_param(name, timeout=timeout), "graph.has_param")

    def delete_param(self, name: str, *, timeout: Timeout = DEFAULT_CALL_TIMEOUT) -> None:
        """Unset parameter ``name`` (ServiceError if the node refuses)."""
        self._loop.run(self.aio.delete_param(name, timeout=timeout), "graph.delete_param")
