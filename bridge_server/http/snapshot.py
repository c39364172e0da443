"""What one bridge process is doing right now, as JSON-able data, and how workers' merge.

:func:`take` reads the live state (sessions, their subscriptions and queues,
the shared ROS subscriptions, served services) plus the process's
:class:`~bridge_server.http.metrics.BridgeMetrics`. It runs on the loop thread, at most
once per request of ``/metrics`` or ``/status.json`` (and a per-topic subset
once a second for the rates), never per message. :func:`merge` combines the
snapshots of several workers into one view of the whole bridge.

Actions: ``actions`` lists the actions clients serve (``served_by`` a client
id) or send goals to (``served_by`` ``ROS``), with their types and the goals in
flight. An action served in ROS stays listed while ``action_goals`` counts
goals of it, with its type from the ROS graph (which lists the goal service
while a server offers it or the bridge's action client for it is kept;
``None`` after both are gone).
"""

from __future__ import annotations

import os
from collections.abc import Collection, Iterable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from bridge_server.http.metrics import add_timing
from bridge_server.http.rates import merge_history
from bridge_server.http.status import COUNTERS, BridgeStatus

if TYPE_CHECKING:
    from bridge_server.http.metrics import BridgeMetrics
    from rosbridge_core.graph import Graph
    from rosbridge_core.session.client_status import ClientStatus
    from rosbridge_core.session.outbox import TopicQueue
    from rosbridge_core.session.ownership import Ownership
    from rosbridge_core.session.resume import SessionStore

__all__ = ["Observed", "Reporting", "merge", "take", "topic_totals"]


class Subscribed(Protocol):
    """A session's topics, as far as the status goes."""

    @property
    def subs(self) -> Mapping[str, TopicQueue]:
        """Its subscriptions, by topic."""


class Reporting(Protocol):
    """A session as the status reads it (a rosbridge or a Foxglove one)."""

    @property
    def sid(self) -> int:
        """The client's id."""

    @property
    def topics(self) -> Subscribed:
        """What it subscribes to."""

    def describe(self, worker: int) -> ClientStatus:
        """Its typed status in worker ``worker``."""


class Sessions(Protocol):
    """Where a kind of session is kept (the Foxglove hub)."""

    @property
    def sessions(self) -> Collection[Reporting]:
        """The live sessions."""


class Forwarding(Protocol):
    """The worker machinery, as far as the status goes."""

    forwarded: int
    """Session resumes handed to the worker that keeps them."""


class Worker(Protocol):
    """The settings the status names."""

    @property
    def worker_index(self) -> int:
        """This process's index among the workers."""


class Observed(Protocol):
    """What the status reads of a bridge (:class:`~bridge_server.front.server.Bridge`)."""

    @property
    def metrics(self) -> BridgeMetrics:
        """The counters."""

    @property
    def graph(self) -> Graph:
        """The ROS side."""

    @property
    def config(self) -> Worker:
        """The settings."""

    @property
    def sessions(self) -> Collection[Reporting]:
        """The rosbridge sessions."""

    @property
    def foxglove(self) -> Sessions:
        """The Foxglove sessions."""

    @property
    def service_owners(self) -> Ownership[Any]:
        """Who serves which service."""

    @property
    def resumable(self) -> SessionStore[Any]:
        """The sessions kept for a resume."""

    @property
    def forwarder(self) -> Forwarding | None:
        """With ``--workers``: the hand-over of resumes."""

_GOAL_SERVICE = "/_action/send_goal"


def topic_totals(bridge: Observed) -> dict[str, dict[str, Any]]:
    """Per-topic counters of this process (closed objects' counts included; ``in_use``
    marks topics a client or the bridge's ROS side uses now)."""
    topics: dict[str, dict[str, Any]] = {}
    for name, counts in bridge.metrics.retired.items():
        topics[name] = dict(counts)
    for name, shared in bridge.graph.subscriptions.items():
        t = topics.setdefault(name, {})
        t["ros_received"] = t.get("ros_received", 0) + shared.received
        if shared.type_name is not None:
            t["type"] = shared.type_name
    for name, _type, _latch in bridge.graph.publishers:
        t = topics.setdefault(name, {})
        t.setdefault("type", _type)
        t["bridge_publishers"] = t.get("bridge_publishers", 0) + 1
    for name in bridge.graph.subscriptions:
        topics[name]["in_use"] = True
    for name, _type, _latch in bridge.graph.publishers:
        topics[name]["in_use"] = True
    every: list[Reporting] = [*bridge.sessions, *bridge.foxglove.sessions]
    for session in every:
        for sub in session.topics.subs.values():
            t = topics.setdefault(sub.topic, {})
            t["in_use"] = True
            t["subscribers"] = t.get("subscribers", 0) + 1
            t["sent"] = t.get("sent", 0) + sub.sent
            t["sent_bytes"] = t.get("sent_bytes", 0) + sub.sent_bytes
            t["drops"] = t.get("drops", 0) + sub.dropped_total
    return topics


def take(bridge: Observed, rates: Mapping[str, Mapping[str, float]]) -> dict[str, Any]:
    """This process's snapshot (see the module docstring)."""
    from rosbridge_core import __version__

    rec = bridge.metrics
    worker = bridge.config.worker_index
    topics = topic_totals(bridge)
    for name, r in rates.items():
        if name in topics:
            topics[name].update(r)
    every: list[Reporting] = [*bridge.sessions, *bridge.foxglove.sessions]
    clients = tuple(session.describe(worker) for session in sorted(every, key=lambda s: s.sid))
    services = [
        {"name": name, "type": served.type_name, "served_by": f"{worker}-{owner.session.sid}"}
        for name, owner in bridge.service_owners.items()
        if (served := owner.served.get(name)) is not None
    ]
    return BridgeStatus(
        version=__version__,
        worker=worker,
        workers=[
            {
                "index": worker,
                "pid": os.getpid(),
                "node": bridge.graph.name,
                "started": rec.started,
                "clients": len(clients),
            }
        ],
        started=rec.started,
        connections=rec.connections,
        sessions_resumed=bridge.resumable.resumed,
        sessions_expired=bridge.resumable.expired,
        sessions_forwarded=0 if bridge.forwarder is None else bridge.forwarder.forwarded,
        refused=dict(rec.refused),
        errors=dict(rec.errors),
        service_calls=rec.services.data,
        action_goals=rec.actions.data,
        topics=topics,
        clients=clients,
        services=services,
        actions=_actions(bridge),
    ).to_json()


def _actions(bridge: Observed) -> list[dict[str, Any]]:
    """Actions in use through this process: served by a client, or called by one."""
    worker = bridge.config.worker_index
    found: dict[str, dict[str, Any]] = {}
    for session in bridge.sessions:
        acts = getattr(session, "actions", None)
        for name, served in getattr(acts, "served", {}).items():
            a = found.setdefault(name, {"name": name, "type": served.type_name, "goals": 0})
            a["served_by"] = f"{worker}-{session.sid}"
            a["goals"] += len(served.goals)
        for goal in getattr(acts, "goals", {}).values():
            a = found.setdefault(goal.name, {"name": goal.name, "type": goal.type_name,
                                             "served_by": "ROS", "goals": 0})
            a["goals"] += 1
    counted = [name for name in bridge.metrics.actions.data if name not in found]
    if counted:  # no goal of these is in flight: the graph knows their types
        types = _graph_action_types(bridge)
        for name in counted:
            found[name] = {"name": name, "type": types.get(name), "served_by": "ROS",
                           "goals": 0}
    return [found[k] for k in sorted(found)]


def _graph_action_types(bridge: Observed) -> dict[str, str]:
    """Action name -> type of the actions the ROS graph lists a goal service of (served,
    or only called)."""
    types = {}
    for service, service_types in bridge.graph.service_names_and_types():
        if service.endswith(_GOAL_SERVICE) and service_types:
            types[service.removesuffix(_GOAL_SERVICE)] = service_types[0].removesuffix(
                "_SendGoal")
    return types


_MAX_FIELDS = ("ros_received_per_s",)  # each worker receives the same ROS stream


def merge(snaps: Iterable[Mapping[str, Any]]) -> dict[str, Any]:
    """One view of several workers: counts add up, lists join, ROS input rates take the max."""
    snaps = list(snaps)
    if len(snaps) == 1:
        return dict(snaps[0])
    out: dict[str, Any] = {
        "version": snaps[0]["version"],
        "worker": snaps[0]["worker"],
        "workers": [],
        "started": min(s["started"] for s in snaps),
        **dict.fromkeys((c.name for c in COUNTERS), 0),
        "refused": {},
        "errors": {},
        "service_calls": {},
        "action_goals": {},
        "topics": {},
        "clients": [],
        "services": [],
        "actions": [],
    }
    for s in snaps:
        for c in COUNTERS:
            out[c.name] += s.get(c.name, 0)
        for key in ("workers", "clients", "services"):
            out[key].extend(s[key])
        _add_actions(out["actions"], s["actions"])
        for key in ("refused", "errors"):
            _add(out[key], s[key])
        for key in ("service_calls", "action_goals"):
            for name, entry in s[key].items():
                add_timing(out[key], name, entry)
        for name, t in s["topics"].items():
            acc = out["topics"].setdefault(name, {})
            for field, v in t.items():
                if field == "type":
                    acc.setdefault("type", v)
                elif field in _MAX_FIELDS:
                    acc[field] = max(acc.get(field, 0), v)
                else:
                    acc[field] = acc.get(field, 0) + v
    history = merge_history(s.get("history") for s in snaps)
    if history is not None:
        out["history"], out["rate_window_s"] = history, snaps[0].get("rate_window_s")
    out["workers"].sort(key=lambda w: w["index"])
    out["clients"].sort(key=lambda c: (c["worker"], c["sid"]))
    out["services"].sort(key=lambda sv: sv["name"])
    return out


def _add_actions(into: list[dict[str, Any]], more: Iterable[Mapping[str, Any]]) -> None:
    """Join workers' action lists: one entry per action, goals in flight added up, the
    type any worker knows, served by a client if one serves it."""
    by_name = {a["name"]: a for a in into}
    for a in more:
        acc = by_name.get(a["name"])
        if acc is None:
            acc = by_name[a["name"]] = dict(a)
            into.append(acc)
            continue
        acc["goals"] += a["goals"]
        acc["type"] = acc["type"] or a["type"]
        if acc["served_by"] == "ROS":
            acc["served_by"] = a["served_by"]
    into.sort(key=lambda a: a["name"])


def _add(into: dict[str, Any], more: Mapping[str, Any]) -> None:
    for k, v in more.items():
        into[k] = into.get(k, 0) + v
