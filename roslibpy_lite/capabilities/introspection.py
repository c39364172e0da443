"""Introspection: what the ROS graph holds and the nodes' parameters, as typed values.

:class:`Introspection` is ``ros.graph`` on every client (the asyncio
:class:`~roslibpy_lite.client.Client`, :class:`~roslibpy_lite.mock.MockRos`,
and, blocking, :mod:`roslibpy_lite.sync`). It asks the bridge's ``/rosapi/*``
services (the bridge answers them from the ROS graph; MockRos's in-memory bridge
answers them from what it holds) and turns the answers into small frozen values::

    for t in await ros.graph.topics():
        print(t.name, t.type)
    node = await ros.graph.node("/talker")      # its publishers, subscribers, services
    speed = await ros.graph.get_param("/talker:speed", default=1.0)

Names not in the graph give ``None`` (:meth:`Introspection.topic_type`) or raise
:class:`~roslibpy_lite.exceptions.ServiceError` saying so (:meth:`Introspection.node`);
a parameter that is not set gives ``default``. Parameter names are ROS 2's
``/node:param``; values are what JSON carries (bool, int, float, str, lists of them).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Awaitable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar, overload

from .._api_types import DEFAULT_CALL_TIMEOUT
from ..exceptions import ServiceError, UsageError

__all__ = ["Caller", "GraphAction", "GraphNode", "GraphService", "GraphTopic", "Introspection",
           "rosapi_type"]

ROSAPI_TYPES = {
    "action_servers": "GetActionServers",
    "get_time": "GetTime",
    "get_ros_version": "GetROSVersion",
}
"""The rosapi service types whose name is not the service's name in CamelCase."""


def rosapi_type(name: str) -> str:
    """The type of ``/rosapi/<name>`` (``topics`` -> ``rosapi_msgs/srv/Topics``)."""
    camel = ROSAPI_TYPES.get(name) or "".join(p.capitalize() for p in name.split("_"))
    return f"rosapi_msgs/srv/{camel}"


@dataclass(frozen=True, slots=True, order=True)
class _Named:
    name: str
    type: str


N = TypeVar("N", bound=_Named)


class GraphTopic(_Named):
    """A topic in the ROS graph (``name``) and its ``type`` (``pkg/msg/Name``)."""

    __slots__ = ()


class GraphService(_Named):
    """A served service (``name``) and its ``type`` (``pkg/srv/Name``)."""

    __slots__ = ()


class GraphAction(_Named):
    """A served action (``name``) and its ``type`` (``pkg/action/Name``)."""

    __slots__ = ()


@dataclass(frozen=True, slots=True, order=True)
class GraphNode:
    """A node (fully qualified name) and the topics and services it uses, each sorted."""

    name: str
    publishers: tuple[str, ...]
    """The topics it publishes."""
    subscribers: tuple[str, ...]
    """The topics it subscribes to."""
    services: tuple[str, ...]
    """The services it serves."""


class Caller(Protocol):
    """What introspection needs of a client: a service call (``RosBase.call_service``)."""

    def call_service(
        self, service: str, type: str, args: Mapping[str, Any] | None = None, *,
        timeout: float | None = DEFAULT_CALL_TIMEOUT,
    ) -> Awaitable[dict[str, Any]]:
        """Call ``service`` and answer its response."""
        ...


class Introspection:
    """The ROS graph and parameters as the bridge sees them (module doc): ``ros.graph``.

    Every method takes ``timeout`` (seconds for each rosapi call; None waits for ever)
    and raises what :meth:`~roslibpy_lite.ros.RosBase.call_service` raises.
    """

    def __init__(self, client: Caller) -> None:
        self._client = client

    async def rosapi(self, name: str, args: Mapping[str, Any] | None = None, *,
                     timeout: float | None = DEFAULT_CALL_TIMEOUT) -> dict[str, Any]:
        """Call ``/rosapi/<name>`` with ``args`` and return its response as it came."""
        return await self._client.call_service(f"/rosapi/{name}", rosapi_type(name), args or {},
                                               timeout=timeout)

    # -- topics, services, actions ---------------------------------------------------------------

    async def topics(self, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[GraphTopic]:
        """Every topic in the graph with its type, sorted by name."""
        reply = await self.rosapi("topics", timeout=timeout)
        pairs = zip(reply["topics"], reply["types"], strict=True)
        return sorted(GraphTopic(str(n), str(t)) for n, t in pairs)

    async def topic_type(self, topic: str, *,
                         timeout: float | None = DEFAULT_CALL_TIMEOUT) -> str | None:
        """The type of ``topic``, or None if the graph does not know it."""
        _check_name(topic, "topic")
        return _found((await self.rosapi("topic_type", {"topic": topic}, timeout=timeout))["type"])

    async def services(self, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[GraphService]:
        """Every served service with its type, sorted by name (the bridge's rosapi too)."""
        return await self._typed(GraphService, "services", "service", timeout)

    async def service_type(self, service: str, *,
                           timeout: float | None = DEFAULT_CALL_TIMEOUT) -> str | None:
        """The type of ``service``, or None if no node serves it."""
        return await self._type_of("service", service, timeout)

    async def actions(self, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[GraphAction]:
        """Every served action with its type, sorted by name."""
        return await self._typed(GraphAction, "action_servers", "action", timeout)

    async def action_type(self, action: str, *,
                          timeout: float | None = DEFAULT_CALL_TIMEOUT) -> str | None:
        """The type of ``action``, or None if no action server serves it."""
        return await self._type_of("action", action, timeout)

    async def _type_of(self, kind: str, name: str, timeout: float | None) -> str | None:
        _check_name(name, kind)
        return _found((await self.rosapi(f"{kind}_type", {kind: name}, timeout=timeout))["type"])

    async def _typed(self, cls: type[N], listing: str, kind: str,
                     timeout: float | None) -> list[N]:
        """``/rosapi/<listing>``'s names, each with its ``<kind>_type``, asked at once; a
        server that went away since the listing is left out."""
        names = (await self.rosapi(listing, timeout=timeout))[listing]
        types = await asyncio.gather(*(self._type_of(kind, n, timeout) for n in names))
        return sorted(cls(str(n), t) for n, t in zip(names, types, strict=True) if t is not None)

    # -- nodes -----------------------------------------------------------------------------------

    async def node_names(self, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[str]:
        """Every node's fully qualified name, sorted."""
        return sorted(str(n) for n in (await self.rosapi("nodes", timeout=timeout))["nodes"])

    async def node(self, name: str, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> GraphNode:
        """What node ``name`` (``/ns/name``) publishes, subscribes to and serves.

        Raises:
            ServiceError: the node is not in the graph (the text says so).
        """
        _check_name(name, "node")
        reply = await self.rosapi("node_details", {"node": name}, timeout=timeout)
        return GraphNode(name, *(tuple(sorted(str(x) for x in reply[key]))
                                for key in ("publishing", "subscribing", "services")))

    async def nodes(self, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[GraphNode]:
        """Every node with its interfaces (:meth:`node` for each, at once), sorted by name;
        a node that left the graph since the listing is left out."""

        async def details(name: str) -> GraphNode | None:
            try:
                return await self.node(name, timeout=timeout)
            except ServiceError:
                return None

        found = await asyncio.gather(*(details(n) for n in await self.node_names(timeout=timeout)))
        return [n for n in found if n is not None]

    # -- parameters ------------------------------------------------------------------------------

    @overload
    async def params(self, node: None = None, *,
                     timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[str]: ...

    @overload
    async def params(self, node: str, *,
                     timeout: float | None = DEFAULT_CALL_TIMEOUT) -> dict[str, Any]: ...

    async def params(self, node: str | None = None, *,
                     timeout: float | None = DEFAULT_CALL_TIMEOUT) -> list[str] | dict[str, Any]:
        """Every parameter's name (``/node:param``), sorted; with ``node``, that node's
        parameters and their values (``{"gain": 0.5}``, by name)."""
        reply = await self.rosapi("get_param_names", timeout=timeout)
        names = sorted(str(n) for n in reply["names"])
        if node is None:
            return names
        _check_name(node, "node")
        prefix = ("/" + node.lstrip("/")) + ":"
        mine = [n for n in names if n.startswith(prefix)]
        values = await asyncio.gather(*(self.get_param(n, timeout=timeout) for n in mine))
        return {n[len(prefix):]: v for n, v in zip(mine, values, strict=True)}

    async def get_param(self, name: str, default: Any = None, *,
                        timeout: float | None = DEFAULT_CALL_TIMEOUT) -> Any:
        """The value of parameter ``name`` (``/node:param``), or ``default`` if it is not set.

        Raises:
            ServiceError: the node does not answer parameter requests, or ``name`` is malformed.
        """
        _check_param(name)
        reply = await self.rosapi("get_param", {"name": name, "default_value": ""},
                                  timeout=timeout)
        text = reply.get("value", "")
        return default if text == "" else json.loads(text)

    async def set_param(self, name: str, value: Any, *,
                        timeout: float | None = DEFAULT_CALL_TIMEOUT) -> None:
        """Set parameter ``name`` (``/node:param``) to ``value``.

        Raises:
            UsageError: ``value`` is not something JSON (and so a parameter) can carry.
            ServiceError: the node refused the value (a parameter of another type, say).
        """
        _check_param(name)
        try:
            text = json.dumps(value, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise UsageError(f"set_param {name}: {exc}") from None
        await self.rosapi("set_param", {"name": name, "value": text}, timeout=timeout)

    async def has_param(self, name: str, *, timeout: float | None = DEFAULT_CALL_TIMEOUT) -> bool:
        """Whether parameter ``name`` (``/node:param``) is set."""
        _check_param(name)
        return bool((await self.rosapi("has_param", {"name": name}, timeout=timeout))["exists"])

    async def delete_param(self, name: str, *,
                           timeout: float | None = DEFAULT_CALL_TIMEOUT) -> None:
        """Unset parameter ``name`` (``/node:param``); ServiceError if the node refuses."""
        _check_param(name)
        await self.rosapi("delete_param", {"name": name}, timeout=timeout)


def _found(type_name: Any) -> str | None:
    return str(type_name) or None


def _check_name(name: Any, kind: str) -> None:
    if not isinstance(name, str) or not name:
        raise UsageError(f"a {kind} name must be a non-empty string, got {name!r}")


def _check_param(name: Any) -> None:
    _check_name(name, "parameter")
    node, sep, param = name.partition(":")
    if not sep or not node or not param:
        raise UsageError(f"parameter name {name!r}: expected '/node:param' (ROS 2 parameters "
                         "belong to a node)")
