"""The ``/rosapi/*`` services that describe types: typedefs (``message_details`` and
friends), the installed interfaces and their full definition texts."""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from rosbridge_core.interfaces import BridgeError
from rosbridge_core.session.rosapi.common import FIELDS, HANDLERS, TYPES, BridgeView, str_field

if TYPE_CHECKING:
    from rosbridge_core.graph import TypesPort

__all__: list[str] = []


def message_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Field names, types, array lengths and constants of a message type and its parts."""
    name = str_field(args, "type")
    return {"typedefs": bridge.graph.typedefs(name, "msg")}


def service_request_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of a service type's request."""
    return {"typedefs": bridge.graph.typedefs(str_field(args, "type"), "srv", "Request")}


def service_response_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of a service type's response."""
    return {"typedefs": bridge.graph.typedefs(str_field(args, "type"), "srv", "Response")}


_full_texts: weakref.WeakKeyDictionary[TypesPort, dict[str, str]] = weakref.WeakKeyDictionary()
"""Per graph: a relay's robots may each define a name their own way."""


def _full_text(graph: TypesPort, type_name: str) -> str:
    """A topic type's definition with its dependencies' ("" if not installed; cached)."""
    texts = _full_texts.setdefault(graph, {})
    text = texts.get(type_name)
    if text is None:
        try:
            text = graph.interface_definition(type_name)["definition"]
        except BridgeError:
            text = ""
        texts[type_name] = text
    return text


def interfaces(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every interface type installed with the bridge (what a client may ``load_types``)."""
    return {"interfaces": bridge.graph.installed_interfaces()}


def topics_and_raw_types(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Topics, their types, and each type's full definition text (with its dependencies)."""
    pairs = sorted(bridge.graph.topic_names_and_types())
    types = [t[0] if t else "" for _, t in pairs]
    return {
        "topics": [n for n, _ in pairs],
        "types": types,
        "typedefs_full_text": [_full_text(bridge.graph, t) if t else "" for t in types],
    }


def interface_definition(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The full definition text of any installed message, service or action type.

    The type's own ``.msg``/``.srv``/``.action`` text, then every message type it
    uses, each after a line of 80 ``=`` and ``MSG: pkg/msg/Name`` (the ``ros2msg``
    layout rosbag2 writes into MCAP schemas); clients build typed classes from it.
    """
    return bridge.graph.interface_definition(str_field(args, "type"))


HANDLERS.update(
    {
        "/rosapi/interface_definition": interface_definition,
        "/rosapi/interfaces": interfaces,
        "/rosapi/message_details": message_details,
        "/rosapi/service_request_details": service_request_details,
        "/rosapi/service_response_details": service_response_details,
        "/rosapi/topics_and_raw_types": topics_and_raw_types,
    }
)
TYPES.update(
    {
        "/rosapi/interface_definition": "rosapi_msgs/srv/InterfaceDefinition",
        "/rosapi/interfaces": "rosapi_msgs/srv/Interfaces",
        "/rosapi/message_details": "rosapi_msgs/srv/MessageDetails",
        "/rosapi/service_request_details": "rosapi_msgs/srv/ServiceRequestDetails",
        "/rosapi/service_response_details": "rosapi_msgs/srv/ServiceResponseDetails",
        "/rosapi/topics_and_raw_types": "rosapi_msgs/srv/TopicsAndRawTypes",
    }
)
FIELDS.update(
    {
        "/rosapi/interface_definition": ("type",),
        "/rosapi/message_details": ("type",),
        "/rosapi/service_request_details": ("type",),
        "/rosapi/service_response_details": ("type",),
    }
)
