"""The ``/rosapi/*`` introspection services, answered by the bridge itself.

rosapi_msgs is not on PyPI, so these services are not ROS services: a client's
``call_service`` to one of the names below is answered in the bridge from the
ROS graph, with the response fields stock clients (roslibpy, roslib) read.
They are listed by ``/rosapi/services`` like any other service, with their
rosapi_msgs types. Node names are fully qualified (``/ns/name``); type names
use the ``pkg/msg/Type`` spelling.

=================================  ===============  ===========================================
service                            request          response
=================================  ===============  ===========================================
/rosapi/topics                     (none)           topics, types
/rosapi/topics_for_type            type             topics
/rosapi/topic_type                 topic            type ("" if unknown)
/rosapi/services                   (none)           services
/rosapi/services_for_type          type             services
/rosapi/service_type               service          type ("" if unknown)
/rosapi/service_node               service          node ("" if unknown)
/rosapi/nodes                      (none)           nodes
/rosapi/node_details               node             subscribing, publishing, services
/rosapi/publishers                 topic            publishers
/rosapi/subscribers                topic            subscribers
/rosapi/publishers_qos             topic            publishers, qos (ours: each publisher's
                                                    offered QoS, rosbag2's keys and words)
/rosapi/action_servers             (none)           action_servers
/rosapi/action_type                action           type ("" if no server offers it)
/rosapi/action_goal_details        type             typedefs of the goal
/rosapi/action_result_details      type             typedefs of the result
/rosapi/action_feedback_details    type             typedefs of the feedback
/rosapi/get_time                   (none)           time {sec, nanosec} (and ROS 1 secs, nsecs)
/rosapi/get_ros_version            (none)           version 2, distro "jazzy"
/rosapi/message_details            type             typedefs (the type's, then nested types')
/rosapi/service_request_details    type             typedefs of the request
/rosapi/service_response_details   type             typedefs of the response
/rosapi/topics_and_raw_types       (none)           topics, types, typedefs_full_text
/rosapi/interfaces                 (none)           interfaces (every installed msg, srv and
                                                    action type, ``pkg/msg/Name``)
/rosapi/interface_definition       type             type, definition (ours: the ros2msg text
                                                    of any installed msg, srv or action)
/rosapi/get_param_names            (none)           names (``/node:param``)
/rosapi/get_param                  name, default_   value (JSON text), successful, reason
                                   value
/rosapi/has_param                  name             exists
/rosapi/set_param                  name, value      (empty; result false if the node refuses)
/rosapi/delete_param               name             (empty; result false if the node refuses)
=================================  ===============  ===========================================

Parameters are ROS 2 node parameters named ``/node:param``, read and written
through the node's own parameter services (``rcl_interfaces``, by the
:class:`~rosbridge_core.graph.Graph`); values travel as JSON text, as in rosapi.
Every answer comes from the Graph: nothing here knows rclpy.
"""

from __future__ import annotations

import asyncio
import json
import weakref
from collections.abc import Awaitable, Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from rosbridge_core.interfaces import BridgeError, canonical_name
from rosbridge_core.security.names import InvalidNameError, check_name
from rosbridge_core.security.permissions import MAY

if TYPE_CHECKING:
    from rosbridge_core.graph import Graph

__all__ = [
    "ASYNC_HANDLERS",
    "FIELDS",
    "HANDLERS",
    "TYPES",
    "BridgeView",
    "Owners",
    "RosapiError",
    "request_args",
]

DISTRO = "jazzy"


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


def _str_field(args: Mapping[str, Any], name: str) -> str:
    if not isinstance(args, Mapping):
        raise RosapiError("args must be an object")
    value = args.get(name)
    if not isinstance(value, str):
        raise RosapiError(f"args: field {name!r} must be a string")
    return value


def _topic_field(args: Mapping[str, Any]) -> str:
    """``args.topic`` as a full, valid topic name (relative names are made absolute)."""
    topic = _str_field(args, "topic")
    topic = topic if topic.startswith("/") else "/" + topic
    try:
        check_name(topic)
    except InvalidNameError as exc:
        raise RosapiError(f"args.topic: {exc}") from None
    return topic


def _full(name: str, namespace: str) -> str:
    ns = namespace.rstrip("/")
    return f"{ns}/{name}"


def _split(full: str) -> tuple[str, str]:
    full = full if full.startswith("/") else "/" + full
    ns, _, name = full.rpartition("/")
    return name, ns or "/"


def _own_services() -> list[tuple[str, str]]:
    return sorted((name, TYPES[name]) for name in (*HANDLERS, *ASYNC_HANDLERS))


def _all_services(bridge: BridgeView) -> list[tuple[str, str]]:
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
    return sorted(found | set(_own_services()))


def _msg_type(name: str) -> str:
    try:
        return canonical_name(name, "msg")
    except BridgeError as exc:
        raise RosapiError(str(exc)) from None


def _srv_type(name: str) -> str:
    try:
        return canonical_name(name, "srv")
    except BridgeError as exc:
        raise RosapiError(str(exc)) from None


def topics(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every topic in the graph and its (first) type."""
    pairs = sorted(bridge.graph.topic_names_and_types())
    return {"topics": [n for n, _ in pairs], "types": [t[0] if t else "" for _, t in pairs]}


def topics_for_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Topics whose type is the given one (either spelling)."""
    wanted = _msg_type(_str_field(args, "type"))
    pairs = sorted(bridge.graph.topic_names_and_types())
    return {"topics": [n for n, types in pairs if wanted in types]}


def topic_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The type of one topic, "" if the graph does not know it."""
    types = bridge.graph.topic_types(_str_field(args, "topic"))
    return {"type": types[0] if types else ""}


def services(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every service in the graph, plus the bridge's own rosapi services."""
    return {"services": [n for n, _ in _all_services(bridge)]}


def services_for_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Services whose type is the given one (either spelling)."""
    wanted = _srv_type(_str_field(args, "type"))
    return {"services": [n for n, t in _all_services(bridge) if t == wanted]}


def service_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The type of one service, "" if unknown."""
    name = _str_field(args, "service")
    for n, t in _all_services(bridge):
        if n == name:
            return {"type": t}
    return {"type": ""}


_UNKNOWN = "_NODE_NAME_UNKNOWN_"


def _node_names(bridge: BridgeView) -> list[tuple[str, str]]:
    names = bridge.graph.node_names()
    return sorted({(n, ns) for n, ns in names if n != _UNKNOWN})


def _endpoint_nodes(nodes: list[tuple[str, str]]) -> list[str]:
    return sorted({_full(n, ns) for n, ns in nodes if n != _UNKNOWN})


def nodes(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every node, fully qualified."""
    return {"nodes": [_full(n, ns) for n, ns in _node_names(bridge)]}


def service_node(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The node serving a service, "" if unknown."""
    name = _str_field(args, "service")
    if name in HANDLERS or name in bridge.service_owners:
        # rosapi itself, or served by one of this bridge's clients: this node serves it,
        # whatever the graph says yet
        return {"node": _full(*bridge.graph.own_node())}
    for n, ns in _node_names(bridge):
        try:
            found = bridge.graph.node_services(n, ns)
        except Exception:
            continue
        if any(s == name for s, _ in found):
            return {"node": _full(n, ns)}
    return {"node": ""}


def node_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Topics a node subscribes to and publishes, and the services it offers."""
    full = _str_field(args, "node")
    name, ns = _split(full)
    if (name, ns) not in _node_names(bridge):
        raise RosapiError(f"node {full} is not in the ROS graph")
    subs, pubs, srvs = bridge.graph.node_endpoints(name, ns)
    if (name, ns) == bridge.graph.own_node():
        srvs += [n for n, _ in _own_services()]
    return {"subscribing": sorted(subs), "publishing": sorted(pubs), "services": sorted(srvs)}


def publishers(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Nodes publishing on a topic."""
    return {"publishers": _endpoint_nodes(bridge.graph.topic_publishers(_topic_field(args)))}


def publishers_qos(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Each publisher of a topic (its node) and the QoS it offers, with the keys and words
    rosbag2 records as a channel's ``offered_qos_profiles``; the graph reports no history
    ("unknown", depth 0), as rosbag2 records it too."""
    found = bridge.graph.topic_publishers_qos(_topic_field(args))
    return {"publishers": [_full(n, ns) for n, ns, _ in found], "qos": [q for _, _, q in found]}


def subscribers(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Nodes subscribed to a topic."""
    return {"subscribers": _endpoint_nodes(bridge.graph.topic_subscribers(_topic_field(args)))}


def action_servers(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Actions that have a goal service in the graph."""
    suffix = "/_action/send_goal"
    names = {n[: -len(suffix)] for n, _ in _all_services(bridge) if n.endswith(suffix)}
    names.update(bridge.action_owners)  # served by our clients, even while the graph lags
    return {"action_servers": sorted(names)}


def get_time(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The bridge node's clock; ROS 1 key names are added for older clients."""
    sec, nanosec = bridge.graph.now()
    return {"time": {"sec": sec, "nanosec": nanosec, "secs": sec, "nsecs": nanosec}}


def get_ros_version(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """ROS 2, Jazzy."""
    return {"version": 2, "distro": DISTRO}


HANDLERS: dict[str, Handler] = {
    "/rosapi/topics": topics,
    "/rosapi/topics_for_type": topics_for_type,
    "/rosapi/topic_type": topic_type,
    "/rosapi/services": services,
    "/rosapi/services_for_type": services_for_type,
    "/rosapi/service_type": service_type,
    "/rosapi/service_node": service_node,
    "/rosapi/nodes": nodes,
    "/rosapi/node_details": node_details,
    "/rosapi/publishers": publishers,
    "/rosapi/subscribers": subscribers,
    "/rosapi/publishers_qos": publishers_qos,
    "/rosapi/action_servers": action_servers,
    "/rosapi/get_time": get_time,
    "/rosapi/get_ros_version": get_ros_version,
}
"""Service name -> handler."""

TYPES: dict[str, str] = {
    "/rosapi/topics": "rosapi_msgs/srv/Topics",
    "/rosapi/topics_for_type": "rosapi_msgs/srv/TopicsForType",
    "/rosapi/topic_type": "rosapi_msgs/srv/TopicType",
    "/rosapi/services": "rosapi_msgs/srv/Services",
    "/rosapi/services_for_type": "rosapi_msgs/srv/ServicesForType",
    "/rosapi/service_type": "rosapi_msgs/srv/ServiceType",
    "/rosapi/service_node": "rosapi_msgs/srv/ServiceNode",
    "/rosapi/nodes": "rosapi_msgs/srv/Nodes",
    "/rosapi/node_details": "rosapi_msgs/srv/NodeDetails",
    "/rosapi/publishers": "rosapi_msgs/srv/Publishers",
    "/rosapi/subscribers": "rosapi_msgs/srv/Subscribers",
    "/rosapi/publishers_qos": "rosapi_msgs/srv/PublishersQos",
    "/rosapi/action_servers": "rosapi_msgs/srv/GetActionServers",
    "/rosapi/get_time": "rosapi_msgs/srv/GetTime",
    "/rosapi/get_ros_version": "rosapi_msgs/srv/GetROSVersion",
}
"""Service name -> the rosapi_msgs type it is listed with."""

FIELDS: dict[str, tuple[str, ...]] = {
    "/rosapi/topics_for_type": ("type",),
    "/rosapi/topic_type": ("topic",),
    "/rosapi/services_for_type": ("type",),
    "/rosapi/service_type": ("service",),
    "/rosapi/service_node": ("service",),
    "/rosapi/node_details": ("node",),
    "/rosapi/publishers": ("topic",),
    "/rosapi/subscribers": ("topic",),
    "/rosapi/publishers_qos": ("topic",),
}
"""Request field order, for ``args`` given as a list."""


# -- type definitions (message_details and friends) ----------------------------------------

def message_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Field names, types, array lengths and constants of a message type and its parts."""
    name = _str_field(args, "type")
    return {"typedefs": bridge.graph.typedefs(name, "msg")}


def service_request_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of a service type's request."""
    return {"typedefs": bridge.graph.typedefs(_str_field(args, "type"), "srv", "Request")}


def service_response_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of a service type's response."""
    return {"typedefs": bridge.graph.typedefs(_str_field(args, "type"), "srv", "Response")}


_full_texts: weakref.WeakKeyDictionary[Graph, dict[str, str]] = weakref.WeakKeyDictionary()
"""Per graph: a relay's robots may each define a name their own way."""


def _full_text(graph: Graph, type_name: str) -> str:
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
    return bridge.graph.interface_definition(_str_field(args, "type"))


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


# -- what the caller's role may use (permissions.MAY; the gate's filter keeps those) ----------

MAX_ASKED_NAMES = 10_000
"""The most names one ``/rosapi/may_*`` request may ask about."""


def may_use(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The names asked (``names``), of which the session's gate keeps the allowed ones."""
    names = args.get("names", [])
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise RosapiError("names: expected a list of names (strings)")
    if len(names) > MAX_ASKED_NAMES:
        raise RosapiError(f"names: {len(names)} names, at most {MAX_ASKED_NAMES} a request")
    return {"names": names}


for _service in MAY:
    HANDLERS[_service] = may_use
    TYPES[_service] = "rosapi_msgs/srv/MayUse"
    FIELDS[_service] = ("names",)


# -- actions ---------------------------------------------------------------------------------


def action_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The type of one action (``pkg/action/Type``), "" if no server offers it."""
    name = _str_field(args, "action").rstrip("/")
    name = name if name.startswith("/") else "/" + name
    owner = bridge.action_owners.get(name)  # served by one of our clients
    if owner is not None and name in owner.served:
        return {"type": owner.served[name].type_name}
    goal_service = name + "/_action/send_goal"
    for n, t in _all_services(bridge):
        if n == goal_service:
            return {"type": t.removesuffix("_SendGoal")}
    return {"type": ""}


def action_goal_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of an action type's goal."""
    return {"typedefs": bridge.graph.typedefs(_str_field(args, "type"), "action", "Goal")}


def action_result_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of an action type's result."""
    return {"typedefs": bridge.graph.typedefs(_str_field(args, "type"), "action", "Result")}


def action_feedback_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of an action type's feedback."""
    return {"typedefs": bridge.graph.typedefs(_str_field(args, "type"), "action", "Feedback")}


_ACTION_CALLS = {
    "/rosapi/action_type": (action_type, "ActionType", "action"),
    "/rosapi/action_goal_details": (action_goal_details, "ActionGoalDetails", "type"),
    "/rosapi/action_result_details": (action_result_details, "ActionResultDetails", "type"),
    "/rosapi/action_feedback_details": (action_feedback_details, "ActionFeedbackDetails", "type"),
}
for _service, (_handler, _srv, _field) in _ACTION_CALLS.items():
    HANDLERS[_service] = _handler
    TYPES[_service] = f"rosapi_msgs/srv/{_srv}"
    FIELDS[_service] = (_field,)


# -- parameters (``/node:param`` names, through each node's parameter services) ------------

PARAM_TIMEOUT = 2.0
"""Seconds ``get_param_names`` waits for each listed node's parameter service."""

AsyncHandler = Callable[["BridgeView", Mapping[str, Any]], Awaitable[dict[str, Any]]]


def _param_name(args: Mapping[str, Any]) -> tuple[str, str, str]:
    full = _str_field(args, "name")
    node, sep, param = full.partition(":")
    if not sep or not node or not param:
        raise RosapiError(f"args.name: expected 'node_name:param_name', got {full!r}")
    node = node if node.startswith("/") else "/" + node
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
    own = _full(*graph.own_node())
    nodes = [_full(n, ns) for n, ns in _node_names(bridge)]

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


ASYNC_HANDLERS: dict[str, AsyncHandler] = {
    "/rosapi/get_param_names": get_param_names,
    "/rosapi/get_param": get_param,
    "/rosapi/has_param": has_param,
    "/rosapi/set_param": set_param,
    "/rosapi/delete_param": delete_param,
}
"""Service name -> handler that has to ask ROS nodes (awaited)."""

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


def request_args(service: str, args: Mapping[str, Any] | list[Any] | None) -> dict[str, Any]:
    """The request of a rosapi call as an object: a list is zipped onto the fields in
    order; a field the request lacks is an error naming it."""
    fields = FIELDS.get(service, ())
    where = f"{TYPES[service]} request"
    if args is None:
        return {}
    if isinstance(args, list):
        if len(args) > len(fields):
            raise RosapiError(
                f"args: {len(args)} values given but the {where} has {len(fields)} fields"
                + (f" ({', '.join(fields)})" if fields else "")
            )
        return dict(zip(fields, args, strict=False))
    for key in args:
        if key not in fields:
            raise RosapiError(
                f"args.{key}: the {where} has no field {key!r}"
                + (f" (its fields: {', '.join(fields)})" if fields else " (it has no fields)")
            )
    return dict(args)
