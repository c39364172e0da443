"""The ``/rosapi/*`` services of actions: an action's type and its parts' typedefs."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.session.rosapi.common import (
    FIELDS,
    HANDLERS,
    TYPES,
    BridgeView,
    all_services,
    str_field,
)

__all__: list[str] = []



def action_type(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """The type of one action (``pkg/action/Type``), "" if no server offers it."""
    name = str_field(args, "action").rstrip("/")
    name = absolute_name(name)
    owner = bridge.action_owners.get(name)  # served by one of our clients
    if owner is not None and name in owner.served:
        return {"type": owner.served[name].type_name}
    goal_service = name + "/_action/send_goal"
    for n, t in all_services(bridge):
        if n == goal_service:
            return {"type": t.removesuffix("_SendGoal")}
    return {"type": ""}


def action_goal_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of an action type's goal."""
    return {"typedefs": bridge.graph.typedefs(str_field(args, "type"), "action", "Goal")}


def action_result_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of an action type's result."""
    return {"typedefs": bridge.graph.typedefs(str_field(args, "type"), "action", "Result")}


def action_feedback_details(bridge: BridgeView, args: Mapping[str, Any]) -> dict[str, Any]:
    """Typedefs of an action type's feedback."""
    return {"typedefs": bridge.graph.typedefs(str_field(args, "type"), "action", "Feedback")}


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
