"""Roles: capabilities granted on name patterns, and what each op needs.

A role grants capabilities on ``fnmatch`` globs (``*`` also matches ``/``)::

    [roles.operator]
    subscribe = ["*"]
    introspection = ["*"]
    publish = ["/cmd_vel"]
    call_service = ["/reset", "/dock/*"]
    deny.publish = ["/rosout"]

Capabilities (:data:`CAPABILITIES`): ``subscribe``, ``publish`` (also
advertise), ``call_service``, ``serve_service`` (advertise_service),
``send_action_goal`` (and cancel the client's own goals), ``cancel_any_goal``
(with ``send_action_goal``: also cancel goals other clients sent, through the
action's ``_action/cancel_goal`` service, see :mod:`rosbridge_core.session.actions`),
``serve_action`` (advertise_action and
the feedback/result of served goals), ``params`` (the ``/node:param`` names
of rosapi's get/set/has/delete_param and get_param_names), ``introspection``
(the rosapi lists and lookups; answers list only the names it matches) and
``take_over`` (advertise a service another client serves; without it the
first owner keeps the name) and ``clients`` (see where other clients connect
from, on the status page). ``all`` grants every capability. Deny wins over
allow.

``limits.fragment_bytes`` and ``limits.inflight_bytes`` bound what each principal of the
role may hold over all its connections (:mod:`rosbridge_core.security.accounts`).

On a relay, which serves many robots on one port, ``robots = ["robot1", "lab-*"]``
limits a role to the robots whose names those globs match (a client of the role that
names another robot in its URL is refused before the handshake); a role without it
reaches every robot. A robot's own bridge serves one robot and ignores it.

:func:`requirement` maps an op to the (capability, name) it needs, keyed by
op type in one table, so new op classes are covered by adding a line.
"""

from __future__ import annotations

import fnmatch
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from rosbridge_core.interfaces import BridgeError
from rosbridge_core.parameters import PARAMETER_EVENTS
from rosbridge_core.protocol.names import absolute_name
from rosbridge_core.security.accounts import LimitsError, kinds_from_table

__all__ = [
    "CAPABILITIES",
    "LISTING",
    "MAY",
    "PARAMETER_LISTING",
    "Role",
    "RoleError",
    "UnsafeNameError",
    "filter_rosapi",
    "hidden_requirement",
    "requirement",
    "rosapi_requirement",
    "sees",
]

CAPABILITIES = (
    "subscribe",
    "publish",
    "call_service",
    "serve_service",
    "send_action_goal",
    "cancel_any_goal",
    "serve_action",
    "params",
    "introspection",
    "take_over",
    "clients",
)


class RoleError(BridgeError):
    """A role definition is malformed (the text names the role and the key)."""


@dataclass
class Role:
    """A named set of allowed and denied name patterns per capability."""

    name: str
    allow: dict[str, tuple[str, ...]] = field(default_factory=dict)
    deny: dict[str, tuple[str, ...]] = field(default_factory=dict)
    robots: tuple[str, ...] | None = None
    """Globs of the robots a relay lets the role reach (``None``: every robot)."""
    limits: dict[str, int] = field(default_factory=dict)
    """What each principal of the role may hold over all its connections, per kind
    (``limits.fragment_bytes``, ``limits.inflight_bytes``: :mod:`.accounts`)."""
    _cache: dict[tuple[str, str], bool] = field(default_factory=dict, repr=False)

    @classmethod
    def from_table(cls, name: str, table: Mapping[str, Any]) -> Role:
        """Build a role from its TOML table (see the module docstring)."""
        role = cls(name)
        for key, value in table.items():
            if key == "robots":
                if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                    raise RoleError(f"role {name}: robots must be a list of robot name patterns")
                role.robots = tuple(value)
            elif key == "limits":
                try:
                    role.limits = kinds_from_table(value, f"role {name}: limits")
                except LimitsError as exc:
                    raise RoleError(str(exc)) from None
            elif key == "deny":
                if not isinstance(value, Mapping):
                    raise RoleError(f"role {name}: 'deny' must be a table of capabilities")
                for dkey, dvalue in value.items():
                    role._add(role.deny, dkey, dvalue, f"deny.{dkey}")
            else:
                role._add(role.allow, key, value, key)
        return role

    def _add(self, into: dict[str, tuple[str, ...]], key: str, value: Any, where: str) -> None:
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise RoleError(f"role {self.name}: {where} must be a list of name patterns")
        caps = CAPABILITIES if key == "all" else (key,)
        if key != "all" and key not in CAPABILITIES:
            raise RoleError(
                f"role {self.name}: unknown capability {key!r} "
                f"(known: all, {', '.join(CAPABILITIES)})"
            )
        for cap in caps:
            into[cap] = into.get(cap, ()) + tuple(value)

    def allows(self, capability: str, name: str) -> bool:
        """Whether the role may use ``capability`` on ``name`` (deny wins)."""
        key = (capability, name)
        found = self._cache.get(key)
        if found is None:
            found = _matches(self.allow.get(capability, ()), name) and not _matches(
                self.deny.get(capability, ()), name
            )
            if len(self._cache) < 50_000:
                self._cache[key] = found
        return found

    def reaches(self, robot: str) -> bool:
        """Whether a relay lets this role reach ``robot`` (see the module docstring)."""
        return self.robots is None or _matches(self.robots, robot)

    def has(self, capability: str) -> bool:
        """Whether the role grants ``capability`` on some name (checks that name none).

        A deny pattern that matches every name (``*``) takes the capability away here too.
        """
        return bool(self.allow.get(capability)) and not any(
            p.strip("*") == "" for p in self.deny.get(capability, ())
        )


def _matches(patterns: tuple[str, ...], name: str) -> bool:
    return any(fnmatch.fnmatchcase(name, p) for p in patterns)



# op class -> (capability, function giving the name it acts on)
def requirement(op: Any) -> tuple[str, str] | None:
    """The (capability, name) an op needs, or ``None`` if it needs none (its class declares
    both: :attr:`~rosbridge_core.protocol.ops._OpFacts.NEEDS` and ``TARGET``). Ops that need
    none (unsubscribe, unadvertise*, service_response, set_level, ...) only touch what the
    client already owns."""
    capability = op.NEEDS
    if capability is None:
        return None
    return capability, absolute_name(op.target())


# -- names that belong to another capability --------------------------------------------------

_ACTION_PART = "/_action/"
_ACTION_SERVICES = ("send_goal", "cancel_goal", "get_result")
_ACTION_TOPICS = ("feedback", "status")
PARAMETER_SERVICES = (
    "describe_parameters",
    "get_parameter_types",
    "get_parameters",
    "list_parameters",
    "set_parameters",
    "set_parameters_atomically",
)
"""The services every rclpy/rclcpp node offers under its own name for its parameters."""


def hidden_requirement(capability: str, name: str) -> tuple[str, str]:
    """What using ``name`` with ``capability`` really needs, when the name is another
    capability's internals.

    An action ``/a`` is made of services ``/a/_action/send_goal|cancel_goal|get_result`` and
    topics ``/a/_action/feedback|status``; a node's parameters are reached through its
    services ``/node/get_parameters``, ``/node/set_parameters``, ... and reported on
    ``/parameter_events``. Calling, subscribing or publishing those as plain names must need
    the capability that governs what they do, whatever the role's ``call_service`` or
    ``subscribe`` globs say:

    - an action's services and topics need ``send_action_goal`` on the action to call or
      subscribe, ``serve_action`` on it to publish;
    - a node's parameter services need ``params`` on every parameter of the node
      (``/node:*`` must match, so ``/node:*_display`` alone is not enough);
    - ``/parameter_events`` needs ``params`` on every parameter of every node (``*:*``).
    """
    head, sep, tail = name.rpartition(_ACTION_PART)
    if sep and head:
        if capability == "call_service" and tail in _ACTION_SERVICES:
            return "send_action_goal", head
        if capability == "subscribe" and tail in _ACTION_TOPICS:
            return "send_action_goal", head
        if capability == "publish" and tail in _ACTION_TOPICS:
            return "serve_action", head
    if capability == "call_service":
        node, _, service = name.rpartition("/")
        if node and service in PARAMETER_SERVICES:
            return "params", f"{node}:*"
    if name == PARAMETER_EVENTS and capability in ("subscribe", "publish"):
        return "params", "*:*"
    return capability, name


# -- rosapi: which capability a call needs, and filtering of the lists it answers ------------

LISTING: tuple[str, str] = ("introspection", "*")
"""What listing the ROS graph needs (rosapi's lists, Foxglove's connection graph):
``introspection`` on some name (``*`` is checked as "any pattern at all", see
:meth:`Role.has`). A list answered holds only the names :func:`sees` lets the role see."""

PARAMETER_LISTING: tuple[str, str] = ("params", "*")
"""What listing the parameters of every node needs (rosapi's ``get_param_names``,
Foxglove's ``getParameters`` and ``subscribeParameterUpdates`` with no names): ``params``
on some name; the answer holds only the ``/node:param`` names the role's ``params`` match."""


def sees(role: Role | None, name: str) -> bool:
    """Whether an answer about the ROS graph may name ``name`` (a topic, service, action or
    node) to ``role``: ``introspection`` on it (no role: every name)."""
    return role is None or role.allows(LISTING[0], name)


_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


class UnsafeNameError(BridgeError):
    """A name in a request holds characters no ROS name has (the text quotes it)."""


_PARAM_SERVICES = {"/rosapi/get_param", "/rosapi/has_param", "/rosapi/set_param",
                   "/rosapi/delete_param"}
_NAME_ARGS = ("topic", "service", "node", "action")


def rosapi_requirement(service: str, args: Mapping[str, Any]) -> tuple[str, str]:
    """The (capability, name) a call to a rosapi service needs.

    Parameter services need ``params`` on ``/node:param``; lookups of one
    topic/service/node need ``introspection`` on that name; the rest (lists,
    type definitions, time) need ``introspection`` on anything (``*`` is
    checked as "any pattern at all", see :meth:`Role.has`).
    """
    for key in ("name", *_NAME_ARGS):
        value = args.get(key)
        if isinstance(value, str) and _CONTROL.search(value):
            raise UnsafeNameError(
                f"{service}: {key} {value!r} contains a control character (such as NUL); "
                "ROS names never do"
            )
    if service in MAY:  # asking about one's own role: the capability on some name
        return MAY[service], "*"
    if service in _PARAM_SERVICES:
        name = args.get("name")
        if isinstance(name, str):
            node, _, param = name.partition(":")
            return "params", f"{absolute_name(node)}:{param}"
        return "params", "*"
    if service == "/rosapi/get_param_names":
        return PARAMETER_LISTING
    for key in _NAME_ARGS:
        value = args.get(key)
        if isinstance(value, str):
            return LISTING[0], absolute_name(value)
    return LISTING


# service -> (capability, list fields filtered by the first one's names, parallel fields)
_LISTS: dict[str, tuple[str, tuple[str, ...]]] = {
    "/rosapi/topics": ("introspection", ("topics", "types")),
    "/rosapi/topics_and_raw_types": ("introspection", ("topics", "types", "typedefs_full_text")),
    "/rosapi/topics_for_type": ("introspection", ("topics",)),
    "/rosapi/services": ("introspection", ("services",)),
    "/rosapi/services_for_type": ("introspection", ("services",)),
    "/rosapi/nodes": ("introspection", ("nodes",)),
    "/rosapi/publishers": ("introspection", ("publishers",)),
    "/rosapi/subscribers": ("introspection", ("subscribers",)),
    "/rosapi/publishers_qos": ("introspection", ("publishers", "qos")),
    "/rosapi/action_servers": ("introspection", ("action_servers",)),
    "/rosapi/get_param_names": ("params", ("names",)),
}
MAY = {f"/rosapi/may_{c}": c for c in ("publish", "call_service", "send_action_goal", "params")}
"""rosapi services answering which of the names asked the role may use with one capability
(an MCP server offers tools for those only): the handler echoes the names and
:func:`filter_rosapi` keeps those the gate would let through (read-only; asking needs the
capability on some name, so a role without it is refused at once)."""
_INDEPENDENT = {"/rosapi/node_details": ("subscribing", "publishing", "services")}
_LOOKUPS = {"/rosapi/service_node": "node"}
"""Answers naming one node: blanked (as for an unknown name) if the role may not see it."""


def filter_rosapi(role: Role, service: str, values: dict[str, Any]) -> dict[str, Any]:
    """A rosapi answer with only the names ``role`` may see."""
    asked = MAY.get(service)
    if asked is not None:
        names = values.get("names")
        if isinstance(names, list):
            values = {**values, "names": [
                n for n in names if role.allows(*hidden_requirement(asked, str(n)))]}
        return values
    entry = _LISTS.get(service)
    if entry is not None:
        capability, fields = entry
        names = values.get(fields[0])
        if isinstance(names, list):
            keep = [i for i, n in enumerate(names) if role.allows(capability, str(n))]
            values = dict(values)
            for f in fields:
                column = values.get(f)
                if isinstance(column, list) and len(column) == len(names):
                    values[f] = [column[i] for i in keep]
        return values
    field_name = _LOOKUPS.get(service)
    if field_name is not None:
        found = values.get(field_name)
        if isinstance(found, str) and found and not sees(role, found):
            values = {**values, field_name: ""}
        return values
    independent = _INDEPENDENT.get(service)
    if independent is not None:
        values = dict(values)
        for f in independent:
            column = values.get(f)
            if isinstance(column, list):
                values[f] = [n for n in column if sees(role, str(n))]
    return values
