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

The services are answered by the modules of this package, each adding its own to the tables
(:mod:`.introspection`, :mod:`.definitions`, :mod:`.may_use`, :mod:`.actions`,
:mod:`.parameters`); :mod:`.common` holds the tables and what the parts share.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rosbridge_core.session.rosapi import (  # each adds its services to the tables
    actions,
    definitions,
    introspection,
    may_use,
    parameters,
)
from rosbridge_core.session.rosapi.common import (
    ASYNC_HANDLERS,
    FIELDS,
    HANDLERS,
    TYPES,
    BridgeView,
    Owners,
    RosapiError,
)

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

_PARTS = (introspection, definitions, may_use, actions, parameters)


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
