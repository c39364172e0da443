"""What the bridge tells about ROS types and nodes, from rclpy: rosapi typedefs, full
interface definitions, node parameters.

The ``/rosapi/*`` services (:mod:`rosbridge_core.session.rosapi`) ask for these through
the :class:`~rosbridge_core.graph.Graph`; :class:`~.node.RosNode` answers with the
functions here. Errors are :class:`~rosbridge_core.interfaces.BridgeError`s whose text
says what was wrong (a rosapi caller gets it as the call's failure).
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rcl_interfaces.msg import Parameter, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters

from bridge_server.rclpy_graph.types import (
    resolve_action,
    resolve_message,
    resolve_service,
    type_name_of,
)
from rosbridge_core.interfaces import BridgeError, canonical_name
from rosbridge_core.parameters import parameter_obj, parameter_value
from rosbridge_core.typedefs import typedefs_of

if TYPE_CHECKING:
    from bridge_server.rclpy_graph.node import RosNode

__all__ = [
    "PARAM_CALL_TIMEOUT",
    "PARAM_DISCOVERY",
    "get_parameter",
    "interface_definition",
    "parameter_names",
    "set_parameter",
    "typedefs",
]

PARAM_DISCOVERY = 5.0
"""Seconds a named node's parameter service may stay out of the ROS graph before a
get/set/has/delete fails (a node that does not exist is reported then)."""

PARAM_CALL_TIMEOUT = 10.0
"""Seconds a get/set/has/delete waits for a listed node to match and answer (a busy
machine can take seconds to match a node that has just started)."""


# -- typedefs (rosapi message_details and friends) -----------------------------------------

def _constants(cls: type[Any]) -> dict[str, Any]:
    meta = type(cls)
    return dict(getattr(meta, f"_{meta.__name__}__constants", {}) or {})


def _typedefs(cls: type[Any], name: str) -> list[dict[str, Any]]:
    """The typedef of ``cls`` then those of every nested type, each once."""
    return typedefs_of(cls, name, constants=_constants, resolve=resolve_message,
                       name_of=type_name_of)


def typedefs(name: str, kind: str, part: str | None = None) -> list[dict[str, Any]]:
    """The rosapi typedefs of type ``name`` of ``kind`` (``msg``, ``srv``, ``action``), of
    its ``part`` for a service or an action (``Request``, ``Goal``, ...), then those of
    every nested type."""
    if kind == "msg":
        cls = resolve_message(name)
        return _typedefs(cls, canonical_name(name, "msg"))
    if kind == "srv":
        cls = resolve_service(name)
        canonical = canonical_name(name, "srv")
    else:
        cls = resolve_action(name)
        canonical = canonical_name(name, "action")
    return _typedefs(getattr(cls, part or ""), f"{canonical}_{part}")


# -- interface definitions -------------------------------------------------------------------


def _source(package: str, kind: str, name: str) -> str | None:
    """The installed ``.msg``/``.srv``/``.action`` text of a type (None if not found)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes += [sys.prefix, sys.base_prefix]
    for prefix in prefixes:
        path = Path(prefix) / "share" / package / kind / f"{name}.{kind}"
        if path.is_file():
            try:
                return path.read_text(encoding="utf-8")
            except OSError:
                return None
    return None


def interface_definition(name: str) -> dict[str, Any]:
    """The full definition text of any installed message, service or action type.

    The type's own ``.msg``/``.srv``/``.action`` text, then every message type it
    uses, each after a line of 80 ``=`` and ``MSG: pkg/msg/Name`` (the ``ros2msg``
    layout rosbag2 writes into MCAP schemas); clients build typed classes from it.
    """
    from msgs.parser import DefinitionError, parse_action, parse_message, parse_service

    match = _TYPE_NAME.match(name)
    if match is None:
        raise BridgeError(f"type: {name!r} is not a type name (expected 'pkg/msg/Name', "
                          "'pkg/srv/Name', 'pkg/action/Name' or 'pkg/Name')")
    package, kind, short = match["pkg"], match["kind"], match["name"]
    found = next(((k, text) for k in ((kind,) if kind else ("msg", "srv", "action"))
                  if (text := _source(package, k, short)) is not None), None)
    if found is None:
        raise BridgeError(f"type: {name} is not installed on the robot (no "
                          f"share/{package}/{kind or 'msg|srv|action'}/{short} definition)")
    kind, text = found
    parts: list[str] = [text.rstrip("\n")]
    try:
        if kind == "msg":
            todo = [parse_message(text, package, short)]
        elif kind == "srv":
            srv = parse_service(text, package, short)
            todo = [srv.request, srv.response]
        else:
            act = parse_action(text, package, short)
            todo = [act.goal, act.result, act.feedback]
        seen = {f"{package}/msg/{short}"}
        while todo:
            spec = todo.pop(0)
            for f in spec.fields:
                if f.type.is_primitive or f.type.message_type in seen:
                    continue
                dep = f.type.message_type
                seen.add(dep)
                dep_pkg, _, dep_name = dep.split("/")
                dep_text = _source(dep_pkg, "msg", dep_name)
                if dep_text is None:
                    raise BridgeError(f"type: {name} uses {dep}, which is not installed")
                parts.append("=" * 80 + f"\nMSG: {dep}\n" + dep_text.rstrip("\n"))
                todo.append(parse_message(dep_text, dep_pkg, dep_name))
    except DefinitionError as exc:
        raise BridgeError(
            f"type: the installed definition of {name} does not parse: {exc}") from None
    return {"type": f"{package}/{kind}/{short}", "definition": "\n".join(parts) + "\n"}


_TYPE_NAME = re.compile(
    r"^(?P<pkg>[a-z][a-z0-9_]*)/(?:(?P<kind>msg|srv|action)/)?(?P<name>[A-Z][A-Za-z0-9_]*)$")


# -- parameters (through each node's own parameter services, rcl_interfaces) ----------------


async def parameter_names(ros: RosNode, node: str, timeout: float) -> list[str]:
    """Names of ``node``'s parameters (any failure raises)."""
    response = await ros.call_when_ready(
        f"{node}/list_parameters", ListParameters, ListParameters.Request(), timeout,
        read_only=True,
    )
    return list(response.result.names)


async def get_parameter(ros: RosNode, node: str, name: str) -> tuple[bool, Any]:
    """(is set, value) of one parameter of ``node``."""
    response = await ros.call_when_ready(
        f"{node}/get_parameters", GetParameters, GetParameters.Request(names=[name]),
        PARAM_CALL_TIMEOUT, discovery_wait=PARAM_DISCOVERY, read_only=True,
    )
    values = list(response.values)
    if not values or values[0].type == 0:
        return False, None
    return True, parameter_value(values[0])


async def set_parameter(ros: RosNode, node: str, name: str, value: Any) -> tuple[bool, str]:
    """Set (``None``: unset) one parameter of ``node``: (accepted, the node's reason)."""
    request = SetParameters.Request(
        parameters=[Parameter(name=name, value=_to_parameter_value(value))]
    )
    response = await ros.call_when_ready(
        f"{node}/set_parameters", SetParameters, request, PARAM_CALL_TIMEOUT,
        discovery_wait=PARAM_DISCOVERY,
    )
    result = response.results[0]
    return bool(result.successful), str(result.reason)


def _to_parameter_value(value: Any) -> Any:
    """A plain value as rclpy's ``ParameterValue`` (the fields as
    :func:`~rosbridge_core.parameters.parameter_obj` chooses them; a byte array's items as
    1-byte ``bytes``, rclpy's own)."""
    obj = parameter_obj(value)
    pv = ParameterValue(type=obj.pop("type"))
    for field, found in obj.items():
        setattr(pv, field, [bytes((b,)) for b in found] if field == "byte_array_value" else found)
    return pv
