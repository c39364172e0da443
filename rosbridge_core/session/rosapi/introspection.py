"""The ``/rosapi/*`` services that read the ROS graph: topics, services, nodes, endpoints,
action servers, the clock and the ROS version."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rosbridge_core.session.rosapi.common import (
    FIELDS,
    HANDLERS,
    TYPES,
    UNKNOWN_NODE,
    BridgeView,
    RosapiError,
    all_services,
    msg_type,
    node_names,
    own_services,
    qualified,
    split_node,
    srv_type,
    str_field,
    topic_field,
)

__all__ = ["DISTRO"]

DISTRO = "jazzy"


def topics(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every topic in the graph and its (first) type."""
    pairs = sorted(bridge.graph.topic_names_and_types())
    return {"topics": [n for n, _ in pairs], "types": [t[0] if t else "" for _, t in pairs]}


def topics_for_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Topics whose type is the given one (either spelling)."""
    wanted = msg_type(str_field(args, "type"))
    pairs = sorted(bridge.graph.topic_names_and_types())
    return {"topics": [n for n, types in pairs if wanted in types]}


def topic_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The type of one topic, "" if the graph does not know it."""
    types = bridge.graph.topic_types(str_field(args, "topic"))
    return {"type": types[0] if types else ""}


def services(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every service in the graph, plus the bridge's own rosapi services."""
    return {"services": [n for n, _ in all_services(bridge)]}


def services_for_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Services whose type is the given one (either spelling)."""
    wanted = srv_type(str_field(args, "type"))
    return {"services": [n for n, t in all_services(bridge) if t == wanted]}


def service_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The type of one service, "" if unknown."""
    name = str_field(args, "service")
    for n, t in all_services(bridge):
        if n == name:
            return {"type": t}
    return {"type": ""}


def _endpoint_nodes(nodes: list[tuple[str, str]]) -> list[str]:
    return sorted({qualified(n, ns) for n, ns in nodes if n != UNKNOWN_NODE})


def nodes(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Every node, fully qualified."""
    return {"nodes": [qualified(n, ns) for n, ns in node_names(bridge)]}


def service_node(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The node serving a service, "" if unknown."""
    name = str_field(args, "service")
    if name in HANDLERS or name in bridge.service_owners:
        # rosapi itself, or served by one of this bridge's clients: this node serves it,
        # whatever the graph says yet
        return {"node": qualified(*bridge.graph.own_node())}
    for n, ns in node_names(bridge):
        try:
            found = bridge.graph.node_services(n, ns)
        except Exception:
            continue
        if any(s == name for s, _ in found):
            return {"node": qualified(n, ns)}
    return {"node": ""}


def node_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Topics a node subscribes to and publishes, and the services it offers."""
    full = str_field(args, "node")
    name, ns = split_node(full)
    if (name, ns) not in node_names(bridge):
        raise RosapiError(f"node {full} is not in the ROS graph")
    subs, pubs, srvs = bridge.graph.node_endpoints(name, ns)
    if (name, ns) == bridge.graph.own_node():
        srvs += [n for n, _ in own_services()]
    return {"subscribing": sorted(subs), "publishing": sorted(pubs), "services": sorted(srvs)}


def publishers(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Nodes publishing on a topic."""
    return {"publishers": _endpoint_nodes(bridge.graph.topic_publishers(topic_field(args)))}


def publishers_qos(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Each publisher of a topic (its node) and the QoS it offers, with the keys and words
    rosbag2 records as a channel's ``offered_qos_profiles``; the graph reports no history
    ("unknown", depth 0), as rosbag2 records it too."""
    found = bridge.graph.topic_publishers_qos(topic_field(args))
    return {"publishers": [qualified(n, ns) for n, ns, _ in found], "qos": [q for _, _, q in found]}


def subscribers(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Nodes subscribed to a topic."""
    return {"subscribers": _endpoint_nodes(bridge.graph.topic_subscribers(topic_field(args)))}


def action_servers(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Actions that have a goal service in the graph."""
    suffix = "/_action/send_goal"
    names = {n[: -len(suffix)] for n, _ in all_services(bridge) if n.endswith(suffix)}
    names.update(bridge.action_owners)  # served by our clients, even while the graph lags
    return {"action_servers": sorted(names)}


def get_time(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The bridge node's clock; ROS 1 key names are added for older clients."""
    sec, nanosec = bridge.graph.now()
    return {"time": {"sec": sec, "nanosec": nanosec, "secs": sec, "nsecs": nanosec}}


def get_ros_version(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """ROS 2, Jazzy."""
    return {"version": 2, "distro": DISTRO}


HANDLERS.update({
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
})
TYPES.update({
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
})
FIELDS.update({
    "/rosapi/topics_for_type": ("type",),
    "/rosapi/topic_type": ("topic",),
    "/rosapi/services_for_type": ("type",),
    "/rosapi/service_type": ("service",),
    "/rosapi/service_node": ("service",),
    "/rosapi/node_details": ("node",),
    "/rosapi/publishers": ("topic",),
    "/rosapi/subscribers": ("topic",),
    "/rosapi/publishers_qos": ("topic",),
})
