"""The bridge's ``/rosapi/*`` services, played in memory (for :class:`~.memory.MemoryTransport`).

The in-memory bridge answers the introspection services a real bridge answers
from the ROS graph (``bridge_server/session/rosapi.py``), from what it holds:
the topics it has seen (advertised, subscribed or injected), the services and
actions served through it, and a parameter store. Its graph has one node,
:data:`MOCK_NODE` (a bridge's own node publishes, subscribes and serves for its
clients), plus each node named by a parameter. Answers have the real bridge's
fields and its errors' words, so code (and ``ros.graph``) reads both alike.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from ..capabilities.introspection import rosapi_type

__all__ = ["MOCK_NODE", "MemoryRosapi", "RosapiRefusal"]

MOCK_NODE = "/roslibpy_lite_mock"
"""The node that publishes, subscribes and serves for MockRos's client."""


class RosapiRefusal(Exception):
    """A rosapi request the bridge answers with ``result: false`` (the text says why)."""


class _HeldTopic(Protocol):
    @property
    def type_name(self) -> str: ...
    @property
    def sub_ids(self) -> Mapping[Any, None]: ...
    @property
    def advertised(self) -> bool: ...


class _HeldActions(Protocol):
    @property
    def served(self) -> Mapping[str, tuple[str, str]]: ...


class Held(Protocol):
    """What the in-memory bridge (:class:`~.memory.MemoryTransport`) holds, as its rosapi
    answers read it (a protocol, so this module does not import the transport's)."""

    @property
    def topics(self) -> Mapping[str, _HeldTopic]:
        """Topics by name."""

    @property
    def services(self) -> Mapping[str, str]:
        """Served services' types by name."""

    @property
    def actions(self) -> _HeldActions:
        """Served actions."""


class MemoryRosapi:
    """The ``/rosapi/*`` answers of one in-memory bridge (module doc)."""

    def __init__(self, bridge: Held) -> None:
        self.bridge = bridge
        self.params: dict[str, Any] = {}
        """The parameter store: ``/node:param`` -> value (what JSON carries)."""
        self._handlers: dict[str, Callable[[Mapping[str, Any]], dict[str, Any]]] = {
            "/rosapi/topics": self._topics,
            "/rosapi/topic_type": self._topic_type,
            "/rosapi/services": self._services,
            "/rosapi/service_type": self._service_type,
            "/rosapi/action_servers": self._action_servers,
            "/rosapi/action_type": self._action_type,
            "/rosapi/nodes": self._nodes,
            "/rosapi/node_details": self._node_details,
            "/rosapi/get_param_names": self._param_names,
            "/rosapi/get_param": self._get_param,
            "/rosapi/has_param": self._has_param,
            "/rosapi/set_param": self._set_param,
            "/rosapi/delete_param": self._delete_param,
        }

    def types(self) -> dict[str, str]:
        """The rosapi services answered here and their types."""
        return {name: rosapi_type(name.removeprefix("/rosapi/")) for name in self._handlers}

    def answer(self, service: str, args: Mapping[str, Any]) -> dict[str, Any] | None:
        """The response of ``service``, None if it is not a rosapi service answered here.

        Raises:
            RosapiRefusal: the request is wrong or names what is not there.
        """
        handler = self._handlers.get(service)
        return None if handler is None else handler(args)

    # -- the graph -------------------------------------------------------------------------------

    def _topics(self, args: Mapping[str, Any]) -> dict[str, Any]:
        names = sorted(self.bridge.topics)
        return {"topics": names, "types": [self.bridge.topics[n].type_name for n in names]}

    def _topic_type(self, args: Mapping[str, Any]) -> dict[str, Any]:
        entry = self.bridge.topics.get(_field(args, "topic"))
        return {"type": entry.type_name if entry else ""}

    def _served(self) -> dict[str, str]:
        return {**self.bridge.services, **self.types()}

    def _services(self, args: Mapping[str, Any]) -> dict[str, Any]:
        return {"services": sorted(self._served())}

    def _service_type(self, args: Mapping[str, Any]) -> dict[str, Any]:
        return {"type": self._served().get(_field(args, "service"), "")}

    def _action_servers(self, args: Mapping[str, Any]) -> dict[str, Any]:
        return {"action_servers": sorted(self.bridge.actions.served)}

    def _action_type(self, args: Mapping[str, Any]) -> dict[str, Any]:
        served = self.bridge.actions.served.get("/" + _field(args, "action").lstrip("/"))
        return {"type": served[1] if served else ""}

    def _nodes(self, args: Mapping[str, Any]) -> dict[str, Any]:
        return {"nodes": sorted({MOCK_NODE} | {p.partition(":")[0] for p in self.params})}

    def _node_details(self, args: Mapping[str, Any]) -> dict[str, Any]:
        node = _field(args, "node")
        if node not in self._nodes(args)["nodes"]:
            raise RosapiRefusal(f"node {node} is not in the ROS graph")
        if node != MOCK_NODE:
            return {"subscribing": [], "publishing": [], "services": []}
        topics = self.bridge.topics
        return {
            "subscribing": sorted(n for n, e in topics.items() if e.sub_ids),
            "publishing": sorted(n for n, e in topics.items() if e.advertised),
            "services": sorted(self._served()),
        }

    # -- parameters ------------------------------------------------------------------------------

    def _param_names(self, args: Mapping[str, Any]) -> dict[str, Any]:
        return {"names": sorted(self.params)}

    def _get_param(self, args: Mapping[str, Any]) -> dict[str, Any]:
        name = _param(args)
        if name not in self.params:
            default = args.get("default_value", "")
            return {"value": default if isinstance(default, str) else "", "successful": True,
                    "reason": f"{name} is not set"}
        return {"value": json.dumps(self.params[name]), "successful": True, "reason": ""}

    def _has_param(self, args: Mapping[str, Any]) -> dict[str, Any]:
        return {"exists": _param(args) in self.params}

    def _set_param(self, args: Mapping[str, Any]) -> dict[str, Any]:
        name = _param(args)
        text = args.get("value")
        if not isinstance(text, str):
            raise RosapiRefusal("args.value: must be a JSON text (a string)")
        try:
            value = json.loads(text)
        except ValueError as exc:
            raise RosapiRefusal(f"args.value: not valid JSON ({exc})") from None
        old = self.params.get(name)
        if old is not None and _kind(old) != _kind(value):
            raise RosapiRefusal(f"{name}: the node refused the value: the parameter is "
                                f"{_kind(old)}, not {_kind(value)}")
        self.params[name] = value
        return {}

    def _delete_param(self, args: Mapping[str, Any]) -> dict[str, Any]:
        self.params.pop(_param(args), None)
        return {}


def _field(args: Mapping[str, Any], name: str) -> str:
    value = args.get(name)
    if not isinstance(value, str) or not value:
        raise RosapiRefusal(f"args.{name}: must be a non-empty string, got {value!r}")
    return value


def _param(args: Mapping[str, Any]) -> str:
    full = _field(args, "name")
    node, sep, param = full.partition(":")
    if not sep or not node or not param:
        raise RosapiRefusal(f"args.name: expected 'node_name:param_name', got {full!r}")
    return full if node.startswith("/") else "/" + full


def _kind(value: Any) -> str:
    """A parameter's type as rclpy names it (a parameter keeps the type it was set with)."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "double"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    return type(value).__name__
