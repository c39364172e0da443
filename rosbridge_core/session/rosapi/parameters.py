"""The ``/rosapi/*`` parameter services: ROS 2 node parameters named ``/node:param``, read and
written through the node's own parameter services (by the :class:`~rosbridge_core.graph.Graph`);
values travel as JSON text, as in rosapi."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Mapping
from typing import Any

from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.security.names import InvalidNameError, check_name
from rosbridge_core.session.rosapi.common import (
    ASYNC_HANDLERS,
    FIELDS,
    TYPES,
    BridgeView,
    RosapiError,
    node_names,
    qualified,
    str_field,
)

__all__ = ["PARAM_TIMEOUT"]


PARAM_TIMEOUT = 2.0
"""Seconds ``get_param_names`` waits for each listed node's parameter service."""

def _param_name(args: Mapping[str, Any]) -> tuple[str, str, str]:
    full = str_field(args, "name")
    node, sep, param = full.partition(":")
    if not sep or not node or not param:
        raise RosapiError(f"args.name: expected 'node_name:param_name', got {full!r}")
    node = absolute_name(node)
    try:  # before rclpy sees it: a bad node name is the caller's mistake, not ours
        check_name(node, "node")
    except InvalidNameError as exc:
        raise RosapiError(f"args.name: {exc}") from None
    return node, param, f"{node}:{param}"


def _json_arg(args: Mapping[str, Any], name: str) -> Any:
    text = args.get(name)
    if text is None or text == "":
        return None
    if not isinstance(text, str):
        raise RosapiError(f"args.{name}: must be a JSON text (a string)")
    try:
        return json.loads(text)
    except ValueError as exc:
        raise RosapiError(f"args.{name}: not valid JSON ({exc})") from None


async def get_param_names(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every parameter of every node that offers parameter services, as ``/node:param``
    (a node the graph lists no ``list_parameters`` service of is skipped at once)."""
    graph = bridge.graph
    own = qualified(*graph.own_node())
    nodes = [qualified(n, ns) for n, ns in node_names(bridge)]

    async def one(node: str) -> list[str]:
        if node == own or graph.server_count(f"{node}/list_parameters") == 0:
            return []  # no parameter services (start_parameter_services=False): not asked
        try:
            names = await graph.parameter_names(node, PARAM_TIMEOUT)
        except Exception:
            return []
        return [f"{node}:{name}" for name in names]

    found = await asyncio.gather(*(one(n) for n in nodes))
    return {"names": sorted(name for names in found for name in names)}


async def _get_value(bridge: BridgeView, node: str, param: str) -> tuple[bool, Any]:
    try:
        return await bridge.graph.get_parameter(node, param)
    except (TimeoutError, LookupError):
        raise RosapiError(f"node {node} does not answer parameter requests") from None


async def _set_value(bridge: BridgeView, node: str, param: str, value: Any) -> tuple[bool, str]:
    try:
        return await bridge.graph.set_parameter(node, param, value)
    except (TimeoutError, LookupError):
        raise RosapiError(f"node {node} does not answer parameter requests") from None
    except ValueError as exc:  # a value no parameter can hold
        raise RosapiError(str(exc)) from None


async def get_param(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """A parameter's value as JSON text (``default_value`` if it is not set)."""
    node, param, full = _param_name(args)
    default = args.get("default_value", "")
    is_set, value = await _get_value(bridge, node, param)
    if not is_set:
        return {"value": default if isinstance(default, str) else "", "successful": True,
                "reason": f"{full} is not set"}
    if isinstance(value, bytes):  # a byte array reads as its numbers, as it always has
        value = list(value)
    return {"value": json.dumps(value), "successful": True, "reason": ""}


async def has_param(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Whether a parameter is set."""
    node, param, _ = _param_name(args)
    is_set, _value = await _get_value(bridge, node, param)
    return {"exists": is_set}


async def set_param(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Set a parameter from JSON text; fails (result false) if the node refuses."""
    node, param, full = _param_name(args)
    ok, reason = await _set_value(bridge, node, param, _json_arg(args, "value"))
    if not ok:
        raise RosapiError(f"{full}: the node refused the value" + (f": {reason}" * bool(reason)))
    return {}


async def delete_param(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Unset (undeclare) a parameter; fails if the node does not allow it."""
    node, param, full = _param_name(args)
    ok, reason = await _set_value(bridge, node, param, None)
    if not ok:
        raise RosapiError(f"{full}: the node refused to unset it" + (f": {reason}" * bool(reason)))
    return {}


ASYNC_HANDLERS.update({
    "/rosapi/get_param_names": get_param_names,
    "/rosapi/get_param": get_param,
    "/rosapi/has_param": has_param,
    "/rosapi/set_param": set_param,
    "/rosapi/delete_param": delete_param,
})

TYPES.update(
    {
        "/rosapi/get_param_names": "rosapi_msgs/srv/GetParamNames",
        "/rosapi/get_param": "rosapi_msgs/srv/GetParam",
        "/rosapi/has_param": "rosapi_msgs/srv/HasParam",
        "/rosapi/set_param": "rosapi_msgs/srv/SetParam",
        "/rosapi/delete_param": "rosapi_msgs/srv/DeleteParam",
    }
)
FIELDS.update(
    {
        "/rosapi/get_param_names": (),
        "/rosapi/get_param": ("name", "default_value"),
        "/rosapi/has_param": ("name",),
        "/rosapi/set_param": ("name", "value"),
        "/rosapi/delete_param": ("name",),
    }
)
