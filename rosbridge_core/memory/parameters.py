"""Parameters in the in-memory graph: a node's parameter services answered from a dict
(:class:`ServedParameters`, as an rclpy node answers them) and the Graph port's parameter
methods, which call a node's services through the graph (:class:`ParameterCalls`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from rosbridge_core.interfaces import ServiceCallError
from rosbridge_core.memory.services import Handler, Named, ServiceServer
from rosbridge_core.parameters import PARAMETER_TYPE_NAMES, parameter_obj, parameter_value
from rosbridge_core.protocol.names import node_path

__all__ = ["PARAM_WAIT", "ParameterCalls", "ServedParameters", "parameter_obj"]


class _Registry(Protocol):
    def add_server(self, server: ServiceServer) -> None: ...


class _ParamNode(Named, Protocol):
    """What a node's parameter services need of it (:class:`~.graph.MemoryGraph`)."""

    @property
    def ros(self) -> _Registry: ...

    def resolve_service(self, name: str) -> Any: ...


class _Caller(Protocol):
    """What the parameter calls need of the calling node (:class:`~.graph.MemoryGraph`)."""

    def resolve_service(self, name: str) -> Any: ...

    def server_count(self, service: str) -> int: ...

    async def _request(self, service: str, srv_cls: Any, request: Any, timeout: float,
                       discovery_wait: float, deadline: float | None = None) -> Any: ...

    async def _parameter_call(self, node: str, part: str, args: Mapping[str, Any],
                              timeout: float) -> Any: ...


class ServedParameters:
    """A node's ``list_parameters``, ``get_parameters`` and ``set_parameters`` services,
    answered from ``values`` (a set changes it in place)."""

    def __init__(self, node: _ParamNode, values: dict[str, Any], declared: set[str]) -> None:
        self.node = node
        self.values = values
        self.declared = declared

    def serve(self) -> None:
        """Put the three services into the graph, under the node's name."""
        node = self.node
        base = node_path(node.namespace, node.name)
        parts: tuple[tuple[str, Handler], ...] = (
            ("list_parameters", self._list_parameters), ("get_parameters", self._get_parameters),
            ("set_parameters", self._set_parameters))
        for part, handler in parts:
            kind = "".join(w.capitalize() for w in part.split("_"))
            node.ros.add_server(ServiceServer(node, f"{base}/{part}",
                                              f"rcl_interfaces/srv/{kind}", handler))

    async def _list_parameters(self, request: Any) -> Any:
        cls = self.node.resolve_service("rcl_interfaces/srv/ListParameters").Response
        return cls.from_json({"result": {"names": sorted(self.values)}})

    async def _get_parameters(self, request: Any) -> Any:
        cls = self.node.resolve_service("rcl_interfaces/srv/GetParameters").Response
        params = self.values
        return cls.from_json({"values": [parameter_obj(params.get(n)) for n in request.names]})

    async def _set_parameters(self, request: Any) -> Any:
        """Each parameter set as an rclpy node sets it: one the node was made with (declared)
        keeps its type and cannot be unset (rclpy's refusals); others may be anything."""
        cls = self.node.resolve_service("rcl_interfaces/srv/SetParameters").Response
        params = self.values
        results = []
        for p in request.parameters:
            value = parameter_value(p.value)
            old = params.get(p.name) if p.name in self.declared else None
            old_type, new_type = _parameter_type(old), int(p.value.type)
            if old is not None and value is None:
                results.append({"successful": False,
                                "reason": "Static parameter cannot be undeclared"})
            elif old is not None and old_type != new_type:
                results.append({"successful": False, "reason": (
                    f"Wrong parameter type, expected 'Type.{PARAMETER_TYPE_NAMES[old_type]}' got "
                    f"'Type.{PARAMETER_TYPE_NAMES[new_type]}'")})
            else:
                if value is None:
                    params.pop(p.name, None)
                else:
                    params[p.name] = value
                results.append({"successful": True, "reason": ""})
        return cls.from_json({"results": results})


class ParameterCalls:
    """The Graph port's parameter methods: each calls the node's parameter services through
    the graph, as an rclpy node's parameter client does."""

    async def _parameter_call(self: _Caller, node: str, part: str, args: Mapping[str, Any],
                              timeout: float) -> Any:
        """The answer of ``node``'s parameter service ``part`` (as an rclpy node's):
        ``LookupError`` if the node has none, ``TimeoutError`` if it does not answer."""
        service = f"{node}/{part}"
        kind = "".join(w.capitalize() for w in part.split("_"))
        srv_cls = self.resolve_service(f"rcl_interfaces/srv/{kind}")
        try:
            return await self._request(service, srv_cls, srv_cls.Request.from_json(args),
                                       timeout, timeout / 2)
        except ServiceCallError as exc:
            if self.server_count(service):
                raise TimeoutError(f"service {service} did not answer") from exc
            raise LookupError(f"service {service} does not exist (not in the ROS graph)"
                              ) from None

    async def parameter_names(self: _Caller, node: str, timeout: float) -> list[str]:
        """Names of ``node``'s parameters (any failure raises)."""
        answer = await self._parameter_call(node, "list_parameters", {}, timeout)
        return list(answer.result.names)

    async def get_parameter(self: _Caller, node: str, name: str) -> tuple[bool, Any]:
        """(is set, value) of one parameter of ``node``."""
        answer = await self._parameter_call(node, "get_parameters", {"names": [name]},
                                            PARAM_WAIT)
        values = answer.values
        if not values or values[0].type == 0:
            return False, None
        return True, parameter_value(values[0])

    async def set_parameter(self: _Caller, node: str, name: str, value: Any) -> tuple[bool, str]:
        """Set (``None``: unset) one parameter of ``node``: (accepted, reason); ``ValueError``
        for a value a parameter cannot hold."""
        param = {"name": name, "value": parameter_obj(value)}
        answer = await self._parameter_call(node, "set_parameters", {"parameters": [param]},
                                            PARAM_WAIT)
        result = answer.results[0]
        return bool(result.successful), str(result.reason)


PARAM_WAIT = 5.0
"""Seconds a parameter get or set waits for the node's parameter service."""


def _parameter_type(value: Any) -> int:
    """The ``ParameterType`` number of a plain value (0: not set)."""
    return int(parameter_obj(value)["type"])
