"""What every ``/rosapi/*`` handler shares: the bridge as rosapi reads it (:class:`BridgeView`),
the error, the tables each part of :mod:`rosbridge_core.session.rosapi` adds its services to,
the request fields, node names, and the services the graph and rosapi list."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from rosbridge_core.interfaces import BridgeError, canonical_name
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.security.names import InvalidNameError, check_name

if TYPE_CHECKING:
    from rosbridge_core.graph import Graph

__all__ = [
    "ASYNC_HANDLERS",
    "FIELDS",
    "HANDLERS",
    "TYPES",
    "AsyncHandler",
    "BridgeView",
    "Handler",
    "Owners",
    "RosapiError",
]


class RosapiError(BridgeError):
    """A rosapi request was invalid (the text says which field and why)."""


class Owners(Protocol):
    """The names the bridge's clients serve, and who serves each
    (:class:`~rosbridge_core.session.ownership.Ownership`)."""

    def __contains__(self, name: object) -> bool:
        """Whether a client serves ``name``."""

    def __iter__(self) -> Iterator[str]:
        """The names served."""

    def get(self, name: str) -> Any:
        """The client's provider serving ``name`` (``None``: none does)."""


class BridgeView(Protocol):
    """What rosapi reads of the bridge (:class:`~rosbridge_core.session.host.Shared` is it
    all): the ROS graph, and the names its clients serve."""

    @property
    def graph(self) -> Graph:
        """The ROS side."""

    @property
    def service_owners(self) -> Owners:
        """The services the bridge's clients serve."""

    @property
    def action_owners(self) -> Owners:
        """The actions the bridge's clients serve."""


Handler = Callable[["BridgeView", Mapping[str, Any]], dict[str, Any]]
AsyncHandler = Callable[["BridgeView", Mapping[str, Any]], Awaitable[dict[str, Any]]]

HANDLERS: dict[str, Handler] = {}
"""Service name -> handler."""

ASYNC_HANDLERS: dict[str, AsyncHandler] = {}
"""Service name -> handler that has to ask ROS nodes (awaited)."""

TYPES: dict[str, str] = {}
"""Service name -> the rosapi_msgs type it is listed with."""

FIELDS: dict[str, tuple[str, ...]] = {}
"""Request field order, for ``args`` given as a list."""


def str_field(args: Mapping[str, Any], name: str) -> str:
    """``args.<name>``, a string; a :class:`RosapiError` naming the field if it is not."""
    if not isinstance(args, Mapping):
        raise RosapiError("args must be an object")
    value = args.get(name)
    if not isinstance(value, str):
        raise RosapiError(f"args: field {name!r} must be a string")
    return value


def topic_field(args: Mapping[str, Any]) -> str:
    """``args.topic`` as a full, valid topic name (relative names are made absolute)."""
    topic = str_field(args, "topic")
    topic = absolute_name(topic)
    try:
        check_name(topic)
    except InvalidNameError as exc:
        raise RosapiError(f"args.topic: {exc}") from None
    return topic


def qualified(name: str, namespace: str) -> str:
    ns = namespace.rstrip("/")
    return f"{ns}/{name}"


def split_node(full: str) -> tuple[str, str]:
    full = absolute_name(full)
    ns, _, name = full.rpartition("/")
    return name, ns or "/"


def own_services() -> list[tuple[str, str]]:
    return sorted((name, TYPES[name]) for name in (*HANDLERS, *ASYNC_HANDLERS))


def all_services(bridge: BridgeView) -> list[tuple[str, str]]:
    """Services that have a server (the graph also lists names that only have clients).

    Servers are counted by service name, never looked up by node name: several nodes may
    share a name (two bridges started with the same ``--node-name``, or any two nodes a
    careless launch file named alike), and a by-node query sees only one of them.
    """
    graph = bridge.graph
    found = {
        (name, types[0] if types else "")
        for name, types in graph.service_names_and_types()
        if graph.server_count(name) > 0
    }
    return sorted(found | set(own_services()))


def msg_type(name: str) -> str:
    try:
        return canonical_name(name, "msg")
    except BridgeError as exc:
        raise RosapiError(str(exc)) from None


def srv_type(name: str) -> str:
    try:
        return canonical_name(name, "srv")
    except BridgeError as exc:
        raise RosapiError(str(exc)) from None


UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def node_names(bridge: BridgeView) -> list[tuple[str, str]]:
    names = bridge.graph.node_names()
    return sorted({(n, ns) for n, ns in names if n != UNKNOWN_NODE})
